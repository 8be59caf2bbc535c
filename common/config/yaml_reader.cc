#include "common/config/yaml_reader.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace cnc::config {
namespace {
std::string describe(const std::string& file, const std::string& key_path, const std::string& what) {
  std::string where = file.empty() ? "" : file + ": ";
  return where + (key_path.empty() ? std::string("(top level)") : key_path) + ": " + what;
}
std::string mark_of(const YAML::Node& n) {
  const YAML::Mark m = n.Mark();
  if (m.line < 0) return "";
  return " (line " + std::to_string(m.line + 1) + ", column " + std::to_string(m.column + 1) + ")";
}
}  // namespace

ConfigError::ConfigError(const std::string& file, const std::string& key_path, const std::string& what)
    : std::runtime_error(describe(file, key_path, what)), key_path_(key_path) {}

MapReader::MapReader(YAML::Node node, std::string path, std::string file, KeyTable known)
    : node_(std::move(node)), path_(std::move(path)), file_(std::move(file)), known_(known) {
  if (node_ && !node_.IsNull() && !node_.IsMap()) throw ConfigError(file_, path_, "expected a mapping" + mark_of(node_));
}

std::string MapReader::child_path(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }
std::string MapReader::item_path(const std::string& key, size_t index) const {
  return child_path(key) + "[" + std::to_string(index) + "]";
}

void MapReader::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(file_, child_path(key), what);
}

void MapReader::ask(const std::string& key) const {
  if (known_.empty()) return;
  if (std::find(known_.begin(), known_.end(), key) == known_.end())
    throw std::logic_error(file_ + ": " + child_path(key) + ": read, but not in the reader's table of known keys");
  asked_.insert(key);
}

bool MapReader::has(const std::string& key) const {
  ask(key);
  return node_ && node_.IsMap() && node_[key];
}

YAML::Node MapReader::scalar(const std::string& key) {
  ask(key);
  used_.insert(key);
  YAML::Node n = node_[key];
  if (!n.IsScalar()) fail(key, "expected a scalar value" + mark_of(n));
  return n;
}

double MapReader::require_double(const std::string& key, double min, double max) {
  if (!has(key)) fail(key, "is required");
  YAML::Node n = scalar(key);
  double v = 0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    fail(key, "expected a number, got '" + n.Scalar() + "'" + mark_of(n));
  }
  if (!std::isfinite(v)) fail(key, "must be finite, got '" + n.Scalar() + "'");
  if (v < min || v > max) {
    std::ostringstream os;
    os << "out of range: " << v << " not in [" << min << ", " << max << "]" << mark_of(n);
    fail(key, os.str());
  }
  return v;
}

double MapReader::get_double(const std::string& key, double fallback, double min, double max) {
  return has(key) ? require_double(key, min, max) : fallback;
}

int64_t MapReader::require_int(const std::string& key, int64_t min, int64_t max) {
  if (!has(key)) fail(key, "is required");
  YAML::Node n = scalar(key);
  int64_t v = 0;
  try {
    v = n.as<int64_t>();
  } catch (const YAML::Exception&) {
    fail(key, "expected an integer, got '" + n.Scalar() + "'" + mark_of(n));
  }
  if (v < min || v > max) {
    fail(key, "out of range: " + std::to_string(v) + " not in [" + std::to_string(min) + ", " + std::to_string(max) +
                  "]" + mark_of(n));
  }
  return v;
}

int64_t MapReader::get_int(const std::string& key, int64_t fallback, int64_t min, int64_t max) {
  return has(key) ? require_int(key, min, max) : fallback;
}

bool MapReader::get_bool(const std::string& key, bool fallback) {
  if (!has(key)) return fallback;
  YAML::Node n = scalar(key);
  try {
    return n.as<bool>();
  } catch (const YAML::Exception&) {
    fail(key, "expected true or false, got '" + n.Scalar() + "'" + mark_of(n));
  }
}

std::string MapReader::require_string(const std::string& key) {
  if (!has(key)) fail(key, "is required");
  return scalar(key).Scalar();
}

std::string MapReader::get_string(const std::string& key, const std::string& fallback) {
  return has(key) ? require_string(key) : fallback;
}

std::string MapReader::get_choice(const std::string& key, const std::string& fallback,
                                  const std::set<std::string>& choices) {
  const std::string v = get_string(key, fallback);
  if (choices.count(v) == 0) {
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
    fail(key, "'" + v + "' is not one of: " + list);
  }
  return v;
}

MapReader MapReader::map(const std::string& key, KeyTable known) {
  ask(key);
  used_.insert(key);
  if (!has(key)) return MapReader(YAML::Node(YAML::NodeType::Map), child_path(key), file_, known);
  return MapReader(node_[key], child_path(key), file_, known);
}

YAML::Node MapReader::sequence(const std::string& key) {
  ask(key);
  used_.insert(key);
  if (!has(key)) return YAML::Node(YAML::NodeType::Sequence);
  YAML::Node n = node_[key];
  if (!n.IsSequence()) fail(key, "expected a list" + mark_of(n));
  return n;
}

void MapReader::finish() const {
  for (const std::string_view k : known_) {
    if (asked_.count(std::string(k)) == 0)
      throw std::logic_error(file_ + ": " + child_path(std::string(k)) + ": in the table of known keys, never read");
  }
  if (!node_ || !node_.IsMap()) return;
  std::set<std::string> seen;
  for (const auto& kv : node_) {
    // A complex key ("? [a, b]", "? {a: 1}") is no name: as<std::string> would throw yaml-cpp's bad conversion.
    if (!kv.first.IsScalar()) throw ConfigError(file_, path_, "a key must be a plain name" + mark_of(kv.first));
    const std::string key = kv.first.Scalar();
    if (!seen.insert(key).second) fail(key, "duplicate key" + mark_of(kv.first));
    if (used_.count(key) == 0) fail(key, "unknown key" + mark_of(kv.first));
  }
}

YAML::Node load_yaml_file(const std::string& file) {
  try {
    return YAML::LoadFile(file);
  } catch (const YAML::BadFile&) {
    throw ConfigError(file, "", "cannot open the file");
  } catch (const YAML::ParserException& e) {
    throw ConfigError(file, "", "YAML syntax error at line " + std::to_string(e.mark.line + 1) + ", column " +
                                    std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
}

}  // namespace cnc::config
