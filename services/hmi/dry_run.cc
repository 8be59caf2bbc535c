#include "services/hmi/dry_run.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <vector>

namespace cnc::hmi {

using json = nlohmann::json;

namespace {

// cnc-plan --modes: "line,codes,feed,speed,tool,offset_x,offset_y,offset_z" rows, as
// [[line, codes, F, S, T, [x, y, z]], ...] (at most 100,000 rows: a longer program's
// later lines show the last one's).
json read_modes(const std::string& path) {
  json rows = json::array();
  std::ifstream f(path);
  std::string row;
  std::getline(f, row);  // header
  while (std::getline(f, row) && rows.size() < 100000) {
    std::vector<std::string> c;
    for (size_t b = 0;;) {
      const size_t e = row.find(',', b);
      c.push_back(row.substr(b, e == std::string::npos ? std::string::npos : e - b));
      if (e == std::string::npos) break;
      b = e + 1;
    }
    if (c.size() != 8) continue;
    auto num = [](const std::string& t) {
      const double v = std::strtod(t.c_str(), nullptr);
      return std::isfinite(v) ? v : 0.0;
    };
    rows.push_back({std::atoi(c[0].c_str()), c[1], num(c[2]), num(c[3]), std::atoi(c[4].c_str()),
                    {num(c[5]), num(c[6]), num(c[7])}});
  }
  return rows;
}

}  // namespace

void DryRun::start(int64_t token, const std::string& program, bool block_delete, std::vector<double> start_mm) {
  cancel();
  cancelled_ = false;
  thread_ = std::thread([this, token, program, block_delete, start = std::move(start_mm)] {
    run(token, program, block_delete, start);
  });
}

void DryRun::cancel() {
  cancelled_ = true;
  if (const pid_t p = pid_.load(); p > 0) kill(p, SIGTERM);
  if (thread_.joinable()) thread_.join();
}

void DryRun::run(int64_t token, const std::string& program, bool block_delete, const std::vector<double>& start_mm) {
  char tmpl[] = "/tmp/cnc-hmi-plan-XXXXXX";
  const int fd = mkstemp(tmpl);
  if (fd < 0) return;
  close(fd);
  const std::string csv = tmpl;
  // The arguments before the fork: the child only execs.
  std::string start;
  for (double v : start_mm) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", v);  // the position exactly
    if (!start.empty()) start += ',';
    start += buf;
  }
  // The modal state per line (the active codes, F, S, the work offset) beside the setpoints.
  const std::string modes = csv + ".modes";
  std::vector<const char*> argv = {exe_.c_str(),  "--machine", machine_.c_str(), "--program", program.c_str(),
                                   "--csv",       csv.c_str(), "--with-kind",    "--modes",   modes.c_str(),
                                   "--block-delete", block_delete ? "on" : "off"};
  if (!start.empty()) argv.insert(argv.end(), {"--start", start.c_str()});
  argv.push_back(nullptr);
  // Its stderr kept: a refusal names the place (file:line:column), which the page shows.
  const std::string err = csv + ".err";
  const pid_t child = fork();
  if (child == 0) {
    const int devnull = open("/dev/null", O_WRONLY);
    if (devnull >= 0) dup2(devnull, 1);
    const int errfd = open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (errfd >= 0) dup2(errfd, 2);
    execv(exe_.c_str(), const_cast<char* const*>(argv.data()));
    _exit(127);
  }
  json out;
  out["t"] = "preview";
  out["token"] = token;
  out["path"] = program;
  if (child < 0) {
    out["error"] = "cannot start the dry run";
  } else {
    pid_ = child;
    int status = 0;
    waitpid(child, &status, 0);
    pid_ = 0;
    if (cancelled_) {
      std::filesystem::remove(csv);
      std::filesystem::remove(err);
      std::filesystem::remove(modes);
      return;
    }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
      // Its last line says why ("cnc-plan: program refused: FILE:LINE:COLUMN: ...").
      std::ifstream e(err);
      std::string why;
      for (std::string l; std::getline(e, l);)
        if (!l.empty()) why = l;
      out["error"] = why.empty() ? "the dry run (" + exe_ + ") ended with status " + std::to_string(WEXITSTATUS(status))
                                 : why;
    } else {
      // Thinned: a point where the path moved 0.05 mm or its line or kind changed, at most 40,000.
      std::ifstream f(csv);
      std::string row;
      std::getline(f, row);  // header
      std::vector<double> pts;
      std::vector<int> lines, rapid;
      double lx = 1e300, ly = 1e300, lz = 1e300;
      int lline = -1, lrapid = -1;
      double tol = 0.05;
      while (std::getline(f, row)) {
        double v[6];
        size_t b = 0;
        int k = 0;
        for (; k < 6; ++k) {
          size_t e = row.find(',', b);
          if (e == std::string::npos) break;
          v[k] = std::strtod(row.c_str() + b, nullptr);
          b = e + 1;
        }
        if (k < 6) continue;
        const int line = static_cast<int>(v[5]);
        // The last column (--with-kind): the block's kind; a rapid is drawn apart from the feeds.
        const int is_rapid = row.ends_with(",rapid") ? 1 : 0;
        if (std::fabs(v[2] - lx) + std::fabs(v[3] - ly) + std::fabs(v[4] - lz) < tol && line == lline &&
            is_rapid == lrapid)
          continue;
        lx = v[2], ly = v[3], lz = v[4], lline = line, lrapid = is_rapid;
        pts.insert(pts.end(), {std::round(v[2] * 1000) / 1000, std::round(v[3] * 1000) / 1000,
                               std::round(v[4] * 1000) / 1000});
        lines.push_back(line);
        rapid.push_back(is_rapid);
        if (lines.size() > 40000) {  // coarser, from the start again would cost a second pass: halve
          std::vector<double> p2;
          std::vector<int> l2, r2;
          for (size_t i = 0; i < lines.size(); i += 2) {
            p2.insert(p2.end(), {pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]});
            l2.push_back(lines[i]);
            r2.push_back(rapid[i]);
          }
          pts.swap(p2);
          lines.swap(l2);
          rapid.swap(r2);
          tol *= 2;
        }
      }
      out["points"] = pts;
      out["lines"] = lines;
      out["rapid"] = rapid;
      out["modes"] = read_modes(modes);
    }
  }
  std::filesystem::remove(csv);
  std::filesystem::remove(err);
  std::filesystem::remove(modes);
  std::lock_guard<std::mutex> lk(mu_);
  result_ = out.dump();
}

}  // namespace cnc::hmi
