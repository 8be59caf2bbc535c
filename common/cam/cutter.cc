#include "common/cam/cutter.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace cnc::cam {

double Cutter::height_at(double rho) const {
  const double t = rho - ring_radius();
  if (t <= 0) return 0;
  const double r = corner_radius_mm;
  return r - std::sqrt(std::max(0.0, (r - t) * (r + t)));
}

Cutter make_cutter(double diameter_mm, double corner_radius_mm, double flute_length_mm) {
  if (!(std::isfinite(diameter_mm) && diameter_mm > 0))
    throw std::invalid_argument("cutter diameter must be > 0, got " + std::to_string(diameter_mm));
  if (!(std::isfinite(corner_radius_mm) && corner_radius_mm >= 0 && corner_radius_mm <= 0.5 * diameter_mm))
    throw std::invalid_argument("corner radius must be in [0, D/2], got " + std::to_string(corner_radius_mm));
  if (!(std::isfinite(flute_length_mm) && flute_length_mm > 0))
    throw std::invalid_argument("flute length must be > 0, got " + std::to_string(flute_length_mm));
  return Cutter{diameter_mm, corner_radius_mm, flute_length_mm};
}

namespace {
double parse_number(std::string_view s, std::string_view spec) {
  double v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
    throw std::invalid_argument("cutter '" + std::string(spec) + "': '" + std::string(s) + "' is not a number");
  return v;
}
}  // namespace

Cutter parse_cutter(std::string_view spec) {
  std::vector<std::string_view> parts;
  for (std::size_t b = 0;;) {
    const std::size_t e = spec.find(':', b);
    parts.push_back(spec.substr(b, e == std::string_view::npos ? std::string_view::npos : e - b));
    if (e == std::string_view::npos) break;
    b = e + 1;
  }
  double flute = -1;
  if (parts.size() > 1 && parts.back().substr(0, 2) == "L=") {
    flute = parse_number(parts.back().substr(2), spec);
    parts.pop_back();
  }
  const std::string_view kind = parts[0];
  const std::size_t want = kind == "bull" ? 3 : 2;
  if ((kind != "ball" && kind != "flat" && kind != "bull") || parts.size() != want)
    throw std::invalid_argument("cutter '" + std::string(spec) + "': expected ball:D, flat:D or bull:D:r (optionally :L=flute)");
  const double d = parse_number(parts[1], spec);
  const double r = kind == "ball" ? 0.5 * d : kind == "flat" ? 0.0 : parse_number(parts[2], spec);
  if (kind == "bull" && !(r > 0 && r < 0.5 * d))
    throw std::invalid_argument("cutter '" + std::string(spec) + "': a bull cutter needs 0 < r < D/2 (use ball or flat otherwise)");
  return make_cutter(d, r, flute < 0 ? 4 * d : flute);
}

}  // namespace cnc::cam
