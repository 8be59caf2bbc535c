#pragma once
// Strict YAML reading into plain structs. Every key a reader does not consume is an
// error, and every error names its key path (e.g. `axes[1].max_velocity_mm_s`).
#include <yaml-cpp/yaml.h>

#include <limits>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace cnc::config {

class ConfigError : public std::runtime_error {
 public:
  ConfigError(const std::string& file, const std::string& key_path, const std::string& what);
  const std::string& key_path() const { return key_path_; }

 private:
  std::string key_path_;
};

// The keys one mapping may hold. A reader given such a table reads only keys in it
// (another is a bug: std::logic_error), asks for each of them before finish() (else
// std::logic_error), and finish() rejects every key outside it: the table is the
// reader's own list, so docs/config.md can be checked against it.
using KeyTable = std::span<const std::string_view>;

// A view of one YAML mapping. Read its fields with the typed getters, then call
// finish(), which rejects every key that was not read.
class MapReader {
 public:
  MapReader(YAML::Node node, std::string path, std::string file, KeyTable known = {});

  bool has(const std::string& key) const;
  double get_double(const std::string& key, double fallback, double min = -std::numeric_limits<double>::max(),
                    double max = std::numeric_limits<double>::max());
  double require_double(const std::string& key, double min = -std::numeric_limits<double>::max(),
                        double max = std::numeric_limits<double>::max());
  int64_t get_int(const std::string& key, int64_t fallback, int64_t min, int64_t max);
  int64_t require_int(const std::string& key, int64_t min, int64_t max);
  bool get_bool(const std::string& key, bool fallback);
  std::string get_string(const std::string& key, const std::string& fallback);
  std::string require_string(const std::string& key);
  // One of `choices`; the error lists them.
  std::string get_choice(const std::string& key, const std::string& fallback, const std::set<std::string>& choices);

  // Sub-mappings and sequences; the child readers share the file name.
  MapReader map(const std::string& key, KeyTable known = {});  // a missing key reads as an empty map
  YAML::Node sequence(const std::string& key);
  std::string child_path(const std::string& key) const;
  std::string item_path(const std::string& key, size_t index) const;
  const std::string& file() const { return file_; }
  const std::string& path() const { return path_; }

  [[noreturn]] void fail(const std::string& key, const std::string& what) const;
  void finish() const;

 private:
  YAML::Node scalar(const std::string& key);
  void ask(const std::string& key) const;  // checks `key` against the table, notes it asked
  YAML::Node node_;
  std::string path_;
  std::string file_;
  KeyTable known_;
  std::set<std::string> used_;
  mutable std::set<std::string> asked_;
};

// Opens a YAML file; a syntax error names file:line:column.
YAML::Node load_yaml_file(const std::string& file);

}  // namespace cnc::config
