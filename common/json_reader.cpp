#include "common/json_reader.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "common/error.h"

namespace hsd {
namespace fs = std::filesystem;

namespace {

// Deeper documents are refused at parse time: a config is a few levels deep,
// and nlohmann copies and merges recursively, so a document nested 10^5 levels
// would overflow the stack.
constexpr int kMaxJsonDepth = 64;

struct TooDeep {};

// Parses text; throws TooDeep beyond kMaxJsonDepth and nlohmann's exceptions
// (parse_error for bad syntax or invalid UTF-8, out_of_range for numbers no
// double holds, e.g. 1e400).
Json parse_bounded(const std::string& text) {
  Json::parser_callback_t cb = [](int depth, Json::parse_event_t, Json&) {
    if (depth > kMaxJsonDepth) throw TooDeep{};
    return true;
  };
  return Json::parse(text, cb);
}

void deep_merge(Json& base, const Json& over) {
  if (!base.is_object() || !over.is_object()) {
    base = over;
    return;
  }
  for (auto it = over.begin(); it != over.end(); ++it) {
    if (base.contains(it.key()) && base[it.key()].is_object() && it.value().is_object())
      deep_merge(base[it.key()], it.value());
    else
      base[it.key()] = it.value();
  }
}

Json load_rec(const fs::path& path, std::vector<fs::path>& chain) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) input_error(path.string(), "config file not found");
  const fs::path canon = fs::weakly_canonical(path, ec);
  for (const auto& p : chain)
    if (p == canon) input_error(path.string(), "\"extends\" forms a cycle");
  chain.push_back(canon);
  Json j = read_json_file(path.string());
  if (!j.is_object()) input_error(path.string(), "a config must be a JSON object");
  if (j.contains("extends")) {
    if (!j["extends"].is_string()) input_error(path.string() + ": extends", "must be a file name");
    const fs::path parent = path.parent_path() / j["extends"].get<std::string>();
    Json base = load_rec(parent, chain);
    j.erase("extends");
    deep_merge(base, j);
    j = std::move(base);
  }
  chain.pop_back();
  return j;
}

std::string type_name(const Json& j) {
  if (j.is_null()) return "null";
  if (j.is_boolean()) return "a boolean";
  if (j.is_number()) return "a number";
  if (j.is_string()) return "a string";
  if (j.is_array()) return "an array";
  return "an object";
}

}  // namespace

Json parse_json_text(const std::string& text, const std::string& what) {
  try {
    return parse_bounded(text);
  } catch (const TooDeep&) {
    input_error(what, "JSON nested more than " + std::to_string(kMaxJsonDepth) + " levels deep");
  } catch (const Json::out_of_range& e) {
    input_error(what, std::string("a number out of the range of a double (") + e.what() + ")");
  } catch (const Json::exception& e) {
    input_error(what, std::string("invalid JSON (") + e.what() + ")");
  }
}

Json read_json_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) input_error(path, std::string("cannot read (") + std::strerror(errno) + ")");
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) input_error(path, std::string("cannot read (") + std::strerror(errno) + ")");
  return parse_json_text(text, path);
}

Json load_json_with_extends(const std::string& path) {
  std::vector<fs::path> chain;
  return load_rec(fs::path(path), chain);
}

void apply_override(Json& root, const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    input_error("--set " + assignment, "expected dotted.key=VALUE");
  const std::string key = assignment.substr(0, eq);
  const std::string text = assignment.substr(eq + 1);
  Json value;
  try {
    value = parse_bounded(text);
  } catch (const TooDeep&) {
    input_error("--set " + key, "value nested more than " + std::to_string(kMaxJsonDepth) + " levels deep");
  } catch (const Json::out_of_range&) {
    input_error("--set " + key, "number out of the range of a double: " + text);
  } catch (const Json::parse_error&) {
    value = text;  // bare word: a string
  }
  try {
    (void)value.dump();
  } catch (const Json::type_error&) {
    input_error("--set " + key, "value is not valid UTF-8 text");
  }
  Json* node = &root;
  size_t start = 0;
  while (true) {
    const auto dot = key.find('.', start);
    const std::string part = key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (part.empty()) input_error("--set " + assignment, "empty key component");
    if (dot == std::string::npos) {
      (*node)[part] = value;
      break;
    }
    if (!node->contains(part)) (*node)[part] = Json::object();
    node = &(*node)[part];
    if (!node->is_object())
      input_error("--set " + assignment, "'" + key.substr(0, dot) + "' is not an object");
    start = dot + 1;
  }
}

JsonReader::JsonReader(const Json& root) : JsonReader(&root, "", std::make_shared<Shared>()) {}

JsonReader::JsonReader(const Json* node, std::string prefix, std::shared_ptr<Shared> shared)
    : node_(node), prefix_(std::move(prefix)), shared_(std::move(shared)) {}

void JsonReader::record_unlike_fallback() { shared_->record = true; }
std::vector<std::string> JsonReader::unlike_fallback() const { return shared_->unlike; }

template <class T>
T JsonReader::noted(const std::string& key, T value, const T& fallback) const {
  if (shared_->record && !(value == fallback)) shared_->unlike.push_back(path(key));
  return value;
}

std::string JsonReader::path(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

void JsonReader::fail(const std::string& key, const std::string& what) const {
  input_error("config key " + path(key), what);
}

std::vector<std::string> JsonReader::keys() const {
  std::vector<std::string> k;
  if (node_->is_object())
    for (const auto& it : node_->items()) k.push_back(it.key());
  return k;
}

bool JsonReader::has(const std::string& key) const { return node_->contains(key); }

const Json& JsonReader::at(const std::string& key) const {
  if (!node_->contains(key)) fail(key, "missing (required)");
  shared_->used.insert(path(key));
  return (*node_)[key];
}

JsonReader JsonReader::child(const std::string& key) const {
  const Json& j = at(key);
  if (!j.is_object()) fail(key, "expected an object, got " + type_name(j));
  return JsonReader(&j, path(key), shared_);
}

std::optional<JsonReader> JsonReader::optional_child(const std::string& key) const {
  if (!has(key)) return std::nullopt;
  return child(key);
}

double JsonReader::get_number(const std::string& key) const {
  const Json& j = at(key);
  if (!j.is_number()) fail(key, "expected a number, got " + type_name(j));
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail(key, "must be finite");
  return v;
}
double JsonReader::get_number(const std::string& key, double fallback) const {
  return has(key) ? noted(key, get_number(key), fallback) : fallback;
}
double JsonReader::get_number_or_null(const std::string& key, double fallback) const {
  if (!has(key)) return fallback;
  if (at(key).is_null()) return fallback;
  return noted(key, get_number(key), fallback);
}

int64_t JsonReader::get_int(const std::string& key) const {
  const Json& j = at(key);
  if (j.is_number_integer()) return j.get<int64_t>();
  if (j.is_number_float()) {
    const double v = j.get<double>();
    if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 9e15) return int64_t(v);
  }
  fail(key, "expected an integer, got " + (j.is_number() ? j.dump() : type_name(j)));
}
int64_t JsonReader::get_int(const std::string& key, int64_t fallback) const {
  return has(key) ? noted(key, get_int(key), fallback) : fallback;
}

std::string JsonReader::get_string(const std::string& key) const {
  const Json& j = at(key);
  if (!j.is_string()) fail(key, "expected a string, got " + type_name(j));
  return j.get<std::string>();
}
std::string JsonReader::get_string(const std::string& key, const std::string& fallback) const {
  return has(key) ? noted(key, get_string(key), fallback) : fallback;
}

std::vector<double> JsonReader::get_number_array(const std::string& key) const {
  const Json& j = at(key);
  if (!j.is_array()) fail(key, "expected an array of numbers, got " + type_name(j));
  std::vector<double> out;
  for (size_t i = 0; i < j.size(); ++i) {
    if (!j[i].is_number()) fail(key, "element " + std::to_string(i) + " is " + type_name(j[i]) + ", expected a number");
    const double v = j[i].get<double>();
    if (!std::isfinite(v)) fail(key, "element " + std::to_string(i) + " is not finite");
    out.push_back(v);
  }
  return out;
}
namespace {
void find_unused(const Json& j, const std::string& prefix, const std::set<std::string>& used,
                 std::string& first) {
  if (!first.empty() || !j.is_object()) return;
  for (auto it = j.begin(); it != j.end() && first.empty(); ++it) {
    const std::string p = prefix.empty() ? it.key() : prefix + "." + it.key();
    if (!it.key().empty() && it.key()[0] == '_') continue;  // "_note" keys are free text
    if (!used.count(p)) {
      first = p;
      return;
    }
    find_unused(it.value(), p, used, first);
  }
}
}  // namespace

void JsonReader::check_all_used() const {
  std::string first;
  find_unused(*node_, prefix_, shared_->used, first);
  if (!first.empty()) input_error("config key " + first, "unknown key (misspelt, or not valid here)");
}

std::vector<std::string> JsonReader::get_string_array(const std::string& key) const {
  const Json& j = at(key);
  if (!j.is_array()) fail(key, "expected an array of strings, got " + type_name(j));
  std::vector<std::string> out;
  for (size_t i = 0; i < j.size(); ++i) {
    if (!j[i].is_string()) fail(key, "element " + std::to_string(i) + " is " + type_name(j[i]) + ", expected a string");
    out.push_back(j[i].get<std::string>());
  }
  return out;
}

bool JsonReader::get_bool(const std::string& key, bool fallback) const {
  if (!has(key)) return fallback;
  const Json& j = at(key);
  if (!j.is_boolean()) fail(key, "expected true or false, got " + type_name(j));
  return noted(key, j.get<bool>(), fallback);
}

}  // namespace hsd
