#pragma once
// Randomized programs for the interpolator core ("Paths without defects",
// item 3), shared by tests/unit/interpolator_property_test.cc and the driver
// tools/bench/path_property.cc. A program is G-code text on sim3's travel, made of
// pieces that each start where the one before ends:
//   * NURBS, LinuxCNC G5.2 (degree 2-4, XY) and Fanuc G6.2 (degree 1-4, XYZ), with
//     clustered knots (two 1e-3 apart), repeated knots (multiplicity up to the
//     degree), zero tangents at either end (first / last control point doubled),
//     weights 0.05-20, at normal size, very short (1-10 um) or long (100 mm);
//   * arcs (G2/G3 in G17/G18/G19, sometimes helical) whose end lies off the start
//     radius by up to LinuxCNC's tolerance (0.028 mm, or 0.1 % of the radius);
//   * runs of 50-500 G1 micro-segments of 0.05-0.5 mm, coordinates rounded to 3
//     decimals;
//   * G1 lines of 1-10 um and of 100 mm;
// feeds 100-6000 mm/min. Each program runs through the interpreter (as the server
// runs it) and the interpolator core fed as the dry run feeds it (FeedPolicy over a
// SyncPlanLink), and its setpoints are checked:
//   finite, within every axis's travel; per-axis velocity, acceleration and jerk by
//   finite differences of the setpoints (T = ipo period, the machine at rest before
//   the first and after the last setpoint, as ./cnc plan counts them) within 1 % of
//   the limits; on arcs and NURBS, the chord error of every step both of whose
//   setpoints lie in the block, measured against the exact curve (the distance of
//   the curve between the two parameters from the segment between the two
//   setpoints), within the chord tolerance + 1 %; the last setpoint on the program's
//   end point within 1e-9 mm.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/motion/path_segment.h"
#include "tests/unit/program_test_util.h"

namespace cnc::proptest {

using V3 = std::array<double, 3>;

// Classes of pieces (a bit each) the generator may produce; a run can be limited to
// a subset.
enum Class : uint32_t {
  kNurbsG5 = 1u << 0,
  kNurbsG6 = 1u << 1,
  kClusteredKnots = 1u << 2,   // G6.2 with two interior knots 1e-3 apart
  kRepeatedKnots = 1u << 3,    // G6.2 with an interior knot of multiplicity 2..degree
  kZeroTangentStart = 1u << 4, // NURBS with its first control point doubled
  kZeroTangentEnd = 1u << 5,   // NURBS with its last control point doubled
  kExtremeWeights = 1u << 6,   // NURBS weights 0.05..20 (else all 1)
  kShort = 1u << 7,            // a 1-10 um line or NURBS
  kLong = 1u << 8,             // a 100 mm line or NURBS
  kArc = 1u << 9,
  kArcMismatch = 1u << 10,     // an arc ending off its start radius
  kMicro = 1u << 11,           // a run of G1 micro-segments
  kLine = 1u << 12,
  kSmallArc = 1u << 13,        // an arc of radius below 1 mm
  kArcXZYZ = 1u << 14,         // an arc in G18 or G19
  kHelix = 1u << 15,           // an arc whose third axis moves
  kMicroG64 = 1u << 16,        // a run of G1 micro-segments under G64 P (fitted, blended)
  kAllClasses = (1u << 17) - 1,
};

inline std::string class_names(uint32_t c) {
  static const char* const kNames[] = {"nurbs-g5.2", "nurbs-g6.2",      "clustered-knots", "repeated-knots",
                                       "zero-tangent-start", "zero-tangent-end", "extreme-weights", "short",
                                       "long",       "arc",             "arc-end-off-radius", "micro-segments",
                                       "line",       "small-arc",       "arc-g18-g19",     "helix",
                                       "micro-segments-g64"};
  std::string s;
  for (int i = 0; i < 17; ++i)
    if (c & (1u << i)) {
      if (!s.empty()) s += '+';
      s += kNames[i];
    }
  return s;
}

struct Piece {
  uint32_t classes = 0;
  std::string text;  // whole lines, each ending in '\n'
  V3 start{}, end{};
  int first_line = 0, last_line = 0;  // in the program, 1-based
  double time_s = 0;                   // its length at its feed (a rough program time)
};

struct Program {
  std::string text;
  std::vector<Piece> pieces;
  V3 end{};
  uint32_t classes = 0;
  // Cycles after which a run that has not finished is stuck: 3x the pieces' time
  // at their feeds, 0.5 s per line for the stops, and a minute.
  int64_t max_cycles = 0;
};

// Numbers as the program writes them and as the interpreter reads them back.
inline std::string fmt(double x, int decimals = 6) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", decimals, x);
  if (std::string(b) == "-0.000000" || std::string(b) == "-0.000") std::snprintf(b, sizeof b, "%.*f", decimals, 0.0);
  return b;
}
inline double q(double x, int decimals = 6) { return std::strtod(fmt(x, decimals).c_str(), nullptr); }

class Generator {
 public:
  // The box the generator keeps every point in (inside sim3's travel X -5..400,
  // Y -5..300, Z -150..5).
  static constexpr V3 kLo{0, 0, -145}, kHi{395, 295, 0};

  Generator(uint64_t seed, uint32_t allowed = kAllClasses) : rng_(seed), allowed_(allowed) {}

  Program program(int min_pieces = 3, int max_pieces = 10) {
    Program p;
    V3 cur{uni(20, 375), uni(20, 275), uni(-125, -5)};
    for (double& c : cur) c = q(c);
    std::string head = "G21 G90 G91.1 G17 G94\nG0 X" + fmt(cur[0]) + " Y" + fmt(cur[1]) + " Z" + fmt(cur[2]) + "\n";
    int line = 3;
    p.text = head;
    const int n = static_cast<int>(uni_int(min_pieces, max_pieces));
    for (int i = 0; i < n; ++i) {
      Piece pc = piece(cur);
      if (pc.text.empty()) continue;
      pc.first_line = line;
      line += static_cast<int>(std::count(pc.text.begin(), pc.text.end(), '\n'));
      pc.last_line = line - 1;
      p.text += pc.text;
      p.classes |= pc.classes;
      cur = pc.end;
      p.pieces.push_back(std::move(pc));
    }
    p.text += "M2\n";
    p.end = cur;
    double t = 60 + 0.5 * line;
    for (const Piece& pc : p.pieces) t += 3 * pc.time_s;
    p.max_cycles = static_cast<int64_t>(t / 0.004);
    return p;
  }

  // One piece from `cur`, of a class the generator is allowed.
  Piece piece(const V3& cur) {
    for (int attempt = 0; attempt < 100; ++attempt) {
      const double r = uni(0, 1);
      Piece pc;
      if (r < 0.22) pc = nurbs_g5(cur);
      else if (r < 0.47) pc = nurbs_g6(cur);
      else if (r < 0.67) pc = arc(cur);
      else if (r < 0.77) pc = micro(cur);
      else pc = line(cur);
      if (!pc.text.empty() && (pc.classes & ~allowed_) == 0) return pc;
    }
    return {};
  }

  double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  int64_t uni_int(int64_t a, int64_t b) { return std::uniform_int_distribution<int64_t>(a, b)(rng_); }
  bool coin(double p) { return uni(0, 1) < p; }
  double log_uni(double a, double b) { return std::exp(uni(std::log(a), std::log(b))); }
  double feed() { return std::round(uni(100, 6000)); }

 private:
  static V3 clamp_box(V3 p) {
    for (int a = 0; a < 3; ++a) p[a] = std::clamp(p[a], kLo[a], kHi[a]);
    return p;
  }
  static bool inside(const V3& p) {
    for (int a = 0; a < 3; ++a)
      if (!(p[a] >= kLo[a] && p[a] <= kHi[a])) return false;
    return true;
  }
  V3 unit_dir(double zshare = 0.5) {
    for (;;) {
      V3 d{uni(-1, 1), uni(-1, 1), uni(-1, 1) * zshare};
      const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      if (n > 0.1) return {d[0] / n, d[1] / n, d[2] / n};
    }
  }
  static std::string xyz(const V3& p, int decimals = 6) {
    return "X" + fmt(p[0], decimals) + " Y" + fmt(p[1], decimals) + " Z" + fmt(p[2], decimals);
  }

  // Size class of a NURBS or a line: short (1-10 um), long (100 mm) or normal.
  double size(uint32_t* cls, double normal_lo, double normal_hi) {
    const double r = uni(0, 1);
    if (r < 0.15) {
      *cls |= kShort;
      return uni(1e-3, 1e-2);
    }
    if (r < 0.3) {
      *cls |= kLong;
      return 100;
    }
    return uni(normal_lo, normal_hi);
  }

  Piece line(const V3& cur) {
    Piece pc;
    pc.classes = kLine;
    const double len = size(&pc.classes, 0.5, 30);
    V3 e = cur;
    bool ok = false;
    for (int t = 0; t < 200 && !ok; ++t) {
      const V3 d = unit_dir();
      for (int a = 0; a < 3; ++a) e[a] = q(cur[a] + len * d[a]);
      ok = inside(e) && e != cur;
    }
    if (!ok) return {};
    pc.start = cur;
    pc.end = e;
    const double f = feed();
    pc.text = "G1 " + xyz(e) + " F" + fmt(f, 0) + "\n";
    pc.time_s = len / (f / 60);
    return pc;
  }

  Piece micro(const V3& cur) {
    Piece pc;
    pc.classes = kMicro;
    pc.start = cur;
    const int n = static_cast<int>(uni_int(50, 500));
    double th = uni(0, 2 * std::numbers::pi), slope = coin(0.5) ? 0 : uni(-0.2, 0.2);
    const double bend = log_uni(1e-3, 0.3);  // heading change per segment (rad, sd)
    std::normal_distribution<double> turn(0, bend);
    V3 p = cur;
    const double f = feed();
    double len = 0;
    // Half the runs under G64 P (fitted within P, corners blended), as CAM output runs
    // (drawn only where the class is allowed: other masks keep their programs).
    const bool g64 = (allowed_ & kMicroG64) != 0 && coin(0.5);
    if (g64) pc.classes |= kMicroG64;
    pc.text = g64 ? "G64 P" + fmt(log_uni(1e-3, 0.05), 4) + "\nG1" : "G1";
    for (int i = 0; i < n; ++i) {
      const double L = uni(0.05, 0.5);
      th += turn(rng_);
      if (coin(0.02)) th += uni(-2, 2);  // an occasional corner
      V3 e{};
      for (int t = 0; t < 8; ++t) {
        e = {q(p[0] + L * std::cos(th), 3), q(p[1] + L * std::sin(th), 3), q(p[2] + L * slope, 3)};
        if (inside(e)) break;
        th += std::numbers::pi / 2 + uni(0, 1);
        slope = -slope;
      }
      if (!inside(e) || e == p) continue;
      pc.text += (i == 0 ? " " : "") + xyz(e, 3) + (i == 0 ? " F" + fmt(f, 0) : "") + "\n";
      p = e;
      len += L;
    }
    if (p == cur) return {};
    if (g64) pc.text += "G61\n";
    pc.end = p;
    pc.time_s = len / (f / 60);
    return pc;
  }

  // Weights: all 1, or each 0.05..20 (log-uniform, sometimes at the ends of the range).
  std::vector<double> weights(int n, uint32_t* cls) {
    std::vector<double> w(static_cast<size_t>(n), 1.0);
    if (coin(0.5)) {
      *cls |= kExtremeWeights;
      for (double& x : w) {
        const double r = uni(0, 1);
        x = r < 0.1 ? 0.05 : r < 0.2 ? 20 : q(log_uni(0.05, 20));
      }
    }
    return w;
  }

  // Control points from `cur`: along a chord of length `len` with a lateral spread,
  // clamped into the box (the curve stays in their convex hull). `axes`: 2 = XY only.
  std::vector<V3> control_points(const V3& cur, int n, double len, int axes, uint32_t* cls) {
    std::vector<V3> cp(static_cast<size_t>(n), cur);
    V3 d = unit_dir(axes == 2 ? 0 : 0.5);
    const double lat = len * uni(0.1, 0.8);
    for (int k = 1; k < n; ++k) {
      const double t = static_cast<double>(k) / (n - 1);
      V3 p = cur;
      for (int a = 0; a < axes; ++a) p[a] = cur[a] + t * len * d[a] + lat * uni(-1, 1) * (a == 2 ? 0.5 : 1);
      p = clamp_box(p);
      for (double& c : p) c = q(c);
      cp[static_cast<size_t>(k)] = p;
    }
    if (n >= 3 && coin(0.3)) {
      *cls |= kZeroTangentStart;
      cp[1] = cp[0];
    }
    if (n >= 3 && coin(0.3)) {
      *cls |= kZeroTangentEnd;
      cp[static_cast<size_t>(n - 1)] = cp[static_cast<size_t>(n - 2)];
    }
    // Not a curve of zero length.
    if (cp.back() == cp.front()) return {};
    return cp;
  }
  static double polygon_length(const std::vector<V3>& cp) {
    double L = 0;
    for (size_t k = 1; k < cp.size(); ++k)
      L += std::hypot(cp[k][0] - cp[k - 1][0], cp[k][1] - cp[k - 1][1], cp[k][2] - cp[k - 1][2]);
    return L;
  }

  Piece nurbs_g5(const V3& cur) {
    Piece pc;
    pc.classes = kNurbsG5;
    const int order = static_cast<int>(uni_int(3, 5));
    const int n = order + static_cast<int>(uni_int(0, 6));
    const double len = size(&pc.classes, 1, 40);
    const std::vector<V3> cp = control_points(cur, n, len, 2, &pc.classes);
    if (cp.empty()) return {};
    const std::vector<double> w = weights(n, &pc.classes);
    pc.start = cur;
    pc.end = cp.back();
    const double f = feed();
    pc.time_s = polygon_length(cp) / (f / 60);
    pc.text = "G17 F" + fmt(f, 0) + "\n";
    // The opening line's X Y is control point 1 (the current point is 0, weight 1).
    pc.text += "G5.2 X" + fmt(cp[1][0]) + " Y" + fmt(cp[1][1]) + " P" + fmt(w[1]) + " L" + std::to_string(order) + "\n";
    for (int k = 2; k < n; ++k)
      pc.text += "X" + fmt(cp[static_cast<size_t>(k)][0]) + " Y" + fmt(cp[static_cast<size_t>(k)][1]) + " P" +
                 fmt(w[static_cast<size_t>(k)]) + "\n";
    pc.text += "G5.3\n";
    return pc;
  }

  Piece nurbs_g6(const V3& cur) {
    Piece pc;
    pc.classes = kNurbsG6;
    const int order = static_cast<int>(uni_int(2, 5));
    const int degree = order - 1;
    const int n = order + static_cast<int>(uni_int(0, 6));
    const double len = size(&pc.classes, 1, 40);
    const std::vector<V3> cp = control_points(cur, n, len, 3, &pc.classes);
    if (cp.empty()) return {};
    const std::vector<double> w = weights(n, &pc.classes);
    // Knots: `order` zeros, n - order interior knots in (0.05, 0.95), `order` ones.
    const int m = n - order;
    std::vector<double> inner(static_cast<size_t>(m));
    for (double& k : inner) k = q(uni(0.05, 0.95));
    std::sort(inner.begin(), inner.end());
    if (m >= 2 && coin(0.35)) {
      pc.classes |= kClusteredKnots;
      const size_t i = static_cast<size_t>(uni_int(0, m - 2));
      inner[i + 1] = q(inner[i] + 1e-3);
      std::sort(inner.begin(), inner.end());
    }
    if (m >= 2 && degree >= 2 && coin(0.35)) {
      pc.classes |= kRepeatedKnots;
      const int mult = static_cast<int>(uni_int(2, std::min(degree, m)));
      const size_t i = static_cast<size_t>(uni_int(0, m - mult));
      for (int j = 1; j < mult; ++j) inner[i + static_cast<size_t>(j)] = inner[i];
      std::sort(inner.begin(), inner.end());
    }
    std::vector<double> knots(static_cast<size_t>(order), 0.0);
    knots.insert(knots.end(), inner.begin(), inner.end());
    knots.insert(knots.end(), static_cast<size_t>(order), 1.0);
    pc.start = cur;
    pc.end = cp.back();
    const double f = feed();
    pc.time_s = polygon_length(cp) / (f / 60);
    pc.text = "G6.2 P" + std::to_string(order) + " K" + fmt(knots[0]) + " " + xyz(cp[0]) + " R" + fmt(w[0]) + " F" +
              fmt(f, 0) + "\n";
    for (int k = 1; k < n; ++k)
      pc.text += "K" + fmt(knots[static_cast<size_t>(k)]) + " " + xyz(cp[static_cast<size_t>(k)]) + " R" +
                 fmt(w[static_cast<size_t>(k)]) + "\n";
    for (int k = n; k < n + order; ++k) pc.text += "K" + fmt(knots[static_cast<size_t>(k)]) + "\n";
    return pc;
  }

  Piece arc(const V3& cur) {
    Piece pc;
    pc.classes = kArc;
    const int plane = static_cast<int>(uni_int(0, 2));
    static const int kA1[] = {0, 2, 1}, kA2[] = {1, 0, 2}, kA3[] = {2, 1, 0};
    static const char* const kG[] = {"G17", "G18", "G19"};
    const int a1 = kA1[plane], a2 = kA2[plane], a3 = kA3[plane];
    const bool mismatch = coin(0.6);
    for (int t = 0; t < 200; ++t) {
      const double r = log_uni(0.1, 60);
      const double th0 = uni(0, 2 * std::numbers::pi);
      // Centre offset from the start (incremental, G91.1), as the program writes it.
      const double i1 = q(-r * std::cos(th0)), i2 = q(-r * std::sin(th0));
      const double c1 = cur[a1] + i1, c2 = cur[a2] + i2;
      const double r1 = std::hypot(i1, i2);
      const double tol = std::max(0.028, 0.001 * r1);
      const double reach = r1 + tol;
      if (c1 - reach < kLo[a1] || c1 + reach > kHi[a1] || c2 - reach < kLo[a2] || c2 + reach > kHi[a2]) continue;
      const bool ccw = coin(0.5);
      const double sweep = coin(0.1) ? log_uni(1e-3, 0.05) : uni(0.05, 2 * std::numbers::pi - 0.05);
      const double th1 = std::atan2(cur[a2] - c2, cur[a1] - c1) + (ccw ? sweep : -sweep);
      const double r2 = mismatch ? r1 + uni(-0.97, 0.97) * tol : r1;
      V3 e = cur;
      e[a1] = q(c1 + r2 * std::cos(th1));
      e[a2] = q(c2 + r2 * std::sin(th1));
      if (coin(0.3)) e[a3] = q(std::clamp(cur[a3] + uni(-5, 5), kLo[a3], kHi[a3]));
      // What the interpreter will see (LinuxCNC's check: 0.0283 mm, or 0.1 % up to 2.83 mm).
      const double r2q = std::hypot(e[a1] - c1, e[a2] - c2);
      const double abs_err = std::fabs(r2q - r1), rel_err = abs_err / std::max(r1, r2q);
      if (abs_err > 2 * 0.01 * std::numbers::sqrt2 * 0.99 && rel_err > 0.001 * 0.99) continue;
      if (e == cur) continue;
      if (abs_err > 1e-5) pc.classes |= kArcMismatch;
      if (r1 < 1) pc.classes |= kSmallArc;
      if (plane != 0) pc.classes |= kArcXZYZ;
      if (e[a3] != cur[a3]) pc.classes |= kHelix;
      pc.start = cur;
      pc.end = e;
      static const char kOff[] = {'I', 'J', 'K'};
      const double f = feed();
      pc.time_s = (std::max(r1, r2q) * sweep + std::fabs(e[a3] - cur[a3])) / (f / 60);
      pc.text = std::string(kG[plane]) + (ccw ? " G3 " : " G2 ") + xyz(e) + " " + kOff[a1] + fmt(i1) + " " + kOff[a2] +
                fmt(i2) + " F" + fmt(f, 0) + "\n";
      return pc;
    }
    return {};
  }

  std::mt19937_64 rng_;
  uint32_t allowed_;
};

// ---- running and checking --------------------------------------------------------

// The worst value of one property over a program, and where (line, cycle).
struct Worst {
  double value = 0;
  int line = 0;
  int64_t cycle = -1;
  void take(double v, int l, int64_t c) {
    if (v > value || (std::isnan(v) && !std::isnan(value))) {
      value = v;
      line = l;
      cycle = c;
    }
  }
};

struct Result {
  std::string error;     // the interpreter or the interpolator refused the program
  bool done = false;     // the core reached kDone
  int stuck_line = 0;    // when not: the line of the last setpoint
  int64_t setpoints = 0;
  int64_t nonfinite = 0;
  Worst travel_mm;       // how far outside the travel (0 inside)
  Worst vel, acc, jerk;  // peak use of the axis limits
  Worst chord;           // chord error / tolerance
  Worst off_curve_mm;    // |setpoint - curve(u)| on arcs and NURBS
  double end_mm = 0;     // last setpoint to the program's end point
  int64_t chord_steps = 0;
  int64_t checks = 0;    // property evaluations
};

// Distance from x to the segment a-b.
inline double dist_to_segment(const motion::AxisVec& x, const V3& a, const V3& b) {
  double ab2 = 0, t = 0;
  for (int i = 0; i < 3; ++i) {
    ab2 += (b[i] - a[i]) * (b[i] - a[i]);
    t += (x[i] - a[i]) * (b[i] - a[i]);
  }
  t = ab2 > 0 ? std::clamp(t / ab2, 0.0, 1.0) : 0.0;
  double d2 = 0;
  for (int i = 0; i < 3; ++i) {
    const double c = a[i] + t * (b[i] - a[i]) - x[i];
    d2 += c * c;
  }
  return std::sqrt(d2);
}

// The chord error of one step: the largest distance of the exact curve between u0
// and u1 from the segment between the two setpoints. 8 samples, then a
// golden-section search around the largest (a step's bulge is one hump).
inline double chord_error(const motion::PathSegment& seg, double u0, double u1, const V3& p0, const V3& p1) {
  constexpr int kN = 8;
  double best = 0;
  int at = 0;
  for (int i = 0; i <= kN; ++i) {
    const double d = dist_to_segment(seg.point(u0 + (u1 - u0) * i / kN), p0, p1);
    if (d > best) best = d, at = i;
  }
  double lo = u0 + (u1 - u0) * std::max(0, at - 1) / kN, hi = u0 + (u1 - u0) * std::min(kN, at + 1) / kN;
  const double g = (std::sqrt(5.0) - 1) / 2;
  double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
  double f1 = dist_to_segment(seg.point(x1), p0, p1), f2 = dist_to_segment(seg.point(x2), p0, p1);
  for (int it = 0; it < 20; ++it) {
    if (f1 > f2) {
      hi = x2, x2 = x1, f2 = f1;
      x1 = hi - g * (hi - lo);
      f1 = dist_to_segment(seg.point(x1), p0, p1);
    } else {
      lo = x1, x1 = x2, f1 = f2;
      x2 = lo + g * (hi - lo);
      f2 = dist_to_segment(seg.point(x2), p0, p1);
    }
  }
  return std::max({best, f1, f2});
}

inline config::MachineConfig sim3() {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
}

struct Sp {
  V3 p;
  int64_t block;
  int line;
  double u;
};

inline Result run_and_check(const config::MachineConfig& cfg, const std::string& text, const V3& end,
                            int64_t max_cycles) {
  Result r;
  std::vector<program::Block> blocks;
  try {
    test::TempDir dir;
    const std::string path = (dir.path() / "p.ngc").string();
    test::write_file(path, text);
    blocks = test::run_program(path);
  } catch (const std::exception& e) {
    r.error = std::string("interpreter: ") + e.what();
    return r;
  }
  interp::SyncPlanLink planner(cfg);
  interp::Interpolator core(cfg, planner);
  const interp::FeedPolicy feed(cfg);
  core.set_auto_resume_pauses(true);
  core.apply_command({interp::Command::Kind::kLoad, 1.0});
  core.apply_command({interp::Command::Kind::kStart, 1.0});
  std::vector<Sp> sps;
  sps.push_back({{core.last().position_mm[0], core.last().position_mm[1], core.last().position_mm[2]}, -1, 0, 0});
  for (int64_t k = 0; k < max_cycles && core.state() != interp::RunState::kDone; ++k) {
    const bool fed = feed.cycle(
        core,
        [&](int64_t index) -> std::unique_ptr<program::Block> {
          if (index >= static_cast<int64_t>(blocks.size())) return nullptr;
          return std::make_unique<program::Block>(blocks[static_cast<size_t>(index)]);
        },
        [](int64_t) {}, [](int) {});
    const std::string failure = core.take_plan_failure();
    if (!fed || !failure.empty()) {
      r.error = "interpolator: " + (failure.empty() ? core.last_refusal() : failure);
      return r;
    }
    const interp::Setpoint& s = core.step();
    sps.push_back({{s.position_mm[0], s.position_mm[1], s.position_mm[2]}, s.block_index, s.source_line, s.u});
  }
  r.done = core.state() == interp::RunState::kDone;
  if (!r.done) r.stuck_line = sps.back().line;
  r.setpoints = static_cast<int64_t>(sps.size()) - 1;

  // Finite and within travel.
  for (size_t i = 1; i < sps.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = sps[i].p[a];
      const auto& ax = cfg.axes[static_cast<size_t>(a)];
      if (!std::isfinite(x)) ++r.nonfinite;
      r.travel_mm.take(std::max({0.0, ax.min_mm - x, x - ax.max_mm}), sps[i].line, static_cast<int64_t>(i));
      r.checks += 2;
    }
  }
  // Velocity, acceleration, jerk: the machine at rest before and after.
  {
    std::vector<Sp> q = sps;
    q.insert(q.begin(), 2, sps.front());
    q.push_back(sps.back());
    q.push_back(sps.back());
    const double T = cfg.ipo_period_s;
    for (size_t i = 3; i < q.size(); ++i) {
      const int line = q[i].block >= 0 ? q[i].line : q[i - 1].line;
      const int64_t cyc = static_cast<int64_t>(i) - 2;
      for (int a = 0; a < 3; ++a) {
        const auto& ax = cfg.axes[static_cast<size_t>(a)];
        const double v = (q[i].p[a] - q[i - 1].p[a]) / T;
        const double acc = (q[i].p[a] - 2 * q[i - 1].p[a] + q[i - 2].p[a]) / (T * T);
        const double j = (q[i].p[a] - 3 * q[i - 1].p[a] + 3 * q[i - 2].p[a] - q[i - 3].p[a]) / (T * T * T);
        r.vel.take(std::fabs(v) / ax.max_velocity_mm_s, line, cyc);
        r.acc.take(std::fabs(acc) / ax.max_accel_mm_s2, line, cyc);
        r.jerk.take(std::fabs(j) / ax.max_jerk_mm_s3, line, cyc);
        r.checks += 3;
      }
    }
  }
  // Chord error and on-curve on arcs and NURBS, against each block's exact curve.
  {
    std::map<int64_t, std::unique_ptr<motion::PathSegment>> segs;
    auto seg_of = [&](int64_t bi) -> const motion::PathSegment* {
      if (bi < 0 || bi >= static_cast<int64_t>(blocks.size())) return nullptr;
      const program::Block& b = blocks[static_cast<size_t>(bi)];
      if (b.kind != program::BlockKind::kArcCw && b.kind != program::BlockKind::kArcCcw &&
          b.kind != program::BlockKind::kNurbs)
        return nullptr;
      auto& s = segs[bi];
      if (!s) s = std::make_unique<motion::PathSegment>(b, static_cast<int>(b.start.size()));
      return s.get();
    };
    for (size_t i = 1; i < sps.size(); ++i) {
      const motion::PathSegment* seg = seg_of(sps[i].block);
      if (seg == nullptr) continue;
      const motion::AxisVec c = seg->point(sps[i].u);
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += (c[a] - sps[i].p[a]) * (c[a] - sps[i].p[a]);
      r.off_curve_mm.take(std::sqrt(d2), sps[i].line, static_cast<int64_t>(i));
      ++r.checks;
      if (sps[i - 1].block != sps[i].block || !(sps[i].u > sps[i - 1].u)) continue;
      const double e = chord_error(*seg, sps[i - 1].u, sps[i].u, sps[i - 1].p, sps[i].p);
      r.chord.take(e / cfg.chord_tolerance_mm, sps[i].line, static_cast<int64_t>(i));
      ++r.chord_steps;
      ++r.checks;
    }
  }
  const V3& last = sps.back().p;
  r.end_mm = std::max({std::fabs(last[0] - end[0]), std::fabs(last[1] - end[1]), std::fabs(last[2] - end[2])});
  r.checks += 1;
  return r;
}

// The properties a result must have; "" when it has them all, else which fail (with
// the measured values).
inline std::string violations(const Result& r) {
  std::string s;
  char b[200];
  auto add = [&](const char* what, const Worst& w, double limit) {
    if (w.value <= limit) return;
    std::snprintf(b, sizeof b, "%s %.4g (limit %.4g) at line %d cycle %lld; ", what, w.value, limit, w.line,
                  static_cast<long long>(w.cycle));
    s += b;
  };
  if (!r.error.empty()) return "refused: " + r.error;
  if (!r.done) s += "did not finish (at line " + std::to_string(r.stuck_line) + "); ";
  if (r.nonfinite > 0) s += std::to_string(r.nonfinite) + " non-finite coordinates; ";
  add("outside travel mm", r.travel_mm, 0);
  add("velocity/limit", r.vel, 1.01);
  add("acceleration/limit", r.acc, 1.01);
  add("jerk/limit", r.jerk, 1.01);
  add("chord error/tolerance", r.chord, 1.01);
  add("setpoint off its curve mm", r.off_curve_mm, 1e-6);
  if (!(r.end_mm <= 1e-9)) {
    std::snprintf(b, sizeof b, "end point off by %.3g mm; ", r.end_mm);
    s += b;
  }
  return s;
}

}  // namespace cnc::proptest
