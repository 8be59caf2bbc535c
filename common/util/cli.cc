#include "common/util/cli.h"

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "common/util/install.h"

namespace cnc::util::cli {

void setup(CLI::App& app) {
  const std::string& name = app.get_name();
  app.description(name + ": " + app.get_description());
  app.set_help_flag("-h,--help", "print this help and exit");
  app.set_version_flag("--version", name + " " + util::version(), "print the program's version and exit");
  app.option_defaults()->always_capture_default();
}

namespace {
CLI::Validator number_check(const char* name, bool (*ok)(double), const char* what) {
  return CLI::Validator(
      [ok, what](std::string& s) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(s, v) || !std::isfinite(v)) return s + " is not a number";
        return ok(v) ? std::string() : s + " " + what;
      },
      name);
}
}  // namespace

CLI::Validator positive() {
  return number_check("POSITIVE", [](double v) { return v > 0; }, "is not positive");
}

CLI::Validator non_negative() {
  return number_check("NONNEGATIVE", [](double v) { return v >= 0; }, "is negative");
}

int parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // An unknown flag is named first, before what else is missing (a required
    // subcommand or option is checked before the leftovers).
    const std::vector<std::string> rest = app.remaining(true);
    if (!rest.empty() && dynamic_cast<const CLI::ExtrasError*>(&e) == nullptr) {
      std::string list;
      for (const auto& r : rest) list += (list.empty() ? "" : " ") + r;
      return bad_flag(app, std::string(rest.size() == 1 ? "The following argument was not expected: "
                                                         : "The following arguments were not expected: ") +
                               list);
    }
    return bad_flag(app, e.what());
  }
  return -1;
}

int bad_flag(const CLI::App& app, const std::string& what) {
  std::fprintf(stderr, "%s: %s (see %s --help)\n", app.get_name().c_str(), what.c_str(), app.get_name().c_str());
  return kExitBadFlag;
}

}  // namespace cnc::util::cli
