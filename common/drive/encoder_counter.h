#pragma once
// A spindle encoder's 32-bit position counter, unwrapped into a position that runs
// on across the counter's wrap. Two reads are joined by their difference modulo 2^32
// taken the shorter way, so the position is continuous as long as the counter moves
// less than 2^31 counts between two reads (at 10,000 rpm and 2^17 counts per
// revolution: 98 s; a link lost for longer than that, or a drive that restarted and
// zeroed its counter, makes it jump). The first read sets the position to the
// counter's value as its field reads it (sign-extended where the field is signed).
// Plain data: it runs on the bridge's link workers.
#include <cstdint>

namespace cnc::drive {

class EncoderCounter {
 public:
  // A read of the counter (Field::decode_raw of its two registers); the unwrapped position.
  int64_t update(int64_t raw) {
    if (!known_) {
      counts_ = raw;
      known_ = true;
    } else {
      const auto step = static_cast<uint32_t>(static_cast<uint64_t>(raw) - static_cast<uint64_t>(last_));
      counts_ += static_cast<int32_t>(step);
    }
    last_ = raw;
    return counts_;
  }
  bool known() const { return known_; }
  int64_t counts() const { return counts_; }

 private:
  bool known_ = false;
  int64_t last_ = 0;
  int64_t counts_ = 0;
};

}  // namespace cnc::drive
