#pragma once
// The machine's program directory as the HMI offers it: the programs under it, and
// a name from a browser resolved to a file inside it, or refused with the reason.
#include <cstdint>
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

// A program uploaded from a browser (the API's `upload`), checked before anything is
// written: `name` a plain file name (no folder, not hidden, of letters, digits and
// "._-+", at most 100 characters, a program's extension .ngc .nc .tap), `text` at most
// `max_bytes` and text (no NUL byte), an existing file replaced only when `replace`.
// "" when it may be written, else why not (naming the name, the limit's config key...).
std::string check_upload(const std::string& dir, const std::string& name, const std::string& text, int64_t max_bytes,
                         bool replace);
// Writes it (a temporary file in `dir`, synced, renamed over the name): "" or why not.
std::string write_upload(const std::string& dir, const std::string& name, const std::string& text);

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
