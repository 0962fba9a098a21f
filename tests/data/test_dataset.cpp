// Loading a dataset (data/dataset.h): parallel, deterministic, resampling
// other bands; ensure_dataset generating on first use only when allowed
// (data/synthetic_dataset.h).
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "common/error.h"
#include "common/log.h"
#include "data/dataset.h"
#include "data/manifest.h"
#include "data/synthetic_dataset.h"
#include "helpers.h"
#include "scene_helpers.h"

using namespace hsd;
namespace fs = std::filesystem;
using test::nm;
using test::flat_scene;

TEST_CASE("data: loading is parallel and deterministic and resamples other bands", "[data]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_loader";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto w = nm({450, 550, 650});
  data::Manifest m;
  for (int i = 0; i < 5; ++i) {
    const std::string f = "s" + std::to_string(i) + ".exr";
    data::SpectralScene s = flat_scene(i == 3 ? nm({440, 500, 560, 620, 680}) : w, 6, 7, 0.1 * (i + 1), 1.0 + i);
    data::write_scene_exr((dir / f).string(), s);
    m.scenes.push_back({f, i == 4 ? "val" : "train", ""});
  }
  data::write_manifest(dir.string(), m);
  const auto a = data::load_split(dir.string(), "train", w, 10e-9, 3);
  REQUIRE(a.size() == 4);
  for (size_t i = 0; i < 4; ++i) {
    CHECK(a[i].file == "s" + std::to_string(i) + ".exr");
    CHECK(a[i].scene.spectral.size(0) == 3);
    CHECK(a[i].scene.spectral.mean().item<double>() == Approx(0.1 * double(i + 1)).epsilon(1e-3));
  }
  const auto serial = data::load_split(dir.string(), "train", w, 10e-9, 1);
  for (size_t i = 0; i < 4; ++i) CHECK(serial[i].scene.spectral.equal(a[i].scene.spectral));  // same with 1 or 3 threads
  CHECK(data::load_split(dir.string(), "val", w, 10e-9, 2).size() == 1);
  CHECK_THROWS_AS(data::load_split(dir.string(), "test", w, 10e-9, 2), InputError);
  // A broken scene is reported by name.
  std::ofstream(dir / "s2.exr", std::ios::trunc) << "truncated";
  try {
    data::load_split(dir.string(), "all", w, 10e-9, 3);
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("s2.exr"));
  }
}

TEST_CASE("data: ensure_dataset generates on first use only when the config allows it", "[data][generator]") {
  const fs::path root = fs::temp_directory_path() / "hsd_test_ensure";
  fs::remove_all(root);
  const std::vector<std::string> small{"data.root=\"" + root.string() + "\"", "data.generator.train_scenes=1",
                                       "data.generator.val_scenes=0", "data.generator.test_scenes=0",
                                       "data.generator.colorchecker=false", "data.generator.width_px=40",
                                       "data.generator.height_px=32"};
  auto with = [&](const std::string& extra) {
    auto o = small;
    o.push_back(extra);
    return load_config(test::source_path("configs/tiny.json"), o);
  };
  try {
    data::ensure_dataset(with("data.generate_if_missing=false"));
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("data.root"));
  }
  CHECK_FALSE(fs::exists(root / "manifest.json"));
  CHECK(data::ensure_dataset(with("data.generate_if_missing=true")) == root.string());
  const data::Manifest m = data::read_manifest(root.string());
  REQUIRE(m.scenes.size() == 1);
  CHECK(m.scenes[0].split == "train");
  const auto loaded = data::load_split(root.string(), "train", with("seed=0").optics.wavelengths_m(), 100e-9, 1);
  CHECK(loaded[0].scene.spectral.sizes() == torch::IntArrayRef({3, 32, 40}));
  // The same settings again, or only another seed (runs of several seeds share
  // one dataset): the folder is used as it is (nothing rewritten).
  const auto t0 = fs::last_write_time(root / "manifest.json");
  const int w0 = log::warning_count();
  data::ensure_dataset(with("data.generate_if_missing=true"));
  data::ensure_dataset(with("seed=7"));
  CHECK(fs::last_write_time(root / "manifest.json") == t0);
  CHECK(log::warning_count() == w0);
  // Other generator settings: the generator's own folder is made again, with a warning.
  data::ensure_dataset(with("data.generator.layouts={\"dead_leaves\":1,\"tabletop\":0,\"classic_tabletop\":0}"));
  CHECK(log::warning_count() == w0 + 1);
  CHECK_THAT(data::read_manifest(root.string()).scenes[0].notes, Catch::StartsWith("dead leaves"));
  // What hsd_scenes wrote is the user's output: other settings give a warning, never a replacement.
  const fs::path mine = fs::temp_directory_path() / "hsd_test_ensure_scenes";
  fs::remove_all(mine);
  auto at_mine = [&](const std::string& extra) {
    auto o = small;
    o.push_back("data.root=\"" + mine.string() + "\"");
    o.push_back(extra);
    return load_config(test::source_path("configs/tiny.json"), o);
  };
  data::generate_dataset(at_mine("seed=0"), mine.string());  // as hsd_scenes does
  const auto t1 = fs::last_write_time(mine / "manifest.json");
  data::ensure_dataset(at_mine("data.generator.texture_scale_max=1.0"));
  CHECK(log::warning_count() == w0 + 2);
  CHECK(fs::last_write_time(mine / "manifest.json") == t1);
  // A garbled generator.json: a warning, nothing replaced.
  std::ofstream(root / "generator.json") << "[1, 2";
  const auto t2 = fs::last_write_time(root / "manifest.json");
  data::ensure_dataset(with("data.generator.texture_scale_max=1.1"));
  CHECK(log::warning_count() == w0 + 3);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  // An earlier hsd's generated folder (colorchecker_layout.json, no generator.json): a warning, nothing replaced.
  fs::remove(root / "generator.json");
  std::ofstream(root / "colorchecker_layout.json") << "{}";
  data::ensure_dataset(with("data.generator.texture_scale_max=1.2"));
  CHECK(log::warning_count() == w0 + 4);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  // A dataset the generator did not write is never replaced, and nothing is said.
  fs::remove(root / "colorchecker_layout.json");
  data::ensure_dataset(with("data.generator.texture_scale_max=1.2"));
  CHECK(log::warning_count() == w0 + 4);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  CHECK_THAT(data::read_manifest(root.string()).scenes[0].notes, Catch::StartsWith("dead leaves"));
}
