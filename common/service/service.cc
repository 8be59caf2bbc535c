#include "common/service/service.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <exception>

#include "common/config/yaml_reader.h"
#include "common/util/cli.h"
#include "common/util/install.h"
#include "common/util/signals.h"

namespace cnc::service {

std::string Args::option(const std::string& key, const std::string& fallback) const {
  auto it = options.find(key);
  return it == options.end() ? fallback : it->second;
}

double Args::number(const std::string& key, double fallback) const {
  auto it = options.find(key);
  if (it == options.end()) return fallback;
  double v = 0;
  if (!CLI::detail::lexical_cast(it->second, v) || !std::isfinite(v))
    throw FlagError("--" + key + ": " + it->second + " is not a number");
  return v;
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

// The flags by CLI11 in the style of every program (util/cli.h): --help and
// --version, an error naming the flag for an unknown or malformed one (exit 2).
int run(const Spec& spec, int argc, char** argv,
        const std::function<int(const config::MachineConfig&, const Args&)>& body) {
  Args args;
  CLI::App app{spec.summary, spec.name};
  util::cli::setup(app);
  app.add_option("--machine", args.machine_file, "the cell's machine config (YAML)")
      ->type_name("FILE")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  for (const auto& o : spec.options) {
    CLI::Option* opt =
        app.add_option_function<std::string>("--" + o.name, [&args, o](const std::string& v) { args.options[o.name] = v; },
                                             o.help)
            ->type_name(o.value.empty() ? "VALUE" : o.value)
            ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    if (o.number) opt->check(CLI::Number);
  }
  for (const auto& f : spec.flags) app.add_flag_callback("--" + f.name, [&args, f] { args.flags.insert(f.name); }, f.help);
  if (const int rc = util::cli::parse(app, argc, argv); rc >= 0) return rc;
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
      // The interpolator, bridge and monitor still take axes for joints: a five-axis
      // machine would move its joints to the tool's coordinates.
      if (cfg.kinematics.type != "identity" && !spec.applies_kinematics) {
        std::string what = "the cell applies only identity kinematics so far, not ";
        what += cfg.kinematics.type;
        throw config::ConfigError(args.machine_file, "kinematics.type", what += " (docs/motion.md#five-axis-kinematics)");
      }
    }
    return body(cfg, args);
  } catch (const FlagError& e) {
    return util::cli::bad_flag(app, e.what());
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
