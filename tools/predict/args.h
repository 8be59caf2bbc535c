#pragma once
// A small --key value parser for cnc-predict and its bench.
#include <cstdio>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace cnc::predict {

class Args {
 public:
  Args(int argc, char** argv, int first) {
    for (int i = first; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg.rfind("--", 0) != 0) {
        positional_.push_back(arg);
        continue;
      }
      const std::string a(arg.begin() + 2, arg.end());
      const size_t eq = a.find('=');
      if (eq != std::string::npos) {
        opts_[a.substr(0, eq)] = a.substr(eq + 1);
      } else if (i + 1 < argc && std::string(argv[i + 1]).rfind("--", 0) != 0) {
        opts_.insert_or_assign(a, std::string(argv[++i]));
      } else {
        opts_.insert_or_assign(a, std::string(1, '1'));
      }
    }
  }
  bool has(const std::string& k) const { return opts_.count(k) > 0; }
  std::string str(const std::string& k, const std::string& fallback = "") const {
    auto it = opts_.find(k);
    return it == opts_.end() ? fallback : it->second;
  }
  std::string require(const std::string& k) const {
    if (!has(k)) throw std::invalid_argument("--" + k + " is required");
    return str(k);
  }
  double num(const std::string& k, double fallback) const { return has(k) ? to_double(k, str(k)) : fallback; }
  double require_num(const std::string& k) const { return to_double(k, require(k)); }
  int integer(const std::string& k, int fallback) const { return has(k) ? static_cast<int>(to_double(k, str(k))) : fallback; }
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  static double to_double(const std::string& k, const std::string& v) {
    char* end = nullptr;
    const double d = std::strtod(v.c_str(), &end);
    if (end == v.c_str() || *end != '\0') throw std::invalid_argument("--" + k + ": not a number: '" + v + "'");
    return d;
  }
  std::map<std::string, std::string> opts_;
  std::vector<std::string> positional_;
};

}  // namespace cnc::predict
