#include "common/service/service.h"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <exception>

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

namespace {
void usage(const Spec& spec) {
  std::fprintf(stderr, "%s %s: %s\nusage: %s%s", spec.name.c_str(), util::version(), spec.summary.c_str(), spec.name.c_str(),
               spec.needs_machine ? " --machine FILE" : "");
  for (const auto& o : spec.options) std::fprintf(stderr, " [--%s VALUE]", o.c_str());
  for (const auto& f : spec.flags) std::fprintf(stderr, " [--%s]", f.c_str());
  std::fprintf(stderr, "\n");
}
}  // namespace

int run(const Spec& spec, int argc, char** argv,
        const std::function<int(const config::MachineConfig&, const Args&)>& body) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      usage(spec);
      return kExitOk;
    }
    if (a == "--version") {
      std::printf("%s %s\n", spec.name.c_str(), util::version());
      return kExitOk;
    }
    if (a.rfind("--", 0) != 0) {
      std::fprintf(stderr, "%s: unexpected argument '%s'\n", spec.name.c_str(), a.c_str());
      usage(spec);
      return kExitBadInput;
    }
    const std::string key = a.substr(2);
    if (spec.flags.count(key)) {
      args.flags.insert(key);
      continue;
    }
    if (key != "machine" && spec.options.count(key) == 0) {
      std::fprintf(stderr, "%s: unknown option '%s'\n", spec.name.c_str(), a.c_str());
      usage(spec);
      return kExitBadInput;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s: option '%s' needs a value\n", spec.name.c_str(), a.c_str());
      return kExitBadInput;
    }
    if (key == "machine") {
      args.machine_file = argv[++i];
    } else {
      args.options[key] = argv[++i];
    }
  }
  spdlog::set_pattern("%H:%M:%S.%e %n[%l] %v");
  spdlog::default_logger()->set_level(spdlog::level::info);
  util::install_stop_handlers();
  try {
    config::MachineConfig cfg;
    if (spec.needs_machine || !args.machine_file.empty()) {
      if (args.machine_file.empty()) {
        std::fprintf(stderr, "%s: --machine FILE is required\n", spec.name.c_str());
        usage(spec);
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
