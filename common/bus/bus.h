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
// * Signing (Security::enabled): every publish carries a MAC trailer (auth.h) under
//   the cell's key; every received message is verified before any subscriber sees
//   it. Dropped and counted per channel and cause: unsigned, unknown key (or one
//   whose grace period ended), forged (the tag does not verify), stale (time stamp
//   outside the freshness window around the receive time) and replayed (sequence
//   number not newer than the sender's last, outside a 64-message reorder window).
//   Only a verified message creates per-sender state, so a stranger cannot grow it.
//   Keys are re-read when the key file changes by a thread of the bus (once a
//   second), handed to the receiving thread through a triple buffer: the cyclic
//   paths never read files, lock or allocate for it.
// * A publish that fails (sendto refused: no route, a firewall rule, a full
//   buffer) never throws: it returns false, is counted per channel and in total,
//   keeps its cause (channel and errno text) and consumes no sequence number, so a
//   message sent again later keeps its stream contiguous. Cyclic code checks
//   publish_failures() once per cycle and brings its process to a controlled stop.
#include <lcm/lcm.h>

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "common/bus/auth.h"
#include "common/util/clock.h"
#include "common/util/triple_buffer.h"

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
  // Signing on: messages dropped before any subscriber saw them (not in `received`).
  int64_t rejected_unsigned = 0;     // no signature trailer
  int64_t rejected_unknown_key = 0;  // signed with a key id this cell does not accept (now)
  int64_t rejected_forged = 0;       // the tag does not verify
  int64_t rejected_stale = 0;        // time stamp outside the freshness window
  int64_t rejected_replayed = 0;     // sequence number already seen or too old for the window
  int64_t reordered = 0;             // accepted late, within the sender's reorder window
  int64_t rejected() const {
    return rejected_unsigned + rejected_unknown_key + rejected_forged + rejected_stale + rejected_replayed;
  }
};

// Why a received message was dropped by the signature checks.
enum class Reject : int { kUnsigned = 0, kUnknownKey, kForged, kStale, kReplayed };
inline constexpr int kRejectCauses = 5;
// "unsigned", "unknown_key", "forged", "stale", "replayed"
const char* reject_name(Reject r);
int64_t rejected_count(const ChannelStats& st, Reject r);

// Signing and verification of every message of a bus (see the header comment).
struct Security {
  bool enabled = false;
  KeySet keys;           // the keys to start with (read_key_file(key_file) in the services)
  std::string key_file;  // "" = fixed keys; else re-read when it changes
  bool watch = true;     // a thread of the bus checks key_file once a second; false: reload_keys() only
  double max_age_s = 2.0;  // freshness window: |receive time - message utime| must not exceed it
};

// Offline verification of a recorded log (the logger keeps every datagram whole,
// trailer included): per message the signature under the key file's keys, the key
// not past its end at the message's time stamp, and a sequence number newer per
// (channel, sender) than the ones before (64-message reorder window). No freshness
// check: a log is old.
class LogVerifier {
 public:
  struct Counts {
    int64_t verified = 0;
    std::array<int64_t, kRejectCauses> bad{};  // by Reject cause (kStale unused)
    int64_t bad_total() const;
  };
  explicit LogVerifier(const KeySet& keys) : keys_(keys) {}
  // True when the message verifies; counts it either way.
  bool check(const std::string& channel, const void* data, size_t size);
  const std::map<std::string, Counts>& counts() const { return counts_; }
  int64_t verified() const;
  int64_t bad() const;

 private:
  KeySet keys_;
  std::map<std::string, Counts> counts_;
  std::map<std::pair<std::string, int32_t>, std::pair<int64_t, uint64_t>> seq_;
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
  // security: signing and verification (off by default: nothing signed, nothing checked).
  explicit Bus(const std::string& url, int32_t sender = 0, int queue_capacity = 1000, Security security = {});
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
  // Appends this bus's signature trailer to buf[0..size) (buf must hold size +
  // kTrailerBytes) and returns the new size; `size` unchanged when signing is off,
  // 0 when no key signs now. For bytes stamped by the caller (the logger's stats).
  size_t sign_into(const std::string& channel, uint8_t* buf, size_t size);
  bool signing() const { return security_.enabled; }

  // Signing on: the messages dropped per cause since the bus was opened (all
  // channels), and a description of the last one ("T.SETPOINTS from sender 77:
  // forged"); fixed storage, no allocation.
  int64_t rejected_total(Reject r) const { return rejects_[static_cast<int>(r)]; }
  const char* last_reject() const { return last_reject_.data(); }
  const char* last_reject(Reject r) const { return last_reject_by_cause_[static_cast<size_t>(r)].data(); }
  // Re-reads the key file now (tests, or a bus without the watch thread). False when
  // it cannot be used (the keys in use stay); why in key_error().
  bool reload_keys();
  // Key file changes taken (by the watch thread or reload_keys) and refused since the bus was opened.
  int64_t key_reloads() const { return key_reloads_.load(); }
  int64_t key_reload_failures() const { return key_reload_failures_.load(); }
  // Replaces the keys (tests; a bus with a watched key file takes them from the file).
  void set_keys(const KeySet& keys);
  std::string key_error() const;

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
  // Signing on: verifies a received message; false when it is dropped (counted).
  bool admit(const std::string& channel, const void* data, size_t size, int64_t recv_utime);
  void reject(const std::string& channel, Reject why, const void* data, size_t size);
  bool load_keys_from_file();  // reads key_file into keybuf_ (one writer at a time)
  void watch_keys(std::stop_token stop);
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
  struct SenderSeq {
    int64_t last = 0;   // the newest sequence number accepted
    uint64_t seen = 0;  // signing on: bit i set = last - i was accepted (reorder and replay window)
  };
  std::map<std::string, std::map<int32_t, SenderSeq>, std::less<>> last_seq_;
  std::string rx_channel_;  // the channel of the message being delivered (its capacity is reused)
  // Several subscriptions may match one channel: count (and verify) each message once.
  const lcm_recv_buf_t* last_accounted_ = nullptr;
  bool last_admitted_ = true;
  std::map<std::string, int64_t> out_seq_;
  std::vector<uint8_t> encode_buf_;
  int64_t publish_failures_ = 0;
  std::array<char, 160> last_publish_error_{};
  int inject_failures_ = 0;

  Security security_;
  int64_t max_age_us_ = 0;
  util::TripleBuffer<KeySet> keybuf_;  // writer: the watch thread (or reload_keys); reader: this bus's thread
  mutable std::mutex key_write_mutex_;        // held only while a new key set is written (never by the reader)
  std::array<int64_t, kRejectCauses> rejects_{};
  std::array<char, 160> last_reject_{};
  std::array<std::array<char, 160>, kRejectCauses> last_reject_by_cause_{};
  std::atomic<int64_t> key_reloads_{0};
  std::atomic<int64_t> key_reload_failures_{0};
  std::string key_error_;
  int64_t key_file_stamp_ns_ = 0;  // the key file as read at construction (mtime, inode, size)
  uint64_t key_file_ino_ = 0;
  int64_t key_file_size_ = 0;
  std::jthread watcher_;  // last: stopped and joined first
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
                       // A signed message's trailer follows the encoded bytes (verified
                       // by admit() when signing is on; stripped too when reading a signed log).
                       const size_t n = payload_size(data, size);
                       ok = msg.decode(data, 0, static_cast<int>(n)) == static_cast<int>(n);
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
      // Room for the signature trailer: once the buffer has grown, no allocation.
      encode_buf_.resize(static_cast<size_t>(size) + (security_.enabled ? kTrailerBytes : 0));
      ok = msg.encode(encode_buf_.data(), 0, size) == size;
    }
  } catch (...) {
    ok = false;
  }
  if (!ok) {
    publish_failed(channel, -1, true);  // -1: the message did not encode
    return false;
  }
  if (security_.enabled && sign_into(channel, encode_buf_.data(), encode_buf_.size() - kTrailerBytes) == 0) {
    publish_failed(channel, -2, true);  // -2: no key signs now
    return false;
  }
  return publish_encoded(channel, encode_buf_.data(), encode_buf_.size(), true);
}

}  // namespace cnc::bus
