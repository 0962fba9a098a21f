// The documentation's links: every relative link and picture in README.md,
// CONTRIBUTING.md, docs/*.md and the libraries' READMEs names a file that
// exists, and every #anchor (in-page or on another page) names a heading of
// its page, slugged as GitHub does (web addresses are not followed); and
// docs/configuration.md documents exactly the keys of configs/base.json, with
// their defaults.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
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

namespace {
// GitHub's anchor of a heading: lower case; letters, digits, '_' and '-'
// kept, spaces to '-', every other character dropped. Non-ASCII: Latin and
// Greek letters are kept, everything else (×, ², ±, dashes, arrows, quotes)
// is dropped, which covers the characters these pages use.
std::string heading_slug(const std::string& heading) {
  std::string out;
  for (size_t i = 0; i < heading.size();) {
    const unsigned char c = static_cast<unsigned char>(heading[i]);
    if (c < 0x80) {
      if (std::isalnum(c) || c == '_' || c == '-') out += char(std::tolower(c));
      else if (c == ' ') out += '-';
      ++i;
      continue;
    }
    const size_t n = c >= 0xF0 ? 4 : c >= 0xE0 ? 3 : 2;  // UTF-8 sequence length
    uint32_t cp = c & (n == 2 ? 0x1F : n == 3 ? 0x0F : 0x07);
    for (size_t k = 1; k < n && i + k < heading.size(); ++k) cp = (cp << 6) | (heading[i + k] & 0x3F);
    const bool latin = cp >= 0xC0 && cp <= 0x24F && cp != 0xD7 && cp != 0xF7;
    const bool greek = cp >= 0x391 && cp <= 0x3C9;
    if (latin || greek) out += heading.substr(i, n);  // kept as written (these pages use lower case there)
    i += n;
  }
  return out;
}

// The anchors of a page's headings (outside fenced code), with GitHub's
// "-1", "-2" suffixes for repeats.
std::set<std::string> page_anchors(const std::string& text) {
  std::set<std::string> anchors;
  std::map<std::string, int> seen;
  std::istringstream in(text);
  bool fenced = false;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("```", 0) == 0) fenced = !fenced;
    if (fenced || line.empty() || line[0] != '#') continue;
    const size_t start = line.find_first_not_of('#');
    if (start == std::string::npos || line[start] != ' ') continue;
    const std::string slug = heading_slug(line.substr(start + 1));
    const int k = seen[slug]++;
    anchors.insert(k == 0 ? slug : slug + "-" + std::to_string(k));
  }
  return anchors;
}
}  // namespace

TEST_CASE("docs: headings slug as GitHub anchors them", "[docs]") {
  CHECK(heading_slug("What the test scenes' depth allows") == "what-the-test-scenes-depth-allows");
  CHECK(heading_slug("The DOE ablation (`hsd_ablate`, `configs/ablation_quick.json`)") ==
        "the-doe-ablation-hsd_ablate-configsablation_quickjson");
  CHECK(heading_slug("Depth ≤ 0.5× the constant") == "depth--05-the-constant");
  const std::set<std::string> a = page_anchors("# Top\n```sh\n# not a heading\n```\n## Top\n#not\n");
  CHECK(a == std::set<std::string>{"top", "top-1"});
}

TEST_CASE("docs: every relative link in the README, CONTRIBUTING, docs/ and the library READMEs resolves", "[docs]") {
  const fs::path root = test::source_path("");
  std::vector<fs::path> pages{root / "README.md", root / "CONTRIBUTING.md"};
  for (const auto& e : fs::directory_iterator(root / "docs"))
    if (e.path().extension() == ".md") pages.push_back(e.path());
  for (const char* lib : {"common", "optics", "data", "model", "viz", "train", "apps"})
    if (fs::exists(root / lib / "README.md")) pages.push_back(root / lib / "README.md");
  const std::regex link(R"(\]\(([^)\s]+)\))");
  int checked = 0, anchored = 0;
  for (const auto& page : pages) {
    const std::string text = read_text_file(page.string());
    for (auto it = std::sregex_iterator(text.begin(), text.end(), link); it != std::sregex_iterator(); ++it) {
      std::string target = (*it)[1].str();
      if (target.rfind("http://", 0) == 0 || target.rfind("https://", 0) == 0 || target.rfind("mailto:", 0) == 0)
        continue;
      const size_t hash = target.find('#');
      const std::string anchor = hash == std::string::npos ? "" : target.substr(hash + 1);
      target = target.substr(0, hash);
      const fs::path file = target.empty() ? page : page.parent_path() / target;
      INFO(page.string() << " links to " << (*it)[1].str());
      CHECK(fs::exists(file));
      ++checked;
      if (!anchor.empty() && fs::exists(file) && file.extension() == ".md") {
        CHECK(page_anchors(read_text_file(file.string())).count(anchor) == 1);
        ++anchored;
      }
    }
  }
  CHECK(checked > 20);  // the pattern finds the links (the README alone has more)
  CHECK(anchored >= 4);  // and the anchored ones (four when this was written)
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

// The value at a dotted path of `j`.
const Json& at_path(const Json& j, const std::string& path) {
  const Json* v = &j;
  std::istringstream parts(path);
  for (std::string part; std::getline(parts, part, '.');) v = &v->at(part);
  return *v;
}

// Whether a documented default equals the config's value: numbers to the
// six significant digits the table prints, arrays element by element.
bool same_default(const Json& documented, const Json& actual) {
  if (documented.is_number() && actual.is_number()) {
    const double a = documented.get<double>(), b = actual.get<double>();
    return std::abs(a - b) <= 2e-6 * std::max(std::abs(a), std::abs(b)) + 1e-300;
  }
  if (documented.is_array() && actual.is_array()) {
    if (documented.size() != actual.size()) return false;
    for (size_t i = 0; i < documented.size(); ++i)
      if (!same_default(documented[i], actual[i])) return false;
    return true;
  }
  return documented == actual;
}

// The rows' defaults: key -> the second cell's first `code` span, when the
// cell is only that span (a cell with more, e.g. "`[420, …]` (25 values)",
// abbreviates and is not compared).
std::map<std::string, std::string> documented_defaults(const std::string& text) {
  std::map<std::string, std::string> out;
  const std::regex row(R"(^\| `([A-Za-z0-9_.]+)` \| `([^`]*)` \|)");
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::smatch m;
    if (std::regex_search(line, m, row)) out[m[1].str()] = m[2].str();
  }
  return out;
}
}  // namespace

TEST_CASE("docs: docs/configuration.md gives each key the default of configs/base.json", "[docs]") {
  const Json base = load_json_with_extends(test::source_path("configs/base.json"));
  const auto defaults = documented_defaults(read_text_file(test::source_path("docs/configuration.md")));
  int compared = 0;
  for (const auto& [key, cell] : defaults) {
    Json documented;
    try {
      documented = Json::parse(cell);
    } catch (const std::exception&) {
      continue;  // not JSON (an abbreviation): not compared
    }
    INFO(key << ": documented default " << cell << ", configs/base.json " << at_path(base, key).dump());
    CHECK(same_default(documented, at_path(base, key)));
    ++compared;
  }
  CHECK(compared > 150);  // nearly every row is compared
  // The check can fail: a wrong default is seen as one.
  CHECK_FALSE(same_default(Json::parse("0.05"), Json::parse("0.5")));
  CHECK_FALSE(same_default(Json::parse("[1, 2]"), Json::parse("[1, 3]")));
  CHECK(same_default(Json::parse("0.461538"), Json::parse("0.46153846153846156")));
}

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
