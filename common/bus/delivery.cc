#include "common/bus/delivery.h"

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>
#include <utility>

namespace cnc::bus {

namespace {

double at_fraction(const std::vector<double>& sorted, double f) {
  if (sorted.empty()) return 0;
  const auto i = static_cast<size_t>(f * static_cast<double>(sorted.size() - 1) + 0.5);
  return sorted[std::min(i, sorted.size() - 1)];
}

// Consecutive stamps of one sender on one channel.
using Stamps = std::vector<int64_t>;

// The longest interval between consecutive stamps that overlaps [from, to]; 0 when none.
double longest_gap_within(const Stamps& s, int64_t from, int64_t to) {
  auto it = std::lower_bound(s.begin(), s.end(), from);
  if (it != s.begin()) --it;  // the interval that spans `from`
  int64_t longest = 0;
  for (; it != s.end() && it + 1 != s.end() && *it < to; ++it) longest = std::max(longest, *(it + 1) - *it);
  return static_cast<double>(longest) / 1e3;
}

}  // namespace

DeliveryReport analyse_delivery(std::vector<DeliveryEvent> events, double stall_ms) {
  DeliveryReport out;
  const auto threshold_us = static_cast<int64_t>(stall_ms * 1e3);
  std::stable_sort(events.begin(), events.end(),
                   [](const DeliveryEvent& a, const DeliveryEvent& b) { return a.received_us < b.received_us; });

  std::map<std::string, std::vector<double>> latency;
  std::map<std::string, std::map<int32_t, Stamps>> stamps;
  for (const DeliveryEvent& e : events) {
    latency[e.channel].push_back(static_cast<double>(e.received_us - e.published_us) / 1e3);
    stamps[e.channel][e.sender].push_back(e.published_us);
  }
  for (auto& [ch, lat] : latency) {
    std::sort(lat.begin(), lat.end());
    ChannelDelivery c;
    c.channel = ch;
    c.events = static_cast<int64_t>(lat.size());
    c.p50_ms = at_fraction(lat, 0.5);
    c.p999_ms = at_fraction(lat, 0.999);
    c.max_ms = lat.back();
    std::vector<int64_t> intervals;
    for (auto& [sender, s] : stamps[ch]) {
      std::sort(s.begin(), s.end());
      for (size_t i = 1; i < s.size(); ++i) {
        intervals.push_back(s[i] - s[i - 1]);
        if (s[i] - s[i - 1] > static_cast<int64_t>(c.longest_publish_gap_ms * 1e3)) {
          c.longest_publish_gap_ms = static_cast<double>(s[i] - s[i - 1]) / 1e3;
          c.longest_publish_gap_at_us = s[i - 1];
        }
      }
    }
    if (intervals.size() >= 10) {
      std::nth_element(intervals.begin(), intervals.begin() + static_cast<std::ptrdiff_t>(intervals.size() / 2),
                       intervals.end());
      c.periodic = intervals[intervals.size() / 2] * 4 < threshold_us;
    }
    out.channels.push_back(c);
  }

  for (size_t i = 0; i + 1 < events.size(); ++i) {
    const int64_t from = events[i].received_us, to = events[i + 1].received_us;
    if (to - from <= threshold_us) continue;
    DeliveryStall st;
    st.from_us = from;
    st.length_ms = static_cast<double>(to - from) / 1e3;
    std::set<int32_t> senders;
    for (size_t j = i + 1; j < events.size(); ++j) {
      const DeliveryEvent& e = events[j];
      if (e.received_us > to + threshold_us) break;  // what the silence held arrives together at its end
      // Stamped inside the silence and held back (not just the message that ends it).
      if (e.published_us > from && e.published_us < to && e.received_us - e.published_us > threshold_us / 2) {
        ++st.published_in;
        senders.insert(e.sender);
      }
    }
    st.senders_in = static_cast<int>(senders.size());
    st.delivery = st.published_in > 0;
    for (const ChannelDelivery& c : out.channels) {
      if (!c.periodic) continue;
      double longest = 0;
      for (const auto& [sender, s] : stamps[c.channel]) longest = std::max(longest, longest_gap_within(s, from, to));
      if (longest <= 0) continue;
      char b[160];
      std::snprintf(b, sizeof b, "%s%s %.1f ms", st.publisher_gaps.empty() ? "" : ", ", c.channel.c_str(), longest);
      st.publisher_gaps += b;
    }
    out.stalls.push_back(std::move(st));
  }
  return out;
}

std::string format_delivery(const DeliveryReport& r, int64_t t0_us, double stall_ms) {
  std::string out;
  char b[2048];
  std::snprintf(b, sizeof b, "delivery: publisher's stamp to the logger's receive stamp, ms\n%-28s %10s %8s %8s %8s %s\n",
                "channel", "events", "p50", "p99.9", "max", "longest publish gap (periodic channels)");
  out += b;
  for (const ChannelDelivery& c : r.channels) {
    std::snprintf(b, sizeof b, "%-28s %10lld %8.2f %8.2f %8.2f", c.channel.c_str(), static_cast<long long>(c.events),
                  c.p50_ms, c.p999_ms, c.max_ms);
    out += b;
    if (c.periodic) {
      std::snprintf(b, sizeof b, " %.1f ms at %.3f s", c.longest_publish_gap_ms,
                    static_cast<double>(c.longest_publish_gap_at_us - t0_us) / 1e6);
      out += b;
    }
    out += "\n";
  }
  std::snprintf(b, sizeof b, "delivery stalls (nothing received for over %.0f ms): %zu\n", stall_ms, r.stalls.size());
  out += b;
  for (const DeliveryStall& s : r.stalls) {
    const std::string gaps = s.publisher_gaps.empty() ? "" : "; publishers' longest gaps in it: " + s.publisher_gaps;
    if (s.delivery) {
      std::snprintf(b, sizeof b, "  at %.3f s: nothing received for %.1f ms; %lld message(s) from %d sender(s) "
                    "published meanwhile arrived after it%s -> the delivery stalled, not (only) the publishers\n",
                    static_cast<double>(s.from_us - t0_us) / 1e6, s.length_ms, static_cast<long long>(s.published_in),
                    s.senders_in, gaps.c_str());
    } else {
      std::snprintf(b, sizeof b, "  at %.3f s: nothing received for %.1f ms, nothing published in it%s -> a pause of "
                    "the publishers\n",
                    static_cast<double>(s.from_us - t0_us) / 1e6, s.length_ms, gaps.c_str());
    }
    out += b;
  }
  return out;
}

}  // namespace cnc::bus
