#pragma once
// Watches a service's failed publishes (Bus::publish never throws; it counts).
// Once per cycle:
//
//   if (health.check(now_s)) enter_fault(health.cause());   // new failures this cycle
//   health.report(now_s, "program stopped; RESET to continue");
//
// check() is true on the cycle where a failure streak begins (the caller stops its
// axes and goes to FAULT). report() sends one ALARM naming the cause, the number of
// failed publishes and the time the streak lasted, once the bus carries messages
// again: it tries at most every 100 ms, and a try that fails counts in the streak.
// No allocation while the bus fails (the cause is kept in fixed storage).
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>

#include "cnc/lcmt_alarm.hpp"
#include "common/bus/bus.h"

namespace cnc::service {

class BusHealth {
 public:
  BusHealth(bus::Bus& bus, std::string alarm_channel, std::string source, int8_t severity)
      : bus_(bus), channel_(std::move(alarm_channel)), source_(std::move(source)), severity_(severity),
        seen_(bus.publish_failures()) {}

  // True when publishes failed since the last call and no streak was open: a new
  // fault. Further failures extend the open streak (counted, false).
  bool check(double now_s) {
    const int64_t n = bus_.publish_failures();
    if (n == seen_) return false;
    const int64_t added = n - seen_;
    seen_ = n;
    streak_failures_ += added;
    last_failure_s_ = now_s;
    if (open_) return false;
    open_ = true;
    first_failure_s_ = now_s;
    std::snprintf(cause_.data(), cause_.size(), "%s", bus_.last_publish_error());
    return true;
  }

  // Sends the streak's ALARM once the bus works again. `action`: what the service did.
  // Returns true when the alarm went out.
  bool report(double now_s, const char* action) {
    if (!open_ || now_s - last_try_s_ < 0.1) return false;
    last_try_s_ = now_s;
    cnc::lcmt_alarm al{};
    al.source = source_;
    al.severity = severity_;
    al.code = "publish_failed";
    char text[512];
    std::snprintf(text, sizeof text, "%lld publish(es) failed over %.3f s (first: %s); %s",
                  static_cast<long long>(streak_failures_), last_failure_s_ - first_failure_s_, cause_.data(), action);
    al.text = text;
    if (!bus_.publish(channel_, al)) {
      check(now_s);  // the try failed too: part of the streak, not a new one
      return false;
    }
    total_failures_ += streak_failures_;
    ++streaks_;
    streak_failures_ = 0;
    open_ = false;
    return true;
  }

  bool failing() const { return open_; }
  const char* cause() const { return cause_.data(); }
  int64_t streaks_reported() const { return streaks_; }
  int64_t failures_reported() const { return total_failures_; }

 private:
  bus::Bus& bus_;
  std::string channel_;
  std::string source_;
  int8_t severity_;
  int64_t seen_;
  bool open_ = false;
  int64_t streak_failures_ = 0;
  int64_t total_failures_ = 0;
  int64_t streaks_ = 0;
  double first_failure_s_ = 0;
  double last_failure_s_ = 0;
  double last_try_s_ = -1e9;
  std::array<char, 160> cause_{};
};

// Signed channels: raises an ALARM when the bus dropped messages (bus::Reject), at
// most one per cause and second, naming the count since the last alarm of that
// cause, the channels and the last sender, so an attacker's flood makes one alarm a
// second and cause, never a flood of alarms. Call it as often as you like (every
// cycle): when nothing was dropped it compares five counters and returns. Raising
// an alarm allocates nothing either: the text is formatted into fixed storage and
// the alarm message, its strings reserved up front, is reused; the counts already
// reported are kept per channel in a fixed table (keyed by the bus's stats entries,
// which do not move).
class RejectAlarms {
 public:
  static constexpr double kMinPeriodS = 1.0;
  static constexpr size_t kTextBytes = 480;
  static constexpr size_t kMaxChannels = 64;

  RejectAlarms(bus::Bus& bus, std::string alarm_channel, std::string source)
      : bus_(bus), channel_(std::move(alarm_channel)) {
    al_.source = std::move(source);
    al_.severity = cnc::lcmt_alarm::WARNING;
    al_.code.reserve(32);
    al_.text.reserve(kTextBytes);
  }

  // Returns the number of alarms sent.
  int report(double now_s) {
    int sent = 0;
    for (int c = 0; c < bus::kRejectCauses; ++c) {
      const auto cause = static_cast<bus::Reject>(c);
      const int64_t n = bus_.rejected_total(cause);
      if (n == reported_[c] || now_s - last_s_[c] < kMinPeriodS) continue;
      char text[kTextBytes];
      size_t len = 0;
      const auto add = [&](const char* fmt, auto... args) {
        if (len >= sizeof text) return;
        const int k = std::snprintf(text + len, sizeof text - len, fmt, args...);
        if (k > 0) len = std::min(sizeof text - 1, len + static_cast<size_t>(k));
      };
      add("%lld %s message(s) dropped (total %lld): ", static_cast<long long>(n - reported_[c]),
          bus::reject_name(cause), static_cast<long long>(n));
      bool first = true;
      for (const auto& [ch, st] : bus_.stats()) {  // per channel: the drops since this cause's last alarm
        const int64_t now_n = bus::rejected_count(st, cause);
        int64_t& seen = seen_for(&st)[c];
        if (now_n <= seen) continue;
        add("%s%s %lld", first ? "" : ", ", ch.c_str(), static_cast<long long>(now_n - seen));
        first = false;
        seen = now_n;
      }
      add("; last: %s", bus_.last_reject(cause));
      al_.code.assign("bus_");
      al_.code.append(bus::reject_name(cause));
      al_.text.assign(text, len);
      reported_[c] = n;
      last_s_[c] = now_s;
      ++alarms_;
      if (bus_.publish(channel_, al_)) ++sent;
    }
    return sent;
  }
  int64_t alarms() const { return alarms_; }

 private:
  struct Seen {
    const bus::ChannelStats* stats = nullptr;
    std::array<int64_t, bus::kRejectCauses> counts{};
  };
  std::array<int64_t, bus::kRejectCauses>& seen_for(const bus::ChannelStats* st) {
    for (Seen& s : seen_) {
      if (s.stats == st) return s.counts;
      if (s.stats == nullptr) {
        s.stats = st;
        return s.counts;
      }
    }
    return overflow_;  // more channels than the table: counted together
  }

  bus::Bus& bus_;
  std::string channel_;
  cnc::lcmt_alarm al_{};
  std::array<int64_t, bus::kRejectCauses> reported_{};
  std::array<double, bus::kRejectCauses> last_s_{-1e9, -1e9, -1e9, -1e9, -1e9};
  std::array<Seen, kMaxChannels> seen_{};
  std::array<int64_t, bus::kRejectCauses> overflow_{};
  int64_t alarms_ = 0;
};

}  // namespace cnc::service
