// G64 P at every point of the path (issue 31): random CAM-like programs through the
// dry run's pipeline (ProgramServer with the machine's program set-up, FeedPolicy over
// an inline SyncPlanLink, the interpolator core, as cnc-plan runs them), their
// setpoints played back by the drive bridge's fine interpolation (BridgeCore, 1 ms),
// and the largest distance of the commanded path from the programmed geometry.
//
// Programs (fixed seeds, coordinates at 2-5 decimals, on sim3's travel), one kind
// each: short moves (0.01-0.5 mm), zig-zag rasters, runs with spikes, hairpins,
// peck cycles (G83 and written out as G0/G1), micro-arcs (G2/G3 of 0.05-2 mm among
// short lines), uneven polygons. Each program body runs under G61 (the reference)
// and under G64 P for P = 0.001, 0.01, 0.0254 and 0.1 mm.
//
// The programmed geometry is the same program's blocks under G61: its G0/G1 lines
// and its G2/G3 arcs (PathSegment's exact curve, a spiral where the end lies off the
// start radius), before the G64 P fit and blends. The commanded path is measured
// twice: the coarse setpoints (4 ms) joined by straight lines, and the bridge's fine
// commands (1 ms) joined by straight lines; what the drive does between two servo
// ticks is not measured.
//
// The distances, and the bound they carry (tests/unit/path_distance.h). For a path chord c and a set of straight
// segments S_i, f(x) = min_i d(x, S_i) is what is wanted, max over x in c. Each
// d(., S_i) is convex along c (the distance to a convex set), so on any piece
// [x0, x1] of c: max f <= min_i max(d(x0, S_i), d(x1, S_i)) =: U, and max f >=
// max(f(x0), f(x1)) =: L. A piece is halved until U - L <= kEps (U stays an upper
// bound if the depth limit stops it first); the halving ends because every d(., S_i)
// is 1-Lipschitz (U - L <= the piece's length). Only segments within kReach of the
// chord take part (a grid finds them), and where U exceeds kReach all of them do.
// Arcs enter S as inscribed polylines whose pieces leave the arc by at most kSagitta
// (a spiral's radius changes by at most 0.028 mm over the arc: the piece count has a
// 1.5x margin for it), which moves any distance by at most kSagitta. So the true
// largest distance lies in [L - kSagitta, U + kSagitta], and the figures printed are
// U: an upper bound, at most kEps + 2 kSagitta = 5e-6 mm above the truth. The
// reverse figure ("back": how far a programmed point lies from the path, a corner
// cut, a spike's tip not reached) is the same computation with the roles swapped.
//
// What is asserted: every program accepted and finished, the bridge never faulting;
// the end point reached exactly (1e-9 mm) by the last setpoint and by the bridge's
// command 2 s after the setpoints stand; on the default programs, within
// kSettleBoundMm 100 ms after the setpoints stand, and per
// kind and mode, the largest distance of the coarse path from the geometry within
// kCurrentBound (the goal, P, where it holds today; where it does not, the bound this
// commit measured, documented there: the goal is NOT met there and the test does not
// pretend it is), the fine path within that + kBridgeDepartureMm, the geometry from
// the coarse path within that (a corner cut by P by design); under G61 every programmed
// vertex within kG61VertexBoundMm of the coarse path (G61 is no exact stop today:
// the table counts the vertices no setpoint lies on).
//
// CNC_GTOL_PROGRAMS=N runs N program bodies per kind instead of the default: a
// longer report, asserting the invariants (accepted, finished, no bridge fault, the
// end point) but not the bounds, which are the default programs' (10 per kind find
// the coarse path within 0.99 P everywhere, the G61 micro-arcs' chords at 1.06 x
// the chord tolerance, the bridge's fine commands up to 7.9 um off the setpoints'
// path: at stops, 1.05 P on zig-zags at P0.01). CNC_GTOL_WRITE=DIR writes
// every program run into DIR (<kind>-<seed>-<mode>.ngc), for `./cnc plan` on the
// worst cases the table names by seed and line.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/motion/path_segment.h"
#include "services/drive_bridge/drive_bridge.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/path_distance.h"
#include "tests/unit/temp_dir.h"

namespace cnc::gtol {
namespace {

using V3 = pathdist::V3;

constexpr double kEps = 1e-6;      // mm: U - L of every chord's largest distance
constexpr double kSagitta = 2e-6;  // mm: an arc's inscribed polyline from the arc
constexpr double kExact = 1e-9;    // mm: "reached exactly"
// After the program's last setpoint the interpolator goes on sending it: the bridge's
// commands are measured until kTailCycles (2 s) and their distance from the end
// point reported at kSettleCycles (100 ms).
constexpr int kTailCycles = 500;
constexpr int kSettleCycles = 25;

using pathdist::dot;
using pathdist::FarthestPoint;
using pathdist::lerp;
using pathdist::norm;
using pathdist::Range;
using pathdist::SegmentSet;
using pathdist::sub;

// ---- programs ------------------------------------------------------------------------

enum Kind : int { kShortMoves, kZigzag, kSpike, kHairpin, kPeck, kMicroArc, kPolygon, kKinds };
const char* const kKindNames[kKinds] = {"short-moves", "zig-zag", "spikes", "hairpins",
                                        "pecks", "micro-arcs", "polygons"};
constexpr std::array<double, 4> kTolerances{0.001, 0.01, 0.0254, 0.1};

// One program body of a kind (without its mode line), as a CAM post writes it:
// coordinates at 2-5 decimals (one count per program), modal G1, feed on the first
// move. Everything stays within 50 mm of a centre at least 60 mm inside sim3's travel.
class CamProgram {
 public:
  CamProgram(Kind kind, uint64_t seed) : rng_(seed * 7919 + static_cast<uint64_t>(kind)) {
    decimals_ = static_cast<int>(uni_int(2, 5));
    centre_ = {uni(60, 340), uni(60, 240), uni(-90, -30)};
    cur_ = round(V3{centre_[0] + uni(-10, 10), centre_[1] + uni(-10, 10), centre_[2] + 5});
    text_ = "G0 " + xyz(cur_) + "\n";
    switch (kind) {
      case kShortMoves: short_moves(); break;
      case kZigzag: zigzag(); break;
      case kSpike: spikes(); break;
      case kHairpin: hairpins(); break;
      case kPeck: pecks(); break;
      case kMicroArc: micro_arcs(); break;
      case kPolygon: polygons(); break;
      case kKinds: break;
    }
  }
  // The whole program under `mode` (e.g. "G61", "G64 P0.01").
  std::string text(const std::string& mode) const {
    return "G21 G90 G17 G94 G91.1 G40 G80\n" + mode + "\n" + text_ + "G0 Z" + fmt(centre_[2] + 20) + "\nM2\n";
  }

 private:
  double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  int64_t uni_int(int64_t a, int64_t b) { return std::uniform_int_distribution<int64_t>(a, b)(rng_); }
  double log_uni(double a, double b) { return std::exp(uni(std::log(a), std::log(b))); }
  bool coin(double p) { return uni(0, 1) < p; }
  double normal(double sd) { return std::normal_distribution<double>(0, sd)(rng_); }

  std::string fmt(double x) const {
    char b[64];
    std::snprintf(b, sizeof b, "%.*f", decimals_, x);
    std::string s = b;
    if (s.find_first_not_of("-0.") == std::string::npos) s = "0";  // no "-0.000"
    return s;
  }
  double round(double x) const { return std::strtod(fmt(x).c_str(), nullptr); }
  V3 round(const V3& p) const { return {round(p[0]), round(p[1]), round(p[2])}; }
  std::string xyz(const V3& p) const { return "X" + fmt(p[0]) + " Y" + fmt(p[1]) + " Z" + fmt(p[2]); }
  bool inside(const V3& p) const {
    return std::fabs(p[0] - centre_[0]) < 35 && std::fabs(p[1] - centre_[1]) < 35 && std::fabs(p[2] - centre_[2]) < 25;
  }

  void feed(double f) { feed_ = " F" + std::to_string(static_cast<int>(std::round(f))); }
  // A G1 to p (rounded); none where rounding leaves the tool standing.
  void g1(const V3& target) {
    const V3 p = round(target);
    if (p == cur_) return;
    text_ += (modal_g1_ ? "" : "G1 ") + xyz(p) + feed_ + "\n";
    feed_.clear();
    modal_g1_ = true;
    cur_ = p;
  }
  void g0(const V3& target) {
    const V3 p = round(target);
    if (p == cur_) return;
    text_ += "G0 " + xyz(p) + "\n";
    modal_g1_ = false;
    cur_ = p;
  }
  double surface(double x, double y) const {
    return centre_[2] + amp_ * std::sin(x / wx_) * std::cos(y / wy_);
  }
  void pick_surface() {
    amp_ = coin(0.3) ? 0 : uni(0.2, 4);
    wx_ = uni(3, 20);
    wy_ = uni(3, 20);
  }

  // A wandering 3D path of short moves, a CAM tolerance's segment length.
  void short_moves() {
    feed(uni(500, 6000));
    const double step = log_uni(0.01, 0.5), bend = log_uni(0.002, 0.2);
    double th = uni(0, 2 * std::numbers::pi), ph = uni(-0.3, 0.3);
    V3 p = cur_;
    const int n = static_cast<int>(uni_int(150, 400));
    for (int i = 0; i < n; ++i) {
      th += normal(bend);
      ph = std::clamp(ph + normal(0.5 * bend), -0.5, 0.5);
      if (coin(0.02)) th += uni(-2.5, 2.5);  // a corner now and then
      const double l = step * uni(0.5, 1.5);
      V3 e{p[0] + l * std::cos(th) * std::cos(ph), p[1] + l * std::sin(th) * std::cos(ph), p[2] + l * std::sin(ph)};
      if (!inside(e)) {
        th += std::numbers::pi;
        ph = -ph;
        continue;
      }
      g1(e);
      p = e;
    }
  }

  // Rows of short moves over a curved surface, a step-over at each row's end.
  void zigzag() {
    feed(uni(1000, 6000));
    pick_surface();
    const int rows = static_cast<int>(uni_int(4, 10));
    const double len = uni(5, 30), step = log_uni(0.05, 1.0), over = log_uni(0.05, 1.0);
    const double a = uni(0, 2 * std::numbers::pi);
    const V3 o = cur_;
    const int moves = std::max(2, static_cast<int>(len / step));
    for (int r = 0; r < rows; ++r)
      for (int i = 0; i <= moves; ++i) {
        const double s = (r % 2 ? moves - i : i) * step, t = r * over;
        const double x = o[0] + s * std::cos(a) - t * std::sin(a), y = o[1] + s * std::sin(a) + t * std::cos(a);
        g1({x, y, surface(x, y)});
      }
  }

  // A gently curving run of short moves with narrow spikes out of it (in Z or sideways).
  void spikes() {
    feed(uni(1000, 6000));
    pick_surface();
    double th = uni(0, 2 * std::numbers::pi);
    const double step = log_uni(0.05, 0.5), bend = log_uni(0.002, 0.05);
    V3 p = cur_;
    const int n = static_cast<int>(uni_int(100, 300));
    for (int i = 0; i < n; ++i) {
      th += normal(bend);
      V3 e{p[0] + step * std::cos(th), p[1] + step * std::sin(th), 0};
      e[2] = surface(e[0], e[1]);
      if (!inside(e)) {
        th += std::numbers::pi;
        continue;
      }
      if (coin(0.05)) {
        const double h = log_uni(0.02, 3), w = uni(0, 0.3) * step;
        V3 tip = lerp(p, e, 0.5 * w / step);
        if (coin(0.5)) {
          tip[2] += coin(0.5) ? h : -h;
        } else {
          tip[0] -= h * std::sin(th);
          tip[1] += h * std::cos(th);
        }
        g1(p);
        g1(tip);
        g1(lerp(p, e, w / step));
      }
      g1(e);
      p = e;
    }
  }

  // Legs that turn back by 150-179.8 degrees, the turn's side alternating: a tight zig-zag.
  void hairpins() {
    feed(uni(500, 6000));
    const double base = uni(0, 2 * std::numbers::pi);
    double th = base;
    const double leg = log_uni(0.1, 5);
    const bool climb = coin(0.3);
    V3 p = cur_;
    const int n = static_cast<int>(uni_int(30, 150));
    for (int i = 0; i < n; ++i) {
      const double l = leg * uni(0.7, 1.3);
      V3 e{p[0] + l * std::cos(th), p[1] + l * std::sin(th), p[2] + (climb ? uni(-0.05, 0.05) : 0)};
      if (!inside(e)) {
        th += std::numbers::pi;
        continue;
      }
      g1(e);
      p = e;
      const double delta = log_uni(0.2, 30) * std::numbers::pi / 180;
      th += (i % 2 ? 1 : -1) * (std::numbers::pi - delta);
    }
  }

  // Holes drilled in pecks: G83 (the interpreter's cycle) or written out in G0/G1.
  void pecks() {
    const int holes = static_cast<int>(uni_int(3, 8));
    const double top = centre_[2];
    const double r_plane = top + uni(0.5, 3), depth = uni(3, 20), q = uni(0.3, 3);
    const double f = uni(100, 800);
    const bool cycle = coin(0.5);
    for (int h = 0; h < holes; ++h) {
      const V3 at = round(V3{centre_[0] + uni(-30, 30), centre_[1] + uni(-30, 30), top - depth});
      if (cycle) {
        if (h == 0) {
          text_ += "G98 G83 " + xyz(at) + " R" + fmt(r_plane) + " Q" + fmt(q) + " F" +
                   std::to_string(static_cast<int>(std::round(f))) + "\n";
        } else {
          text_ += "X" + fmt(at[0]) + " Y" + fmt(at[1]) + "\n";
        }
        continue;
      }
      g0({cur_[0], cur_[1], r_plane});
      g0({at[0], at[1], r_plane});
      feed(f);
      for (double z = top - q;; z -= q) {
        const double bottom = std::max(z, top - depth);
        g1({at[0], at[1], bottom});
        g0({at[0], at[1], r_plane});
        if (bottom <= top - depth) break;
        g0({at[0], at[1], bottom + 0.5});
      }
    }
    if (cycle) {
      text_ += "G80\n";
      modal_g1_ = false;
      text_ += "G0 Z" + fmt(centre_[2] + 10) + "\n";
    }
  }

  // Small arcs (radius 0.05-2 mm, 10-270 degrees, tangent or with a kink) among short lines.
  void micro_arcs() {
    feed(uni(300, 5000));
    g1({cur_[0], cur_[1], centre_[2]});
    double th = uni(0, 2 * std::numbers::pi);
    const int n = static_cast<int>(uni_int(40, 150));
    for (int i = 0; i < n; ++i) {
      if (coin(0.3)) th += uni(-1.5, 1.5);  // a kink
      if (coin(0.4)) {
        const double l = log_uni(0.05, 1);
        const V3 e{cur_[0] + l * std::cos(th), cur_[1] + l * std::sin(th), cur_[2]};
        if (!inside(e)) {
          th += std::numbers::pi;
          continue;
        }
        g1(e);
        continue;
      }
      const double r = log_uni(0.05, 2), sweep = uni(10, 270) * std::numbers::pi / 180;
      const int side = coin(0.5) ? 1 : -1;  // +1: centre on the left (G3)
      const V3 c{cur_[0] - side * r * std::sin(th), cur_[1] + side * r * std::cos(th), cur_[2]};
      const V3 cr = round(c);
      const double rr = std::hypot(cur_[0] - cr[0], cur_[1] - cr[1]);
      if (rr < 2 * std::pow(10.0, -decimals_)) continue;
      const double a0 = std::atan2(cur_[1] - cr[1], cur_[0] - cr[0]), a1 = a0 + side * sweep;
      const double dz = coin(0.2) ? uni(-0.3, 0.3) : 0;
      const V3 e = round(V3{cr[0] + rr * std::cos(a1), cr[1] + rr * std::sin(a1), cur_[2] + dz});
      if (!inside(e) || (e[0] == cur_[0] && e[1] == cur_[1])) {
        th += std::numbers::pi;
        continue;
      }
      text_ += std::string(side > 0 ? "G3 " : "G2 ") + xyz(e) + " I" + fmt(cr[0] - cur_[0]) + " J" +
               fmt(cr[1] - cur_[1]) + feed_ + "\n";
      feed_.clear();
      modal_g1_ = false;
      cur_ = e;
      th = a1 + side * std::numbers::pi / 2;
    }
  }

  // Closed polygons with uneven sides (0.1-30 mm) and angles, loops stepping down in Z.
  void polygons() {
    feed(uni(500, 6000));
    const int loops = static_cast<int>(uni_int(1, 3));
    for (int k = 0; k < loops; ++k) {
      const int n = static_cast<int>(uni_int(3, 14));
      std::vector<double> ang(static_cast<size_t>(n));
      for (double& a : ang) a = uni(0, 2 * std::numbers::pi);
      std::sort(ang.begin(), ang.end());
      const double big = log_uni(1, 15);
      const double z = centre_[2] - k * uni(0.1, 2);
      std::vector<V3> v;
      for (double a : ang) {
        const double r = big * (coin(0.3) ? uni(0.02, 0.3) : uni(0.5, 1));
        v.push_back({centre_[0] + r * std::cos(a), centre_[1] + r * std::sin(a), z});
      }
      g1(v[0]);
      for (size_t i = 1; i < v.size(); ++i) g1(v[i]);
      g1(v[0]);
    }
  }

  std::mt19937_64 rng_;
  int decimals_ = 3;
  V3 centre_{}, cur_{};
  std::string text_, feed_;
  bool modal_g1_ = false;
  double amp_ = 0, wx_ = 10, wy_ = 10;
};

// ---- the run -------------------------------------------------------------------------

config::MachineConfig sim3() {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
}

// What a setpoint's block is: a programmed line, rapid or arc, or one of the G64 P
// curves (a fitted cubic, a quartic corner blend).
enum Shape : int { kLine, kRapid, kArc, kFit, kBlend, kNone, kShapes };
const char kShapeLetters[] = "LRAFB-";

int shape_of(const program::Block& b) {
  switch (b.kind) {
    case program::BlockKind::kLine: return kLine;
    case program::BlockKind::kRapid: return kRapid;
    case program::BlockKind::kArcCw:
    case program::BlockKind::kArcCcw: return kArc;
    case program::BlockKind::kNurbs: return b.nurbs.order == 5 ? kBlend : kFit;
    default: return kNone;
  }
}

struct Playback {
  std::string error;
  std::vector<program::Block> blocks;
  std::vector<V3> coarse;  // from the start position, one per cycle
  std::vector<int> line;   // source line of each coarse point
  std::vector<int> shape;  // and the Shape of its block
  std::vector<V3> fine;    // the bridge's commands, one per servo tick
  V3 fine_settle{};        // the command kSettleCycles after the setpoints stand
  std::string bridge_fault;  // a fault, or the first setpoint the bridge did not accept
};

// The program through the dry run's pipeline (tools/plan/main.cc), then its setpoints
// through the drive bridge core as the node feeds it (one setpoint, then the servo
// ticks of one coarse period), past the end until the commands stand.
Playback play(const config::MachineConfig& cfg, const std::string& text) {
  Playback r;
  test::TempDir dir;
  const std::string path = dir.write("p.ngc", text);
  pps::ProgramSetup setup = pps::program_setup(cfg);
  setup.machine.write_var_file = false;
  pps::ProgramServer server(std::move(setup), pps::ServerLimits{});
  const pps::LoadResult loaded = server.load(path, 1);
  if (!loaded.ok) {
    r.error = "refused: " + loaded.error;
    return r;
  }
  const int64_t num_blocks = server.num_blocks();
  for (int64_t i = 0; i < num_blocks; ++i) {
    const program::Block* b = server.block(i);
    if (b == nullptr) {
      r.error = "block not served";
      return r;
    }
    r.blocks.push_back(*b);
  }
  interp::SyncPlanLink planner(cfg);
  interp::Interpolator core(cfg, planner);
  const interp::FeedPolicy feed(cfg);
  core.set_auto_resume_pauses(true);
  core.apply_command({interp::Command::Kind::kLoad, 1.0});
  core.apply_command({interp::Command::Kind::kStart, 1.0});
  const auto& p0 = core.last().position_mm;
  r.coarse.push_back({p0[0], p0[1], p0[2]});
  r.line.push_back(0);
  r.shape.push_back(kNone);
  bridge::BridgeCore br(cfg);
  bridge::AxisArray hold{};
  for (int a = 0; a < 3; ++a) hold[static_cast<size_t>(a)] = p0[static_cast<size_t>(a)];
  br.engage(hold);
  const int ticks = static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s));
  auto to_bridge = [&](int64_t cycle, const bridge::AxisArray& p) {
    const bridge::BridgeCore::Verdict v = br.on_setpoint(cycle, p);
    if (v != bridge::BridgeCore::Verdict::kAccepted && r.bridge_fault.empty())
      r.bridge_fault = "setpoint " + std::to_string(cycle) + " not accepted (" + std::to_string(static_cast<int>(v)) +
                       "): " + br.fault_reason() + br.waiting_reason();
    for (int t = 0; t < ticks; ++t) {
      const bridge::AxisArray& c = br.tick();
      r.fine.push_back({c[0], c[1], c[2]});
    }
  };
  int64_t cycle = 0;
  for (int64_t k = 0; k < 10'000'000 && core.state() != interp::RunState::kDone; ++k) {
    const bool fed = feed.cycle(
        core,
        [&](int64_t index) -> std::unique_ptr<program::Block> {
          if (index >= num_blocks) return nullptr;
          return std::make_unique<program::Block>(r.blocks[static_cast<size_t>(index)]);
        },
        [](int64_t) {}, [](int) {});
    const std::string failure = core.take_plan_failure();
    if (!fed || !failure.empty()) {
      r.error = "interpolator: " + (failure.empty() ? core.last_refusal() : failure);
      return r;
    }
    const interp::Setpoint& s = core.step();
    r.coarse.push_back({s.position_mm[0], s.position_mm[1], s.position_mm[2]});
    r.line.push_back(s.source_line);
    r.shape.push_back(s.block_index >= 0 && s.block_index < num_blocks
                          ? shape_of(r.blocks[static_cast<size_t>(s.block_index)])
                          : kNone);
    to_bridge(s.cycle, s.position_mm);
    cycle = s.cycle;
  }
  if (core.state() != interp::RunState::kDone) r.error = "did not finish";
  // The interpolator goes on sending where it stands.
  bridge::AxisArray last{};
  for (int a = 0; a < 3; ++a) last[static_cast<size_t>(a)] = r.coarse.back()[static_cast<size_t>(a)];
  for (int k = 1; k <= kTailCycles; ++k) {
    to_bridge(cycle + k, last);
    if (k == kSettleCycles) r.fine_settle = r.fine.back();
  }
  if (br.faulted() && r.bridge_fault.empty()) r.bridge_fault = br.fault_reason();
  return r;
}

// The programmed geometry of a G61 run's blocks: its lines and its arcs' inscribed
// polylines (within kSagitta of the arc); `vertices`: every motion block's end.
SegmentSet geometry_of(const std::vector<program::Block>& blocks, std::vector<V3>* vertices) {
  SegmentSet g(0.25);
  for (const program::Block& b : blocks) {
    if (b.start.size() < 3) continue;
    const V3 s{b.start[0], b.start[1], b.start[2]}, e{b.end[0], b.end[1], b.end[2]};
    switch (b.kind) {
      case program::BlockKind::kLine:
      case program::BlockKind::kRapid:
        if (s != e) g.add(s, e);
        vertices->push_back(e);
        break;
      case program::BlockKind::kArcCw:
      case program::BlockKind::kArcCcw: {
        const motion::PathSegment seg(b, 3);
        int a1 = 0, a2 = 1;
        if (b.arc.plane == 18) a1 = 2, a2 = 0;
        if (b.arc.plane == 19) a1 = 1, a2 = 2;
        const auto sa1 = static_cast<size_t>(a1), sa2 = static_cast<size_t>(a2);
        const double r = std::max(std::hypot(s[sa1] - b.arc.center[sa1], s[sa2] - b.arc.center[sa2]),
                                  std::hypot(e[sa1] - b.arc.center[sa1], e[sa2] - b.arc.center[sa2]));
        const int n = pathdist::arc_pieces(seg.arc_sweep_rad(), r, kSagitta);
        V3 prev = s;
        for (int k = 1; k <= n; ++k) {
          const motion::AxisVec p = seg.point(seg.u_begin() + (seg.u_end() - seg.u_begin()) * k / n);
          const V3 x = k == n ? e : V3{p[0], p[1], p[2]};
          g.add(prev, x);
          prev = x;
        }
        vertices->push_back(e);
        break;
      }
      case program::BlockKind::kNurbs:
        ADD_FAILURE() << "a NURBS block in the G61 reference";
        break;
      default:
        break;
    }
  }
  return g;
}

// ---- figures -------------------------------------------------------------------------

// One path (coarse or fine) against the geometry, and the geometry against it.
struct Measure {
  int64_t points = 0;       // setpoints or fine commands
  int64_t points_over = 0;  // farther than the threshold from the geometry
  int64_t chords_over = 0;  // a chord with a point farther than the threshold
  double max_mm = 0;        // largest distance of the path from the geometry (upper bound)
  int max_line = 0;         // the program line there (fine: of the setpoint two periods on, roughly)
  int max_shape = kNone;    // and the shape of the block
  std::array<int64_t, kShapes> chords_over_by_shape{};  // by the shape of the chord's end
  double back_mm = 0;       // largest distance of the geometry from the path (upper bound)
};

Measure measure(const std::vector<V3>& path, const std::vector<int>& line_of, const std::vector<int>& shape_of,
                const SegmentSet& geometry,
                double threshold_mm, bool back) {
  Measure m;
  m.points = static_cast<int64_t>(path.size()) - 1;
  FarthestPoint to_geometry(geometry);
  bool last_over = false;
  for (size_t i = 1; i < path.size(); ++i) {
    if (path[i] == path[i - 1]) {
      m.points_over += last_over ? 1 : 0;
      continue;
    }
    const Range r = to_geometry.of(path[i - 1], path[i]);
    last_over = r.at_q > threshold_mm;
    m.points_over += last_over ? 1 : 0;
    const size_t at = std::min(i, line_of.size() - 1);
    if (r.hi > threshold_mm) {
      ++m.chords_over;
      ++m.chords_over_by_shape[static_cast<size_t>(shape_of[at])];
    }
    if (r.hi > m.max_mm) {
      m.max_mm = r.hi;
      m.max_line = line_of[at];
      m.max_shape = shape_of[at];
    }
  }
  if (!back) return m;
  // Back: every programmed segment (in pieces of at most 1 mm) against the path's chords.
  SegmentSet chords(0.25);
  for (size_t i = 1; i < path.size(); ++i)
    if (path[i] != path[i - 1]) chords.add(path[i - 1], path[i]);
  FarthestPoint to_path(chords);
  for (size_t i = 0; i < geometry.size(); ++i) {
    const V3 a = geometry.start(static_cast<int>(i)), b = geometry.end(static_cast<int>(i));
    const int n = std::max(1, static_cast<int>(std::ceil(norm(sub(b, a)))));
    for (int k = 0; k < n; ++k) {
      const Range r = to_path.of(lerp(a, b, static_cast<double>(k) / n), lerp(a, b, static_cast<double>(k + 1) / n));
      m.back_mm = std::max(m.back_mm, r.hi);
    }
  }
  return m;
}

// G61: how each programmed vertex (a motion block's end) is met by a path.
struct Vertices {
  int64_t total = 0;
  int64_t not_on_a_point = 0;  // no setpoint (fine command) on it within kExact
  double max_cut_mm = 0;       // largest distance of a vertex from the path
};

Vertices vertices_met(const std::vector<V3>& path, const std::vector<V3>& vertices) {
  Vertices v;
  SegmentSet chords(0.25);
  for (size_t i = 1; i < path.size(); ++i)
    if (path[i] != path[i - 1]) chords.add(path[i - 1], path[i]);
  std::vector<int> ids;
  for (const V3& x : vertices) {
    ++v.total;
    chords.near(x, x, 0.5, &ids);
    if (ids.empty()) chords.all(&ids);
    double on = 1e300, cut = 1e300;
    for (int k : ids) {
      on = std::min({on, norm(sub(chords.start(k), x)), norm(sub(chords.end(k), x))});
      cut = std::min(cut, chords.dist(k, x));
    }
    if (on > kExact) ++v.not_on_a_point;
    v.max_cut_mm = std::max(v.max_cut_mm, cut);
  }
  return v;
}

// Figures summed over the programs of one kind and one mode.
struct Row {
  int programs = 0;
  Measure coarse, fine;
  Vertices vc, vf;
  int worst_seed = 0;
  int fine_worst_seed = 0;
  double end_mm = 0;     // largest distance of the last setpoint or command from the program's end
  double settle_mm = 0;  // largest distance of the command kSettleCycles after the end from it
  void add(const Measure& c, const Measure& f, int seed) {
    ++programs;
    for (auto [sum, m] : {std::pair{&coarse, &c}, std::pair{&fine, &f}}) {
      sum->points += m->points;
      sum->points_over += m->points_over;
      sum->chords_over += m->chords_over;
      for (size_t k = 0; k < kShapes; ++k) sum->chords_over_by_shape[k] += m->chords_over_by_shape[k];
      sum->back_mm = std::max(sum->back_mm, m->back_mm);
    }
    if (c.max_mm > coarse.max_mm) {
      coarse.max_mm = c.max_mm;
      coarse.max_line = c.max_line;
      coarse.max_shape = c.max_shape;
      worst_seed = seed;
    }
    if (f.max_mm > fine.max_mm) {
      fine.max_mm = f.max_mm;
      fine.max_line = f.max_line;
      fine_worst_seed = seed;
    }
  }
};

// The largest distance of the coarse path from the geometry on the default programs,
// in units of P (G61: of the chord tolerance): P itself everywhere since the fit is
// bounded at every point of its spans and P is shared between the fit or blend and
// the chords (program::shape_tolerance_mm); before, the fits (F) reached 12.0 P on
// short moves and 31.8 P on micro-arcs at P0.001, 1.5-2.5 P at P0.01, the blends
// (B) 1.03 P. Still over: micro-arcs under G61, a chord across a junction passed at
// speed, 1.065 x the chord tolerance. Columns: G61, then kTolerances.
constexpr double kCurrentBound[kKinds][1 + kTolerances.size()] = {
    {1.0, 1.0, 1.0, 1.0, 1.0},  // short-moves (0.96, 0.90, 0.96, 0.97 P; 12.00, 1.53, 1.45, 1.00 before)
    {1.0, 1.0, 1.0, 1.0, 1.0},  // zig-zag (1.57 P at 0.001 before)
    {1.0, 1.0, 1.0, 1.0, 1.0},  // spikes (2.25, 1.01 P before)
    {1.0, 1.0, 1.0, 1.0, 1.0},  // hairpins: every turn a stop, no fit, no blend
    {1.0, 1.0, 1.0, 1.0, 1.0},  // pecks: single G1 moves between G0s
    {1.1, 1.0, 1.0, 1.0, 1.0},  // micro-arcs: 1.065 (G61); 31.83, 2.46, 1.57 P before
    {1.0, 1.0, 1.0, 1.0, 1.0},  // polygons (1.03 P at 0.01 before)
};
// The default programs: what the bounds above were measured on.
constexpr int kDefaultProgramsPerKind = 4;
// How far the bridge's fine commands leave the coarse path on their own: at stops,
// where the two moving averages mix the approach and the departure, and after the
// limiter steered (3.9 um measured, polygons under G61; 4.6 um when a stop rested one cycle).
constexpr double kBridgeDepartureMm = 0.005;
// What the measurement itself may add (the header): kEps + 2 kSagitta.
constexpr double kSlackMm = kEps + 2 * kSagitta;
// The bridge's command 100 ms after the setpoints stand: 0.125 um from the end measured.
constexpr double kSettleBoundMm = 2e-4;
// G61: the largest distance of a programmed vertex from the coarse path (0.88 um
// measured: corners the corner rule passes at speed, G61 being no exact stop here).
constexpr double kG61VertexBoundMm = 0.001;

int programs_per_kind() {
  const char* env = std::getenv("CNC_GTOL_PROGRAMS");
  return env != nullptr && std::atoi(env) > 0 ? std::atoi(env) : kDefaultProgramsPerKind;
}

// The measurement against dense sampling: random zig-zag polylines (segments of
// 0.01-0.5 mm, turns of up to 180 degrees) and random chords near them; the bound
// must lie above every sample and within kEps + the sampling's own error (half its
// spacing, the distance being 1-Lipschitz) of the largest.
TEST(PathTolerance, TheLargestDistanceIsBoundedWithinEpsOfDenseSampling) {
  std::mt19937_64 rng(31);
  auto uni = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  double worst_gap = 0;
  for (int trial = 0; trial < 200; ++trial) {
    SegmentSet set(0.25);
    std::vector<V3> pts{{uni(0, 1), uni(0, 1), uni(0, 0.1)}};
    for (int k = 0; k < 20; ++k) {
      const double l = uni(0.01, 0.5), th = uni(0, 2 * std::numbers::pi);
      const V3& b = pts.back();
      pts.push_back({b[0] + l * std::cos(th), b[1] + l * std::sin(th), b[2] + uni(-0.02, 0.02)});
      set.add(pts[pts.size() - 2], pts.back());
    }
    const size_t at = static_cast<size_t>(uni(0, 19.99));
    const V3 p = lerp(pts[at], pts[at + 1], uni(0, 1)), dir{uni(-1, 1), uni(-1, 1), uni(-0.1, 0.1)};
    const double len = uni(0.001, 0.6);
    const V3 q{p[0] + len * dir[0], p[1] + len * dir[1], p[2] + len * dir[2]};
    FarthestPoint fp(set);
    const Range r = fp.of(p, q);
    constexpr int kSamples = 20000;
    double dense = 0;
    std::vector<int> all;
    set.all(&all);
    for (int k = 0; k <= kSamples; ++k) {
      const V3 x = lerp(p, q, static_cast<double>(k) / kSamples);
      double d = 1e300;
      for (int i : all) d = std::min(d, set.dist(i, x));
      dense = std::max(dense, d);
    }
    const double spacing = norm(sub(q, p)) / kSamples;
    EXPECT_GE(r.hi, dense - 1e-12) << trial;
    EXPECT_LE(r.hi, dense + kEps + 0.5 * spacing + 1e-12) << trial;
    EXPECT_LE(r.lo, r.hi) << trial;
    worst_gap = std::max(worst_gap, r.hi - dense);
  }
  std::printf("largest bound above dense sampling: %.3g mm\n", worst_gap);
}

// The largest distance of the commanded path from the programmed geometry, under
// G64 P (bounds of this commit: see below) and under G61.
TEST(PathTolerance, G64PAtEveryPointOfRandomCamPrograms) {
  const config::MachineConfig cfg = sim3();
  const int per_kind = programs_per_kind();
  const int ticks = static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s));
  // rows[kind][0]: G61; rows[kind][1 + t]: G64 P kTolerances[t].
  std::array<std::array<Row, 1 + kTolerances.size()>, kKinds> rows{};
  for (int kind = 0; kind < kKinds; ++kind) {
    for (int seed = 1; seed <= per_kind; ++seed) {
      const CamProgram prog(static_cast<Kind>(kind), static_cast<uint64_t>(seed));
      const Playback ref = play(cfg, prog.text("G61"));
      ASSERT_EQ(ref.error, "") << kKindNames[kind] << " seed " << seed << "\n" << prog.text("G61");
      std::vector<V3> vertices;
      const SegmentSet geometry = geometry_of(ref.blocks, &vertices);
      ASSERT_FALSE(vertices.empty());
      const V3 end = vertices.back();
      for (size_t mode = 0; mode <= kTolerances.size(); ++mode) {
        const double p = mode == 0 ? cfg.chord_tolerance_mm : kTolerances[mode - 1];
        char mode_text[32];
        std::snprintf(mode_text, sizeof mode_text, mode == 0 ? "G61" : "G64 P%g", p);
        const Playback r = mode == 0 ? ref : play(cfg, prog.text(mode_text));
        if (const char* dir = std::getenv("CNC_GTOL_WRITE")) {
          const std::string name = std::string(dir) + "/" + kKindNames[kind] + "-" + std::to_string(seed) + "-" +
                                   (mode == 0 ? std::string("G61") : "P" + std::to_string(kTolerances[mode - 1])) +
                                   ".ngc";
          std::FILE* f = std::fopen(name.c_str(), "w");
          ASSERT_NE(f, nullptr) << name;
          std::fputs(prog.text(mode_text).c_str(), f);
          std::fclose(f);
        }
        ASSERT_EQ(r.error, "") << kKindNames[kind] << " seed " << seed << " " << mode_text;
        EXPECT_EQ(r.bridge_fault, "") << kKindNames[kind] << " seed " << seed << " " << mode_text;
        std::vector<int> fine_line(r.fine.size() + 1), fine_shape(r.fine.size() + 1);
        for (size_t j = 0; j < fine_line.size(); ++j) {
          const size_t k = std::min(r.line.size() - 1, j / static_cast<size_t>(ticks) + 2);
          fine_line[j] = r.line[k];
          fine_shape[j] = r.shape[k];
        }
        std::vector<V3> fine{r.coarse.front()};
        fine.insert(fine.end(), r.fine.begin(), r.fine.end());
        const Measure c = measure(r.coarse, r.line, r.shape, geometry, p, true);
        const Measure f = measure(fine, fine_line, fine_shape, geometry, p, false);
        Row& row = rows[static_cast<size_t>(kind)][mode];
        row.add(c, f, seed);
        row.end_mm = std::max({row.end_mm, norm(sub(r.coarse.back(), end)), norm(sub(fine.back(), end))});
        row.settle_mm = std::max(row.settle_mm, norm(sub(r.fine_settle, end)));
        if (mode == 0) {
          for (auto [sum, v] : {std::pair{&row.vc, vertices_met(r.coarse, vertices)},
                                std::pair{&row.vf, vertices_met(fine, vertices)}}) {
            sum->total += v.total;
            sum->not_on_a_point += v.not_on_a_point;
            sum->max_cut_mm = std::max(sum->max_cut_mm, v.max_cut_mm);
          }
        }
      }
    }
  }

  // The table. "over": setpoints (commands) and chords farther than P from the
  // geometry (G61: than the chord tolerance); "max": the largest distance of the
  // path from the geometry, "back": of the geometry from the path, mm and /P;
  // "worst": where the coarse maximum is (seed:line, the shape of its block: L line,
  // R rapid, A arc, F fitted cubic, B corner blend); "by shape": the coarse chords
  // over P by the shape of their end's block.
  std::printf("\nG64 P at every point: %d programs per kind, sim3, coarse 4 ms setpoints and fine 1 ms commands\n",
              per_kind);
  std::printf("%-11s %-9s %8s %6s %6s %10s %7s %8s %6s %6s %10s %7s %10s %7s  %-8s %s\n", "kind", "mode", "setpts",
              "over", "chords", "max mm", "/P", "fine", "over", "chords", "max mm", "/P", "back mm", "/P",
              "worst", "by shape");
  for (int kind = 0; kind < kKinds; ++kind)
    for (size_t mode = 0; mode <= kTolerances.size(); ++mode) {
      const Row& w = rows[static_cast<size_t>(kind)][mode];
      const double p = mode == 0 ? cfg.chord_tolerance_mm : kTolerances[mode - 1];
      char m[32];
      std::snprintf(m, sizeof m, mode == 0 ? "G61" : "P%g", p);
      std::string by_shape;
      for (size_t k = 0; k < kShapes; ++k)
        if (w.coarse.chords_over_by_shape[k] > 0)
          by_shape += std::string(1, kShapeLetters[k]) + ":" + std::to_string(w.coarse.chords_over_by_shape[k]) + " ";
      std::printf("%-11s %-9s %8lld %6lld %6lld %10.6f %7.2f %8lld %6lld %6lld %10.6f %7.2f %10.6f %7.2f  "
                  "%d:%d%c  %-24s fine %d:%d\n",
                  kKindNames[kind], m, static_cast<long long>(w.coarse.points),
                  static_cast<long long>(w.coarse.points_over), static_cast<long long>(w.coarse.chords_over),
                  w.coarse.max_mm, w.coarse.max_mm / p, static_cast<long long>(w.fine.points),
                  static_cast<long long>(w.fine.points_over), static_cast<long long>(w.fine.chords_over),
                  w.fine.max_mm, w.fine.max_mm / p, w.coarse.back_mm, w.coarse.back_mm / p, w.worst_seed,
                  w.coarse.max_line, kShapeLetters[w.coarse.max_shape], by_shape.c_str(), w.fine_worst_seed,
                  w.fine.max_line);
      // The same figures in the test's XML report (--gtest_output=xml).
      char figures[160];
      std::snprintf(figures, sizeof figures, "setpoints %lld over %lld chords over %lld max %.6f mm %.2f P fine %.6f",
                    static_cast<long long>(w.coarse.points), static_cast<long long>(w.coarse.points_over),
                    static_cast<long long>(w.coarse.chords_over), w.coarse.max_mm, w.coarse.max_mm / p,
                    w.fine.max_mm);
      RecordProperty(std::string(kKindNames[kind]) + "_" + m, figures);
    }
  std::printf("\nG61, the programmed vertices (motion block ends): how many no setpoint / no fine command lies "
              "on (within %g mm), the largest distance of a vertex from the coarse / fine path; the end point: "
              "largest error of the last setpoint and of the command %g s after the stream stands (every mode), "
              "and of the command %d ms after it\n",
              kExact, kTailCycles * cfg.ipo_period_s, static_cast<int>(kSettleCycles * cfg.ipo_period_s * 1e3));
  for (int kind = 0; kind < kKinds; ++kind) {
    const Row& w = rows[static_cast<size_t>(kind)][0];
    double end_mm = 0, settle_mm = 0;
    for (const Row& m : rows[static_cast<size_t>(kind)]) {
      end_mm = std::max(end_mm, m.end_mm);
      settle_mm = std::max(settle_mm, m.settle_mm);
    }
    std::printf("%-11s %6lld vertices, not on a point %6lld / %6lld, from the path %.6f / %.6f mm, end %.3g mm, "
                "%.3g mm\n",
                kKindNames[kind], static_cast<long long>(w.vc.total), static_cast<long long>(w.vc.not_on_a_point),
                static_cast<long long>(w.vf.not_on_a_point), w.vc.max_cut_mm, w.vf.max_cut_mm, end_mm, settle_mm);
  }
  const bool default_programs = per_kind == kDefaultProgramsPerKind;
  for (int kind = 0; kind < kKinds; ++kind) {
    const Row& g61 = rows[static_cast<size_t>(kind)][0];
    if (default_programs) {
      EXPECT_LE(g61.vc.max_cut_mm, kG61VertexBoundMm) << kKindNames[kind];
    }
    for (size_t mode = 0; mode <= kTolerances.size(); ++mode) {
      const Row& w = rows[static_cast<size_t>(kind)][mode];
      const double p = mode == 0 ? cfg.chord_tolerance_mm : kTolerances[mode - 1];
      const double bound = kCurrentBound[kind][mode] * p;
      const std::string what = std::string(kKindNames[kind]) + (mode == 0 ? " G61" : " P" + std::to_string(p));
      EXPECT_EQ(w.programs, per_kind) << what;
      EXPECT_LE(w.end_mm, kExact) << what;
      if (!default_programs) continue;
      EXPECT_LE(w.settle_mm, kSettleBoundMm) << what;
      EXPECT_LE(w.coarse.max_mm, bound + kSlackMm) << what;
      EXPECT_LE(w.fine.max_mm, bound + kBridgeDepartureMm + kSlackMm) << what;
      // Back: a corner is cut by P less the chords' share by design, the chords inside a curve by their share.
      EXPECT_LE(w.coarse.back_mm, bound + kSlackMm) << what;
    }
  }
}

}  // namespace
}  // namespace cnc::gtol
