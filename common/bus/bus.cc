#include "common/bus/bus.h"

#include <unistd.h>

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

Bus::Bus(const std::string& url, int32_t sender, int queue_capacity) : url_(url), queue_capacity_(queue_capacity) {
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
    if (sub->bus->last_accounted_ != rbuf) {
      sub->bus->last_accounted_ = rbuf;
      sub->bus->account(ch, rbuf->data, rbuf->data_size);
    }
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
  if (ch_it == last_seq_.end()) ch_it = last_seq_.emplace(channel, std::map<int32_t, int64_t>{}).first;
  auto it = ch_it->second.find(hdr->sender);
  if (it == ch_it->second.end()) {
    ch_it->second.emplace(hdr->sender, hdr->seq);
    return;
  }
  const int64_t expected = it->second + 1;
  if (hdr->seq > expected) {
    st.seq_gaps += hdr->seq - expected;
  } else if (hdr->seq < expected) {
    ++st.seq_restarts;
  }
  it->second = hdr->seq;
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
                err < 0 ? "the message does not encode" : std::strerror(err));
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
