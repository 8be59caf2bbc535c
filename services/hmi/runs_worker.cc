#include "services/hmi/runs_worker.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

namespace cnc::hmi {

using json = nlohmann::json;

namespace {

// Runs a program to its end (a child process; its output to `log_file`): its exit
// status, or -1 when it could not start or was cancelled.
int run_child(const std::vector<std::string>& argv, const std::string& log_file, std::atomic<pid_t>* pid_slot) {
  std::vector<char*> a;
  for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
  a.push_back(nullptr);
  const pid_t child = fork();
  if (child == 0) {
    const int out = open(log_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (out >= 0) {
      dup2(out, 1);
      dup2(out, 2);
    }
    execv(a[0], a.data());
    _exit(127);
  }
  if (child < 0) return -1;
  *pid_slot = child;
  int status = 0;
  waitpid(child, &status, 0);
  *pid_slot = 0;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

RunsWorker::RunsWorker(std::string dir, std::string logexport, std::string make_report)
    : dir_(std::move(dir)), logexport_(std::move(logexport)), make_report_(std::move(make_report)) {
  thread_ = std::thread([this] { loop(); });
}

RunsWorker::~RunsWorker() {
  {
    std::lock_guard<std::mutex> lk(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (const pid_t p = child_.load(); p > 0) kill(p, SIGTERM);
  thread_.join();
}

bool RunsWorker::post(Job j) {
  std::lock_guard<std::mutex> lk(mu_);
  if (jobs_.size() >= 8) return false;
  jobs_.push_back(std::move(j));
  cv_.notify_one();
  return true;
}

std::vector<std::pair<uint64_t, json>> RunsWorker::take() {
  std::lock_guard<std::mutex> lk(mu_);
  std::vector<std::pair<uint64_t, json>> out;
  out.swap(out_);
  return out;
}

std::string RunsWorker::report_dir(const RunEntry& r) {
  if (r.log.find('/') != std::string::npos) return r.name + "/report";
  return std::filesystem::path(r.name).stem().string() + "-report";
}

json RunsWorker::list() {
  json runs = json::array();
  for (const auto& r : list_runs(dir_)) {
    const std::string path = dir_ + "/" + r.log;
    const std::string key = path + "|" + std::to_string(r.bytes) + "|" + std::to_string(r.mtime_s);
    auto it = cache_.find(path);
    if (it == cache_.end() || it->second.first != key) {
      it = cache_.insert_or_assign(path, std::make_pair(key, summarize_log(path))).first;
    }
    const RunSummary& sum = it->second.second;
    json row = {{"name", r.name},         {"log", r.log},         {"mtime", r.mtime_s},
                {"bytes", r.bytes},       {"report", r.report},   {"programs", sum.programs},
                {"mdi_lines", sum.mdi_lines}, {"duration_s", std::round(sum.duration_s * 10) / 10},
                {"start", sum.start_utime_s}, {"alarms", sum.alarms}, {"faults", sum.faults}};
    if (!sum.ok) row["error"] = sum.error;
    if (r.report) row["report_url"] = "/runs/" + report_dir(r) + "/index.html";
    runs.push_back(row);
  }
  return {{"t", "runs"}, {"runs", runs}, {"dir", dir_}};
}

json RunsWorker::report(const Job& j) {
  const auto all = list_runs(dir_);
  const auto it = std::find_if(all.begin(), all.end(), [&](const auto& r) { return r.log == j.log; });
  if (it == all.end())
    return {{"t", "result"}, {"id", j.id}, {"ok", false}, {"text", "report: no run '" + j.log + "' in " + dir_}};
  const std::string out = dir_ + "/" + report_dir(*it);
  std::filesystem::create_directories(out);
  const std::string log = dir_ + "/" + it->log;
  const std::string messages = out + "/make.log";
  std::filesystem::remove(messages);
  int rc = run_child({logexport_, "--log", log, "--out", out}, messages, &child_);
  if (rc == 0) {
    std::vector<std::string> mk = {"/usr/bin/python3", make_report_, out, "--title", it->name};
    const std::string lat = std::filesystem::path(log).parent_path().string() + "/latency";
    if (std::filesystem::is_directory(lat)) mk.insert(mk.end(), {"--latency-dir", lat});
    rc = run_child(mk, messages, &child_);
  }
  if (rc != 0)
    return {{"t", "result"}, {"id", j.id}, {"ok", false},
            {"text", "report of " + it->log + " failed (status " + std::to_string(rc) + "): see " + messages}};
  return {{"t", "result"}, {"id", j.id}, {"ok", true}, {"text", "report of " + it->log + " ready"},
          {"report_url", "/runs/" + report_dir(*it) + "/index.html"}};
}

// The run's path for the page to play back in its preview (the page animates it: the
// machine is not involved).
json RunsWorker::playback(const Job& j) {
  const auto all = list_runs(dir_);
  const auto it = std::find_if(all.begin(), all.end(), [&](const auto& r) { return r.log == j.log; });
  if (it == all.end())
    return {{"t", "result"}, {"id", j.id}, {"ok", false}, {"text", "playback: no run '" + j.log + "' in " + dir_}};
  const RunPath p = log_path(dir_ + "/" + it->log);
  if (!p.ok || p.t_s.empty())
    return {{"t", "result"}, {"id", j.id}, {"ok", false},
            {"text", "playback: " + (p.ok ? "no setpoints in " + it->log : p.error)}};
  std::vector<double> xyz(p.xyz.size()), ts(p.t_s.size());
  for (size_t i = 0; i < xyz.size(); ++i) xyz[i] = std::round(p.xyz[i] * 1000) / 1000;
  for (size_t i = 0; i < ts.size(); ++i) ts[i] = std::round(p.t_s[i] * 1000) / 1000;
  return {{"t", "playback"}, {"id", j.id}, {"log", it->log}, {"points", xyz}, {"times", ts}, {"lines", p.lines},
          {"duration_s", p.duration_s}, {"setpoints", p.setpoints}};
}

void RunsWorker::loop() {
  for (;;) {
    Job j;
    {
      std::unique_lock<std::mutex> lk(mu_);
      cv_.wait(lk, [&] { return stop_ || !jobs_.empty(); });
      if (stop_) return;
      j = std::move(jobs_.front());
      jobs_.pop_front();
    }
    json r = j.kind == "report" ? report(j) : j.kind == "playback" ? playback(j) : list();
    std::lock_guard<std::mutex> lk(mu_);
    out_.emplace_back(j.client, std::move(r));
    if (j.kind == "report") out_.emplace_back(j.client, list());
  }
}

}  // namespace cnc::hmi
