#pragma once
// Message authentication of the cell's channels (the architecture's trust contract).
//
// A signed message is the LCM-encoded message followed by a 40-byte trailer:
//
//   key id (4 bytes, big-endian) | tag (32 bytes) | magic "CNM" + version 1 (4 bytes)
//
// The tag is HMAC-SHA-512-256 (libsodium's crypto_auth) under the cell's key over
//
//   channel length (4 bytes BE) | channel name | the encoded message | key id | magic
//
// The encoded message begins with the fingerprint and the common header (utime,
// seq, sender), so the tag binds the channel, the sender, its sequence number, the
// time stamp and the payload. LCM's typed decode reads the bytes before the trailer;
// a raw subscriber (the logger) gets the whole datagram, so a log keeps every MAC.
//
// Keys live in a key file (text, one key a line) that must belong to the user and be
// readable by nobody else (mode 0600 or stricter):
//
//   key ID SECRET SIGN_FROM ACCEPT_UNTIL
//
// ID: 8 hex digits; SECRET: 64 hex digits (32 bytes); SIGN_FROM: wall time in µs
// from which the key signs (0: always); ACCEPT_UNTIL: wall time in µs after which a
// message under this key is refused (0: no end). A sender signs with the key whose
// SIGN_FROM is the latest one not in the future; a receiver accepts every key of the
// file within its ACCEPT_UNTIL. `cnc-key rotate` adds a new key and ends the old
// one's acceptance a grace period after the new one starts signing.
#include <sodium.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

namespace cnc::bus {

inline constexpr size_t kKeyBytes = 32;
inline constexpr size_t kTagBytes = crypto_auth_hmacsha512256_BYTES;  // 32
inline constexpr size_t kTrailerBytes = 4 + kTagBytes + 4;
inline constexpr std::array<uint8_t, 4> kTrailerMagic = {'C', 'N', 'M', 1};
inline constexpr int kMaxKeys = 4;

struct Key {
  uint32_t id = 0;
  std::array<uint8_t, kKeyBytes> secret{};
  int64_t sign_from_utime = 0;     // 0: signs from the start
  int64_t accept_until_utime = 0;  // 0: accepted without end
  // HMAC state with the key already absorbed (inner and outer pads): copied per
  // message, so signing and verifying hash only the message (two SHA-512 blocks less).
  crypto_auth_hmacsha512256_state base{};
};

// The keys of a cell: plain data (fixed arrays), copied between threads without allocation.
struct KeySet {
  std::array<Key, kMaxKeys> keys{};
  int count = 0;

  // The key that signs at `now_utime`; nullptr when none does yet.
  const Key* signing_key(int64_t now_utime) const;
  // The key with this id that is still accepted at `now_utime`; nullptr otherwise.
  const Key* accepting_key(uint32_t id, int64_t now_utime) const;
  // The key with this id whatever its times (offline verification of a log).
  const Key* find(uint32_t id) const;
  // Adds a key (prepares its HMAC state). False when the set is full or the id is taken.
  bool add(const Key& k);
};

class KeyFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "" when `path` is a regular file owned by the effective user and neither group nor
// others have any access to it; otherwise why not, naming the file and its mode
// ("key file /x/cell.key has mode 0644 (group/others may read it); chmod 600 /x/cell.key").
std::string key_file_problem(const std::string& path);
// Reads a key file after the check above; throws KeyFileError naming the file (and
// its mode, or the line) when it cannot be used.
KeySet read_key_file(const std::string& path);
// Writes the set atomically (a temporary file of mode 0600 renamed over `path`).
void write_key_file(const std::string& path, const KeySet& keys);
// One new random key (id random, non-zero, not in `avoid`).
Key generate_key(const KeySet& avoid = {});
// The set after a rotation at `now_utime`: a new key signing from now + activate_s;
// every older key accepted until then + grace_s (or its own earlier end); keys whose
// acceptance has ended are dropped.
KeySet rotate_keys(const KeySet& old, int64_t now_utime, double activate_s, double grace_s);

// True when the last bytes of the datagram are a trailer (magic and room for it
// after the common header).
bool has_trailer(const void* data, size_t size);
// The datagram's size without its trailer (size when there is none).
size_t payload_size(const void* data, size_t size);
// The key id named by a trailer (has_trailer must hold).
uint32_t trailer_key_id(const void* data, size_t size);

// Writes the trailer for `msg` (n bytes, on `channel`) under `key` into out[0..kTrailerBytes).
// No allocation.
void sign(const Key& key, std::string_view channel, const void* msg, size_t n, uint8_t* out);
// Verifies the trailer at the end of data[0..size) under `key` (constant-time compare).
bool verify(const Key& key, std::string_view channel, const void* data, size_t size);

// Hex helpers for the key file and tools.
std::string to_hex(const uint8_t* p, size_t n);

}  // namespace cnc::bus
