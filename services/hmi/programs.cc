#include "services/hmi/programs.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>

namespace fs = std::filesystem;

namespace cnc::hmi {

namespace {
bool is_program(const fs::path& p) {
  const std::string e = p.extension().string();
  return e == ".ngc" || e == ".nc" || e == ".tap" || e == ".NGC" || e == ".NC";
}
double mtime_s(const fs::path& p) {
  struct stat st {};
  if (stat(p.c_str(), &st) != 0) return 0;
  return static_cast<double>(st.st_mtim.tv_sec) + 1e-9 * static_cast<double>(st.st_mtim.tv_nsec);
}
}  // namespace

std::vector<std::string> list_programs(const std::string& dir, size_t limit) {
  std::vector<std::string> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (!it->is_regular_file(ec) || !is_program(it->path())) continue;
    // Only what would load: a link leading out of the folder is not offered.
    std::string why;
    const std::string rel = fs::relative(it->path(), dir, ec).string();
    if (!resolve_program(dir, rel, &why).empty()) out.push_back(rel);
    if (out.size() >= limit) break;
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::string resolve_program(const std::string& dir, const std::string& name, std::string* error) {
  const fs::path rel(name);
  if (name.empty()) {
    *error = "no program named";
    return "";
  }
  if (rel.is_absolute()) {
    *error = "'" + name + "' is an absolute path: programs load from the program directory " + dir + " only";
    return "";
  }
  for (const auto& part : rel) {
    if (part == "..") {
      *error = "'" + name + "' climbs out of the program directory " + dir + " (..)";
      return "";
    }
  }
  std::error_code ec;
  const fs::path base = fs::canonical(dir, ec);
  if (ec) {
    *error = "the program directory " + dir + " (hmi.program_dir) is not there: " + ec.message();
    return "";
  }
  const fs::path full = fs::canonical(base / rel, ec);
  if (ec) {
    *error = "'" + name + "' is not in the program directory " + dir;
    return "";
  }
  // Symbolic links resolved: the file itself must lie under the directory.
  const auto [b_end, f_it] = std::mismatch(base.begin(), base.end(), full.begin(), full.end());
  if (b_end != base.end()) {
    *error = "'" + name + "' leads outside the program directory " + dir + " (a link to " + full.string() + ")";
    return "";
  }
  if (!fs::is_regular_file(full, ec) || !is_program(full)) {
    *error = "'" + name + "' is not a program file (.ngc, .nc, .tap) in " + dir;
    return "";
  }
  return full.string();
}

std::string check_upload(const std::string& dir, const std::string& name, const std::string& text, int64_t max_bytes,
                         bool replace) {
  const std::string q = "'" + name + "'";
  if (name.empty()) return "no file name";
  if (name.size() > 100) return "the name is " + std::to_string(name.size()) + " characters long, more than 100";
  if (name.find('/') != std::string::npos || name.find('\\') != std::string::npos)
    return q + " names a folder: a plain file name only (programs go into " + dir + " itself)";
  if (name[0] == '.') return q + " is a hidden file (starts with '.')";
  for (const char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-' || c == '+'))
      return q + " has a character other than letters, digits and . _ - +";
  if (!is_program(fs::path(name))) return q + " is not a program's name: the extension must be .ngc, .nc or .tap";
  if (static_cast<int64_t>(text.size()) > max_bytes)
    return q + " is " + std::to_string(text.size()) + " bytes, more than hmi.upload_max_bytes (" +
           std::to_string(max_bytes) + ")";
  if (const size_t nul = text.find('\0'); nul != std::string::npos)
    return q + " is not text (a NUL byte at offset " + std::to_string(nul) + ")";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return "the program directory " + dir + " (hmi.program_dir) is not there";
  const fs::path target = fs::path(dir) / name;
  if (fs::exists(fs::symlink_status(target, ec))) {
    if (!fs::is_regular_file(fs::symlink_status(target, ec)))
      return q + " exists in " + dir + " and is not a plain file: it is not replaced";
    if (!replace) return q + " exists in " + dir + ": kept (replace it on purpose: replace true)";
  }
  return "";
}

std::string write_upload(const std::string& dir, const std::string& name, const std::string& text) {
  const fs::path target = fs::path(dir) / name;
  std::string tmp = (fs::path(dir) / ".upload-XXXXXX").string();
  const int fd = mkstemp(tmp.data());
  if (fd < 0) return "cannot write into " + dir + ": " + std::strerror(errno);
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  const bool ok = done == text.size() && fchmod(fd, 0644) == 0 && fsync(fd) == 0;
  const int saved = errno;
  close(fd);
  if (!ok || std::rename(tmp.c_str(), target.c_str()) != 0) {
    const std::string why = std::strerror(ok ? errno : saved);
    std::remove(tmp.c_str());
    return "cannot write " + target.string() + ": " + why;
  }
  return "";
}

std::vector<RunEntry> list_runs(const std::string& dir, size_t limit) {
  std::vector<RunEntry> out;
  std::error_code ec;
  for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const fs::path p = it->path();
    if (it->is_regular_file(ec) && p.extension() == ".lcmlog") {
      RunEntry r;
      r.name = p.filename().string();
      r.log = r.name;
      r.mtime_s = mtime_s(p);
      r.bytes = fs::file_size(p, ec);
      r.report = fs::exists(p.parent_path() / (p.stem().string() + "-report") / "index.html", ec);
      out.push_back(r);
    } else if (it->is_directory(ec)) {
      std::error_code ec2;
      for (auto f = fs::directory_iterator(p, ec2); !ec2 && f != fs::directory_iterator(); f.increment(ec2)) {
        if (f->path().extension() != ".lcmlog") continue;
        RunEntry r;
        r.name = p.filename().string();
        r.log = r.name + "/" + f->path().filename().string();
        r.mtime_s = mtime_s(f->path());
        r.bytes = fs::file_size(f->path(), ec2);
        r.report = fs::exists(p / "report" / "index.html", ec2);
        out.push_back(r);
        break;
      }
    }
  }
  std::sort(out.begin(), out.end(), [](const RunEntry& a, const RunEntry& b) { return a.mtime_s > b.mtime_s; });
  if (out.size() > limit) out.resize(limit);
  return out;
}

}  // namespace cnc::hmi
