#pragma once
// What every service's main shares: flags, config loading with exit code 2 on a
// bad config, logging set-up, stop signals.
#include <functional>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/bus/bus.h"
#include "common/config/machine_config.h"

namespace cnc::service {

// A flag's value that the program itself finds malformed (e.g. a number or a word):
// run() exits 2 with "NAME: what (see NAME --help)", as for the flags CLI11 checks.
struct FlagError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Args {
  std::string machine_file;
  std::map<std::string, std::string> options;  // --key value
  std::set<std::string> flags;                 // --flag
  std::string option(const std::string& key, const std::string& fallback = "") const;
  // --key's value as a number (fallback when not given); FlagError naming it when it is none.
  double number(const std::string& key, double fallback) const;
};

// One accepted flag: --NAME (VALUE shown in --help; empty for a switch) and what it does.
struct Flag {
  std::string name;
  std::string value;
  std::string help;
  bool number = false;  // a malformed number is refused naming the flag (exit 2)
};

struct Spec {
  std::string name;                    // e.g. "cnc-interpolator"
  std::string summary;                 // one line for --help
  std::vector<Flag> options;           // accepted --key value options besides --machine
  std::vector<Flag> flags;             // accepted --flag switches
  bool needs_machine = true;
  // Applies the machine's kinematics (the dry run); every other program refuses a
  // machine whose kinematics.type is not identity.
  bool applies_kinematics = false;
};

// Exit codes shared by all services.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitBadInput = 2;  // bad flags or config

// The bus security of a service from the config's `security:` section: signing and
// verification with the key file (read here; KeyFileError when it is missing, not
// the user's or readable by group/others: run() exits 2 naming the file and its
// mode), the file watched for rotations. Signing off: a warning, nothing checked.
bus::Security bus_security(const config::MachineConfig& cfg, const std::string& who);

// Parses flags, loads the machine config, installs the stop handlers and runs
// `body`. A ConfigError, an unusable key file or a bad flag exits 2 with the message on stderr; any other
// exception exits 1.
int run(const Spec& spec, int argc, char** argv,
        const std::function<int(const config::MachineConfig&, const Args&)>& body);

}  // namespace cnc::service
