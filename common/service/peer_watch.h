#pragma once
// Watches the heartbeats of the peers a service depends on. Every service publishes
// HEARTBEAT every timing.heartbeat_period_s (service::Heartbeat); a peer from which
// nothing has come for timing.heartbeat_timeout_s is lost. Any message of the cell's
// channels from the peer's sender id (learnt from its heartbeats: the header's
// `sender`) is a sign of life too, verified like every message where the cell signs:
// a busy or lossy moment that delays or drops its heartbeats while its setpoints or
// statuses still come is no loss.
//
//   PeerWatch peers(bus, cfg, "cnc-interpolator", {"cnc-drive-bridge", "cnc-program-server"});
//   ... every cycle, after the bus was drained:
//   peers.check(now_s);                      // raises the ALARMs
//   if (peers.lost(0)) ...                   // level: the peer is missing now
//
// What is raised, on ALARM with the watcher as source (signed like every message):
//   peer_lost (WARNING)     no heartbeat from P (pid N, last state S) for T s
//   peer_back (INFO)        P is back (pid N), after T s without heartbeat
//   peer_restarted (WARNING) P runs with a new pid: it restarted (within the timeout)
// A peer that stops cleanly says so in its last heartbeat (STOPPING): no alarm, it
// is only marked stopped. A peer never seen is not reported (the operator tool
// reports services that are not up). An alarm is raised at most heartbeat_timeout_s
// plus one call period after the last heartbeat.
//
// Cyclic paths: check() compares time stamps; the heartbeat handler compares the
// service name with the peers' names and stores a time stamp; raising an alarm
// formats into fixed storage and reuses one alarm message whose strings are reserved
// up front: nothing is allocated after construction (tests/unit/peer_watch_test.cc).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"

namespace cnc::service {

class PeerWatch {
 public:
  static constexpr size_t kMaxPeers = 8;
  static constexpr size_t kTextBytes = 256;

  // Subscribes to the cell's HEARTBEAT channel on `bus`.
  PeerWatch(bus::Bus& bus, const config::MachineConfig& cfg, std::string self, std::vector<std::string> peers);
  // For tests: the timeout given, and a clock of the caller's (the handler's time
  // stamps come from `clock`, by default util::monotonic_s).
  PeerWatch(bus::Bus& bus, const std::string& heartbeat_channel, const std::string& alarm_channel, double timeout_s,
            std::string self, std::vector<std::string> peers, double (*clock)() = nullptr);

  // Raises the alarms of peers lost or back since the last call. Returns the number
  // of peers that were found lost in this call.
  int check(double now_s);
  // A heartbeat, as the subscription hands it over (public for tests).
  void on_heartbeat(const cnc::lcmt_heartbeat& m, double now_s);
  // Any other message of the cell from `sender` (public for tests).
  void on_message(int32_t sender, double now_s);

  size_t size() const { return n_; }
  const std::string& name(size_t i) const { return peers_[i].name; }
  // Missing now (found by check), not stopped cleanly.
  bool lost(size_t i) const { return peers_[i].lost; }
  // Said STOPPING in its last heartbeat.
  bool stopped(size_t i) const { return peers_[i].stopped; }
  bool seen(size_t i) const { return peers_[i].last_s > -1e300; }
  double silent_s(size_t i, double now_s) const { return seen(i) ? now_s - peers_[i].last_s : 1e300; }
  // The text of the last peer_lost alarm ("" before any).
  const char* last_lost_text() const { return lost_text_.data(); }
  double timeout_s() const { return timeout_s_; }
  int64_t alarms() const { return alarms_; }

 private:
  struct Peer {
    std::string name;
    double last_s = -1e308;
    double lost_at_s = 0;  // time of its last heartbeat when found lost
    int32_t pid = 0;
    int32_t sender = 0;     // its messages' sender id, from its last heartbeat (0: unknown)
    int8_t state = -1;
    bool lost = false;
    bool stopped = false;
    bool restarted = false;  // a new pid seen: raise peer_restarted on the next check
  };
  void raise(int8_t severity, const char* code, const char* text);

  bus::Bus& bus_;
  std::string alarm_channel_;
  double timeout_s_;
  double (*clock_)();
  std::array<Peer, kMaxPeers> peers_{};
  size_t n_ = 0;
  cnc::lcmt_alarm al_{};
  std::array<char, kTextBytes> lost_text_{};
  int64_t alarms_ = 0;
};

}  // namespace cnc::service
