// The libraries' dependency direction, read from the sources' #include lines:
// apps -> train -> {model, data, optics, viz} -> common, with data -> optics
// (spectral tables) and viz -> optics (display colours) only. A library that
// includes a header from above it fails here, naming the file and the line.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <regex>
#include <set>
#include <string>

#include "helpers.h"

namespace fs = std::filesystem;
using namespace hsd;

TEST_CASE("layout: every library includes only itself and the libraries below it", "[layout]") {
  const std::map<std::string, std::set<std::string>> allowed{
      {"common", {"common"}},
      {"optics", {"common", "optics"}},
      {"viz", {"common", "optics", "viz"}},
      {"data", {"common", "optics", "data"}},
      {"model", {"common", "model"}},
      {"train", {"common", "optics", "data", "model", "viz", "train"}},
  };
  const std::regex include(R"re(^\s*#\s*include\s*"([a-z_]+)/)re");
  int64_t files = 0, includes = 0;
  for (const auto& [lib, ok] : allowed) {
    const fs::path dir = test::source_path(lib);
    REQUIRE(fs::is_directory(dir));
    for (const auto& e : fs::directory_iterator(dir)) {
      const std::string ext = e.path().extension().string();
      if (ext != ".h" && ext != ".cpp") continue;
      ++files;
      std::ifstream in(e.path());
      std::string line;
      for (int n = 1; std::getline(in, line); ++n) {
        std::smatch m;
        if (!std::regex_search(line, m, include)) continue;
        ++includes;
        INFO(e.path().filename().string() << ":" << n << ": " << line);
        CHECK(ok.count(m[1].str()) == 1);
      }
    }
  }
  CHECK(files > 100);
  CHECK(includes > 200);
}

TEST_CASE("layout: no test name holds a semicolon (CMake splits a discovered name there into two tests that both fail)",
          "[layout]") {
  const std::regex test_case(R"re(TEST_CASE\(\s*"([^"]*)")re");
  int64_t names = 0;
  for (const auto& e : fs::recursive_directory_iterator(test::source_path("tests"))) {
    if (e.path().extension() != ".cpp") continue;
    std::ifstream in(e.path());
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (std::sregex_iterator it(text.begin(), text.end(), test_case), end; it != end; ++it) {
      ++names;
      INFO(e.path().filename().string() << ": \"" << (*it)[1].str() << "\"");
      CHECK((*it)[1].str().find(';') == std::string::npos);
    }
  }
  CHECK(names > 100);
}
