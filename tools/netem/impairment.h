#pragma once
// cnc-netem's pure core: which datagram is lost and when each of the others leaves.
// No sockets, no clock: the caller hands in arrival times (ns, any monotonic origin)
// and gets back a verdict. The forwarder (main.cc) and the unit test drive the same
// code.
//
// Loss: each datagram is dropped with probability `loss`, independently.
// Delay: each datagram that is kept is held for a time drawn uniformly from
// [delay - jitter, delay + jitter] ms (clamped at 0). Order: with keep_order off,
// each datagram's release time is its own draw, so two datagrams closer together
// than the spread can leave in the other order (reordering, as a network with
// several paths does); with keep_order on, a datagram never leaves before the one
// that arrived before it (release = max(own draw, previous release): FIFO, as one
// switch queue does; the mean delay is then a little above `delay`).
//
// The random numbers: a 64-bit Mersenne twister seeded with `seed`, two draws per
// datagram (loss, then delay) whatever the parameters, converted to [0, 1) by hand
// (the top 53 bits), so a seed gives the same losses and delays on every platform
// and the same loss pattern whatever the delay settings.
//
// The queue: a fixed number of slots of a fixed size, allocated once; a binary
// heap over the held datagrams by (release time, arrival number). Nothing is
// allocated after construction.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace cnc::netem {

struct Params {
  double loss = 0.0;       // probability of a drop, 0..1
  double delay_ms = 0.0;   // mean delay
  double jitter_ms = 0.0;  // half-width of the uniform spread around delay_ms
  bool keep_order = false;
  uint64_t seed = 1;
};

// "" when the parameters are usable, else what is wrong, naming the flag.
std::string validate(const Params& p);

class Impairment {
 public:
  explicit Impairment(const Params& p);
  // One datagram arriving at now_ns: false when it is lost; else *release_ns is
  // when it may leave (never before now_ns).
  bool admit(int64_t now_ns, int64_t* release_ns);
  const Params& params() const { return p_; }

 private:
  double uniform01();  // [0, 1) from the top 53 bits of one draw
  Params p_;
  std::mt19937_64 rng_;
  int64_t last_release_ns_;
};

// A datagram held in the queue.
struct Held {
  int64_t release_ns = 0;
  int64_t arrival_ns = 0;
  uint64_t number = 0;  // arrival order
  size_t bytes = 0;
  char* data = nullptr;
};

class DelayQueue {
 public:
  DelayQueue(size_t slots, size_t slot_bytes);
  size_t slot_bytes() const { return slot_bytes_; }
  size_t size() const { return heap_.size(); }
  bool full() const { return free_.empty(); }
  // A free slot's buffer to receive into (nullptr when full). Not held until commit().
  char* reserve();
  // Holds the reserved buffer's first `bytes` until release_ns.
  void commit(char* data, size_t bytes, int64_t arrival_ns, int64_t release_ns);
  // The earliest release time held (INT64_MAX when empty).
  int64_t next_release_ns() const;
  // The held datagram that leaves first; valid until pop().
  const Held& front() const { return heap_.front(); }
  void pop();

 private:
  size_t slot_bytes_;
  std::unique_ptr<char[]> arena_;
  std::vector<char*> free_;
  std::vector<Held> heap_;
  uint64_t next_number_ = 0;
};

// What a forwarder did, printed at exit.
struct Counters {
  int64_t received = 0;
  int64_t lost = 0;         // dropped by the loss draw
  int64_t queue_full = 0;   // dropped: every slot held
  int64_t too_large = 0;    // dropped: larger than a slot
  int64_t sent = 0;
  int64_t send_errors = 0;
  int64_t reordered = 0;    // sent after a datagram that arrived later
  int64_t left_in_queue = 0;
  double delay_min_ms = 0, delay_max_ms = 0, delay_sum_ms = 0;  // held time of those sent
  uint64_t max_number_sent = 0;
  bool any_sent = false;
  // Books one datagram sent (its hold, reordering against those before it).
  void on_sent(const Held& h, int64_t sent_ns);
  std::string summary(const std::string& direction) const;
};

}  // namespace cnc::netem
