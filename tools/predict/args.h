#pragma once
// The options of cnc-predict's commands and of its bench: each declared on its CLI11
// command with a description (util/cli.h: --help, --version, a malformed number
// refused naming the flag), read back by name.
#include <map>
#include <stdexcept>
#include <string>

#include "common/util/cli.h"

namespace cnc::predict {

class Args {
 public:
  // --NAME on `cmd`, a number (VALUE names it in --help).
  Args& number(CLI::App* cmd, const std::string& name, const std::string& value, const std::string& help,
               bool required = false) {
    add(cmd, name, value, help, required)->check(CLI::Number);
    return *this;
  }
  // --NAME on `cmd`, a text (a file, a mode, ...).
  Args& text(CLI::App* cmd, const std::string& name, const std::string& value, const std::string& help,
             bool required = false) {
    add(cmd, name, value, help, required);
    return *this;
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
  double num(const std::string& k, double fallback) const { return has(k) ? std::stod(str(k)) : fallback; }
  double require_num(const std::string& k) const { return std::stod(require(k)); }
  int integer(const std::string& k, int fallback) const { return has(k) ? static_cast<int>(num(k, 0)) : fallback; }

 private:
  CLI::Option* add(CLI::App* cmd, const std::string& name, const std::string& value, const std::string& help,
                   bool required) {
    CLI::Option* o =
        cmd->add_option_function<std::string>("--" + name, [this, name](const std::string& v) { opts_[name] = v; },
                                              help)
            ->type_name(value);
    if (required) o->required();
    return o;
  }
  std::map<std::string, std::string> opts_;
};

}  // namespace cnc::predict
