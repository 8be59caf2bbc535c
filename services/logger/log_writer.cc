#include "services/logger/log_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <limits>
#include <stdexcept>

#include "common/bus/log_format.h"

namespace cnc::logger {
namespace {
// The LCM log event: magic, event number, timestamp (µs), channel length, data
// length (all big-endian), then the channel name and the data.
constexpr uint32_t kMagic = 0xEDA1DA01u;
constexpr size_t kEventHeaderBytes = 4 + 8 + 8 + 4 + 4;
// LCM's reader refuses (1.3.1: asserts on) channel names of 1000 bytes or more.
constexpr size_t kMaxChannelBytes = 999;

double now_s() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

void put_be(std::vector<uint8_t>& out, uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
}
}  // namespace

LogWriter::LogWriter(std::string base_path, double rotate_bytes, size_t buffer_bytes, std::string header)
    : base_(std::move(base_path)), header_(std::move(header)), rotate_bytes_(rotate_bytes), buffer_bytes_(buffer_bytes) {
  buf_.reserve(buffer_bytes_ + 1024);
  pending_.reserve(1024);
  // Never over an earlier file (a logger restarted after a crash, two in one second):
  // NAME.lcmlog taken -> NAME-2.lcmlog, NAME-3.lcmlog, ...
  const std::string wanted = base_;
  for (int n = 2; ::access(part_path(0).c_str(), F_OK) == 0; ++n) base_ = wanted + "-" + std::to_string(n);
  if (!open_part(0)) throw std::runtime_error("cannot create log file " + part_path(0) + ": " + std::strerror(errno));
}

LogWriter::~LogWriter() { close(); }

std::string LogWriter::part_path(int part) const {
  return part == 0 ? base_ + ".lcmlog" : base_ + "." + std::to_string(part) + ".lcmlog";
}

bool LogWriter::open_part(int part) {
  const std::string path = part_path(part);
  // O_EXCL: a file that appeared meanwhile is never truncated (the open fails instead).
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) return false;
  close_file();
  fd_ = fd;
  part_ = part;
  path_ = path;
  file_bytes_ = 0;
  file_events_ = 0;
  return true;
}

void LogWriter::close_file() {
  if (fd_ < 0) return;
  const double t0 = now_s();
  ::fsync(fd_);
  max_io_s_ = std::max(max_io_s_, now_s() - t0);
  ::close(fd_);
  fd_ = -1;
}

bool LogWriter::write(const std::string& channel, const void* data, size_t size, int64_t utime) {
  ChannelCounts& counts = channels_[channel];
  if (closed_ || channel.empty() || channel.size() > kMaxChannelBytes ||
      size > static_cast<size_t>(std::numeric_limits<int32_t>::max())) {
    ++counts.dropped;
    ++dropped_;
    return false;
  }
  const size_t event_bytes = kEventHeaderBytes + channel.size() + size;
  const auto unwritten = static_cast<double>(file_bytes_) + static_cast<double>(buf_.size());
  if (!rotation_failed_ && unwritten > 0 && unwritten + static_cast<double>(event_bytes) > rotate_bytes_) {
    write_out();
    // open_part fsyncs and closes the finished file. When the next one cannot be
    // created, the events go on into the current file rather than being lost.
    if (!open_part(part_ + 1)) {
      ++write_errors_;
      rotation_failed_ = true;
    }
  }
  if (file_events_ == 0 && !header_.empty())
    append(bus::kLogFormatChannel, header_.data(), header_.size(), utime, channels_[bus::kLogFormatChannel]);
  append(channel, data, size, utime, counts);
  return true;
}

void LogWriter::append(const std::string& channel, const void* data, size_t size, int64_t utime,
                       ChannelCounts& counts) {
  const size_t event_bytes = kEventHeaderBytes + channel.size() + size;
  if (!buf_.empty() && buf_.size() + event_bytes > buffer_bytes_) write_out();
  put_be(buf_, kMagic, 4);
  put_be(buf_, static_cast<uint64_t>(file_events_++), 8);
  put_be(buf_, static_cast<uint64_t>(utime), 8);
  put_be(buf_, static_cast<uint64_t>(channel.size()), 4);
  put_be(buf_, static_cast<uint64_t>(size), 4);
  buf_.insert(buf_.end(), channel.begin(), channel.end());
  const auto* bytes = static_cast<const uint8_t*>(data);
  buf_.insert(buf_.end(), bytes, bytes + size);
  pending_.push_back(&counts);
  if (buf_.size() >= buffer_bytes_) write_out();
}

bool LogWriter::write_out() {
  if (pending_.empty()) return true;
  size_t done = 0;
  bool ok = fd_ >= 0;
  const double t0 = now_s();
  while (ok && done < buf_.size()) {
    const ssize_t n = ::write(fd_, buf_.data() + done, buf_.size() - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else {
      ok = false;
    }
  }
  max_io_s_ = std::max(max_io_s_, now_s() - t0);
  if (ok) {
    file_bytes_ += static_cast<int64_t>(buf_.size());
    bytes_ += static_cast<int64_t>(buf_.size());
    events_ += static_cast<int64_t>(pending_.size());
    for (ChannelCounts* c : pending_) ++c->logged;
  } else {
    // A torn event would hide the events after it: cut the file back to its last
    // whole event (O_APPEND puts the next write there), or, when even that fails,
    // leave the torn tail where readers stop and go on in the next file.
    if (done > 0 && ::ftruncate(fd_, file_bytes_) != 0) open_part(part_ + 1);
    ++write_errors_;
    dropped_ += static_cast<int64_t>(pending_.size());
    for (ChannelCounts* c : pending_) ++c->dropped;
  }
  buf_.clear();
  pending_.clear();
  return ok;
}

bool LogWriter::flush() {
  rotation_failed_ = false;  // the next event over the size tries again
  return write_out();
}

void LogWriter::close() {
  if (closed_) return;
  write_out();
  close_file();
  closed_ = true;
}

}  // namespace cnc::logger
