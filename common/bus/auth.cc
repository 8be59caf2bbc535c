#include "common/bus/auth.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

namespace cnc::bus {
namespace {
void ensure_sodium() {
  if (sodium_init() < 0) throw KeyFileError("libsodium could not be initialised");
}

void put_be32(uint8_t* p, uint32_t v) {
  p[0] = static_cast<uint8_t>(v >> 24);
  p[1] = static_cast<uint8_t>(v >> 16);
  p[2] = static_cast<uint8_t>(v >> 8);
  p[3] = static_cast<uint8_t>(v);
}
uint32_t get_be32(const uint8_t* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

// The common header (fingerprint 8, utime 8, seq 8, sender 4) must fit before a trailer.
constexpr size_t kMinMessage = 8 + 8 + 8 + 4;

void compute_tag(const Key& key, std::string_view channel, const uint8_t* msg, size_t n, const uint8_t* id_be,
                 uint8_t* tag) {
  crypto_auth_hmacsha512256_state st = key.base;
  uint8_t len_be[4];
  put_be32(len_be, static_cast<uint32_t>(channel.size()));
  crypto_auth_hmacsha512256_update(&st, len_be, sizeof len_be);
  crypto_auth_hmacsha512256_update(&st, reinterpret_cast<const unsigned char*>(channel.data()), channel.size());
  crypto_auth_hmacsha512256_update(&st, msg, n);
  crypto_auth_hmacsha512256_update(&st, id_be, 4);
  crypto_auth_hmacsha512256_update(&st, kTrailerMagic.data(), kTrailerMagic.size());
  crypto_auth_hmacsha512256_final(&st, tag);
}

std::string mode_text(mode_t m) {
  char b[8];
  std::snprintf(b, sizeof b, "0%03o", static_cast<unsigned>(m & 07777));
  return b;
}

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool from_hex(const std::string& s, uint8_t* out, size_t n) {
  if (s.size() != 2 * n) return false;
  for (size_t i = 0; i < n; ++i) {
    const int hi = hex_digit(s[2 * i]), lo = hex_digit(s[2 * i + 1]);
    if (hi < 0 || lo < 0) return false;
    out[i] = static_cast<uint8_t>(hi * 16 + lo);
  }
  return true;
}
}  // namespace

const Key* KeySet::signing_key(int64_t now_utime) const {
  const Key* best = nullptr;
  for (int i = 0; i < count; ++i) {
    const Key& k = keys[static_cast<size_t>(i)];
    if (k.sign_from_utime > now_utime) continue;
    if (k.accept_until_utime != 0 && k.accept_until_utime < now_utime) continue;
    if (best == nullptr || k.sign_from_utime >= best->sign_from_utime) best = &k;
  }
  return best;
}

const Key* KeySet::accepting_key(uint32_t id, int64_t now_utime) const {
  const Key* k = find(id);
  if (k == nullptr) return nullptr;
  if (k->accept_until_utime != 0 && now_utime > k->accept_until_utime) return nullptr;
  return k;
}

const Key* KeySet::find(uint32_t id) const {
  for (int i = 0; i < count; ++i)
    if (keys[static_cast<size_t>(i)].id == id) return &keys[static_cast<size_t>(i)];
  return nullptr;
}

bool KeySet::add(const Key& k) {
  if (count >= kMaxKeys || k.id == 0 || find(k.id) != nullptr) return false;
  ensure_sodium();
  Key& slot = keys[static_cast<size_t>(count)];
  slot = k;
  crypto_auth_hmacsha512256_init(&slot.base, slot.secret.data(), slot.secret.size());
  ++count;
  return true;
}

std::string key_file_problem(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return "key file " + path + ": " + std::strerror(errno) + " (create one with: ./cnc key gen --machine FILE)";
  if (!S_ISREG(st.st_mode)) return "key file " + path + " is not a regular file";
  // root may use the key of the cell's service user (an operator's `sudo cnc-ctl` on a
  // packaged cell, whose key belongs to the cnc user): root reads every file anyway.
  if (st.st_uid != ::geteuid() && ::geteuid() != 0)
    return "key file " + path + " (mode " + mode_text(st.st_mode) + ") belongs to uid " + std::to_string(st.st_uid) +
           ", not to this user (uid " + std::to_string(::geteuid()) + ")";
  if ((st.st_mode & 077) != 0)
    return "key file " + path + " has mode " + mode_text(st.st_mode) +
           ": group or others may access it; it must be readable by its owner only (chmod 600 " + path + ")";
  return "";
}

KeySet read_key_file(const std::string& path) {
  ensure_sodium();
  if (const std::string why = key_file_problem(path); !why.empty()) throw KeyFileError(why);
  std::ifstream in(path);
  if (!in) throw KeyFileError("key file " + path + ": cannot be read");
  KeySet set;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream f(line);
    std::string word, id_hex, secret_hex;
    long long from = 0, until = 0;
    const auto bad = [&](const std::string& what) {
      return KeyFileError("key file " + path + ":" + std::to_string(lineno) + ": " + what +
                          " (expected: key ID(8 hex) SECRET(64 hex) SIGN_FROM_UTIME ACCEPT_UNTIL_UTIME)");
    };
    if (!(f >> word >> id_hex >> secret_hex >> from >> until) || word != "key") throw bad("malformed line");
    std::string rest;
    if (f >> rest) throw bad("unexpected '" + rest + "'");
    Key k;
    uint8_t id_bytes[4];
    if (!from_hex(id_hex, id_bytes, 4)) throw bad("the key id is not 8 hex digits");
    k.id = get_be32(id_bytes);
    if (k.id == 0) throw bad("key id 0 is reserved");
    if (!from_hex(secret_hex, k.secret.data(), k.secret.size())) throw bad("the secret is not 64 hex digits");
    if (from < 0 || until < 0) throw bad("negative time");
    k.sign_from_utime = from;
    k.accept_until_utime = until;
    if (set.find(k.id) != nullptr) throw bad("key id " + id_hex + " appears twice");
    if (!set.add(k)) throw bad("more than " + std::to_string(kMaxKeys) + " keys");
  }
  if (set.count == 0) throw KeyFileError("key file " + path + " holds no key");
  return set;
}

void write_key_file(const std::string& path, const KeySet& keys) {
  std::string text =
      "# cnc cell key file: HMAC-SHA-512-256 keys of the cell's channels. Secret: mode 0600.\n"
      "# key ID SECRET SIGN_FROM_UTIME ACCEPT_UNTIL_UTIME   (times: wall clock, us; 0 = always / no end)\n";
  for (int i = 0; i < keys.count; ++i) {
    const Key& k = keys.keys[static_cast<size_t>(i)];
    uint8_t id_be[4];
    put_be32(id_be, k.id);
    text += "key " + to_hex(id_be, 4) + " " + to_hex(k.secret.data(), k.secret.size()) + " " +
            std::to_string(k.sign_from_utime) + " " + std::to_string(k.accept_until_utime) + "\n";
  }
  const std::string tmp = path + ".tmp" + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) throw KeyFileError("cannot create " + tmp + ": " + std::strerror(errno));
  ::fchmod(fd, 0600);  // whatever the umask
  // A key rewritten by root (`sudo cnc-key rotate` on a packaged cell) keeps the owner
  // of the file it replaces: the cell's service user must go on reading it.
  if (struct stat old{}; ::geteuid() == 0 && ::stat(path.c_str(), &old) == 0 && old.st_uid != 0) {
    if (::fchown(fd, old.st_uid, old.st_gid) != 0) {
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      throw KeyFileError("cannot give " + tmp + " the owner of " + path + ": " + std::strerror(err));
    }
  }
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      throw KeyFileError("cannot write " + tmp + ": " + std::strerror(err));
    }
    done += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0 || ::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    throw KeyFileError("cannot write " + path + ": " + std::strerror(err));
  }
}

Key generate_key(const KeySet& avoid) {
  ensure_sodium();
  Key k;
  do {
    k.id = randombytes_random();
  } while (k.id == 0 || avoid.find(k.id) != nullptr);
  randombytes_buf(k.secret.data(), k.secret.size());
  return k;
}

KeySet rotate_keys(const KeySet& old, int64_t now_utime, double activate_s, double grace_s) {
  Key fresh = generate_key(old);
  fresh.sign_from_utime = now_utime + static_cast<int64_t>(activate_s * 1e6);
  const int64_t old_end = fresh.sign_from_utime + static_cast<int64_t>(grace_s * 1e6);
  std::array<Key, kMaxKeys> kept{};
  int n = 0;
  for (int i = 0; i < old.count; ++i) {
    Key k = old.keys[static_cast<size_t>(i)];
    if (k.accept_until_utime != 0 && k.accept_until_utime < now_utime) continue;  // over
    if (k.accept_until_utime == 0 || k.accept_until_utime > old_end) k.accept_until_utime = old_end;
    kept[static_cast<size_t>(n++)] = k;
  }
  // Room for the new key: the oldest kept keys (first in the file) give way.
  KeySet out;
  for (int i = std::max(0, n - (kMaxKeys - 1)); i < n; ++i) out.add(kept[static_cast<size_t>(i)]);
  out.add(fresh);
  return out;
}

bool has_trailer(const void* data, size_t size) {
  if (size < kMinMessage + kTrailerBytes) return false;
  const auto* p = static_cast<const uint8_t*>(data) + size - kTrailerMagic.size();
  return std::memcmp(p, kTrailerMagic.data(), kTrailerMagic.size()) == 0;
}

size_t payload_size(const void* data, size_t size) { return has_trailer(data, size) ? size - kTrailerBytes : size; }

uint32_t trailer_key_id(const void* data, size_t size) {
  return get_be32(static_cast<const uint8_t*>(data) + size - kTrailerBytes);
}

void sign(const Key& key, std::string_view channel, const void* msg, size_t n, uint8_t* out) {
  put_be32(out, key.id);
  compute_tag(key, channel, static_cast<const uint8_t*>(msg), n, out, out + 4);
  std::memcpy(out + 4 + kTagBytes, kTrailerMagic.data(), kTrailerMagic.size());
}

bool verify(const Key& key, std::string_view channel, const void* data, size_t size) {
  if (!has_trailer(data, size)) return false;
  const auto* p = static_cast<const uint8_t*>(data);
  const uint8_t* trailer = p + size - kTrailerBytes;
  uint8_t tag[kTagBytes];
  compute_tag(key, channel, p, size - kTrailerBytes, trailer, tag);
  return crypto_verify_32(tag, trailer + 4) == 0;
}

std::string to_hex(const uint8_t* p, size_t n) {
  static const char* d = "0123456789abcdef";
  std::string s(2 * n, '0');
  for (size_t i = 0; i < n; ++i) {
    s[2 * i] = d[p[i] >> 4];
    s[2 * i + 1] = d[p[i] & 15];
  }
  return s;
}

}  // namespace cnc::bus
