// The documentation's links: every relative link and picture in README.md,
// CONTRIBUTING.md, docs/*.md and the libraries' READMEs names a file that
// exists (web addresses and in-page anchors are not followed; a link's own
// #anchor is dropped); and docs/configuration.md documents exactly the keys
// of configs/base.json.
#include <catch2/catch.hpp>
#include <filesystem>
#include <regex>
#include <sstream>
#include <string>
#include <set>
#include <vector>

#include "common/atomic_file.h"
#include "common/json_reader.h"
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
    const std::string text = read_text_file(page.string());
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

namespace {
// The dotted paths of the leaves of `j` (values that are not objects; keys
// starting with '_' are comments).
void leaf_keys(const Json& j, const std::string& prefix, std::set<std::string>& out) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!it.key().empty() && it.key()[0] == '_') continue;
    const std::string path = prefix.empty() ? it.key() : prefix + "." + it.key();
    if (it->is_object())
      leaf_keys(*it, path, out);
    else
      out.insert(path);
  }
}

// The keys of docs/configuration.md's reference tables: the first cell of
// every table row that starts with "| `".
std::set<std::string> documented_keys(const std::string& text) {
  std::set<std::string> keys;
  const std::regex row(R"(^\| `([A-Za-z0-9_.]+)` \|)");
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::smatch m;
    if (std::regex_search(line, m, row)) keys.insert(m[1].str());
  }
  return keys;
}
}  // namespace

TEST_CASE("docs: docs/configuration.md has a row for every key of configs/base.json and no other", "[docs]") {
  const Json base = load_json_with_extends(test::source_path("configs/base.json"));
  std::set<std::string> keys;
  leaf_keys(base, "", keys);
  const std::set<std::string> documented = documented_keys(read_text_file(test::source_path("docs/configuration.md")));
  std::string missing, extra;
  for (const auto& k : keys)
    if (!documented.count(k)) missing += k + " ";
  for (const auto& k : documented)
    if (!keys.count(k)) extra += k + " ";
  INFO("keys of base.json without a row in docs/configuration.md: " << missing);
  CHECK(missing.empty());
  INFO("rows of docs/configuration.md that are not keys of base.json: " << extra);
  CHECK(extra.empty());
  CHECK(keys.size() > 150);  // the walk reaches the nested sections
  // The check can fail: a row for a key that does not exist is found.
  CHECK(documented_keys("| `optics.no_such_key` | 1 | x |\n| `seed` | 0 | y |\n") ==
        std::set<std::string>{"optics.no_such_key", "seed"});
}
