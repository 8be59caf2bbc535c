#include "services/logger/logger_node.h"

#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "common/bus/log_format.h"
#include "cnc/lcmt_interp_input.hpp"
#include "common/util/clock.h"

namespace cnc::logger {

int64_t udp_socket_drops() {
  std::set<unsigned long> inodes;
  DIR* dir = opendir("/proc/self/fd");
  if (dir == nullptr) return -1;
  while (const dirent* e = readdir(dir)) {
    char target[64];
    const std::string link = std::string("/proc/self/fd/") + e->d_name;
    const ssize_t n = readlink(link.c_str(), target, sizeof target - 1);
    if (n <= 0) continue;
    target[n] = '\0';
    unsigned long inode = 0;
    if (std::sscanf(target, "socket:[%lu]", &inode) == 1) inodes.insert(inode);
  }
  closedir(dir);
  int64_t drops = 0;
  bool readable = false;
  for (const char* table : {"/proc/self/net/udp", "/proc/self/net/udp6"}) {
    std::ifstream in(table);
    if (!in) continue;
    readable = true;
    std::string line;
    std::getline(in, line);  // the column titles
    while (std::getline(in, line)) {
      // sl local rem st tx:rx tr:when retrnsmt uid timeout inode ref pointer drops
      std::istringstream f(line);
      std::string col[13];
      int i = 0;
      while (i < 13 && f >> col[i]) ++i;
      if (i < 13) continue;
      const unsigned long inode = std::strtoul(col[9].c_str(), nullptr, 10);
      if (inodes.count(inode) != 0) drops += std::strtoll(col[12].c_str(), nullptr, 10);
    }
  }
  return readable ? drops : -1;
}

std::string receive_url(const std::string& url, int64_t bytes) {
  if (url.rfind("udpm://", 0) != 0 || url.find("recv_buf_size=") != std::string::npos) return url;
  return url + (url.find('?') == std::string::npos ? "?" : "&") + "recv_buf_size=" + std::to_string(bytes);
}

LoggerNode::LoggerNode(const config::MachineConfig& cfg, bus::Bus& bus, LogWriter& writer)
    : bus_(bus), writer_(writer), stats_channel_(cfg.channel(kStatsChannel)),
      flush_period_s_(cfg.log_flush_period_s) {
  bus_.subscribe_raw(bus::exact_channel(cfg.channel_prefix) + ".*",
                     [this](const std::string& channel, const void* data, size_t size, int64_t recv_utime) {
                       // The format event is the writer's own, never one from the network.
                       if (channel == bus::kLogFormatChannel) return;
                       // Our own stats are already in the file; the copy multicast loopback
                       // brings back is not written twice (another logger's stats are).
                       if (channel == stats_channel_) {
                         const auto hdr = bus::peek_header(data, size);
                         if (hdr && hdr->sender == bus_.sender()) return;
                       }
                       const int64_t dropped = writer_.dropped();
                       writer_.write(channel, data, size, recv_utime);
                       if (writer_.dropped() == dropped && channel.ends_with("INTERP_INPUT"))
                         note_input(data, size);
                     });
}

void LoggerNode::note_input(const void* data, size_t size) {
  cnc::lcmt_interp_input in;
  if (in.decode(data, 0, static_cast<int>(size)) < 0 || in.index < 0) return;
  InputAcks& a = input_acks_[in.sender];
  if (in.index < a.next) return;  // a copy of one already written
  constexpr size_t kMaxAhead = 65536;  // a sender far ahead of its gap: kept bounded
  if (in.index > a.next) {
    if (a.above.size() < kMaxAhead) a.above.insert(in.index);
    return;
  }
  ++a.next;
  while (!a.above.empty() && *a.above.begin() <= a.next) {
    if (*a.above.begin() == a.next) ++a.next;
    a.above.erase(a.above.begin());
  }
}

void LoggerNode::tick(double now_s) {
  if (last_stats_s_ < 0) last_stats_s_ = last_flush_s_ = last_tick_s_ = now_s;
  max_loop_gap_s_ = std::max(max_loop_gap_s_, now_s - last_tick_s_);
  last_tick_s_ = now_s;
  if (now_s - last_stats_s_ >= kStatsPeriodS) {
    write_stats(false);
    last_stats_s_ = now_s;
  }
  if (now_s - last_flush_s_ >= flush_period_s_) {
    writer_.flush();
    last_flush_s_ = now_s;
  }
}

void LoggerNode::close() {
  write_stats(true);
  writer_.close();
}

cnc::lcmt_logger_stats LoggerNode::make_stats(bool closing) const {
  cnc::lcmt_logger_stats m{};
  m.path = writer_.current_path();
  m.files = writer_.files();
  m.events = writer_.events();
  m.bytes = writer_.bytes();
  m.write_errors = writer_.write_errors();
  m.socket_drops = socket_drops_;
  m.max_io_s = writer_.max_io_s();
  m.max_loop_gap_s = max_loop_gap_s_;
  m.closing = closing;
  int64_t handler_errors = 0;
  std::set<std::string> names;
  for (const auto& [ch, st] : bus_.stats()) names.insert(ch);
  for (const auto& [ch, c] : writer_.channels()) names.insert(ch);
  for (const auto& ch : names) {
    const bus::ChannelStats st = bus_.stats(ch);
    const auto it = writer_.channels().find(ch);
    const LogWriter::ChannelCounts c = it == writer_.channels().end() ? LogWriter::ChannelCounts{} : it->second;
    if (st.received == 0 && c.logged == 0 && c.dropped == 0) continue;  // only published by us, never recorded
    // A message whose handler threw never reached the writer: the logger lost it.
    handler_errors += st.handler_errors;
    m.channel.push_back(ch);
    m.received.push_back(st.received);
    m.logged.push_back(c.logged);
    m.seq_gaps.push_back(st.seq_gaps);
    m.seq_restarts.push_back(st.seq_restarts);
    m.dropped.push_back(c.dropped + st.handler_errors);
  }
  m.num_channels = static_cast<int32_t>(m.channel.size());
  for (const auto& [sender, a] : input_acks_) {
    m.input_sender.push_back(sender);
    m.input_next.push_back(a.next);
  }
  m.num_input_senders = static_cast<int32_t>(m.input_sender.size());
  m.events_dropped = writer_.dropped() + handler_errors;
  return m;
}

void LoggerNode::write_stats(bool closing) {
  socket_drops_ = udp_socket_drops();
  cnc::lcmt_logger_stats m = make_stats(closing);
  m.utime = util::wall_utime();
  m.seq = stats_seq_++;
  m.sender = bus_.sender();
  const int size = m.getEncodedSize();
  encode_buf_.resize(static_cast<size_t>(size) + bus::kTrailerBytes);
  if (m.encode(encode_buf_.data(), 0, size) != size) return;
  // Signed like every message of the cell (signing on), in the file and on the bus.
  size_t n = bus_.sign_into(stats_channel_, encode_buf_.data(), static_cast<size_t>(size));
  if (n == 0) n = static_cast<size_t>(size);  // no key signs now: recorded unsigned, the receivers drop it
  writer_.write(stats_channel_, encode_buf_.data(), n, m.utime);
  try {
    bus_.publish_raw(stats_channel_, encode_buf_.data(), n);
  } catch (const bus::BusError&) {
    // The copy in the file is the one that counts.
  }
}

}  // namespace cnc::logger
