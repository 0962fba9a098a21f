// JSON config files: "extends" inheritance, --set overrides, and a reader that
// turns a JSON tree into typed values while remembering which keys it used, so
// that any key nobody asked for is reported as unknown (a misspelt key is an
// error, not a silently ignored setting). Every error names the dotted key path.
#pragma once
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace hsd {

using Json = nlohmann::json;

// Every JSON document hsd reads goes through these: nesting is bounded (64
// levels) and every failure (syntax, invalid UTF-8, a number no double holds,
// too deep) is an InputError (exit 2) naming `what` (a file or flag).
Json parse_json_text(const std::string& text, const std::string& what);
Json read_json_file(const std::string& path);  // also InputError if unreadable

// Reads a JSON file; if it has "extends": "other.json" (path relative to the
// file), loads that first and deep-merges this file on top (objects merge key
// by key; arrays and scalars replace). Chains and cycles are handled.
Json load_json_with_extends(const std::string& path);

// Applies one "dotted.key=VALUE" override. VALUE is parsed as JSON; if that
// fails it is taken as a string. Intermediate objects are created as needed.
void apply_override(Json& root, const std::string& assignment);

class JsonReader {
 public:
  // `root` must outlive the reader and its children.
  explicit JsonReader(const Json& root);

  bool has(const std::string& key) const;
  std::vector<std::string> keys() const;  // of this object, in the file's order of nlohmann (sorted)
  JsonReader child(const std::string& key) const;  // object; InputError if missing or not an object
  std::optional<JsonReader> optional_child(const std::string& key) const;

  double get_number(const std::string& key) const;  // required
  double get_number(const std::string& key, double fallback) const;
  int64_t get_int(const std::string& key) const;
  int64_t get_int(const std::string& key, int64_t fallback) const;
  std::string get_string(const std::string& key) const;
  std::string get_string(const std::string& key, const std::string& fallback) const;
  std::vector<double> get_number_array(const std::string& key) const;
  std::vector<std::string> get_string_array(const std::string& key) const;
  bool get_bool(const std::string& key, bool fallback) const;
  // Number or null (null -> fallback).
  double get_number_or_null(const std::string& key, double fallback) const;

  // Full dotted path of a key below this reader (for error messages).
  std::string path(const std::string& key) const;
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

  // InputError naming the first key in the tree that no getter consumed.
  void check_all_used() const;

  // From now on, this reader and its children note every key read with a
  // fallback whose value in the file differs from that fallback (the check
  // that configs/base.json states the structs' defaults: tests/common/test_config.cpp).
  void record_unlike_fallback();
  std::vector<std::string> unlike_fallback() const;  // dotted paths, in reading order

 private:
  struct Shared {
    std::set<std::string> used;
    bool record = false;
    std::vector<std::string> unlike;
  };
  JsonReader(const Json* node, std::string prefix, std::shared_ptr<Shared> shared);
  const Json& at(const std::string& key) const;  // marks used
  template <class T>
  T noted(const std::string& key, T value, const T& fallback) const;  // value, noting it if unlike the fallback
  const Json* node_;
  std::string prefix_;
  std::shared_ptr<Shared> shared_;
};

}  // namespace hsd
