// Stops always stop: feed hold, override 0, override 150 % then 0, and stop, on
// every kind of motion (rapid, line, arc, helix, NURBS), commanded while the path
// accelerates, cruises and decelerates. Each case must come to rest within the
// distance of the time-optimal jerk-limited stop from the speed and acceleration at
// the moment of the command (computed here, independently of the core) + 1 %, stay
// on the path within the chord tolerance, publish only finite numbers, keep the
// path's jerk and acceleration limits, and (hold, override 0) resume to the end of
// the block on the path.
//
// Run the executable alone to get the whole table of figures at the end.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/chord_error.h"
#include "common/motion/interpolator.h"
#include "common/motion/path_segment.h"
#include "common/program/block.h"

namespace cnc::interp {
namespace {

using program::Block;
using program::BlockKind;

const config::MachineConfig& sim3() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return cfg;
}
int naxes() { return static_cast<int>(sim3().axes.size()); }

// ---- the bound --------------------------------------------------------------------

// One phase of constant jerk, integrated exactly.
struct Motion {
  double s = 0, v = 0, a = 0;
  void run(double j, double t) {
    s += v * t + a * t * t / 2 + j * t * t * t / 6;
    v += a * t + j * t * t / 2;
    a += j * t;
  }
};

// Distance of the time-optimal stop from path speed v and acceleration a under
// |acceleration| <= A and |jerk| <= J: jerk -J down to the peak deceleration (A at
// most), hold it, jerk +J back to zero so speed and acceleration reach 0 together.
// When the path already decelerates so hard that releasing the brake at once
// reaches v = 0 first, that release is the stop.
Motion time_optimal_stop(double v, double a, double A, double J) {
  Motion m{0, v, a};
  if (v <= 0 && a <= 0) return m;
  if (a < 0 && v <= a * a / (2 * J)) {
    m.run(J, (-a - std::sqrt(std::max(0.0, a * a - 2 * J * v))) / J);
    return m;
  }
  double peak = std::sqrt(J * v + a * a / 2), t_hold = 0;
  if (peak > A) {
    peak = A;
    t_hold = (v + a * a / (2 * J) - A * A / J) / A;
  }
  m.run(-J, (a + peak) / J);
  m.run(0, t_hold);
  m.run(J, peak / J);
  return m;
}
double stop_bound(double v, double a, double A, double J) { return time_optimal_stop(v, a, A, J).s; }

TEST(StopBound, MatchesTheClosedFormsAndEndsAtRest) {
  const double A = 1500, J = 30000;
  // From cruise (a = 0): without reaching A, s = v·sqrt(v/J); reaching it, s = v/2·(v/A + A/J).
  const double v1 = 50;  // J·v = 1.5e6 < A² = 2.25e6
  EXPECT_NEAR(stop_bound(v1, 0, A, J), v1 * std::sqrt(v1 / J), 1e-12);
  const double v2 = 200;
  EXPECT_NEAR(stop_bound(v2, 0, A, J), v2 / 2 * (v2 / A + A / J), 1e-12);
  // Any state: the profile ends at rest, and a fine forward simulation of the same
  // jerk sequence (explicit, 1 µs steps) travels the same distance.
  std::mt19937 rng(42);  // fixed seed
  std::uniform_real_distribution<double> vd(1, 300), ad(-A, A);
  for (int i = 0; i < 200; ++i) {
    const double v = vd(rng), a = ad(rng);
    const Motion m = time_optimal_stop(v, a, A, J);
    ASSERT_NEAR(m.v, 0, 1e-9) << v << " " << a;
    if (!(a < 0 && v <= a * a / (2 * J))) {
      ASSERT_NEAR(m.a, 0, 1e-9) << v << " " << a;
    }
    // Brute force: jerk -J until the brake from here with +J lands (v reaches 0 as a
    // reaches 0), deceleration capped at A.
    double s = 0, vv = v, aa = a;
    const double dt = 1e-6;
    bool releasing = a < 0 && v <= a * a / (2 * J);
    for (int k = 0; k < 10'000'000 && vv > 0 && !(releasing && aa >= 0); ++k) {
      if (!releasing && aa < 0 && vv <= aa * aa / (2 * J)) releasing = true;
      const double j = releasing ? J : (aa <= -A ? 0.0 : -J);
      const double an = std::max(-A, aa + j * dt);
      s += vv * dt + 0.5 * (an - aa) * dt * dt / 3 + aa * dt * dt / 2;
      vv += 0.5 * (aa + an) * dt;
      aa = an;
    }
    EXPECT_NEAR(s, m.s, 2e-4 * m.s + 1e-6) << "v " << v << " a " << a;
  }
}

// ---- programs -----------------------------------------------------------------------

Block end_block(int64_t index, const std::vector<double>& at) {
  Block b;
  b.index = index;
  b.source_line = static_cast<int32_t>(index + 1);
  b.kind = BlockKind::kEnd;
  b.start = b.end = at;
  return b;
}

Block motion_block(BlockKind kind, std::vector<double> end, double feed_mm_per_min) {
  Block b;
  b.index = 0;
  b.source_line = 1;
  b.kind = kind;
  b.start = {0, 0, 0};
  b.end = std::move(end);
  b.feed_mm_per_min = feed_mm_per_min;
  return b;
}

// One long block of each kind from home (0, 0, 0), then the end.
std::vector<Block> program_of(const std::string& kind) {
  Block b;
  if (kind == "rapid") {
    b = motion_block(BlockKind::kRapid, {380, 60, -80}, 0);
  } else if (kind == "line") {
    b = motion_block(BlockKind::kLine, {380, 40, -30}, 9000);
  } else if (kind == "arc") {  // two full circles, R 60, clockwise in XY
    b = motion_block(BlockKind::kArcCw, {0, 0, 0}, 6000);
    b.arc.center = {60, 0, 0};
    b.arc.plane = 17;
    b.arc.turns = 1;
  } else if (kind == "helix") {  // two turns of R 40 in XY while Z falls 30 mm
    b = motion_block(BlockKind::kArcCcw, {0, 0, -30}, 6000);
    b.arc.center = {40, 0, 0};
    b.arc.plane = 17;
    b.arc.turns = 1;
  } else if (kind == "nurbs") {  // a cubic wave along X, falling in Z
    b = motion_block(BlockKind::kNurbs, {300, 0, -20}, 6000);
    b.nurbs.order = 4;
    b.nurbs.control_points = {{0, 0, 0},     {50, 15, -4},   {100, -15, -8}, {150, 15, -12},
                              {200, -15, -16}, {250, 15, -20}, {300, 0, -20}};
    b.nurbs.weights.assign(7, 1.0);
    b.nurbs.knots = {0, 0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1, 1};
  }
  return {b, end_block(1, b.end)};
}

// The path's tangential limits over a block, from the machine config: the path's
// own acceleration and jerk, and each axis's limit over the largest share of the
// tangent it carries, from a dense sampling of the block. Every test program is one
// block between two stops, so no junction is crossed at speed and the planner may
// give it all of each axis's limits (a curved block less: what its curvature leaves).
struct PathLimits {
  double A = 0, J = 0;
};
PathLimits axis_bounded_limits(const Block& b) {
  const config::MachineConfig& cfg = sim3();
  const motion::PathSegment path(b, naxes());
  std::array<double, program::kMaxAxes> tmax{};
  const int n = 4096;
  for (int i = 0; i <= n; ++i) {
    const double u = path.u_begin() + (path.u_end() - path.u_begin()) * i / n;
    motion::AxisVec p{}, d1{}, d2{};
    path.eval(u, &p, &d1, &d2);
    double sp = 0;
    for (int a = 0; a < naxes(); ++a) sp += d1[a] * d1[a];
    sp = std::sqrt(sp);
    for (int a = 0; a < naxes(); ++a) tmax[a] = std::max(tmax[a], std::fabs(d1[a]) / sp);
  }
  PathLimits l{cfg.path_accel_mm_s2, cfg.path_jerk_mm_s3};
  for (int a = 0; a < naxes(); ++a) {
    if (tmax[a] <= 0) continue;
    l.A = std::min(l.A, cfg.axes[a].max_accel_mm_s2 / tmax[a]);
    l.J = std::min(l.J, cfg.axes[a].max_jerk_mm_s3 / tmax[a]);
  }
  return l;
}

// The tangential limits the planner gives the program's first block (its free limits
// once the block after it shows that both of its ends are stops), checked against
// the axes' bound above. The stop bounds and the path's checks use these; every
// axis's own limits are checked apart from them.
PathLimits path_limits(const std::vector<Block>& blocks) {
  Planner planner(sim3());
  PathLimits l;
  for (size_t i = 0; i < blocks.size(); ++i) {
    PlanRequest r;
    r.kind = PlanRequest::Kind::kBlock;
    r.serial = i;
    r.block = new Block(blocks[i]);  // the planner's from here on
    PlanUpdate* u = planner.process(r);
    EXPECT_TRUE(u->error.empty()) << u->error;
    if (i == 0 && u->block != nullptr) l = {u->block->accel, u->block->jerk};
    for (const PlanUpdate::Limits& x : u->limits)
      if (x.serial == 0) l = {x.accel, x.jerk};
    planner.recycle(u);
  }
  const PathLimits bound = axis_bounded_limits(blocks[0]);
  EXPECT_LE(l.A, bound.A * (1 + 1e-9));
  EXPECT_LE(l.J, bound.J * (1 + 1e-9));
  EXPECT_GT(l.A, 0);
  EXPECT_GT(l.J, 0);
  return l;
}

// ---- running ------------------------------------------------------------------------

double step_length(const Setpoint& a, const Setpoint& b) {
  double d2 = 0;
  for (int i = 0; i < naxes(); ++i) d2 += (b.position_mm[i] - a.position_mm[i]) * (b.position_mm[i] - a.position_mm[i]);
  return std::sqrt(d2);
}

struct Run {
  Interpolator ip{sim3()};
  std::vector<Setpoint> sps;  // sps[0]: at rest at home before the first cycle
  explicit Run(const std::vector<Block>& blocks) {
    ip.apply_command({Command::Kind::kStart, 1.0});
    for (const Block& b : blocks) EXPECT_TRUE(ip.apply_block(b)) << ip.last_refusal();
    Setpoint s0 = ip.last();
    s0.num_axes = naxes();
    s0.block_index = 0;
    s0.u = 0;
    sps.push_back(s0);
  }
  void step() { sps.push_back(ip.step()); }
  // Path speed at the end of cycle k: the mean over the step plus half a cycle of
  // the (constant) acceleration published for it.
  double v_end(size_t k) const {
    return step_length(sps[k - 1], sps[k]) / sim3().ipo_period_s + 0.5 * sps[k].path_accel_mm_s2 * sim3().ipo_period_s;
  }
};

// Rapid override (README "Rapid override"): a G0's top speed scales by it (and by the
// feed override up to 1); a feed move's does not.
double top_speed(const std::vector<Block>& blocks, double feed, double rapid) {
  Run r(blocks);
  if (feed != 1.0) r.ip.apply_command({Command::Kind::kOverride, feed});
  if (rapid != 1.0) r.ip.apply_command({Command::Kind::kRapidOverride, rapid});
  for (int i = 0; i < 400'000 && r.ip.state() != RunState::kDone; ++i) r.step();
  EXPECT_EQ(r.ip.state(), RunState::kDone);
  double v = 0;
  for (size_t k = 1; k < r.sps.size(); ++k) v = std::max(v, r.v_end(k));
  return v;
}

TEST(InterpolatorStop, RapidOverrideScalesRapidsOnly) {
  const std::vector<Block> rapid = program_of("rapid"), line = program_of("line");
  const double v_rapid = top_speed(rapid, 1.0, 1.0);
  const double v_half = top_speed(rapid, 1.0, 0.5);
  const double v_both = top_speed(rapid, 0.5, 0.5);
  const double v_line = top_speed(line, 1.0, 1.0), v_line_r = top_speed(line, 1.0, 0.25);
  std::printf("rapid override: G0 top %.2f mm/s, at 50 %% %.2f, with feed 50 %% too %.2f; G1 %.2f, at rapid 25 %% %.2f\n",
              v_rapid, v_half, v_both, v_line, v_line_r);
  EXPECT_NEAR(v_half / v_rapid, 0.5, 0.01);
  EXPECT_NEAR(v_both / v_rapid, 0.25, 0.01);
  EXPECT_NEAR(v_line_r, v_line, 1e-9);
}

enum class Phase { kAccelerating, kCruising, kDecelerating };
enum class Order { kHold, kOverride0, kOverride150Then0, kStop };
const char* name(Phase p) {
  switch (p) {
    case Phase::kAccelerating: return "accelerating";
    case Phase::kCruising: return "cruising";
    case Phase::kDecelerating: return "decelerating";
  }
  return "?";
}
const char* name(Order o) {
  switch (o) {
    case Order::kHold: return "hold";
    case Order::kOverride0: return "override 0";
    case Order::kOverride150Then0: return "override 150%->0";
    case Order::kStop: return "stop";
  }
  return "?";
}

// The cycles at which the phases are taken, from an undisturbed run of the program:
// accelerating: the first cycle at half the cruise speed with at least 30 % of A;
// cruising: 10 cycles into the first stretch of 10 cycles at constant top speed;
// decelerating: override 1 -> 0.4 at that cruising cycle, then the first cycle
// braking at 50 % of A or more (from 100 mm/s, a jerk-limited brake shedding 60 mm/s
// peaks at sqrt(60·J), 64 % of the free limits a NURBS gets; discrete cycles less).
struct Schedule {
  size_t accelerating = 0, cruising = 0, override_drop = 0, decelerating = 0;
};

Schedule schedule_of(const std::vector<Block>& blocks, const PathLimits& lim) {
  Schedule sc;
  Run r(blocks);
  for (int i = 0; i < 200'000 && r.ip.state() != RunState::kDone; ++i) r.step();
  double v_top = 0;
  for (size_t k = 1; k < r.sps.size(); ++k) v_top = std::max(v_top, r.v_end(k));
  for (size_t k = 1; k < r.sps.size() && sc.accelerating == 0; ++k)
    if (r.v_end(k) >= 0.5 * v_top && r.sps[k].path_accel_mm_s2 >= 0.3 * lim.A) sc.accelerating = k;
  int steady = 0;
  for (size_t k = 1; k < r.sps.size() && sc.cruising == 0; ++k) {
    steady = (std::fabs(r.sps[k].path_accel_mm_s2) < 1e-9 && r.v_end(k) >= 0.99 * v_top) ? steady + 1 : 0;
    if (steady == 10) sc.cruising = k + 10;
  }
  EXPECT_GT(sc.accelerating, 0u) << "no accelerating phase";
  EXPECT_GT(sc.cruising, 0u) << "no cruise";
  sc.override_drop = sc.cruising;
  Run d(blocks);
  for (size_t k = 1; k <= sc.override_drop; ++k) d.step();
  d.ip.apply_command({Command::Kind::kOverride, 0.4});
  for (int i = 0; i < 2000 && sc.decelerating == 0; ++i) {
    d.step();
    if (d.sps.back().path_accel_mm_s2 <= -0.5 * lim.A) sc.decelerating = d.sps.size() - 1;
  }
  EXPECT_GT(sc.decelerating, 0u) << "no deceleration after the override drop";
  return sc;
}

struct Row {
  std::string kind, order, phase;
  double v = 0, a = 0, A = 0, J = 0, dist = 0, bound = 0, dev_stop = 0, dev_resume = 0;
  int rest_cycles = 0;
  double ratio() const { return bound > 0 ? dist / bound : 0; }
};
std::vector<Row>& table() {
  static std::vector<Row> rows;
  return rows;
}

void print_row(const Row& r) {
  std::printf("  %-6s %-17s %-13s v %7.2f mm/s a %8.1f mm/s2 | stop %8.4f mm bound %8.4f mm ratio %.4f | "
              "dev stop %.2e resume %.2e mm | %3d cycles\n",
              r.kind.c_str(), r.order.c_str(), r.phase.c_str(), r.v, r.a, r.dist, r.bound, r.ratio(), r.dev_stop,
              r.dev_resume, r.rest_cycles);
}

// Largest distance of the steps k0+1..k1 from the exact path (the block's geometry
// at the published parameter, and the chord of each step against the curve).
double deviation(const motion::PathSegment& path, const std::vector<Setpoint>& sps, size_t k0, size_t k1) {
  double worst = 0;
  for (size_t k = k0 + 1; k <= k1 && k < sps.size(); ++k) {
    const Setpoint& a = sps[k - 1];
    const Setpoint& b = sps[k];
    if (b.block_index != 0 || a.block_index != 0) continue;  // only the motion block moves
    const motion::AxisVec on = path.point(b.u);
    double d2 = 0;
    for (int i = 0; i < naxes(); ++i) d2 += (on[i] - b.position_mm[i]) * (on[i] - b.position_mm[i]);
    worst = std::max(worst, std::sqrt(d2));
    if (b.u > a.u) worst = std::max(worst, motion::chord_error(path, a.u, b.u, a.position_mm, b.position_mm));
  }
  return worst;
}

void run_case(const std::string& kind, Order order, Phase phase) {
  SCOPED_TRACE(kind + " / " + name(order) + " / " + name(phase));
  const config::MachineConfig& cfg = sim3();
  const double T = cfg.ipo_period_s, tol = cfg.chord_tolerance_mm;
  const std::vector<Block> blocks = program_of(kind);
  const motion::PathSegment path(blocks[0], naxes());
  const PathLimits lim = path_limits(blocks);
  const Schedule sc = schedule_of(blocks, lim);

  Run r(blocks);
  const size_t at = phase == Phase::kAccelerating ? sc.accelerating
                    : phase == Phase::kCruising   ? sc.cruising
                                                  : sc.decelerating;
  ASSERT_GT(at, 0u);
  while (r.sps.size() <= at) {
    if (phase == Phase::kDecelerating && r.sps.size() - 1 == sc.override_drop)
      r.ip.apply_command({Command::Kind::kOverride, 0.4});
    r.step();
  }
  // The command (for 150 % -> 0: the 0, 12 cycles after the 150 %).
  size_t k0 = at;
  switch (order) {
    case Order::kHold: r.ip.apply_command({Command::Kind::kHold, 1.0}); break;
    case Order::kOverride0: r.ip.apply_command({Command::Kind::kOverride, 0.0}); break;
    case Order::kStop: r.ip.apply_command({Command::Kind::kStop, 1.0}); break;
    case Order::kOverride150Then0:
      r.ip.apply_command({Command::Kind::kOverride, 1.5});
      for (int i = 0; i < 12; ++i) r.step();
      k0 = r.sps.size() - 1;
      r.ip.apply_command({Command::Kind::kOverride, 0.0});
      break;
  }
  Row row{kind, name(order), name(phase)};
  row.v = r.v_end(k0);
  row.a = r.sps[k0].path_accel_mm_s2;
  row.A = lim.A;
  row.J = lim.J;
  ASSERT_GT(row.v, 1.0) << "moving at the command";
  // The published feed is the step's mean speed.
  EXPECT_NEAR(r.sps[k0].feed_mm_per_min / 60.0, step_length(r.sps[k0 - 1], r.sps[k0]) / T, 1e-6 * row.v);
  row.bound = stop_bound(row.v, row.a, lim.A, lim.J);

  // To rest: no step for 50 cycles in a row.
  size_t rest = 0;
  for (int i = 0; i < 5000 && rest == 0; ++i) {
    r.step();
    const size_t k = r.sps.size() - 1;
    if (step_length(r.sps[k - 1], r.sps[k]) == 0 && r.sps[k].path_accel_mm_s2 == 0) {
      bool still = true;
      for (int q = 0; q < 50 && still; ++q) {
        r.step();
        still = step_length(r.sps[r.sps.size() - 2], r.sps.back()) == 0;
      }
      ASSERT_TRUE(still) << "moved again without a resume";
      rest = k;
    }
  }
  ASSERT_GT(rest, 0u) << "never came to rest";
  row.rest_cycles = static_cast<int>(rest - k0);
  for (size_t k = k0 + 1; k <= rest; ++k) row.dist += step_length(r.sps[k - 1], r.sps[k]);
  row.dev_stop = deviation(path, r.sps, k0, rest);
  if (order == Order::kHold) {
    EXPECT_EQ(r.sps.back().state, RunState::kHeld);
  }
  if (order == Order::kStop) {
    EXPECT_EQ(r.sps.back().state, RunState::kIdle);
  }
  EXPECT_LE(row.dist, row.bound * 1.01) << "stop distance over the jerk-limited bound";
  EXPECT_LE(row.dev_stop, tol) << "left the path while stopping";

  // Resume (hold, override 0) to the end of the block, on the path.
  const size_t resumed = r.sps.size() - 1;
  if (order != Order::kStop) {
    if (order == Order::kHold) r.ip.apply_command({Command::Kind::kResume, 1.0});
    else r.ip.apply_command({Command::Kind::kOverride, 1.0});
    for (int i = 0; i < 200'000 && r.ip.state() != RunState::kDone; ++i) r.step();
    EXPECT_EQ(r.ip.state(), RunState::kDone) << "the resumed motion did not finish";
    for (int a = 0; a < naxes(); ++a)
      EXPECT_NEAR(r.sps.back().position_mm[a], blocks[0].end[static_cast<size_t>(a)], 1e-9) << "axis " << a;
    row.dev_resume = deviation(path, r.sps, resumed, r.sps.size() - 1);
    EXPECT_LE(row.dev_resume, tol) << "left the path after the resume";
  }

  // Every published field finite; the path parameter never goes back; along the
  // path, the acceleration and jerk from finite differences of the step lengths
  // within the path's limits (1 %) over the whole run, stop, override changes and
  // resume included, up to the look-ahead's final approach onto the end point (the
  // last 2 × the stop distance from the top speed; there each axis's own limits).
  double top = 0;
  for (size_t k = 1; k < r.sps.size(); ++k) top = std::max(top, step_length(r.sps[k - 1], r.sps[k]) / T);
  const double approach = 2.0 * stop_bound(top, 0, lim.A, lim.J);
  const motion::AxisVec end_pt = path.end();
  auto near_end = [&](const Setpoint& s) {
    if (order == Order::kStop) return false;
    double d2 = 0;
    for (int a = 0; a < naxes(); ++a) d2 += (s.position_mm[a] - end_pt[a]) * (s.position_mm[a] - end_pt[a]);
    return s.block_index != 0 || (s.u > 0.5 * (path.u_begin() + path.u_end()) && std::sqrt(d2) < approach);
  };
  int bad = 0;
  for (size_t k = 1; k < r.sps.size(); ++k) {
    const Setpoint& s = r.sps[k];
    bool finite = std::isfinite(s.feed_mm_per_min) && std::isfinite(s.path_accel_mm_s2) && std::isfinite(s.u);
    for (int a = 0; a < s.num_axes; ++a) finite = finite && std::isfinite(s.position_mm[a]);
    if (!finite && ++bad <= 3) ADD_FAILURE() << "cycle " << s.cycle << ": a published field is not finite";
    if (s.block_index == r.sps[k - 1].block_index && s.u < r.sps[k - 1].u && ++bad <= 3)
      ADD_FAILURE() << "cycle " << s.cycle << ": went back along the path";
  }
  std::vector<double> v(r.sps.size() + 1, 0.0);  // v[k]: mean speed of step k; at rest after the last
  for (size_t k = 1; k < r.sps.size(); ++k) v[k] = step_length(r.sps[k - 1], r.sps[k]) / T;
  for (size_t k = 2; k < v.size(); ++k) {
    if (k >= r.sps.size() || near_end(r.sps[k]) || near_end(r.sps[k - 1])) continue;
    const double acc = (v[k] - v[k - 1]) / T;
    if (std::fabs(acc) > lim.A * 1.01 && ++bad <= 3)
      ADD_FAILURE() << "cycle " << k << ": path acceleration " << acc << " over " << lim.A;
    if (k < 3) continue;
    const double jerk = (v[k] - 2 * v[k - 1] + v[k - 2]) / (T * T);
    if (std::fabs(jerk) > lim.J * 1.01 && ++bad <= 3)
      ADD_FAILURE() << "cycle " << k << ": path jerk " << jerk << " over " << lim.J << " (v " << v[k - 2] << " "
                    << v[k - 1] << " " << v[k] << ")";
  }
  // Each axis's acceleration and jerk within its limits (1 %), over the whole run.
  std::vector<motion::AxisVec> va(r.sps.size() + 2);  // va[k]: axis velocities of step k
  for (size_t k = 1; k < r.sps.size(); ++k)
    for (int a = 0; a < naxes(); ++a) va[k][a] = (r.sps[k].position_mm[a] - r.sps[k - 1].position_mm[a]) / T;
  for (size_t k = 3; k < va.size(); ++k)
    for (int a = 0; a < naxes(); ++a) {
      const double acc = (va[k - 1][a] - va[k - 2][a]) / T;
      const double jerk = (va[k][a] - 2 * va[k - 1][a] + va[k - 2][a]) / (T * T);
      if (std::fabs(acc) > cfg.axes[a].max_accel_mm_s2 * 1.01 && ++bad <= 3)
        ADD_FAILURE() << "cycle " << k << " axis " << a << ": acceleration " << acc;
      if (std::fabs(jerk) > cfg.axes[a].max_jerk_mm_s3 * 1.01 && ++bad <= 3)
        ADD_FAILURE() << "cycle " << k << " axis " << a << ": jerk " << jerk;
    }
  print_row(row);
  table().push_back(row);
}

class StopMatrix : public ::testing::TestWithParam<std::string> {};

TEST_P(StopMatrix, EveryCommandInEveryPhaseStopsWithinTheJerkLimitedBound) {
  for (Order o : {Order::kHold, Order::kOverride0, Order::kOverride150Then0, Order::kStop})
    for (Phase p : {Phase::kAccelerating, Phase::kCruising, Phase::kDecelerating}) run_case(GetParam(), o, p);
}

INSTANTIATE_TEST_SUITE_P(Kinds, StopMatrix, ::testing::Values("rapid", "line", "arc", "helix", "nurbs"),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

// The whole table and the worst figures, when the executable runs all cases.
class Summary : public ::testing::Environment {
 public:
  void TearDown() override {
    const auto& rows = table();
    if (rows.size() < 2) return;
    std::printf("\nstop distance / jerk-limited bound, worst per motion kind and per command "
                "(path deviation vs chord tolerance %.1e mm):\n", sim3().chord_tolerance_mm);
    auto worst = [&](auto key) {
      std::vector<std::string> keys;
      for (const Row& r : rows)
        if (std::find(keys.begin(), keys.end(), key(r)) == keys.end()) keys.push_back(key(r));
      for (const std::string& k : keys) {
        double ratio = 0, dev = 0, dev_r = 0;
        for (const Row& r : rows)
          if (key(r) == k) {
            ratio = std::max(ratio, r.ratio());
            dev = std::max(dev, r.dev_stop);
            dev_r = std::max(dev_r, r.dev_resume);
          }
        std::printf("  %-17s worst ratio %.4f  max deviation stopping %.2e mm, resuming %.2e mm\n", k.c_str(), ratio,
                    dev, dev_r);
      }
    };
    worst([](const Row& r) { return r.kind; });
    worst([](const Row& r) { return r.order; });
    worst([](const Row& r) { return r.phase; });
  }
};
const auto* const kSummary = ::testing::AddGlobalTestEnvironment(new Summary);

}  // namespace
}  // namespace cnc::interp
