#pragma once
// The machine's program directory as the HMI offers it: the programs under it, and
// a name from a browser resolved to a file inside it, or refused with the reason.
#include <string>
#include <vector>

namespace cnc::hmi {

// Part programs (.ngc, .nc, .tap) under `dir`, by their path relative to it, sorted;
// at most `limit`. Symbolic links to folders are not followed.
std::vector<std::string> list_programs(const std::string& dir, size_t limit = 1000);

// The absolute path of program `name` (relative to `dir`); "" with `error` set when
// the name is absolute, climbs out (".."), leads outside through a link, or is not a
// program file there. Nothing outside `dir` is reachable.
std::string resolve_program(const std::string& dir, const std::string& name, std::string* error);

// The runs of a logger directory: each folder with a .lcmlog in it (./cnc demo's
// runs/demo-*) or a .lcmlog file directly in `dir` (./cnc up's logger), newest first.
struct RunEntry {
  std::string name;      // relative to the runs directory
  std::string log;       // the log file, relative to the runs directory
  double mtime_s = 0;    // the log's modification time (Unix seconds)
  uintmax_t bytes = 0;
  bool report = false;   // NAME/report/index.html exists (./cnc report RUN/LOG --out RUN/report)
};
std::vector<RunEntry> list_runs(const std::string& dir, size_t limit = 200);

}  // namespace cnc::hmi
