#pragma once
// The one LCM wrapper every service uses.
//
// * The same interface over `udpm://` (live), `memq://` (in-process tests) and
//   `file://PATH?speed=0` (reading a log, for replay and analysis).
// * Typed subscriptions decode inside try/catch: LCM 1.3.1's generated decode
//   throws (std::length_error / bad_alloc) on a negative or huge array length. A
//   message that fails to decode is counted and dropped; no exception ever passes
//   through LCM's C frames.
// * Every message type of the cell begins with `int64_t utime; int64_t seq;
//   int32_t sender;`, so the wrapper reads the header from the raw bytes and counts
//   sequence gaps per channel and sender, for typed and raw subscribers alike.
// * A publish that fails (sendto refused: no route, a firewall rule, a full
//   buffer) never throws: it returns false, is counted per channel and in total,
//   keeps its cause (channel and errno text) and consumes no sequence number, so a
//   message sent again later keeps its stream contiguous. Cyclic code checks
//   publish_failures() once per cycle and brings its process to a controlled stop.
#include <lcm/lcm.h>

#include <array>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/util/clock.h"

namespace cnc::bus {

struct WireHeader {
  int64_t utime = 0;
  int64_t seq = 0;
  int32_t sender = 0;
};

// Reads the common header that follows the 8-byte fingerprint; nullopt when the
// buffer is too short to hold it.
std::optional<WireHeader> peek_header(const void* data, size_t size);

struct ChannelStats {
  int64_t received = 0;         // messages that reached this process
  int64_t decode_failures = 0;  // dropped: did not decode as the subscribed type
  int64_t handler_errors = 0;   // a handler threw; the message is lost to it
  int64_t seq_gaps = 0;         // messages missing between two received from one sender
  int64_t seq_restarts = 0;     // a sender's seq went backwards (it restarted)
  int64_t published = 0;
  int64_t publish_failures = 0;  // sends that failed (not counted as published)
};

class BusError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Escapes a channel name for LCM's anchored-regex subscriptions.
std::string exact_channel(const std::string& channel);

class Bus {
 public:
  using RawHandler =
      std::function<void(const std::string& channel, const void* data, size_t size, int64_t recv_utime)>;

  // url: an LCM provider URL; "" uses LCM_DEFAULT_URL or LCM's default.
  // sender: identifies this process in the `sender` field (0 picks one from pid and time).
  // queue_capacity: messages LCM holds per subscription until handled; beyond it
  // LCM drops them silently (they then show as sequence gaps).
  explicit Bus(const std::string& url, int32_t sender = 0, int queue_capacity = 1000);
  ~Bus();
  Bus(const Bus&) = delete;
  Bus& operator=(const Bus&) = delete;

  // Typed subscription to one channel (exact name).
  template <class Msg>
  void subscribe(const std::string& channel, std::function<void(const Msg&)> handler);

  // Raw subscription; `channel_regex` is an LCM regex (e.g. "MILL1\\..*").
  void subscribe_raw(const std::string& channel_regex, RawHandler handler);

  // Stamps utime (wall clock), seq (per channel, from 0) and sender, then publishes.
  // false when the message could not be encoded or sent (counted; see above).
  template <class Msg>
  bool publish(const std::string& channel, Msg& msg);
  // Publishes already encoded bytes unchanged (a log player, a fault injector).
  bool publish_raw(const std::string& channel, const void* data, size_t size);

  // Failed publishes since the bus was opened, and the cause of the last one
  // ("T.SETPOINTS: Network is unreachable"); fixed storage, no allocation.
  int64_t publish_failures() const { return publish_failures_; }
  const char* last_publish_error() const { return last_publish_error_.data(); }
  // Tests: the next `n` publishes fail as if sendto had refused them (EPERM).
  void inject_publish_failures(int n) { inject_failures_ = n; }

  // Waits up to timeout_ms for one message and dispatches it. Returns 1 when a
  // message was handled, 0 on timeout, -1 on error or at the end of a log.
  int handle(int timeout_ms);
  // Handles everything already pending without waiting; returns the count.
  int drain(int max_messages = 10000);

  int fileno() const;
  int32_t sender() const { return sender_; }
  const std::string& url() const { return url_; }
  // Counters per channel name, for heartbeats and tests.
  const std::map<std::string, ChannelStats>& stats() const { return stats_; }
  ChannelStats stats(const std::string& channel) const;

 private:
  struct Subscription {
    Bus* bus;
    std::function<void(const std::string&, const void*, size_t, int64_t)> dispatch;
    lcm_subscription_t* handle = nullptr;
  };
  static void on_message(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  void add_subscription(const std::string& regex,
                        std::function<void(const std::string&, const void*, size_t, int64_t)> dispatch);
  void account(const std::string& channel, const void* data, size_t size);
  int64_t next_seq(const std::string& channel);
  // stamped: the message took a sequence number from next_seq (given back on failure).
  bool publish_encoded(const std::string& channel, const void* data, size_t size, bool stamped);
  void publish_failed(const std::string& channel, int err, bool stamped);

  std::string url_;
  int32_t sender_;
  int queue_capacity_;
  lcm_t* lcm_ = nullptr;
  std::vector<std::unique_ptr<Subscription>> subs_;
  std::map<std::string, ChannelStats> stats_;
  // Last sequence number per channel and sender (looked up without copying the name).
  std::map<std::string, std::map<int32_t, int64_t>, std::less<>> last_seq_;
  std::string rx_channel_;  // the channel of the message being delivered (its capacity is reused)
  // Several subscriptions may match one channel: count each message once.
  const lcm_recv_buf_t* last_accounted_ = nullptr;
  std::map<std::string, int64_t> out_seq_;
  std::vector<uint8_t> encode_buf_;
  int64_t publish_failures_ = 0;
  std::array<char, 160> last_publish_error_{};
  int inject_failures_ = 0;
};

template <class Msg>
void Bus::subscribe(const std::string& channel, std::function<void(const Msg&)> handler) {
  add_subscription(exact_channel(channel),
                   // One message object per subscription, decoded into again and again:
                   // once its vectors and strings have grown to the sizes the stream
                   // uses, delivering a message allocates nothing.
                   [this, handler = std::move(handler), msg = Msg{}](const std::string& ch, const void* data,
                                                                   size_t size, int64_t) mutable {
                     bool ok = false;
                     try {
                       ok = msg.decode(data, 0, static_cast<int>(size)) == static_cast<int>(size);
                     } catch (...) {
                       ok = false;
                     }
                     if (!ok) {
                       ++stats_[ch].decode_failures;
                       return;
                     }
                     try {
                       handler(msg);
                     } catch (...) {
                       ++stats_[ch].handler_errors;
                     }
                   });
}

template <class Msg>
bool Bus::publish(const std::string& channel, Msg& msg) {
  msg.utime = util::wall_utime();
  msg.seq = next_seq(channel);
  msg.sender = sender_;
  bool ok = false;
  try {
    const int size = msg.getEncodedSize();
    if (size >= 0) {
      encode_buf_.resize(static_cast<size_t>(size));
      ok = msg.encode(encode_buf_.data(), 0, size) == size;
    }
  } catch (...) {
    ok = false;
  }
  if (!ok) {
    publish_failed(channel, -1, true);  // -1: the message did not encode
    return false;
  }
  return publish_encoded(channel, encode_buf_.data(), encode_buf_.size(), true);
}

}  // namespace cnc::bus
