// Motion: the axis words' target, G0/G1, arcs, canned cycles (run by cycles.cc),
// G5/G5.1 splines and NURBS curves (G5.2/G5.3, Fanuc G6.2).
#include <optional>

#include "common/rs274/canon_forward.h"
#include "common/rs274/cycles.h"
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

namespace {

// LinuxCNC's arc tolerances (interp_internal.hh), in mm; inch values are these / 25.4
// except where LinuxCNC gives its own.
constexpr double kRadiusToleranceInch = 0.00005;
constexpr double kRadiusToleranceMm = kRadiusToleranceInch * kMmPerInch;
constexpr double kSpiralAbsToleranceInch = 2 * 0.001 * M_SQRT2;
constexpr double kSpiralAbsToleranceMm = 2 * 0.01 * M_SQRT2;
constexpr double kSpiralRelTolerance = 0.001;
constexpr double kArcRToleranceInch = 0.0005;
constexpr double kArcRToleranceMm = 0.005;
constexpr double kTiny = 1e-12;

// A canned cycle made in a tilted work plane's frame: its moves' ends, frame
// coordinates in program units, handed on in work coordinates.
class FramedMoves final : public CanonForward {
 public:
  FramedMoves(Canon& next, std::function<Pose(const Pose&)> to_work) : CanonForward(next), to_work_(std::move(to_work)) {}
  void straight_traverse(const SourceRef& r, const Pose& end) override { CanonForward::straight_traverse(r, to_work_(end)); }
  void straight_feed(const SourceRef& r, const Pose& end) override { CanonForward::straight_feed(r, to_work_(end)); }

 private:
  std::function<Pose(const Pose&)> to_work_;
};


}  // namespace

Pose Interpreter::axis_target(const Words& w, bool machine) const {
  Pose p = position_;
  const double s = length_scale();
  const bool polar = w.on('@') || w.on('^');
  if (polar && twp_ && !machine)
    fail(w.on('@') ? w.column('@') : w.column('^'), "polar coordinates (@ ^) in a tilted work plane (G68.2) are not supported");
  if (twp_ && !machine && (w.axes & 7u) != 0) {
    // X Y Z are in the tilted frame; the ones not named stay where the tool is in it.
    Pose f = frame_of(position_);
    for (int i = 0; i < 3; ++i) {
      const char c = kAxisLetters[i];
      if (!w.on(c)) continue;
      f[static_cast<size_t>(i)] = incremental_ ? f[static_cast<size_t>(i)] + w[c] * s : w[c] * s;
    }
    const Pose q = work_of(f);
    for (size_t i = 0; i < 3; ++i) p[i] = q[i];
  }
  if (polar) {
    // LinuxCNC's polar coordinates: @ distance and ^ angle (degrees, from +X) about
    // the XY zero of the current system; under G91 both add to the current ones.
    const int col = w.on('@') ? w.column('@') : w.column('^');
    if (machine) fail(col, "cannot use polar coordinates with G53");
    if (w.on('X') || w.on('Y')) fail(col, "cannot specify X or Y words with polar coordinates");
    const double px = position_[0], py = position_[1];
    double radius = std::hypot(px, py), theta = std::atan2(py, px);
    if (incremental_) {
      if (px == 0 && py == 0) fail(col, "G91 motion with polar coordinates is indeterminate when at the origin");
      if (w.on('@')) radius += w['@'] * s;
      if (w.on('^')) theta += w['^'] * M_PI / 180.0;
    } else {
      if (w.on('@') && !w.on('^') && px == 0 && py == 0)
        fail(col, "must specify the angle (^) in polar coordinates when at the origin");
      if (w.on('@')) radius = w['@'] * s;
      if (w.on('^')) theta = w['^'] * M_PI / 180.0;
    }
    p[0] = radius * std::cos(theta);
    p[1] = radius * std::sin(theta);
  }
  for (int i = 0; i < kNumAxes; ++i) {
    const char c = kAxisLetters[i];
    if (!w.on(c) || (twp_ && !machine && i < 3)) continue;
    const size_t k = static_cast<size_t>(i);
    const double lin = i < 3 || i >= 6 ? s : 1.0;  // A B C are degrees
    const double v = w[c] * lin;
    if (machine) {
      p[k] = v;  // machine coordinates, turned into program ones below
    } else if (incremental_) {
      p[k] += v;
    } else if (wrapped(c)) {
      p[k] = unwrap_rotary(w, c, v, p[k]);
    } else {
      p[k] = v;
    }
  }
  if (machine) {
    // Axes not named keep their machine position.
    Pose m = machine_of(position_, coord_);
    for (int i = 0; i < kNumAxes; ++i)
      if (w.on(kAxisLetters[i])) m[static_cast<size_t>(i)] = p[static_cast<size_t>(i)];
    Pose q = program_of(m, coord_);
    for (int i = 3; i < 6; ++i) {
      const char c = kAxisLetters[i];
      const size_t k = static_cast<size_t>(i);
      if (w.on(c) && wrapped(c)) q[k] = unwrap_rotary(w.column(c), c, q[k], position_[k], w[c]);
    }
    return q;
  }
  return p;
}

bool Interpreter::wrapped(char axis) const {
  return (axis == 'A' || axis == 'B' || axis == 'C') && setup_.wrapped.find(axis) != std::string::npos;
}

// LinuxCNC's wrapped rotary axis (WRAPPED_ROTARY): the word is an angle in (-360, 360),
// reached from where the axis stands (`at`) forwards for a positive word and
// backwards for a negative one (its sign, also of -0); `commanded` is the word in
// program coordinates (G53: with the offsets taken off).
double Interpreter::unwrap_rotary(const Words& w, char axis, double commanded, double at) const {
  return unwrap_rotary(w.column(axis), axis, commanded, at, w[axis]);
}

double Interpreter::unwrap_rotary(int column, char axis, double commanded, double at, double sign_of) const {
  if (sign_of <= -360.0 || sign_of >= 360.0) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "Invalid absolute position %5.2f for wrapped rotary axis %c", sign_of, axis);
    fail(column, buf);
  }
  double r = std::fabs(commanded) + std::floor(at / 360.0) * 360.0;
  if (!std::signbit(sign_of) && r < at) r += 360.0;
  if (std::signbit(sign_of) && r > at) r -= 360.0;
  return r;
}

void Interpreter::motion(Words& w) {
  const int m = motion_;
  const int col = w.g[1] >= 0 ? w.gcol[1] : (w.axes ? w.column(kAxisLetters[std::countr_zero(w.axes)]) : 0);
  if (m < 0 || m == 800) {
    if (w.axes != 0) fail(col, "axis words without a G code that uses them (motion mode is G80)");
    return;
  }
  const bool g53 = w.g[0] == 530;
  if (!(m >= 730 && m <= 890) || m == 760) in_cycle_ = false;
  if (m == 0 || m == 10) {
    if (w.axes == 0 && w.g[1] < 0) return;  // G0/G1 on its line moves even to where it is (LinuxCNC)
    const Pose end = axis_target(w, g53);
    const Pose shown = program_pose(end);
    if (m == 0) {
      canon_.straight_traverse(ref(col), shown);
    } else {
      if (feed_mode_ == FeedMode::kInverseTime) {
        if (!w.on('F')) fail(col, "G1 in inverse time mode (G93) needs an F word on its line");
        // LinuxCNC: the rate along the move that takes 1/F minutes.
        double lin = 0, rot = 0;
        for (size_t i = 0; i < end.size(); ++i) {
          const double d = (i < 3 || i >= 6 ? to_program(end[i] - position_[i]) : end[i] - position_[i]);
          if (i < 3 || i >= 6) lin += d * d; else rot += d * d;
        }
        const double length = lin > 0 ? std::sqrt(lin) : std::sqrt(rot);
        feed_ = length == 0 ? 0.1 : length * w['F'];
        canon_.set_feed_rate(ref(col), feed_);
      } else if (feed_ <= 0) {
        fail(col, "cannot do G1 with zero feed rate");
      }
      canon_.straight_feed(ref(col), shown);
    }
    position_ = end;
    return;
  }
  if (m == 20 || m == 30) {
    if (g53) fail(w.gcol[0], "G53 with an arc");
    if (feed_mode_ != FeedMode::kInverseTime && feed_ <= 0) fail(col, "cannot make arc with zero feed rate");
    if (feed_mode_ == FeedMode::kInverseTime && !w.on('F')) fail(col, "an arc in inverse time mode (G93) needs an F word");
    arc(w, m == 20, axis_target(w, false));
    return;
  }
  if (m == 760) {
    threading_cycle(w, col);
    return;
  }
  if (m >= 730 && m <= 890) {
    cycle(w);
    return;
  }
  if (m == 50 || m == 51) {
    spline(w, m == 50, col);
    return;
  }
  if (m == 330 || m == 331) {
    synced_move(w, m, col);
    return;
  }
  if (m >= 382 && m <= 385) {
    straight_probe(w, m, col);
    return;
  }
  fail(col, "motion " + g_text(m) + " is not supported");
}

// G33 (spindle-synchronised motion) and G33.1 (rigid tapping): K is the distance along
// the move per spindle revolution. G33.1 goes to the end and back to where it started.
void Interpreter::synced_move(Words& w, int g, int col) {
  const std::string name = g_text(g);
  if (!setup_.spindle_sync)
    fail(col, name + " needs a spindle whose position the machine measures (spindle.encoder_counts_per_rev)");
  if (!w.on('K')) fail(col, "K word missing with g33/g33.1");
  if (w.on('F')) fail(w.column('F'), "F word used with a g33/g33.1");
  if (w['K'] <= 0) fail(w.column('K'), "K (distance per revolution) must be > 0 with " + name);
  if (w.on('$') && spindle_number(w) != 0) fail(w.column('$'), "Invalid spindle ($) number in " + name + " move");
  if (spindle_ == 0) fail(col, "Spindle not turning in " + name);
  if (comp_ != 400) fail(col, name + " with cutter radius compensation on is not supported");
  if (w.g[0] == 530) fail(w.gcol[0], "G53 is only allowed with G0 or G1");
  const Pose end = axis_target(w, false);
  for (size_t i = 3; i < 6; ++i)
    if (end[i] != position_[i]) fail(col, "cannot move rotary axes with " + name);
  comp_filter_->flush();
  const SourceRef r = ref(col);
  const Pose shown = program_pose(end);
  canon_.start_speed_feed_sync(r, w['K'], false);
  if (g == 330) {
    canon_.straight_feed(r, shown);
    position_ = end;
  } else {
    canon_.rigid_tap(r, shown, w.on('I') ? std::max(1.0, w['I']) : 1.0);  // back at the start afterwards
  }
  canon_.stop_speed_feed_sync(r);
}

void Interpreter::arc(Words& w, bool cw, const Pose& end) {
  // In a tilted work plane (G68.2) the arc is made in its frame: the plane is the frame's.
  const Pose from = twp_ ? frame_of(position_) : position_;
  const Pose to = twp_ ? frame_of(end) : end;
  int a1 = 0, a2 = 1, a3 = 2;  // plane axes: first, second, normal
  char o1 = 'I', o2 = 'J';
  if (plane_ == Plane::kXZ) {
    a1 = 2; a2 = 0; a3 = 1; o1 = 'K'; o2 = 'I';
  } else if (plane_ == Plane::kYZ) {
    a1 = 1; a2 = 2; a3 = 0; o1 = 'J'; o2 = 'K';
  }
  const double s = length_scale();
  const double c1 = to_program(from[static_cast<size_t>(a1)]), c2 = to_program(from[static_cast<size_t>(a2)]);
  const double e1 = to_program(to[static_cast<size_t>(a1)]), e2 = to_program(to[static_cast<size_t>(a2)]);
  const int col = w.g[1] >= 0 ? w.gcol[1] : 0;
  const bool inch = units_ == Units::kInch;
  int turns = 1;
  if (w.on('P')) {
    const double p = w['P'];
    turns = static_cast<int>(std::lround(p));
    if (std::fabs(p - turns) > 1e-4 || turns < 1) fail(w.column('P'), "P (turns) of an arc must be a whole number >= 1");
  }
  double cen1 = 0, cen2 = 0;
  const char an1 = kAxisLetters[a1], an2 = kAxisLetters[a2];
  {
    // LinuxCNC: the offset along the plane's normal is an error, not ignored.
    const char normal_offset = plane_ == Plane::kXY ? 'K' : plane_ == Plane::kXZ ? 'J' : 'I';
    const char* plane_name = plane_ == Plane::kXY ? "XY" : plane_ == Plane::kXZ ? "XZ" : "YZ";
    if (w.on(normal_offset))
      fail(w.column(normal_offset), std::string(1, normal_offset) + " word given for an arc in the " + plane_name + " plane");
  }
  if (w.on('R')) {
    if (w.on(o1) || w.on(o2)) fail(w.column('R'), "an arc takes R or centre offsets, not both");
    const double radius = w['R'];
    if (e1 == c1 && e2 == c2) fail(w.column('R'), "current point same as end point of arc (R format cannot make a full circle)");
    const double ar = std::fabs(radius);
    const double mid1 = (e1 + c1) / 2, mid2 = (e2 + c2) / 2;
    double half = std::hypot(mid1 - e1, mid2 - e2);
    if (half - ar > (inch ? kArcRToleranceInch : kArcRToleranceMm))
      fail(w.column('R'), "arc radius " + num(ar) + " too small to reach the end point (half chord " + num(half) + ")");
    if (half / ar > 1 - kTiny) half = ar;
    double theta = std::atan2(e2 - c2, e1 - c1);
    theta += ((cw && radius > 0) || (!cw && radius < 0)) ? -M_PI_2 : M_PI_2;
    const double turn2 = std::asin(half / ar);
    const double off = ar * std::cos(turn2);
    cen1 = mid1 + off * std::cos(theta);
    cen2 = mid2 + off * std::sin(theta);
  } else {
    if (!w.on(o1) && !w.on(o2))
      fail(col, std::string("an arc needs R or a centre offset (") + o1 + " or " + o2 + ") in this plane");
    const double i1 = w.on(o1) ? w[o1] : 0, i2 = w.on(o2) ? w[o2] : 0;
    if (arc_incremental_) {
      cen1 = c1 + i1;
      cen2 = c2 + i2;
    } else {
      cen1 = i1;
      cen2 = i2;
    }
    const double r1 = std::hypot(cen1 - c1, cen2 - c2), r2 = std::hypot(cen1 - e1, cen2 - e2);
    const double rt = inch ? kRadiusToleranceInch : kRadiusToleranceMm;
    const double sat = inch ? kSpiralAbsToleranceInch : kSpiralAbsToleranceMm;
    char buf[400];
    if (r1 < rt || r2 < rt) {
      std::snprintf(buf, sizeof buf, "zero-radius arc: start=(%c%.4f,%c%.4f) center=(%c%.4f,%c%.4f) end=(%c%.4f,%c%.4f)", an1,
                    c1, an2, c2, an1, cen1, an2, cen2, an1, e1, an2, e2);
      fail(col, buf);
    }
    const double abs_err = std::fabs(r1 - r2);
    const double rel_err = abs_err / std::max(r1, r2);
    if (abs_err > sat * 100.0 || (rel_err > kSpiralRelTolerance && abs_err > sat)) {
      std::snprintf(buf, sizeof buf,
                    "radius to end of arc differs from radius to start: start=(%c%.4f,%c%.4f) center=(%c%.4f,%c%.4f) "
                    "end=(%c%.4f,%c%.4f) r1=%.4f r2=%.4f abs_err=%.4g rel_err=%.4f%%",
                    an1, c1, an2, c2, an1, cen1, an2, cen2, an1, e1, an2, e2, r1, r2, abs_err, rel_err * 100);
      fail(col, buf);
    }
  }
  if (feed_mode_ == FeedMode::kInverseTime) {
    const double r = std::hypot(c1 - cen1, c2 - cen2);
    double a0 = std::atan2(c2 - cen2, c1 - cen1), a1e = std::atan2(e2 - cen2, e1 - cen1);
    double sweep = cw ? a0 - a1e : a1e - a0;
    if (sweep <= 0) sweep += 2 * M_PI;
    sweep += 2 * M_PI * (turns - 1);
    const double dz = to_program(to[static_cast<size_t>(a3)] - from[static_cast<size_t>(a3)]);
    const double length = std::hypot(r * sweep, dz);
    feed_ = length == 0 ? 0.1 : length * w['F'];
    canon_.set_feed_rate(ref(col), feed_);
  }
  if (twp_) {
    frame_arc(col, {a1, a2, a3}, cen1 * s, cen2 * s, cw, turns, from, to, end);
    position_ = end;
    return;
  }
  const Pose shown = program_pose(end);
  const int rotation = cw ? -turns : turns;
  canon_.arc_feed(ref(col), e1, e2, cen1, cen2, rotation, shown[static_cast<size_t>(a3)], shown);
  position_ = end;
}

void Interpreter::cycle(Words& w) {
  const int m = motion_;
  const int col = w.g[1] >= 0 ? w.gcol[1] : 0;
  if (plane_ != Plane::kXY && plane_ != Plane::kXZ && plane_ != Plane::kYZ) fail(col, "canned cycle in this plane");
  if (w.axes == 0 && w.g[1] < 0) return;
  // LinuxCNC's plane order: the two plane axes, then the depth axis; I J K follow.
  int a1 = 0, a2 = 1, a3 = 2;
  char o1 = 'I', o2 = 'J', o3 = 'K';
  if (plane_ == Plane::kXZ) { a1 = 2; a2 = 0; a3 = 1; o1 = 'K'; o2 = 'I'; o3 = 'J'; }
  if (plane_ == Plane::kYZ) { a1 = 1; a2 = 2; a3 = 0; o1 = 'J'; o2 = 'K'; o3 = 'I'; }
  const char l1 = kAxisLetters[a1], l2 = kAxisLetters[a2], l3 = kAxisLetters[a3];
  // In a tilted work plane the cycle is made in its frame.
  const Pose here = twp_ ? frame_of(position_) : position_;
  // The depth-axis level where a run of cycle blocks started (G98 returns to it).
  if (!in_cycle_) cycle_old_z_ = to_program(here[static_cast<size_t>(a3)]);
  const bool continuing = prev_motion_ == m;
  CycleInput in;
  in.g = m;
  in.plane = plane_;
  in.incremental = incremental_;
  in.retract_to_r = retract_r_;
  in.start = program_pose(here);
  in.has_x = w.on(l1);
  in.has_y = w.on(l2);
  in.x = in.has_x ? w[l1] : (incremental_ ? 0 : in.start[static_cast<size_t>(a1)]);
  in.y = in.has_y ? w[l2] : (incremental_ ? 0 : in.start[static_cast<size_t>(a2)]);
  // Sticky words: R, the depth, P, Q and G87's I J K keep their last values.
  in.has_z = w.on(l3);
  if (in.has_z) cycle_z_ = w[l3];
  in.has_r = w.on('R');
  if (in.has_r) cycle_r_ = w['R'];
  // P-1 and Q-1 are LinuxCNC's marks of an absent word.
  in.has_p = w.on('P') && w['P'] != -1;
  if (in.has_p) cycle_p_ = w['P'];
  in.has_q = w.on('Q') && w['Q'] != -1;
  if (in.has_q) cycle_q_ = w['Q'];
  in.has_i = w.on(o1);
  if (in.has_i) cycle_i_ = w[o1];
  in.has_j = w.on(o2);
  if (in.has_j) cycle_j_ = w[o2];
  in.has_k = w.on(o3);
  if (in.has_k) cycle_k_ = w[o3];
  in.z = cycle_z_;
  in.r = cycle_r_;
  in.p = cycle_p_;
  in.q = cycle_q_;
  in.i = cycle_i_;
  in.j = cycle_j_;
  in.k = cycle_k_;
  in.continuing = continuing;
  if (w.on('L')) {
    const double l = w['L'];
    in.repeats = static_cast<int>(std::lround(l));
    if (std::fabs(l - in.repeats) > 1e-4) fail(w.column('L'), "L (repeats) must be a whole number");
  }
  in.old_z = cycle_old_z_;
  in.spindle_rpm = speed_;
  in.spindle_cw = spindle_ >= 0;
  in.spindle_turning = spindle_ != 0;
  in.units = units_;
  in.feed_rate = feed_;
  in.inverse_time = feed_mode_ == FeedMode::kInverseTime;
  in.cutter_comp = comp_ != 400;
  in.path_mode = path_;
  in.path_tolerance = path_p_;
  in.naivecam_tolerance = path_q_;
  in.feed_override_enabled = feed_override_;
  in.speed_override_enabled = speed_override_;
  // Polar words (@ ^) in a cycle: LinuxCNC recomputes the hole's XY from them at each
  // repeat (G91 ^60 L6 drills a bolt circle).
  if ((w.on('@') || w.on('^')) && plane_ == Plane::kXY) {
    const double s = length_scale();
    in.next_hole = [this, &w, s](double* x, double* y) {
      Pose saved = position_;
      position_[0] = *x * s;
      position_[1] = *y * s;
      const Pose t = axis_target(w, false);
      position_ = saved;
      *x = to_program(t[0]);
      *y = to_program(t[1]);
    };
  }
  CycleResult res;
  std::optional<FramedMoves> framed;
  if (twp_)
    framed.emplace(canon_, [this](const Pose& p) {
      Pose mm = p;
      for (size_t i = 0; i < mm.size(); ++i) mm[i] = i < 3 || i >= 6 ? p[i] * length_scale() : p[i];
      return program_pose(work_of(mm));
    });
  try {
    res = run_cycle(in, ref(col), framed ? static_cast<Canon&>(*framed) : canon_);
  } catch (const Error& e) {
    if (!e.file_name().empty()) throw;
    fail(e.column() > 0 ? e.column() : col, e.detail());
  }
  for (size_t i = 0; i < res.end.size(); ++i) position_[i] = i < 3 || i >= 6 ? res.end[i] * length_scale() : res.end[i];
  if (twp_) position_ = work_of(position_);
  in_cycle_ = true;
  w.axes = 0;
}

// G5 (cubic) and G5.1 (quadratic) splines in the XY plane, as LinuxCNC makes them:
// a Bezier segment, handed on as a NURBS of order 4 or 3 with clamped knots. G5's I J
// (start to first control point) default to the mirror of the previous G5's P Q, or
// to 0 when the move before was not a G5.
void Interpreter::spline(Words& w, bool cubic, int col) {
  if (plane_ != Plane::kXY) fail(col, "splines must be in the XY plane");
  if (feed_mode_ != FeedMode::kInverseTime && feed_ <= 0) fail(col, "cannot do a spline with zero feed rate");
  const Pose end = axis_target(w, false);
  for (size_t i = 2; i < end.size(); ++i)
    if (end[i] != position_[i]) fail(col, "splines may not have motion in Z, A, B, or C");
  const double s = length_scale();
  const double x0 = position_[0], y0 = position_[1], x1 = end[0], y1 = end[1];
  std::vector<NurbsPoint> pts;
  auto pt = [&](double x, double y) {
    NurbsPoint p;
    p.x = to_program(x);
    p.y = to_program(y);
    p.w = 1;
    pts.push_back(p);
  };
  pt(x0, y0);
  if (cubic) {
    double i = 0, j = 0;
    if (w.on('I') || w.on('J')) {
      if (!(w.on('I') && w.on('J'))) fail(col, "G5: I and J must be given together");
      i = w['I'] * s;
      j = w['J'] * s;
    } else if (prev_motion_ == 50 && spline_continues_) {
      i = -spline_pq_[0];
      j = -spline_pq_[1];
    }
    if (!(w.on('P') && w.on('Q'))) fail(col, "G5 needs P and Q (the end's control point offset)");
    const double pp = w['P'] * s, qq = w['Q'] * s;
    pt(x0 + i, y0 + j);
    pt(x1 + pp, y1 + qq);
    spline_pq_ = {pp, qq};
  } else {
    if (!w.on('I') && !w.on('J')) fail(col, "G5.1 needs I or J (the control point's offset from the start)");
    const double i = w.on('I') ? w['I'] * s : 0, j = w.on('J') ? w['J'] * s : 0;
    pt(x0 + i, y0 + j);
  }
  pt(x1, y1);
  const int order = cubic ? 4 : 3;
  std::vector<double> knots;
  for (int k = 0; k < order; ++k) knots.push_back(0);
  for (int k = 0; k < order; ++k) knots.push_back(1);
  const Pose shown = program_pose(end);
  if (feed_mode_ == FeedMode::kInverseTime) {
    if (!w.on('F')) fail(col, "a spline in inverse time mode (G93) needs an F word");
    feed_ = w['F'] * std::hypot(to_program(x1 - x0), to_program(y1 - y0));
    canon_.set_feed_rate(ref(col), feed_);
  }
  canon_.nurbs_feed(ref(col), order, pts, knots, shown);
  position_ = end;
  spline_continues_ = cubic;
}

// ---- NURBS --------------------------------------------------------------------------

// LinuxCNC's G5.2: the current point is control point 0 with weight P of the opening
// line; X Y P lines add points; G5.3 closes. The knots are LinuxCNC's uniform clamped
// vector.
void Interpreter::nurbs_g5_open(Words& w) {
  if (feed_ <= 0) fail(w.gcol[1], "cannot do G5.2 with zero feed rate");
  if (comp_ != 400) fail(w.gcol[1], "G5.2 with cutter radius compensation on");
  auto n = std::make_unique<NurbsCollect>();
  n->fanuc = false;
  n->order = 3;
  if (w.on('L')) {
    if (w['L'] != std::floor(w['L'])) fail(w.column('L'), "G5.2 L (order) must be a whole number");
    n->order = static_cast<int>(w['L']);
    if (n->order < 3 || n->order > 8) fail(w.column('L'), "G5.2 L (order) must be 3 to 8");
  }
  n->column = w.gcol[1];
  n->line = line_no_;
  n->start = position_;
  nurbs_ = std::move(n);
  // The opening line may hold the first control point after the start.
  NurbsPoint p0;
  int a1 = 0, a2 = 1;
  if (plane_ == Plane::kXZ) { a1 = 2; a2 = 0; }
  if (plane_ == Plane::kYZ) { a1 = 1; a2 = 2; }
  p0.x = to_program(position_[static_cast<size_t>(a1)]);
  p0.y = to_program(position_[static_cast<size_t>(a2)]);
  // LinuxCNC: the opening line's P weighs the start point when the line has no X Y;
  // with X Y it is that control point's weight and the start point weighs 1.
  p0.w = w.axes == 0 && w.on('P') ? w['P'] : 1;
  if (p0.w <= 0) fail(w.column('P'), "NURBS weight P must be positive");
  nurbs_->points.push_back(p0);
  nurbs_->last = position_;
  if (w.axes != 0) nurbs_g5_point(w);
}

void Interpreter::nurbs_g5_point(Words& w) {
  int a1 = 0, a2 = 1;
  if (plane_ == Plane::kXZ) { a1 = 2; a2 = 0; }
  if (plane_ == Plane::kYZ) { a1 = 1; a2 = 2; }
  const char l1 = kAxisLetters[a1], l2 = kAxisLetters[a2];
  if (!w.on(l1) || !w.on(l2))
    fail(w.axes ? w.column(kAxisLetters[std::countr_zero(w.axes)]) : 0,
         std::string("a G5.2 control point needs both ") + l1 + " and " + l2);
  if (w.axes & ~((1u << a1) | (1u << a2))) fail(0, std::string("a G5.2 control point takes only ") + l1 + " and " + l2);
  NurbsPoint p;
  const double s = length_scale();
  double v1 = w[l1] * s, v2 = w[l2] * s;
  if (incremental_) {
    v1 += nurbs_->start[static_cast<size_t>(a1)];
    v2 += nurbs_->start[static_cast<size_t>(a2)];
  }
  p.x = v1 / s;
  p.y = v2 / s;
  // LinuxCNC: "Must specify positive weight P for every Control Point".
  if (!w.on('P')) fail(w.column(l1), "a G5.2 control point needs its weight P (> 0)");
  p.w = w['P'];
  if (p.w <= 0) fail(w.column('P'), "NURBS weight P must be positive");
  nurbs_->points.push_back(p);
  nurbs_->last[static_cast<size_t>(a1)] = v1;
  nurbs_->last[static_cast<size_t>(a2)] = v2;
}

void Interpreter::nurbs_g5_close() {
  NurbsCollect& n = *nurbs_;
  const int npts = static_cast<int>(n.points.size());
  if (npts < n.order)
    fail(w53_column_, "G5.3: a curve of order L = " + std::to_string(n.order) +
                          " needs at least that many control points, the start point included (has " + std::to_string(npts) + ")");
  // LinuxCNC's knot vector: order zeros, then 1, 2, ..., then order copies of the last.
  std::vector<double> knots;
  for (int i = 0; i < n.order; ++i) knots.push_back(0);
  for (int i = 1; i <= npts - n.order; ++i) knots.push_back(i);
  for (int i = 0; i < n.order; ++i) knots.push_back(npts - n.order + 1);
  const Pose shown = program_pose(n.last);
  canon_.nurbs_feed(ref(n.column), n.order, n.points, knots, shown);
  position_ = n.last;
  nurbs_.reset();
  motion_ = -1;
}

// Fanuc G6.2: P order, then one control point per block with its knot K, weight R,
// then `order` blocks of knots only.
void Interpreter::nurbs_fanuc_open(Words& w) {
  if (feed_ <= 0) fail(w.gcol[1], "cannot do G06.2 with zero feed rate");
  if (!w.on('P')) fail(w.gcol[1], "G06.2 needs the curve's order: expected a P word (2 to 8)");
  auto n = std::make_unique<NurbsCollect>();
  n->fanuc = true;
  if (w['P'] != std::floor(w['P'])) fail(w.column('P'), "G06.2 P (order) must be a whole number");
  n->order = static_cast<int>(w['P']);
  if (n->order < 2 || n->order > 8) fail(w.column('P'), "G06.2 P (order) must be 2 to 8");
  n->column = w.gcol[1];
  n->line = line_no_;
  n->start = position_;
  n->last = position_;
  nurbs_ = std::move(n);
  if (!w.on('K')) fail(w.gcol[1], "G06.2 needs a knot K with its first control point");
  // LinuxCNC's G6.2 takes Q1..Q3 (its interpolation method: biarcs, lines, arcs);
  // the cell always interpolates the exact curve.
  if (w.on('Q') && (w['Q'] < 1 || w['Q'] > 3 || w['Q'] != std::floor(w['Q'])))
    fail(w.column('Q'), "G6.2 Q (LinuxCNC's interpolation method) must be 1, 2 or 3");
  nurbs_fanuc_line(w);
  if (nurbs_->points.empty())
    fail(w.gcol[1], "G06.2 needs its first control point (an X, Y, Z or R word) with the knot K");
  // The first control point is where the tool is.
  const NurbsPoint& p0 = nurbs_->points.front();
  const double tol = 1e-6;
  if (std::fabs(p0.x - to_program(position_[0])) > tol || std::fabs(p0.y - to_program(position_[1])) > tol ||
      std::fabs(p0.z - to_program(position_[2])) > tol)
    fail(w.gcol[1], "the first control point of a G06.2 curve must be where the tool is (" + num(to_program(position_[0])) +
                        ", " + num(to_program(position_[1])) + ", " + num(to_program(position_[2])) + ")");
}

void Interpreter::nurbs_fanuc_line(Words& w) {
  NurbsCollect& n = *nurbs_;
  const double k = w['K'];
  if (!n.knots.empty() && k < n.knots.back()) fail(w.column('K'), "knots must not decrease");
  n.knots.push_back(k);
  const bool point = (w.axes & 7u) != 0 || w.on('R');
  if (!point) {
    n.knots_only = true;
    return;
  }
  if (n.knots_only) fail(w.column('K'), "a control point after the closing knots of a G06.2 curve");
  if (w.axes & ~7u) fail(0, "a G06.2 control point takes only X, Y and Z");
  const double s = length_scale();
  for (int i = 0; i < 3; ++i) {
    const char c = kAxisLetters[i];
    if (!w.on(c)) continue;
    const size_t ii = static_cast<size_t>(i);
    n.last[ii] = incremental_ && !n.points.empty() ? n.last[ii] + w[c] * s : (incremental_ ? n.start[ii] + w[c] * s : w[c] * s);
  }
  NurbsPoint p;
  p.x = to_program(n.last[0]);
  p.y = to_program(n.last[1]);
  p.z = to_program(n.last[2]);
  p.w = w.on('R') ? w['R'] : 1;
  p.has_z = true;
  if (p.w <= 0) fail(w.column('R'), "NURBS weight R must be positive");
  n.points.push_back(p);
}

void Interpreter::nurbs_fanuc_close() {
  NurbsCollect& n = *nurbs_;
  const size_t np = n.points.size();
  if (n.knots.size() != np + static_cast<size_t>(n.order))
    fail(0, "the G06.2 curve opened at line " + std::to_string(n.line) + " has " + std::to_string(n.knots.size()) +
                " knots; " + std::to_string(np) + " control points of order " + std::to_string(n.order) + " need " +
                std::to_string(np + static_cast<size_t>(n.order)));
  const Pose shown = program_pose(n.last);
  canon_.nurbs_feed(ref(n.column), n.order, n.points, n.knots, shown);
  position_ = n.last;
  nurbs_.reset();
  motion_ = -1;
}

// Inside a NURBS curve: the line adds to the curve or closes it; true when it
// was the curve's (the block's other steps are then not made).
bool Interpreter::continue_nurbs(Words& w) {
  // A line of comments only (or an empty one) leaves the curve open.
  if (line_.words.empty()) return true;
  if (nurbs_->fanuc) {
    // LinuxCNC's newer G6.2 repeats the G code on its knot-only lines ("G6.2 K29").
    if (w.on('K') && (w.g[1] < 0 || w.g[1] == 62)) {
      nurbs_fanuc_line(w);
      // A curve whose knots are complete (control points + order) ends here.
      if (nurbs_->knots.size() == nurbs_->points.size() + static_cast<size_t>(nurbs_->order)) {
        nurbs_fanuc_close();
        fanuc_closed_line_ = line_no_;
      }
      return true;
    }
    nurbs_fanuc_close();
    return false;
  }
  if (w.g[1] == 53) {
    w53_column_ = w.gcol[1];
    nurbs_g5_close();
    return true;
  }
  // Control point lines: X Y P, where LinuxCNC also takes G5.2 again, a new order L
  // (checked at G5.3) and an S word (a spindle speed for what follows).
  if ((w.g[1] < 0 || w.g[1] == 52) && (w.axes != 0 || w.on('P') || w.on('L'))) {
    if (w.on('S')) {
      speed_ = w['S'];
      canon_.set_spindle_speed(ref(w.column('S')), speed_);
    }
    if (w.on('L')) {
      if (w['L'] != std::floor(w['L']) || w['L'] < 3 || w['L'] > 8)
        fail(w.column('L'), "G5.2 L (order) must be a whole number from 3 to 8");
      nurbs_->order = static_cast<int>(w['L']);
    }
    if (w.axes != 0 || w.on('P')) nurbs_g5_point(w);
    return true;
  }
  fail(w.g[1] >= 0 ? w.gcol[1] : 0, "inside a G5.2 curve: expected X Y P control points or G5.3");
}

// The motion mode and its move (G0-G89, G5.2, G6.2, or axis words alone).
void Interpreter::motion_block(Words& w) {
  prev_motion_ = motion_;
  if (w.g[1] >= 0) {
    motion_ = w.g[1];
    if (motion_ == 800) {
      in_cycle_ = false;
      canon_.comment(ref(w.gcol[1]), "interpreter: motion mode set to none");
    }
  }
  const bool axis_g0 = w.g[0] == 100 || w.g[0] == 280 || w.g[0] == 300 || w.g[0] == 520 || w.g[0] == 920 ||
                       w.g[0] == 431 || w.g[16] == 682;
  if (w.g[1] == 52) {
    nurbs_g5_open(w);
  } else if (w.g[1] == 62) {
    nurbs_fanuc_open(w);
  } else if (w.g[1] == 53) {
    fail(w.gcol[1], "G5.3 without G5.2");
  } else if (w.g[1] >= 0 || (w.axes != 0 && !axis_g0)) {
    motion(w);
  }
}

}  // namespace cnc::rs274
