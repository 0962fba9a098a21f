// The documentation's links: every relative link and picture in README.md,
// CONTRIBUTING.md, docs/*.md and the libraries' READMEs names a file that
// exists (web addresses and in-page anchors are not followed; a link's own
// #anchor is dropped).
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "helpers.h"

namespace fs = std::filesystem;
using namespace hsd;

TEST_CASE("docs: every relative link in the README, CONTRIBUTING, docs/ and the library READMEs resolves", "[docs]") {
  const fs::path root = test::source_path("");
  std::vector<fs::path> pages{root / "README.md", root / "CONTRIBUTING.md"};
  for (const auto& e : fs::directory_iterator(root / "docs"))
    if (e.path().extension() == ".md") pages.push_back(e.path());
  for (const char* lib : {"common", "optics", "data", "model", "viz", "train", "apps"})
    if (fs::exists(root / lib / "README.md")) pages.push_back(root / lib / "README.md");
  const std::regex link(R"(\]\(([^)\s]+)\))");
  int checked = 0;
  for (const auto& page : pages) {
    std::ifstream f(page);
    REQUIRE(f);
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string text = ss.str();
    for (auto it = std::sregex_iterator(text.begin(), text.end(), link); it != std::sregex_iterator(); ++it) {
      std::string target = (*it)[1].str();
      if (target.rfind("http://", 0) == 0 || target.rfind("https://", 0) == 0 || target.rfind("mailto:", 0) == 0 ||
          target[0] == '#')
        continue;
      target = target.substr(0, target.find('#'));
      INFO(page.string() << " links to " << target);
      CHECK(fs::exists(page.parent_path() / target));
      ++checked;
    }
  }
  CHECK(checked > 20);  // the pattern finds the links (the README alone has more)
}
