// Cutter radius compensation as LinuxCNC 2.9's interpreter does it (see cutter_comp.h).
//
// Everything is computed in the plane's own frame (u, v) with w the axis normal to
// it: XY -> (X, Y, Z), XZ -> (Z, X, Y), the order in which ARC_FEED takes the plane
// coordinates. "Left" is left of the direction of travel in that frame.
//
// The model, LinuxCNC's:
//  * `programmed_` is the last programmed (uncompensated) point, `current_` the last
//    compensated point the tool was sent to.
//  * A compensated move is not sent at once: it waits in `held_` until the next move
//    shows the corner between them. Then either the held move's end is moved (a
//    concave corner: the two offset paths are intersected) and it is sent, or it is
//    sent as it is and an arc around the corner is sent after it (a convex corner).
//  * While a move waits, the calls LinuxCNC queues (feed rate, dwell, feed mode,
//    spindle speed, direction and mode, coolant, comments) wait behind it in their order; every other call
//    goes straight through, before the waiting move, as in LinuxCNC.
//  * `start_of_held_` is where the newest held move starts (LinuxCNC's "endpoint"):
//    moving the held end back past it means the offset path has reversed, which is
//    the gouge LinuxCNC refuses.
#include "common/rs274/cutter_comp.h"

#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <utility>

namespace cnc::rs274 {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kHalfPi = std::numbers::pi / 2;
// LinuxCNC's TOLERANCE_CONCAVE_CORNER: corners within this many radians of
// straight-ahead need no arc, and a turn back by more than pi + this is concave.
constexpr double kCornerTolerance = 0.05;
// LinuxCNC's TOLERANCE_EQUAL.
constexpr double kEqual = 1e-6;
// LinuxCNC's CENTER_ARC_RADIUS_TOLERANCE_MM / _INCH (defaults).
constexpr double kSpiralAbsToleranceMm = 2 * 0.01 * std::numbers::sqrt2;
constexpr double kSpiralAbsToleranceInch = 2 * 0.001 * std::numbers::sqrt2;

struct Axes {
  size_t u, v, w;  // Pose indices of the plane's first, second and normal axes
};

Axes axes_of(Plane plane) {
  if (plane == Plane::kXZ) return {2, 0, 1};
  return {0, 1, 2};
}

// Sweep angle from (u1, v1) to (u2, v2) about (cu, cv), counterclockwise positive,
// with |turn| - 1 extra full circles (LinuxCNC's find_turn).
double sweep_of(double u1, double v1, double cu, double cv, int turn, double u2, double v2) {
  if (turn == 0) return 0.0;
  double a = std::atan2(v1 - cv, u1 - cu);
  double b = std::atan2(v2 - cv, u2 - cu);
  if (turn > 0) {
    if (b <= a) b += 2 * kPi;
    return (b - a) + (turn - 1) * (2 * kPi);
  }
  if (a <= b) a += 2 * kPi;
  return (b - a) + (turn + 1) * (2 * kPi);
}

[[noreturn]] void refuse(std::string detail) { throw Error(0, std::move(detail)); }

}  // namespace

struct CutterComp::Impl {
  enum class Kind : uint8_t { kTraverse, kFeed, kArc, kCall };

  struct Held {
    Kind kind = Kind::kCall;
    SourceRef ref;
    Pose end{};          // the other axes' ends (and w for straights)
    double u = 0, v = 0;  // compensated end in the plane (moved at a concave corner)
    // Straights: the direction the move had when it was made, for the reversal check.
    double du = 0, dv = 0;
    // Arcs.
    double cu = 0, cv = 0;
    int turn = 0;
    double w_end = 0;
    double sweep = 0;  // the programmed sweep; 0: a corner arc, never checked
    std::function<void(Canon&)> call;
  };

  explicit Impl(Canon& o) : out(o) {}

  Canon& out;
  int side = 0;  // +1 left (G41), -1 right (G42), 0 off
  double radius = 0;
  Plane plane = Plane::kXY;
  Axes ax{0, 1, 2};
  Units units = Units::kMm;
  bool first_move = true;
  bool arc_not_allowed = false;
  double pu = 0, pv = 0, pw = 0;  // programmed point
  double cu = 0, cv = 0, cw = 0;  // compensated (current) point
  bool stopped_off_path = false;  // G40 left the tool at (cu, cv), off the programmed point
  std::vector<Held> held;
  double start_u = 0, start_v = 0;  // LinuxCNC's "endpoint": where the newest held move starts
  bool start_valid = false;

  bool compensating() const { return side != 0 && radius > 0; }
  bool left() const { return side > 0; }
  // LinuxCNC's TOOL_INSIDE_ARC.
  bool inside(int turn) const { return (left() && turn > 0) || (!left() && turn < 0); }
  double spiral_tolerance() const { return units == Units::kInch ? kSpiralAbsToleranceInch : kSpiralAbsToleranceMm; }

  // A call LinuxCNC queues: held behind a waiting move, else at once.
  void queueable(std::function<void(Canon&)> call) {
    if (held.empty()) {
      call(out);
      return;
    }
    Held h;
    h.kind = Kind::kCall;
    h.call = std::move(call);
    held.push_back(std::move(h));
  }
  // The canonical call Call with these arguments, queued as above.
  template <auto Call, class... Args>
  void queue(const SourceRef& r, const Args&... args) {
    queueable([r, args...](Canon& c) { (c.*Call)(r, args...); });
  }

  void set_start(double u, double v) {
    start_u = u;
    start_v = v;
    start_valid = true;
  }

  Pose place(const Pose& end, double u, double v) const {
    Pose p = end;
    p[ax.u] = u;
    p[ax.v] = v;
    return p;
  }

  void emit(const Held& h) {
    switch (h.kind) {
      case Kind::kTraverse:
        out.straight_traverse(h.ref, place(h.end, h.u, h.v));
        break;
      case Kind::kFeed:
        out.straight_feed(h.ref, place(h.end, h.u, h.v));
        break;
      case Kind::kArc: {
        Pose p = place(h.end, h.u, h.v);
        p[ax.w] = h.w_end;
        out.arc_feed(h.ref, h.u, h.v, h.cu, h.cv, h.turn, h.w_end, p);
        break;
      }
      case Kind::kCall:
        h.call(out);
        break;
    }
  }

  // LinuxCNC's dequeue_canons.
  void send_held() {
    start_valid = false;
    std::vector<Held> now;
    now.swap(held);
    for (const Held& h : now) emit(h);
  }

  // LinuxCNC's move_endpoint_and_flush: every held move now ends at (u, v); a
  // straight that would run backwards, or an arc that would sweep further than
  // programmed, gouges.
  void move_end_and_send(double u, double v) {
    if (held.empty()) return;
    for (Held& h : held) {
      if (h.kind == Kind::kArc) {
        const double r1 = std::hypot(h.u - h.cu, h.v - h.cv);
        const double r2 = std::hypot(u - h.cu, v - h.cv);
        const double new_sweep = sweep_of(start_u, start_v, h.cu, h.cv, h.turn, u, v);
        if (std::fabs(r1 - r2) > .01) {
          char buf[160];
          std::snprintf(buf, sizeof buf,
                        "BUG: cutter compensation has generated an invalid arc with mismatched radii r1 %f r2 %f\n", r1,
                        r2);
          refuse(buf);
        }
        if (h.sweep != 0.0 && start_valid &&
            std::fabs(new_sweep) > std::fabs(h.sweep) + (units == Units::kMm ? .0254 : .001))
          refuse("Arc move in concave corner cannot be reached by the tool without gouging");
      } else if (h.kind == Kind::kTraverse || h.kind == Kind::kFeed) {
        const double dot = h.du * (u - start_u) + h.dv * (v - start_v);
        if (start_valid && dot < 0) {
          refuse(h.kind == Kind::kTraverse
                     ? "Straight traverse in concave corner cannot be reached by the tool without gouging"
                     : "Straight feed in concave corner cannot be reached by the tool without gouging");
        }
      } else {
        continue;
      }
      h.u = u;
      h.v = v;
    }
    send_held();
    set_start(u, v);
  }

  void hold_straight(bool feed, const SourceRef& ref, double du, double dv, double u, double v, const Pose& end) {
    Held h;
    h.kind = feed ? Kind::kFeed : Kind::kTraverse;
    h.ref = ref;
    h.end = end;
    h.u = u;
    h.v = v;
    h.du = du;
    h.dv = dv;
    held.push_back(std::move(h));
  }

  void hold_arc(const SourceRef& ref, double sweep, double u, double v, double c_u, double c_v, int turn, double w_end,
                const Pose& end) {
    Held h;
    h.kind = Kind::kArc;
    h.ref = ref;
    h.end = end;
    h.u = u;
    h.v = v;
    h.cu = c_u;
    h.cv = c_v;
    h.turn = turn;
    h.w_end = w_end;
    h.sweep = sweep;
    held.push_back(std::move(h));
  }

  const Held* front_move() const {
    // LinuxCNC looks at the front of its queue, which is the waiting move whenever
    // there is one (calls are only queued behind a move). After a flush (M0, M1)
    // the queue is empty: LinuxCNC then reads a stale element; we take "no arc".
    if (held.empty() || held.front().kind == Kind::kCall) return nullptr;
    return &held.front();
  }

  // ---- straight moves (G0, G1) ----------------------------------------------------

  void straight(bool feed, const SourceRef& ref, const Pose& end) {
    const double u = end[ax.u], v = end[ax.v], w = end[ax.w];
    if (first_move) {
      // Entry: a straight line to where the tool touches the end point with the
      // line from the start point (the tool's centre) to the end point.
      const double distance = std::hypot(u - cu, v - cv);
      if (distance <= radius) refuse("Length of cutter compensation entry move is not greater than the tool radius");
      const double alpha = std::atan2(v - cv, u - cu) + (left() ? kHalfPi : -kHalfPi);
      const double eu = u + radius * std::cos(alpha), ev = v + radius * std::sin(alpha);
      set_start(cu, cv);
      hold_straight(feed, ref, std::cos(alpha), std::sin(alpha), eu, ev, end);
      first_move = false;
      cu = eu;
      cv = ev;
      cw = w;
      pu = u;
      pv = v;
      pw = w;
      return;
    }
    if (u == pu && v == pv) {
      // No motion in the plane: the tool stays where it is, the move waits with the
      // one before it (a later concave corner moves both).
      hold_straight(feed, ref, 0, 0, cu, cv, end);
      cw = w;
      pw = w;
      return;
    }
    double theta = std::atan2(cv - pv, cu - pu);  // from the programmed point to the tool
    double alpha = std::atan2(v - pv, u - pu);    // of the new move
    double beta = 0, gamma = 0;
    if (left()) {
      if (theta < alpha) theta += 2 * kPi;
      beta = (theta - alpha) - kHalfPi;
      gamma = kHalfPi;
    } else {
      if (alpha < theta) alpha += 2 * kPi;
      beta = (alpha - theta) - kHalfPi;
      gamma = -kHalfPi;
    }
    const double eu = u + radius * std::cos(alpha + gamma), ev = v + radius * std::sin(alpha + gamma);
    const double mu = pu + radius * std::cos(alpha + gamma), mv = pv + radius * std::sin(alpha + gamma);

    bool concave = false;
    if (beta < -kCornerTolerance || beta > kPi + kCornerTolerance) {
      concave = true;
    } else if (beta > kPi - kCornerTolerance) {
      // A reversal off an arc that had the tool outside (the top of an "h"): LinuxCNC
      // keeps the tool on the same side, as a concave corner.
      const Held* f = front_move();
      if (f != nullptr && f->kind == Kind::kArc && ((!left() && f->turn > 0) || (left() && f->turn < 0))) concave = true;
    }

    if (!concave && beta > kCornerTolerance) {
      // Convex: the held move keeps its end; an arc about the programmed corner (a
      // straight for G0, which has no arc) takes the tool to the new move's start.
      move_end_and_send(cu, cv);
      Pose corner = end;
      corner[ax.w] = cw;
      if (feed) {
        hold_arc(ref, 0.0, mu, mv, pu, pv, left() ? -1 : 1, cw, corner);
      } else {
        hold_straight(false, ref, 0, 0, mu, mv, corner);
      }
      send_held();
      set_start(mu, mv);
    } else if (concave) {
      const Held* f = front_move();
      if (f == nullptr || f->kind != Kind::kArc) {
        // line -> line: back up along the held line until the tool touches the new one.
        const double half_corner = (beta + kPi) / 2.0;
        if (half_corner == 0.0) refuse("Zero degree inside corner is invalid for cutter compensation");
        const double retreat = radius / std::tan(half_corner);
        move_end_and_send(cu + retreat * std::cos(theta + gamma), cv + retreat * std::sin(theta + gamma));
      } else {
        // arc -> line: where the held (compensated) arc meets the offset line.
        const double old_r = std::hypot(f->cv - f->v, f->cu - f->u);
        const double base = std::atan2(v - pv, u - pu);
        const double th = f->turn > 0 ? base + kHalfPi : base - kHalfPi;
        const double phi = std::atan2(f->cv - pv, f->cu - pu);
        const bool in = inside(f->turn);
        const double old_r_programmed = in ? old_r + radius : old_r - radius;
        const double d = old_r_programmed * std::cos(th - phi);
        const double l = (in ? d - radius : d + radius) / old_r;
        if (l > 1.0 || l < -1.0)
          refuse("Arc to straight motion makes a corner the compensated tool can't fit in without gouging");
        double angle = 0;
        if (in)
          angle = (f->turn > 0 ? -std::acos(l) : std::acos(l)) + th + kPi;
        else
          angle = (f->turn > 0 ? std::acos(l) : -std::acos(l)) + th + kPi;
        move_end_and_send(f->cu + old_r * std::cos(angle), f->cv + old_r * std::sin(angle));
      }
    } else {
      // Straight on (or a tangent arc -> line): nothing to change.
      send_held();
      set_start(cu, cv);
    }
    hold_straight(feed, ref, u - pu, v - pv, eu, ev, end);
    cu = eu;
    cv = ev;
    cw = w;
    pu = u;
    pv = v;
    pw = w;
  }

  // ---- arcs (G2, G3) --------------------------------------------------------------

  void arc(const SourceRef& ref, double u, double v, double c_u, double c_v, int turn, double w, const Pose& end) {
    if (first_move) {
      arc_entry(ref, u, v, c_u, c_v, turn, w, end);
      return;
    }
    const bool ccw = turn > 0;
    const double arc_r = std::hypot(c_u - u, c_v - v);
    double theta = std::atan2(cv - pv, cu - pu);
    theta = left() ? theta - kHalfPi : theta + kHalfPi;  // direction of travel at the end of the last move
    double delta = std::atan2(c_v - pv, c_u - pu);
    const double alpha = ccw ? delta - kHalfPi : delta + kHalfPi;  // direction at the start of the arc
    double beta = left() ? theta - alpha : alpha - theta;
    beta = beta > 1.5 * kPi ? beta - 2 * kPi : beta < -kHalfPi ? beta + 2 * kPi : beta;

    const bool in = inside(turn);
    double gamma = 0;
    if (in) {
      gamma = std::atan2(c_v - v, c_u - u);
      if (arc_r <= radius) refuse("Tool radius not less than arc radius with comp");
    } else {
      gamma = std::atan2(v - c_v, u - c_u);
      delta += kPi;
    }
    const double eu = u + radius * std::cos(gamma), ev = v + radius * std::sin(gamma);
    const double sweep = sweep_of(pu, pv, c_u, c_v, turn, u, v);

    if (beta < -kCornerTolerance || beta > kPi + kCornerTolerance ||
        (std::fabs(beta - kPi) < kCornerTolerance && !in)) {
      // Concave.
      const Held* f = front_move();
      if (f == nullptr || f->kind != Kind::kArc) {
        // line -> arc: where the held line meets the offset arc.
        const double across = arc_r * std::sin(beta - kHalfPi);
        double dist = 0, angle = 0;
        if (in) {
          dist = arc_r - radius;
          const double l = (across + radius) / dist;
          if (l > 1.0 || l < -1.0) refuse("Arc move in concave corner cannot be reached by the tool without gouging");
          angle = turn > 0 ? theta + std::asin(l) : theta - std::asin(l);
        } else {
          dist = arc_r + radius;
          const double l = (across - radius) / dist;
          if (l > 1.0 || l < -1.0) refuse("Arc move in concave corner cannot be reached by the tool without gouging");
          angle = turn > 0 ? theta + kPi - std::asin(l) : theta + kPi + std::asin(l);
        }
        move_end_and_send(c_u + dist * std::cos(angle), c_v + dist * std::sin(angle));
      } else {
        // arc -> arc: where the two offset circles cross.
        const double old_r = std::hypot(f->cv - f->v, f->cu - f->u);
        const double new_r = in ? arc_r - radius : arc_r + radius;
        const double cc = std::hypot(f->cv - c_v, f->cu - c_u);
        if (old_r == 0 || cc == 0) refuse("Arc to arc motion is invalid because the arcs have the same center");
        const double a = (old_r * old_r + cc * cc - new_r * new_r) / (2 * old_r * cc);
        if (a > 1.0 || a < -1.0)
          refuse("Arc to arc motion makes a corner the compensated tool can't fit in without gouging");
        const double pullback = std::acos(a);
        const double cc_dir = std::atan2(c_v - f->cv, c_u - f->cu);
        double dir = 0;
        if (inside(f->turn))
          dir = turn > 0 ? cc_dir + pullback : cc_dir - pullback;
        else
          dir = turn > 0 ? cc_dir - pullback : cc_dir + pullback;
        move_end_and_send(f->cu + old_r * std::cos(dir), f->cv + old_r * std::sin(dir));
      }
      hold_arc(ref, sweep, eu, ev, c_u, c_v, turn, w, end);
    } else if (beta > kCornerTolerance) {
      // Convex: an arc about the programmed corner first.
      const double mu = pu + radius * std::cos(delta), mv = pv + radius * std::sin(delta);
      send_held();
      Pose corner = end;
      corner[ax.w] = cw;
      hold_arc(ref, 0.0, mu, mv, pu, pv, left() ? -1 : 1, cw, corner);
      send_held();
      set_start(mu, mv);
      hold_arc(ref, sweep, eu, ev, c_u, c_v, turn, w, end);
    } else {
      send_held();
      set_start(cu, cv);
      hold_arc(ref, sweep, eu, ev, c_u, c_v, turn, w, end);
    }
    pu = u;
    pv = v;
    pw = w;
    cu = eu;
    cv = ev;
    cw = w;
  }

  // Entry arc: an arc from the tool's centre through the compensated end, its centre
  // on the line from that end to the programmed centre (LinuxCNC's convert_arc_comp1).
  void arc_entry(const SourceRef& ref, double u, double v, double c_u, double c_v, int turn, double w,
                 const Pose& end) {
    if (std::hypot(u - cu, v - cv) <= radius)
      refuse("Radius of cutter compensation entry arc is not greater than the tool radius");
    const bool in = inside(turn);
    if (in && std::hypot(c_u - cu, c_v - cv) <= radius) refuse("Tool radius not less than arc radius with comp");
    const double gamma = in ? std::atan2(c_v - v, c_u - u) : std::atan2(v - c_v, u - c_u);
    first_move = false;
    pu = u;
    pv = v;
    pw = w;
    const double eu = u + radius * std::cos(gamma), ev = v + radius * std::sin(gamma);
    const double half_chord = std::hypot(cv - ev, cu - eu) / 2.0;
    const double to_centre = std::atan2(c_v - ev, c_u - eu);
    const double corner = std::atan2(cv - ev, cu - eu) - to_centre;
    if (std::fabs(std::cos(corner)) < kEqual) refuse("Tool radius not less than arc radius with comp");
    const double along = half_chord / std::cos(corner);
    const double nu = eu + along * std::cos(to_centre), nv = ev + along * std::sin(to_centre);
    if (std::fabs(std::hypot(nu - eu, nv - ev) - std::hypot(nu - cu, nv - cv)) > spiral_tolerance())
      refuse("Bug in tool radius comp");
    hold_arc(ref, sweep_of(cu, cv, nu, nv, turn, eu, ev), eu, ev, nu, nv, turn, w, end);
    cu = eu;
    cv = ev;
    cw = w;
  }

  // G40, M0/M1/M2/M30/M60: the held moves end where they are.
  void flush() {
    move_end_and_send(cu, cv);
    send_held();
  }
};

CutterComp::CutterComp(Canon& out) : CanonForward(out), impl_(std::make_unique<Impl>(out)) {}
CutterComp::~CutterComp() = default;

void CutterComp::start(int side, double radius, Plane plane, const Pose& programmed) {
  Impl& m = *impl_;
  if (m.side != 0) refuse("Cannot turn cutter radius comp on when on");
  if (plane != Plane::kXY && plane != Plane::kXZ) refuse("Cutter radius compensation allowed only in XY, XZ planes");
  if (side == 0) return;
  if (radius < 0) {  // LinuxCNC: a negative radius swaps the side
    radius = -radius;
    side = -side;
  }
  m.side = side > 0 ? 1 : -1;
  m.radius = radius;
  m.plane = plane;
  m.ax = axes_of(plane);
  m.first_move = true;
  m.stopped_off_path = false;
  m.pu = m.cu = programmed[m.ax.u];
  m.pv = m.cv = programmed[m.ax.v];
  m.pw = m.cw = programmed[m.ax.w];
}

void CutterComp::stop() {
  Impl& m = *impl_;
  if (m.compensating() && !m.first_move) {
    m.flush();
    m.arc_not_allowed = true;
    m.stopped_off_path = true;
  }
  m.side = 0;
  m.radius = 0;
  m.first_move = true;
}

bool CutterComp::active() const { return impl_->side != 0; }

bool CutterComp::tool_point(bool stopped, Plane& plane, double& u, double& v) const {
  const Impl& m = *impl_;
  if (stopped ? !m.stopped_off_path : !(m.compensating() && !m.first_move)) return false;
  plane = m.plane;
  u = m.cu;
  v = m.cv;
  return true;
}

void CutterComp::flush() {
  impl_->flush();
}

// ---- calls LinuxCNC queues behind a waiting move ------------------------------------

void CutterComp::set_feed_rate(const SourceRef& r, double f) {
  impl_->queue<&Canon::set_feed_rate>(r, f);
}
void CutterComp::set_feed_mode(const SourceRef& r, FeedMode m) {
  impl_->queue<&Canon::set_feed_mode>(r, m);
}
void CutterComp::dwell(const SourceRef& r, double s) {
  impl_->queue<&Canon::dwell>(r, s);
}
void CutterComp::set_spindle_speed(const SourceRef& r, double s) {
  impl_->queue<&Canon::set_spindle_speed>(r, s);
}
void CutterComp::set_spindle_mode(const SourceRef& r, double max_rpm) {
  impl_->queue<&Canon::set_spindle_mode>(r, max_rpm);
}
void CutterComp::orient_spindle(const SourceRef& r, double deg, int mode) {
  impl_->queue<&Canon::orient_spindle>(r, deg, mode);
}
void CutterComp::start_spindle_clockwise(const SourceRef& r) {
  impl_->queue<&Canon::start_spindle_clockwise>(r);
}
void CutterComp::start_spindle_counterclockwise(const SourceRef& r) {
  impl_->queue<&Canon::start_spindle_counterclockwise>(r);
}
void CutterComp::stop_spindle_turning(const SourceRef& r) {
  impl_->queue<&Canon::stop_spindle_turning>(r);
}
void CutterComp::mist_on(const SourceRef& r) {
  impl_->queue<&Canon::mist_on>(r);
}
void CutterComp::mist_off(const SourceRef& r) {
  impl_->queue<&Canon::mist_off>(r);
}
void CutterComp::flood_on(const SourceRef& r) {
  impl_->queue<&Canon::flood_on>(r);
}
void CutterComp::flood_off(const SourceRef& r) {
  impl_->queue<&Canon::flood_off>(r);
}
void CutterComp::comment(const SourceRef& r, const std::string& s) {
  impl_->queue<&Canon::comment>(r, s);
}
// Not a LinuxCNC call: the PROCESS directive follows its COMMENT, so it waits with it.
void CutterComp::set_process(const SourceRef& r, const ProcessSettings& p) {
  impl_->queue<&Canon::set_process>(r, p);
}

// ---- calls that change the filter's state (the others that are not queued pass
// straight on, before a waiting move, as in LinuxCNC) ----------------------------

void CutterComp::use_length_units(const SourceRef& r, Units u) {
  Impl& m = *impl_;
  if (m.stopped_off_path && u != m.units) {
    const double f = u == Units::kInch ? 1 / 25.4 : 25.4;
    m.cu *= f;
    m.cv *= f;
  }
  m.units = u;
  next_.use_length_units(r, u);
}

// LinuxCNC's reset empties its queue without sending it.
void CutterComp::on_reset(const SourceRef& r) {
  Impl& m = *impl_;
  m.held.clear();
  m.start_valid = false;
  m.side = 0;
  m.radius = 0;
  m.first_move = true;
  m.arc_not_allowed = false;
  next_.on_reset(r);
}

// ---- calls that end what is held first --------------------------------------------

// LinuxCNC refuses a tool change with compensation on; should one come, the held
// moves go first.
void CutterComp::start_change(const SourceRef& r) {
  flush();
  next_.start_change(r);
}
void CutterComp::change_tool(const SourceRef& r, int t) {
  flush();
  next_.change_tool(r, t);
}
void CutterComp::change_tool_number(const SourceRef& r, int t) {
  flush();
  next_.change_tool_number(r, t);
}
void CutterComp::program_stop(const SourceRef& r) {
  flush();
  next_.program_stop(r);
}
void CutterComp::optional_program_stop(const SourceRef& r) {
  flush();
  next_.optional_program_stop(r);
}
void CutterComp::pallet_shuttle(const SourceRef& r) {
  flush();
  next_.pallet_shuttle(r);
}
void CutterComp::program_end(const SourceRef& r) {
  flush();
  next_.program_end(r);
}

void CutterComp::finish(const SourceRef& r) {
  flush();
  next_.finish(r);
}

// ---- motion ------------------------------------------------------------------------

void CutterComp::straight_traverse(const SourceRef& r, const Pose& end) {
  Impl& m = *impl_;
  m.arc_not_allowed = false;
  m.stopped_off_path = false;
  if (!m.compensating()) {
    next_.straight_traverse(r, end);
    return;
  }
  m.straight(false, r, end);
}

void CutterComp::straight_feed(const SourceRef& r, const Pose& end) {
  Impl& m = *impl_;
  m.arc_not_allowed = false;
  m.stopped_off_path = false;
  if (!m.compensating()) {
    next_.straight_feed(r, end);
    return;
  }
  m.straight(true, r, end);
}

void CutterComp::arc_feed(const SourceRef& r, double first_end, double second_end, double first_axis,
                          double second_axis, int rotation, double axis_end, const Pose& end) {
  Impl& m = *impl_;
  if (m.arc_not_allowed) refuse("The move just after exiting cutter compensation mode must be straight, not an arc");
  m.stopped_off_path = false;
  if (!m.compensating()) {
    next_.arc_feed(r, first_end, second_end, first_axis, second_axis, rotation, axis_end, end);
    return;
  }
  m.arc(r, first_end, second_end, first_axis, second_axis, rotation, axis_end, end);
}

void CutterComp::nurbs_feed(const SourceRef& r, int order, const std::vector<NurbsPoint>& points,
                            const std::vector<double>& knots, const Pose& end) {
  if (impl_->side != 0) refuse("Cannot convert spline with cutter radius compensation");
  impl_->stopped_off_path = false;
  next_.nurbs_feed(r, order, points, knots, end);
}

}  // namespace cnc::rs274
