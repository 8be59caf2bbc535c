#include "common/service/peer_watch.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "common/util/clock.h"

namespace cnc::service {

namespace {
const char* state_name(int8_t s) {
  switch (s) {
    case cnc::lcmt_heartbeat::STARTING: return "starting";
    case cnc::lcmt_heartbeat::RUNNING: return "running";
    case cnc::lcmt_heartbeat::STOPPING: return "stopping";
    case cnc::lcmt_heartbeat::FAULT: return "fault";
  }
  return "unknown";
}
}  // namespace

PeerWatch::PeerWatch(bus::Bus& bus, const config::MachineConfig& cfg, std::string self, std::vector<std::string> peers)
    : PeerWatch(bus, cfg.channel(config::channels::kHeartbeat), cfg.channel(config::channels::kAlarm),
                cfg.heartbeat_timeout_s, std::move(self), std::move(peers)) {}

PeerWatch::PeerWatch(bus::Bus& bus, const std::string& heartbeat_channel, const std::string& alarm_channel,
                     double timeout_s, std::string self, std::vector<std::string> peers, double (*clock)())
    : bus_(bus), alarm_channel_(alarm_channel), timeout_s_(timeout_s), clock_(clock ? clock : &util::monotonic_s) {
  if (peers.size() > kMaxPeers) throw std::invalid_argument("PeerWatch: more than 8 peers");
  for (auto& p : peers) peers_[n_++].name = std::move(p);
  al_.source = std::move(self);
  al_.code.reserve(32);
  al_.text.reserve(kTextBytes);
  bus_.subscribe<cnc::lcmt_heartbeat>(heartbeat_channel,
                                      [this](const cnc::lcmt_heartbeat& m) { on_heartbeat(m, clock_()); });
  // Every channel of the cell (the heartbeat channel's prefix): any message a peer
  // sends is a sign of life. The bus verifies each message once, whichever
  // subscriptions match it, and hands over only what verified.
  const std::string suffix = config::channels::kHeartbeat;
  const std::string prefix = heartbeat_channel.size() >= suffix.size() &&
                                     heartbeat_channel.compare(heartbeat_channel.size() - suffix.size(), suffix.size(),
                                                               suffix) == 0
                                 ? heartbeat_channel.substr(0, heartbeat_channel.size() - suffix.size())
                                 : std::string();
  if (!prefix.empty()) {
    bus_.subscribe_raw(bus::exact_channel(prefix) + ".*",
                       [this](const std::string&, const void* data, size_t size, int64_t) {
                         if (const auto h = bus::peek_header(data, size)) on_message(h->sender, clock_());
                       });
  }
}

void PeerWatch::on_message(int32_t sender, double now_s) {
  if (sender == 0 || sender == bus_.sender()) return;  // unknown, or this process's own
  for (size_t i = 0; i < n_; ++i) {
    Peer& p = peers_[i];
    if (p.sender != sender || p.stopped) continue;
    p.last_s = std::max(p.last_s, now_s);
    return;
  }
}

void PeerWatch::on_heartbeat(const cnc::lcmt_heartbeat& m, double now_s) {
  for (size_t i = 0; i < n_; ++i) {
    Peer& p = peers_[i];
    if (m.service != p.name) continue;
    if (p.pid != 0 && m.pid != p.pid && !p.lost && !p.stopped) p.restarted = true;
    p.last_s = now_s;
    p.pid = m.pid;
    p.sender = m.sender;
    p.state = m.state;
    p.stopped = m.state == cnc::lcmt_heartbeat::STOPPING;
    return;
  }
}

void PeerWatch::raise(int8_t severity, const char* code, const char* text) {
  al_.severity = severity;
  al_.code.assign(code);
  al_.text.assign(text);
  ++alarms_;
  // Rare (a peer lost, back, restarted): logged too, the test harnesses wait on it.
  spdlog::warn("ALARM {} [{}] {}", al_.source, code, text);
  bus_.publish(alarm_channel_, al_);  // a failure is counted by the bus (BusHealth reports it)
}

int PeerWatch::check(double now_s) {
  int found = 0;
  char text[kTextBytes];
  for (size_t i = 0; i < n_; ++i) {
    Peer& p = peers_[i];
    if (!seen(i)) continue;
    if (p.restarted) {
      p.restarted = false;
      std::snprintf(text, sizeof text, "%s runs with a new pid %d: it restarted (its state was lost)", p.name.c_str(),
                    p.pid);
      raise(cnc::lcmt_alarm::WARNING, "peer_restarted", text);
    }
    const double silent = now_s - p.last_s;
    if (!p.lost && !p.stopped && silent > timeout_s_) {
      p.lost = true;
      p.lost_at_s = p.last_s;
      ++found;
      std::snprintf(text, sizeof text, "no heartbeat from %s (pid %d, last state %s) for %.2f s (timeout %.2f s)",
                    p.name.c_str(), p.pid, state_name(p.state), silent, timeout_s_);
      std::snprintf(lost_text_.data(), lost_text_.size(), "%s", text);
      raise(cnc::lcmt_alarm::WARNING, "peer_lost", text);
    } else if (p.lost && (silent <= timeout_s_ || p.stopped)) {
      p.lost = false;
      std::snprintf(text, sizeof text, "%s is back (pid %d, state %s) after %.2f s without a heartbeat", p.name.c_str(),
                    p.pid, state_name(p.state), p.last_s - p.lost_at_s);
      raise(cnc::lcmt_alarm::INFO, "peer_back", text);
    }
  }
  return found;
}

}  // namespace cnc::service
