#pragma once
// Writes events in the standard LCM log format (what lcm-logplayer reads), with
// size-based rotation, periodic flush and fsync on close.
#include <lcm/lcm.h>
#include <lcm/eventlog.h>

#include <cstdint>
#include <string>

namespace cnc::logger {

class LogWriter {
 public:
  // base_path: "DIR/NAME" — files are DIR/NAME.lcmlog, then DIR/NAME.1.lcmlog, ...
  LogWriter(std::string base_path, double rotate_bytes);
  ~LogWriter();
  LogWriter(const LogWriter&) = delete;
  LogWriter& operator=(const LogWriter&) = delete;

  // Returns false when the write failed (the event is counted as dropped).
  bool write(const std::string& channel, const void* data, size_t size, int64_t utime);
  void flush();
  void close();  // flush + fsync
  const std::string& current_path() const { return path_; }
  int64_t events() const { return events_; }
  int64_t dropped() const { return dropped_; }
  int files() const { return part_ + 1; }

 private:
  void open_part();
  std::string base_;
  double rotate_bytes_;
  lcm_eventlog_t* log_ = nullptr;
  std::string path_;
  int part_ = 0;
  int64_t bytes_ = 0;
  int64_t events_ = 0;
  int64_t dropped_ = 0;
};

}  // namespace cnc::logger
