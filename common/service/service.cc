#include "common/service/service.h"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>

#include "common/config/yaml_reader.h"
#include "common/util/install.h"
#include "common/util/signals.h"

namespace cnc::service {

std::string Args::option(const std::string& key, const std::string& fallback) const {
  auto it = options.find(key);
  return it == options.end() ? fallback : it->second;
}

bus::Security bus_security(const config::MachineConfig& cfg, const std::string& who) {
  bus::Security sec;
  if (!cfg.security.signing) {
    spdlog::warn("{}: security.signing is off in {}: messages are neither signed nor checked, anyone on the "
                 "network can move this machine",
                 who, cfg.source_file);
    return sec;
  }
  sec.enabled = true;
  sec.key_file = cfg.security.key_file;
  sec.keys = bus::read_key_file(sec.key_file);
  sec.max_age_s = cfg.security.max_age_s;
  return sec;
}

// The flags by CLI11: --help and --version on every service in one style, and an
// error naming the flag for an unknown or malformed one (exit 2).
int run(const Spec& spec, int argc, char** argv,
        const std::function<int(const config::MachineConfig&, const Args&)>& body) {
  Args args;
  CLI::App app{spec.summary, spec.name};
  app.set_version_flag("--version", spec.name + " " + util::version());
  app.add_option("--machine", args.machine_file, "the cell's machine config (YAML)")
      ->type_name("FILE")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  for (const auto& o : spec.options) {
    app.add_option_function<std::string>("--" + o, [&args, o](const std::string& v) { args.options[o] = v; })
        ->type_name("VALUE")
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  }
  for (const auto& f : spec.flags) app.add_flag_callback("--" + f, [&args, f] { args.flags.insert(f); });
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "%s: %s (see %s --help)\n", spec.name.c_str(), e.what(), spec.name.c_str());
    return kExitBadInput;
  }
  spdlog::set_pattern("%H:%M:%S.%e %n[%l] %v");
  spdlog::default_logger()->set_level(spdlog::level::info);
  util::install_stop_handlers();
  try {
    config::MachineConfig cfg;
    if (spec.needs_machine || !args.machine_file.empty()) {
      if (args.machine_file.empty()) {
        std::fprintf(stderr, "%s: --machine FILE is required (see %s --help)\n", spec.name.c_str(), spec.name.c_str());
        return kExitBadInput;
      }
      cfg = config::load_machine_config(args.machine_file);
    }
    return body(cfg, args);
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "%s: config error: %s\n", spec.name.c_str(), e.what());
    return kExitBadInput;
  } catch (const bus::KeyFileError& e) {
    std::fprintf(stderr, "%s: refusing to start: %s\n", spec.name.c_str(), e.what());
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: fatal: %s\n", spec.name.c_str(), e.what());
    return kExitFailure;
  }
}

}  // namespace cnc::service
