#include "common/rs274/process_directive.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <string>

#include "common/program/block.h"

namespace cnc::rs274 {

namespace {

std::string upper(std::string_view s) {
  std::string u(s);
  for (char& c : u) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return u;
}

// A plain decimal: sign, digits, one point. Returns its length, 0 if none.
size_t scan_number(std::string_view s, size_t i, double* v) {
  size_t k = i;
  if (k < s.size() && (s[k] == '+' || s[k] == '-')) ++k;
  size_t digits = 0;
  while (k < s.size() && std::isdigit(static_cast<unsigned char>(s[k]))) ++k, ++digits;
  if (k < s.size() && s[k] == '.') {
    ++k;
    while (k < s.size() && std::isdigit(static_cast<unsigned char>(s[k]))) ++k, ++digits;
  }
  if (digits == 0) return 0;
  *v = std::strtod(std::string(s.substr(i, k - i)).c_str(), nullptr);
  return k - i;
}

constexpr double kMaxMagnitude = 1e6;

}  // namespace

bool parse_process_directive(std::string_view s, int body_column, ProcessSettings* out) {
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  if (upper(s.substr(i, 7)) != "PROCESS") return false;
  i += 7;
  if (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) return false;
  const auto col = [&](size_t k) { return body_column + static_cast<int>(k); };
  const auto skip = [&] {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  };
  skip();
  if (i >= s.size() || s[i] != ',') {
    // "(PROCESS the part)" is a remark; "(PROCESS BALL_RADIUS=5)" is a mistake.
    if (s.find('=') == std::string_view::npos) return false;
    throw Error(col(i), "expected ',' after PROCESS: (PROCESS, KEY=VALUE, ...)");
  }
  ++i;
  ProcessSettings p;
  for (;;) {
    skip();
    const size_t key_at = i;
    while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) ++i;
    const std::string key = upper(s.substr(key_at, i - key_at));
    if (key.empty()) throw Error(col(key_at), "expected KEY=VALUE in the PROCESS directive");
    const int where = col(key_at);
    skip();
    if (i >= s.size() || s[i] != '=') throw Error(where, "expected '=' and a value after " + key);
    ++i;
    skip();
    double v = 0;
    const size_t len = scan_number(s, i, &v);
    if (len == 0) {
      size_t e = i;
      while (e < s.size() && s[e] != ',') ++e;
      throw Error(where, key + ": expected a number, found '" + std::string(s.substr(i, e - i)) + "'");
    }
    const std::string clean(s.substr(i, len));
    if (!std::isfinite(v) || std::fabs(v) > kMaxMagnitude)
      throw Error(where, key + ": number '" + clean + "' out of range: expected a magnitude of at most 1e6");
    i += len;
    const auto twice = [&](bool had) {
      if (had) throw Error(where, key + " appears twice in the PROCESS directive");
    };
    if (key == "BALL_RADIUS") {
      twice(p.has_ball_radius);
      if (!(v > 0)) throw Error(where, "BALL_RADIUS " + clean + ": expected a positive radius in mm");
      p.ball_radius_mm = v;
      p.has_ball_radius = true;
    } else if (key == "FLUTES") {
      twice(p.has_flutes);
      if (v != std::floor(v) || v < 1 || v > program::kMaxFlutes)
        throw Error(where, "FLUTES " + clean + ": expected a whole number from 1 to " + std::to_string(program::kMaxFlutes));
      p.flutes = static_cast<int>(v);
      p.has_flutes = true;
    } else if (key == "PICK_FEED") {
      twice(p.has_pick_feed);
      if (!(v > 0)) throw Error(where, "PICK_FEED " + clean + ": expected a positive pick feed in mm");
      p.pick_feed_mm = v;
      p.has_pick_feed = true;
    } else if (key == "RMAX_UM") {
      twice(p.has_target_rmax);
      if (v < 0) throw Error(where, "RMAX_UM " + clean + ": expected a target R_max >= 0 in um (0: law off)");
      p.target_rmax_um = v;
      p.has_target_rmax = true;
    } else {
      throw Error(where, "unknown process parameter '" + key + "': expected BALL_RADIUS, FLUTES, PICK_FEED or RMAX_UM");
    }
    skip();
    if (i >= s.size()) break;
    if (s[i] != ',') throw Error(col(i), "expected ',' or ')' after the value of " + key);
    ++i;
  }
  *out = p;
  return true;
}

}  // namespace cnc::rs274
