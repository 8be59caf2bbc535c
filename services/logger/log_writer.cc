#include "services/logger/log_writer.h"

#include <unistd.h>

#include <cstdio>
#include <stdexcept>

namespace cnc::logger {

LogWriter::LogWriter(std::string base_path, double rotate_bytes)
    : base_(std::move(base_path)), rotate_bytes_(rotate_bytes) {
  open_part();
}

LogWriter::~LogWriter() { close(); }

void LogWriter::open_part() {
  path_ = part_ == 0 ? base_ + ".lcmlog" : base_ + "." + std::to_string(part_) + ".lcmlog";
  log_ = lcm_eventlog_create(path_.c_str(), "w");
  if (log_ == nullptr) throw std::runtime_error("cannot create log file " + path_);
  bytes_ = 0;
}

bool LogWriter::write(const std::string& channel, const void* data, size_t size, int64_t utime) {
  if (log_ == nullptr) {
    ++dropped_;
    return false;
  }
  if (bytes_ > 0 && static_cast<double>(bytes_) + static_cast<double>(size) > rotate_bytes_) {
    close();
    ++part_;
    open_part();
  }
  lcm_eventlog_event_t ev{};
  ev.eventnum = events_;
  ev.timestamp = utime;
  ev.channellen = static_cast<int32_t>(channel.size());
  ev.datalen = static_cast<int32_t>(size);
  ev.channel = const_cast<char*>(channel.c_str());
  ev.data = const_cast<void*>(data);
  if (lcm_eventlog_write_event(log_, &ev) != 0) {
    ++dropped_;
    return false;
  }
  ++events_;
  bytes_ += static_cast<int64_t>(size + channel.size() + 28);
  return true;
}

void LogWriter::flush() {
  if (log_ != nullptr) std::fflush(log_->f);
}

void LogWriter::close() {
  if (log_ == nullptr) return;
  std::fflush(log_->f);
  fsync(fileno(log_->f));
  lcm_eventlog_destroy(log_);
  log_ = nullptr;
}

}  // namespace cnc::logger
