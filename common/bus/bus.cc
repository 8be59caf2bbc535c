#include "common/bus/bus.h"

#include <pthread.h>
#include <sched.h>
#include <sys/stat.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace cnc::bus {
namespace {
int64_t read_be64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
  return static_cast<int64_t>(v);
}
int32_t read_be32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | p[i];
  return static_cast<int32_t>(v);
}
// a - b for a >= b: exact in unsigned arithmetic, where int64_t would overflow
// (sequence numbers are whatever a sender writes: INT64_MIN and INT64_MAX included).
uint64_t distance(int64_t a, int64_t b) { return static_cast<uint64_t>(a) - static_cast<uint64_t>(b); }
// total += n, saturating at INT64_MAX (total >= 0).
void add_saturated(int64_t& total, uint64_t n) {
  const auto room = static_cast<uint64_t>(INT64_MAX - total);
  total = n > room ? INT64_MAX : total + static_cast<int64_t>(n);
}
}  // namespace

std::optional<WireHeader> peek_header(const void* data, size_t size) {
  constexpr size_t kFingerprint = 8;
  if (size < kFingerprint + 8 + 8 + 4) return std::nullopt;
  const auto* p = static_cast<const uint8_t*>(data) + kFingerprint;
  return WireHeader{read_be64(p), read_be64(p + 8), read_be32(p + 16)};
}

std::string exact_channel(const std::string& channel) {
  std::string out;
  for (char c : channel) {
    if (std::strchr(".^$|()[]{}*+?\\", c) != nullptr) out += '\\';
    out += c;
  }
  return out;
}

const char* reject_name(Reject r) {
  switch (r) {
    case Reject::kUnsigned: return "unsigned";
    case Reject::kUnknownKey: return "unknown_key";
    case Reject::kForged: return "forged";
    case Reject::kStale: return "stale";
    case Reject::kReplayed: return "replayed";
  }
  return "?";
}

int64_t rejected_count(const ChannelStats& st, Reject r) {
  switch (r) {
    case Reject::kUnsigned: return st.rejected_unsigned;
    case Reject::kUnknownKey: return st.rejected_unknown_key;
    case Reject::kForged: return st.rejected_forged;
    case Reject::kStale: return st.rejected_stale;
    case Reject::kReplayed: return st.rejected_replayed;
  }
  return 0;
}

int64_t LogVerifier::Counts::bad_total() const {
  int64_t n = 0;
  for (int64_t b : bad) n += b;
  return n;
}

int64_t LogVerifier::verified() const {
  int64_t n = 0;
  for (const auto& [ch, c] : counts_) n += c.verified;
  return n;
}

int64_t LogVerifier::bad() const {
  int64_t n = 0;
  for (const auto& [ch, c] : counts_) n += c.bad_total();
  return n;
}

bool LogVerifier::check(const std::string& channel, const void* data, size_t size) {
  Counts& c = counts_[channel];
  const auto bad = [&](Reject r) {
    ++c.bad[static_cast<size_t>(r)];
    return false;
  };
  if (!has_trailer(data, size)) return bad(Reject::kUnsigned);
  const auto hdr = peek_header(data, size);
  const Key* key = keys_.find(trailer_key_id(data, size));
  if (key == nullptr || !hdr) return bad(Reject::kUnknownKey);
  if (!verify(*key, channel, data, size)) return bad(Reject::kForged);
  if (key->accept_until_utime != 0 && hdr->utime > key->accept_until_utime) return bad(Reject::kUnknownKey);
  auto [it, fresh] = seq_.try_emplace({channel, hdr->sender}, hdr->seq, uint64_t{1});
  if (!fresh) {
    auto& [last, seen] = it->second;
    if (hdr->seq > last) {
      const uint64_t ahead = distance(hdr->seq, last);
      seen = ahead >= 64 ? 1 : (seen << ahead) | 1;
      last = hdr->seq;
    } else {
      const uint64_t behind = distance(last, hdr->seq);
      if (behind >= 64 || ((seen >> behind) & 1u)) return bad(Reject::kReplayed);
      seen |= uint64_t{1} << behind;
    }
  }
  ++c.verified;
  return true;
}

namespace {
// Channels a stranger may invent (the logger subscribes to a prefix): rejected
// messages on new channel names beyond this count are counted under one name.
constexpr size_t kMaxChannelStats = 256;
constexpr const char* kOtherChannels = "(other channels)";

struct FileStamp {
  bool ok = false;
  ino_t ino = 0;
  off_t size = 0;
  int64_t mtime_ns = 0;
  bool operator==(const FileStamp&) const = default;
};
FileStamp stamp_of(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  return {true, st.st_ino, st.st_size, static_cast<int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec};
}
}  // namespace

Bus::Bus(const std::string& url, int32_t sender, int queue_capacity, Security security)
    : url_(url), queue_capacity_(queue_capacity), security_(std::move(security)) {
  if (security_.enabled) {
    if (sodium_init() < 0) throw BusError("libsodium could not be initialised");
    if (!security_.key_file.empty()) {
      // The file's stamp before reading it: a change after this is seen by the watch thread.
      const FileStamp st = stamp_of(security_.key_file);
      key_file_stamp_ns_ = st.mtime_ns;
      key_file_ino_ = static_cast<uint64_t>(st.ino);
      key_file_size_ = static_cast<int64_t>(st.size);
      security_.keys = read_key_file(security_.key_file);  // KeyFileError names the file and its mode
    }
    if (security_.keys.count == 0) throw BusError("signing is on but there is no key");
    max_age_us_ = static_cast<int64_t>(security_.max_age_s * 1e6);
    keybuf_.write(security_.keys);
  }
  lcm_ = lcm_create(url.empty() ? nullptr : url.c_str());
  if (lcm_ == nullptr) throw BusError("cannot open LCM at '" + url + "'");
  if (sender == 0) {
    // pid and start time: distinct across restarts, so a restart is not a gap.
    const auto mix = static_cast<uint64_t>(getpid()) * 0x9E3779B97F4A7C15ull ^
                     static_cast<uint64_t>(util::wall_utime());
    sender = static_cast<int32_t>(mix >> 33);
    if (sender == 0) sender = 1;
  }
  sender_ = sender;
  if (security_.enabled && !security_.key_file.empty() && security_.watch) {
    watcher_ = std::jthread([this](std::stop_token stop) { watch_keys(stop); });
  }
}

void Bus::watch_keys(std::stop_token stop) {
  // Created after the service made itself real-time: this thread is not cyclic work.
  sched_param normal{};
  normal.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  FileStamp seen{true, static_cast<ino_t>(key_file_ino_), static_cast<off_t>(key_file_size_), key_file_stamp_ns_};
  std::mutex m;
  std::condition_variable_any cv;
  std::unique_lock lock(m);
  while (!stop.stop_requested()) {
    cv.wait_for(lock, stop, std::chrono::seconds(1), [] { return false; });
    if (stop.stop_requested()) break;
    const FileStamp now = stamp_of(security_.key_file);
    if (now == seen) continue;
    seen = now;
    load_keys_from_file();
  }
}

bool Bus::load_keys_from_file() {
  std::lock_guard guard(key_write_mutex_);
  try {
    const KeySet keys = read_key_file(security_.key_file);
    keybuf_.write(keys);
    ++key_reloads_;
    key_error_.clear();
    spdlog::info("bus: key file {} read again: {} key(s)", security_.key_file, keys.count);
    return true;
  } catch (const std::exception& e) {
    ++key_reload_failures_;
    key_error_ = e.what();
    spdlog::error("bus: key file changed but cannot be used, the keys in use stay: {}", e.what());
    return false;
  }
}

bool Bus::reload_keys() {
  if (!security_.enabled || security_.key_file.empty()) return false;
  return load_keys_from_file();
}

void Bus::set_keys(const KeySet& keys) {
  std::lock_guard guard(key_write_mutex_);
  keybuf_.write(keys);
}

std::string Bus::key_error() const {
  std::lock_guard guard(key_write_mutex_);
  return key_error_;
}

size_t Bus::sign_into(const std::string& channel, uint8_t* buf, size_t size) {
  if (!security_.enabled) return size;
  const Key* k = keybuf_.read().signing_key(util::wall_utime());
  if (k == nullptr) return 0;
  sign(*k, channel, buf, size, buf + size);
  return size + kTrailerBytes;
}

void Bus::reject(const std::string& channel, Reject why, const void* data, size_t size) {
  auto it = stats_.find(channel);
  if (it == stats_.end()) {
    it = stats_.size() < kMaxChannelStats ? stats_.emplace(channel, ChannelStats{}).first
                                          : stats_.emplace(kOtherChannels, ChannelStats{}).first;
  }
  ChannelStats& st = it->second;
  switch (why) {
    case Reject::kUnsigned: ++st.rejected_unsigned; break;
    case Reject::kUnknownKey: ++st.rejected_unknown_key; break;
    case Reject::kForged: ++st.rejected_forged; break;
    case Reject::kStale: ++st.rejected_stale; break;
    case Reject::kReplayed: ++st.rejected_replayed; break;
  }
  ++rejects_[static_cast<int>(why)];
  const auto hdr = peek_header(data, size);
  std::snprintf(last_reject_.data(), last_reject_.size(), "%s from sender %d: %s", it->first.c_str(),
                hdr ? hdr->sender : 0, reject_name(why));
  std::memcpy(last_reject_by_cause_[static_cast<size_t>(why)].data(), last_reject_.data(), last_reject_.size());
}

bool Bus::admit(const std::string& channel, const void* data, size_t size, int64_t recv_utime) {
  const KeySet& keys = keybuf_.read();
  if (!has_trailer(data, size)) {
    reject(channel, Reject::kUnsigned, data, size);
    return false;
  }
  const Key* key = keys.accepting_key(trailer_key_id(data, size), recv_utime);
  if (key == nullptr) {
    reject(channel, Reject::kUnknownKey, data, size);
    return false;
  }
  if (!verify(*key, channel, data, size)) {
    reject(channel, Reject::kForged, data, size);
    return false;
  }
  const auto hdr = peek_header(data, size);  // present: has_trailer checked the length
  if (!hdr || hdr->utime < recv_utime - max_age_us_ || hdr->utime > recv_utime + max_age_us_) {
    reject(channel, Reject::kStale, data, size);
    return false;
  }
  auto ch_it = last_seq_.find(channel);
  if (ch_it != last_seq_.end()) {
    auto it = ch_it->second.find(hdr->sender);
    if (it != ch_it->second.end()) {
      SenderSeq& s = it->second;
      if (hdr->seq > s.last) {
        const uint64_t ahead = distance(hdr->seq, s.last);
        ChannelStats& st = stats_[channel];
        add_saturated(st.seq_gaps, ahead - 1);
        s.seen = ahead >= 64 ? 1 : (s.seen << ahead) | 1;
        s.last = hdr->seq;
        ++st.received;
        return true;
      }
      const uint64_t behind = distance(s.last, hdr->seq);
      if (behind >= 64 || (s.seen >> behind) & 1u) {
        reject(channel, Reject::kReplayed, data, size);
        return false;
      }
      // Late but new: it was counted as missing when a later one came.
      s.seen |= uint64_t{1} << behind;
      ChannelStats& st = stats_[channel];
      if (st.seq_gaps > 0) --st.seq_gaps;
      ++st.reordered;
      ++st.received;
      return true;
    }
  } else {
    ch_it = last_seq_.emplace(channel, std::map<int32_t, SenderSeq>{}).first;
  }
  // A sender not seen before: fresh (checked above), so no older capture of it can pass.
  ch_it->second.emplace(hdr->sender, SenderSeq{hdr->seq, 1});
  ++stats_[channel].received;
  return true;
}

Bus::~Bus() {
  if (lcm_ != nullptr) {
    for (auto& s : subs_) lcm_unsubscribe(lcm_, s->handle);
    lcm_destroy(lcm_);
  }
}

void Bus::add_subscription(const std::string& regex,
                           std::function<void(const std::string&, const void*, size_t, int64_t)> dispatch) {
  auto sub = std::make_unique<Subscription>();
  sub->bus = this;
  sub->dispatch = std::move(dispatch);
  sub->handle = lcm_subscribe(lcm_, regex.c_str(), &Bus::on_message, sub.get());
  if (sub->handle == nullptr) throw BusError("cannot subscribe to '" + regex + "'");
  // LCM's default (30) drops under bursts; the capacity is the caller's choice.
  lcm_subscription_set_queue_capacity(sub->handle, queue_capacity_);
  subs_.push_back(std::move(sub));
}

void Bus::subscribe_raw(const std::string& channel_regex, RawHandler handler) {
  add_subscription(channel_regex, [this, handler = std::move(handler)](const std::string& ch, const void* data,
                                                                      size_t size, int64_t recv_utime) {
    try {
      handler(ch, data, size, recv_utime);
    } catch (...) {
      ++stats_[ch].handler_errors;
    }
  });
}

void Bus::on_message(const lcm_recv_buf_t* rbuf, const char* channel, void* user) {
  auto* sub = static_cast<Subscription*>(user);
  try {
    std::string& ch = sub->bus->rx_channel_;
    ch.assign(channel);  // no allocation once it has held a name this long
    Bus& bus = *sub->bus;
    if (bus.last_accounted_ != rbuf) {
      bus.last_accounted_ = rbuf;
      if (bus.security_.enabled) {
        bus.last_admitted_ = bus.admit(ch, rbuf->data, rbuf->data_size, rbuf->recv_utime);
      } else {
        bus.last_admitted_ = true;
        bus.account(ch, rbuf->data, rbuf->data_size);
      }
    }
    if (!bus.last_admitted_) return;
    sub->dispatch(ch, rbuf->data, rbuf->data_size, rbuf->recv_utime);
  } catch (...) {
    // Nothing may unwind into LCM's C code.
  }
}

void Bus::account(const std::string& channel, const void* data, size_t size) {
  ChannelStats& st = stats_[channel];
  ++st.received;
  const auto hdr = peek_header(data, size);
  if (!hdr) return;
  auto ch_it = last_seq_.find(channel);
  if (ch_it == last_seq_.end()) ch_it = last_seq_.emplace(channel, std::map<int32_t, SenderSeq>{}).first;
  auto it = ch_it->second.find(hdr->sender);
  if (it == ch_it->second.end()) {
    ch_it->second.emplace(hdr->sender, SenderSeq{hdr->seq, 0});
    return;
  }
  if (hdr->seq > it->second.last) {
    add_saturated(st.seq_gaps, distance(hdr->seq, it->second.last) - 1);
  } else {
    ++st.seq_restarts;
  }
  it->second.last = hdr->seq;
}

int64_t Bus::next_seq(const std::string& channel) { return out_seq_[channel]++; }

bool Bus::publish_encoded(const std::string& channel, const void* data, size_t size, bool stamped) {
  if (inject_failures_ > 0) {
    --inject_failures_;
    publish_failed(channel, EPERM, stamped);
    return false;
  }
  errno = 0;
  if (lcm_publish(lcm_, channel.c_str(), data, static_cast<unsigned int>(size)) != 0) {
    publish_failed(channel, errno != 0 ? errno : EIO, stamped);
    return false;
  }
  ++stats_[channel].published;
  return true;
}

void Bus::publish_failed(const std::string& channel, int err, bool stamped) {
  // The sequence number was not used: the next message on the channel takes it.
  if (stamped) {
    auto it = out_seq_.find(channel);
    if (it != out_seq_.end() && it->second > 0) --it->second;
  }
  ++stats_[channel].publish_failures;
  ++publish_failures_;
  std::snprintf(last_publish_error_.data(), last_publish_error_.size(), "publish on %s failed: %s", channel.c_str(),
                err == -2  ? "no key of the key file signs now"
                : err < 0 ? "the message does not encode"
                          : std::strerror(err));
}

bool Bus::publish_raw(const std::string& channel, const void* data, size_t size) {
  return publish_encoded(channel, data, size, false);
}

int Bus::handle(int timeout_ms) {
  last_accounted_ = nullptr;
  const int rc = lcm_handle_timeout(lcm_, timeout_ms);
  last_accounted_ = nullptr;
  if (rc < 0) return -1;
  return rc > 0 ? 1 : 0;
}

int Bus::drain(int max_messages) {
  int n = 0;
  while (n < max_messages && handle(0) > 0) ++n;
  return n;
}

int Bus::fileno() const { return lcm_get_fileno(lcm_); }

ChannelStats Bus::stats(const std::string& channel) const {
  auto it = stats_.find(channel);
  return it == stats_.end() ? ChannelStats{} : it->second;
}

}  // namespace cnc::bus
