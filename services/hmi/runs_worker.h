#pragma once
// The HMI's run analysis worker: lists the recorded runs, makes their reports and
// reads their paths for playback, on a thread of its own.
#include <sys/types.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "services/hmi/programs.h"
#include "services/hmi/runs.h"

namespace cnc::hmi {

// The runs directory for the page, on a thread of its own: a log is
// read whole for its summary (cached by path, size and time), and a report is made by
// the same two steps as ./cnc report (cnc-logexport, make_report.py). Nothing here
// touches the machine.
class RunsWorker {
 public:
  struct Job {
    uint64_t client = 0;
    nlohmann::json id;
    std::string kind;  // "list", "report" or "playback"
    std::string log;   // report, playback: the log, relative to the runs directory (as listed)
  };
  RunsWorker(std::string dir, std::string logexport, std::string make_report);
  ~RunsWorker();
  RunsWorker(const RunsWorker&) = delete;
  RunsWorker& operator=(const RunsWorker&) = delete;
  // False when 8 jobs wait already.
  bool post(Job j);
  // The answers so far: (client, message).
  std::vector<std::pair<uint64_t, nlohmann::json>> take();

 private:
  static std::string report_dir(const RunEntry& r);
  nlohmann::json list();
  nlohmann::json report(const Job& j);
  nlohmann::json playback(const Job& j);
  void loop();

  std::string dir_, logexport_, make_report_;
  std::map<std::string, std::pair<std::string, RunSummary>> cache_;
  std::thread thread_;
  std::atomic<pid_t> child_{0};
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Job> jobs_;
  std::vector<std::pair<uint64_t, nlohmann::json>> out_;
  bool stop_ = false;
};

}  // namespace cnc::hmi
