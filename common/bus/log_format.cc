#include "common/bus/log_format.h"

#include <cstdio>
#include <cstring>

#include "common/util/install.h"

namespace cnc::bus {

std::string log_format_record() {
  return "cnc-log-format " + std::to_string(kLogFormat) + " " + util::version() + " motion " +
         std::to_string(kMotionRevision);
}

bool parse_log_format(const void* data, size_t size, LogFormat* out) {
  static constexpr char kTag[] = "cnc-log-format ";
  const std::string text(static_cast<const char*>(data), size);
  if (text.compare(0, sizeof kTag - 1, kTag) != 0) return false;
  int format = 0, used = 0;
  if (std::sscanf(text.c_str() + sizeof kTag - 1, "%d %n", &format, &used) != 1 || format < 1) return false;
  out->format = format;
  out->version = text.substr(sizeof kTag - 1 + static_cast<size_t>(used));
  out->motion = 1;
  static constexpr char kMotion[] = " motion ";
  if (const size_t at = out->version.rfind(kMotion); at != std::string::npos) {
    int motion = 0;
    char extra = 0;
    if (std::sscanf(out->version.c_str() + at + sizeof kMotion - 1, "%d%c", &motion, &extra) == 1 && motion >= 1) {
      out->motion = motion;
      out->version.resize(at);
    }
  }
  return true;
}

std::string unreadable_log_format(const LogFormat& f) {
  if (f.format >= kOldestReadableLogFormat && f.format <= kLogFormat) return "";
  const std::string by = f.version.empty() ? "" : " (recorded by cnc " + f.version + ")";
  if (f.format > kLogFormat)
    return "the log is in format " + std::to_string(f.format) + by + ", newer than this cnc " + util::version() +
           " reads (formats " + std::to_string(kOldestReadableLogFormat) + " to " + std::to_string(kLogFormat) +
           "): read it with the version that recorded it, or a later one";
  return "the log is in format " + std::to_string(f.format) + by + ", older than this cnc " + util::version() +
         " reads (from format " + std::to_string(kOldestReadableLogFormat) + "): read it with the version that recorded it";
}

}  // namespace cnc::bus
