#include "tools/netem/impairment.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace cnc::netem {

namespace {
// Heap order: the earliest release on top; equal times leave in arrival order.
bool later(const Held& a, const Held& b) {
  return a.release_ns != b.release_ns ? a.release_ns > b.release_ns : a.number > b.number;
}
}  // namespace

std::string validate(const Params& p) {
  if (!std::isfinite(p.loss) || p.loss < 0.0 || p.loss > 1.0) return "--loss must be a percentage from 0 to 100";
  if (!std::isfinite(p.delay_ms) || p.delay_ms < 0.0 || p.delay_ms > 10'000.0)
    return "--delay must be from 0 to 10000 ms";
  if (!std::isfinite(p.jitter_ms) || p.jitter_ms < 0.0 || p.jitter_ms > 10'000.0)
    return "--jitter must be from 0 to 10000 ms";
  return "";
}

Impairment::Impairment(const Params& p)
    : p_(p), rng_(p.seed), last_release_ns_(std::numeric_limits<int64_t>::min()) {}

double Impairment::uniform01() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }

bool Impairment::admit(int64_t now_ns, int64_t* release_ns) {
  const double u_loss = uniform01();
  const double u_delay = uniform01();
  if (u_loss < p_.loss) return false;
  const double ms = std::max(0.0, p_.delay_ms + p_.jitter_ms * (2.0 * u_delay - 1.0));
  int64_t t = now_ns + static_cast<int64_t>(std::llround(ms * 1e6));
  if (p_.keep_order) t = std::max(t, last_release_ns_);
  last_release_ns_ = std::max(last_release_ns_, t);
  *release_ns = t;
  return true;
}

DelayQueue::DelayQueue(size_t slots, size_t slot_bytes)
    : slot_bytes_(slot_bytes), arena_(new char[slots * slot_bytes]) {  // not touched until used
  free_.reserve(slots);
  heap_.reserve(slots);
  // Handed out from the front of the arena first (a LIFO free list): few pages touched.
  for (size_t i = slots; i-- > 0;) free_.push_back(arena_.get() + i * slot_bytes);
}

char* DelayQueue::reserve() { return free_.empty() ? nullptr : free_.back(); }

void DelayQueue::commit(char* data, size_t bytes, int64_t arrival_ns, int64_t release_ns) {
  // `data` is the buffer reserve() returned: the top of the free list.
  free_.pop_back();
  heap_.push_back(Held{release_ns, arrival_ns, next_number_++, bytes, data});
  std::push_heap(heap_.begin(), heap_.end(), later);
}

int64_t DelayQueue::next_release_ns() const {
  return heap_.empty() ? std::numeric_limits<int64_t>::max() : heap_.front().release_ns;
}

void DelayQueue::pop() {
  std::pop_heap(heap_.begin(), heap_.end(), later);
  free_.push_back(heap_.back().data);
  heap_.pop_back();
}

void Counters::on_sent(const Held& h, int64_t sent_ns) {
  const double ms = static_cast<double>(sent_ns - h.arrival_ns) * 1e-6;
  if (!any_sent) {
    delay_min_ms = delay_max_ms = ms;
  } else {
    delay_min_ms = std::min(delay_min_ms, ms);
    delay_max_ms = std::max(delay_max_ms, ms);
    if (h.number < max_number_sent) ++reordered;
  }
  delay_sum_ms += ms;
  max_number_sent = std::max(max_number_sent, h.number);
  any_sent = true;
  ++sent;
}

std::string Counters::summary(const std::string& direction) const {
  char buf[512];
  const double pct = received > 0 ? 100.0 * static_cast<double>(lost) / static_cast<double>(received) : 0.0;
  const double mean = sent > 0 ? delay_sum_ms / static_cast<double>(sent) : 0.0;
  std::snprintf(buf, sizeof buf,
                "%s: received %lld, lost %lld (%.2f %%), queue full %lld, too large %lld, sent %lld, "
                "send errors %lld, reordered %lld, left in queue %lld; held min %.3f mean %.3f max %.3f ms",
                direction.c_str(), static_cast<long long>(received), static_cast<long long>(lost), pct,
                static_cast<long long>(queue_full), static_cast<long long>(too_large), static_cast<long long>(sent),
                static_cast<long long>(send_errors), static_cast<long long>(reordered),
                static_cast<long long>(left_in_queue), delay_min_ms, mean, delay_max_ms);
  return buf;
}

}  // namespace cnc::netem
