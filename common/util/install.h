#pragma once
// What a program knows of its own installation: the version it was built as, and
// where the files it reads at run time live.
#include <string>

namespace cnc::util {

// The version of this build (cmake/version.cmake): the project's version, the number
// of commits and the commit, e.g. "0.1.0+412.g20fd61f" (uncommitted changes do not show).
// Every executable prints it for --version and every service sends it in its heartbeat.
const char* version();

// The path of a file or directory the programs read at run time (drive profiles,
// example configs and programs, plot scripts), given by its place in the source tree,
// e.g. "config/drives" or "tools/cam/plot_rough.py". An installed program (its
// executable in PREFIX/bin, beside PREFIX/share/cnc) finds it under PREFIX/share/cnc,
// which mirrors the source tree's layout; a program in a build tree finds it in the
// source tree it was built from. CNC_SHARE_DIR in the environment overrides both.
std::string resource_path(const std::string& relative);

// The directory of the running executable (/proc/self/exe), empty if unknown.
std::string executable_dir();

}  // namespace cnc::util
