#pragma once
// The dry run of a loaded program for the HMI's preview, in a child process.
#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace cnc::hmi {

// The dry run of a loaded program for the preview: cnc-plan (the same code as
// `./cnc plan`) in a child process, its setpoints thinned to what a canvas shows.
class DryRun {
 public:
  DryRun(std::string machine_file, std::string plan_exe) : machine_(std::move(machine_file)), exe_(std::move(plan_exe)) {}
  ~DryRun() { cancel(); }

  // Cancels the one running. block_delete: the program server's switch the program was
  // loaded with (PROGRAM_STATE), so that the preview skips the '/' lines the run skips;
  // start_mm: where the machine stands (INTERP_STATE, machine coordinates), where the
  // server loaded the program from (empty: home).
  void start(int64_t token, const std::string& program, bool block_delete, std::vector<double> start_mm = {});
  void cancel();
  // The finished preview, once (a JSON text), or "".
  std::string take() {
    std::lock_guard<std::mutex> lk(mu_);
    std::string r;
    r.swap(result_);
    return r;
  }

 private:
  void run(int64_t token, const std::string& program, bool block_delete, const std::vector<double>& start_mm);

  std::string machine_, exe_;
  std::thread thread_;
  std::atomic<pid_t> pid_{0};
  std::atomic<bool> cancelled_{false};
  std::mutex mu_;
  std::string result_;
};

}  // namespace cnc::hmi
