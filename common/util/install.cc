#include "common/util/install.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>

namespace cnc::util {

std::string executable_dir() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  return exe.parent_path().string();
}

std::string resource_path(const std::string& relative) {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("CNC_SHARE_DIR"); env != nullptr && *env != '\0') {
    return (fs::path(env) / relative).string();
  }
  const fs::path dir = executable_dir();
  std::error_code ec;
  if (!dir.empty() && dir.filename() == "bin") {
    const fs::path share = dir.parent_path() / "share" / "cnc";
    if (fs::is_directory(share, ec)) return (share / relative).string();
  }
  return (fs::path(CNC_SOURCE_DIR) / relative).string();
}

}  // namespace cnc::util
