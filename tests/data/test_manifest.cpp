// The dataset manifest (data/manifest.h): round trip, and bad manifests
// refused naming the entry.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "common/error.h"
#include "data/manifest.h"
#include "helpers.h"

using namespace hsd;
namespace fs = std::filesystem;

TEST_CASE("data: manifests round-trip and bad manifests are refused naming the entry", "[data]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_manifest";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "a.exr") << "x";
  std::ofstream(dir / "b.exr") << "x";
  data::Manifest m;
  m.wavelengths_nm = {450, 550};
  m.band_width_nm = 100;
  m.scenes = {{"a.exr", "train", "first"}, {"b.exr", "test", ""}};
  data::write_manifest(dir.string(), m);
  const data::Manifest r = data::read_manifest(dir.string());
  REQUIRE(r.scenes.size() == 2);
  CHECK(r.scenes[0].notes == "first");
  CHECK(r.split("test").size() == 1);
  CHECK(r.wavelengths_nm == m.wavelengths_nm);
  auto refused = [&](const std::string& json, const std::string& needle) {
    std::ofstream(dir / "manifest.json") << json;
    try {
      data::read_manifest(dir.string());
      return std::string("accepted");
    } catch (const InputError& e) {
      const std::string w = e.what();
      return w.find("manifest.json") != std::string::npos && w.find(needle) != std::string::npos ? std::string("ok") : w;
    }
  };
  CHECK(refused(R"({"scenes":[{"file":"a.exr","split":"training"}]})", "scenes[0].split") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"c.exr","split":"train"}]})", "missing file c.exr") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"a.exr","split":"train"},{"file":"a.exr","split":"val"}]})", "twice") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"/etc/passwd","split":"train"}]})", "relative path") == "ok");
  CHECK(refused(R"({"scenes": 3})", "scenes") == "ok");
  CHECK(refused("{not json", "invalid JSON") == "ok");
  CHECK(refused(R"({"scenes":[]})", "no scenes") == "ok");
  fs::remove(dir / "manifest.json");
  CHECK_THROWS_AS(data::read_manifest(dir.string()), InputError);
}
