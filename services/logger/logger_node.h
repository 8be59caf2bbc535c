#pragma once
// The logger's LCM node: every channel of the cell into a LogWriter, and the
// logger's own counts (lcmt_logger_stats) written straight into the log about once
// a second and once at close, so they are in the file even when multicast loopback
// does not bring anything back.
#include <map>
#include <set>
#include <string>

#include "cnc/lcmt_logger_stats.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "services/logger/log_writer.h"

namespace cnc::logger {

// Datagrams the kernel dropped at this process's UDP sockets (the "drops" column
// of /proc/net/udp and udp6 for the socket inodes in /proc/self/fd); -1 when that
// cannot be read.
int64_t udp_socket_drops();

// The URL the logger opens: a udpm:// URL gets recv_buf_size=bytes (LCM's option)
// unless it sets one. The kernel's default receive buffer (net.core.rmem_default,
// ~208 KiB) holds only ~0.1 s of the cell's traffic, so a logger descheduled that
// long on a busy PC loses datagrams; the kernel caps the request at
// net.core.rmem_max.
std::string receive_url(const std::string& url, int64_t bytes);

class LoggerNode {
 public:
  static constexpr double kStatsPeriodS = 1.0;
  static constexpr const char* kStatsChannel = "LOGGER_STATS";

  // Subscribes to every channel of the cell's prefix.
  LoggerNode(const config::MachineConfig& cfg, bus::Bus& bus, LogWriter& writer);

  // Call often (after each bus.handle): flushes every flush period and writes the
  // stats every kStatsPeriodS. now_s: a monotonic clock.
  void tick(double now_s);
  // Writes the closing stats as the file's last event, then closes the writer.
  void close();

  // The counts as they stand: per channel, the bus's receive counters and the
  // writer's logged/dropped counts.
  cnc::lcmt_logger_stats make_stats(bool closing) const;
  const std::string& stats_channel() const { return stats_channel_; }

 private:
  void write_stats(bool closing);

  bus::Bus& bus_;
  LogWriter& writer_;
  std::string stats_channel_;
  double flush_period_s_;
  double last_flush_s_ = -1;
  double last_stats_s_ = -1;
  double last_tick_s_ = -1;
  double max_loop_gap_s_ = 0;
  int64_t stats_seq_ = 0;
  // Per interpolator: the lowest INTERP_INPUT index not yet in the file, and the
  // ones above it already written (bounded), confirmed in every stats report.
  struct InputAcks {
    int64_t next = 0;
    std::set<int64_t> above;
  };
  std::map<int32_t, InputAcks> input_acks_;
  void note_input(const void* data, size_t size);
  int64_t socket_drops_ = 0;
  std::vector<uint8_t> encode_buf_;
};

}  // namespace cnc::logger
