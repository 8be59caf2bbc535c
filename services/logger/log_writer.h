#pragma once
// Writes events in the standard LCM log format (what lcm-logplayer reads), with
// size-based rotation, periodic flush and fsync on close.
//
// Events are assembled whole in a buffer of our own and handed to the kernel by
// write(2) in whole events only (when the buffer fills, on flush(), at rotation and
// at close). So a process killed with SIGKILL leaves a file that ends on an event
// boundary: everything up to the last hand-over is there and readable, only the
// events still in the buffer are lost. A failed write is cut back off the file
// (ftruncate to the last whole event) and the events it carried are counted as
// dropped, per channel; the event numbers of a file then show the hole.
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace cnc::logger {

class LogWriter {
 public:
  struct ChannelCounts {
    int64_t logged = 0;   // handed to the kernel
    int64_t dropped = 0;  // lost by the writer: a failed write, or an event too large for the format
  };

  static constexpr size_t kDefaultBufferBytes = 64 * 1024;

  // base_path: "DIR/NAME" — files are DIR/NAME.lcmlog, then DIR/NAME.1.lcmlog, ...; when
  // DIR/NAME.lcmlog exists already, NAME-2 (-3, ...) instead: an earlier file is never overwritten.
  // A file is closed and the next one started before an event would take it past
  // rotate_bytes (a file holds at least one event, however large).
  // header: when not empty, the first event of every file, on bus::kLogFormatChannel
  // with the time stamp of the event after it (bus::log_format_record()).
  LogWriter(std::string base_path, double rotate_bytes, size_t buffer_bytes = kDefaultBufferBytes,
            std::string header = "");
  ~LogWriter();
  LogWriter(const LogWriter&) = delete;
  LogWriter& operator=(const LogWriter&) = delete;

  // Appends one event. Returns false when it is already known to be lost (too large
  // for the format, or the writer is closed); a later failed write of the buffer
  // shows up in dropped() instead.
  bool write(const std::string& channel, const void* data, size_t size, int64_t utime);
  // Hands the buffered events to the kernel. Returns false when the write failed.
  bool flush();
  void close();  // flush + fsync + close; further writes are dropped

  const std::string& current_path() const { return path_; }
  int files() const { return part_ + 1; }
  int64_t events() const { return events_; }        // handed to the kernel, all files
  int64_t bytes() const { return bytes_; }          // bytes in all files
  int64_t dropped() const { return dropped_; }      // events lost by the writer
  int64_t write_errors() const { return write_errors_; }
  size_t buffered_events() const { return pending_.size(); }
  double max_io_s() const { return max_io_s_; }  // the longest write(2) or fsync so far
  const std::map<std::string, ChannelCounts>& channels() const { return channels_; }

 private:
  bool open_part(int part);
  bool write_out();
  void append(const std::string& channel, const void* data, size_t size, int64_t utime, ChannelCounts& counts);
  void close_file();
  std::string part_path(int part) const;

  std::string base_;
  std::string header_;
  double rotate_bytes_;
  size_t buffer_bytes_;
  int fd_ = -1;
  bool closed_ = false;
  bool rotation_failed_ = false;  // retried at the next flush, not at every event
  std::string path_;
  int part_ = 0;
  int64_t file_bytes_ = 0;   // bytes of the current file on disk
  int64_t file_events_ = 0;  // event number of the next event in the current file
  int64_t events_ = 0;
  int64_t bytes_ = 0;
  int64_t dropped_ = 0;
  int64_t write_errors_ = 0;
  double max_io_s_ = 0;
  std::vector<uint8_t> buf_;
  std::vector<ChannelCounts*> pending_;  // the channel of each event in buf_
  std::map<std::string, ChannelCounts> channels_;
};

}  // namespace cnc::logger
