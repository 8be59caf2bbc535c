#include "common/rs274/block_builder.h"

#include "common/motion/path_segment.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "common/geometry/nurbs.h"
#include "common/geometry/polyline_fit.h"
#include "common/program/block_check.h"

namespace cnc::rs274 {

namespace {

constexpr double kMmPerInch = 25.4;
constexpr char kPoseLetters[] = "XYZABCUVW";
bool linear(size_t i) { return i < 3 || i >= 6; }

}  // namespace

BlockBuilder::BlockBuilder(BuilderSetup setup, std::function<const std::string&(int32_t)> file_name)
    : setup_(std::move(setup)), file_name_(std::move(file_name)) {
  path_tol_mm_ = setup_.default_path_tolerance_mm;  // a program starts in G64
  axis_of_pose_.assign(kNumAxes, -1);
  for (size_t a = 0; a < setup_.axis_names.size(); ++a) {
    const std::string& n = setup_.axis_names[a];
    for (int i = 0; i < kNumAxes; ++i)
      if (n.size() == 1 && n[0] == kPoseLetters[i]) axis_of_pose_[static_cast<size_t>(i)] = static_cast<int>(a);
  }
  position_ = setup_.start_position_mm;
  position_.resize(setup_.axis_names.size(), 0.0);
  speed_rpm_ = setup_.spindle_rpm;
  // No process law until the program describes its cut (set_process).
}

// Program coordinates (program units) → machine coordinates (mm), LinuxCNC's order:
// G92, then the XY rotation about the G5x origin, then G5x and the tool offset.
std::vector<double> BlockBuilder::to_machine(const SourceRef& ref, const Pose& p) const {
  Pose m{};
  for (size_t i = 0; i < m.size(); ++i) m[i] = (linear(i) ? p[i] * scale_ : p[i]) + g92_[i];
  if (rotation_deg_ != 0) {
    const double t = rotation_deg_ * M_PI / 180.0, c = std::cos(t), s = std::sin(t);
    const double x = m[0] * c - m[1] * s, y = m[0] * s + m[1] * c;
    m[0] = x;
    m[1] = y;
  }
  std::vector<double> out = position_;
  for (size_t i = 0; i < m.size(); ++i) {
    const double v = m[i] + g5x_[i] + tool_[i];
    const int a = axis_of_pose_[i];
    if (a >= 0) {
      out[static_cast<size_t>(a)] = v;
    } else if (std::fabs(v) > 1e-9) {
      throw Error(ref.column, std::string("a move of axis ") + kPoseLetters[i] + ", which the machine does not have");
    }
  }
  for (double v : out)
    if (!std::isfinite(v)) throw Error(ref.column, "a coordinate is not a finite number");
  return out;
}

double BlockBuilder::feed_mm_per_min(const SourceRef& ref) const {
  double f = feed_ * scale_;
  if (feed_mode_ == FeedMode::kUnitsPerRev) {
    if (spindle_dir_ == 0 || speed_rpm_ <= 0) throw Error(ref.column, "feed per revolution (G95) with the spindle stopped");
    f *= speed_rpm_;
  }
  if (!(f > 0) || !std::isfinite(f)) throw Error(ref.column, "a feed move with no feed rate");
  return f;
}

// LinuxCNC's feed rules ("G-code overview, Feed rate"; G93): with a linear axis
// moving, the move takes its linear length over F and the rotary axes arrive with it;
// with only rotary axes, F is deg/min (no inch scaling). G93 has made F the rate
// along that same length already (the interpreter). The planner's path is the
// Euclidean length over all axes, mm and degrees alike: the same time at that rate.
bool BlockBuilder::rotary_moves(const std::vector<double>& to) const {
  for (size_t a = 0; a < to.size() && a < position_.size(); ++a)
    if (rotary(a) && to[a] != position_[a]) return true;
  return false;
}

double BlockBuilder::rotary_feed(const SourceRef& ref, const std::vector<double>& to, double lin_len, double f) const {
  double rot2 = 0;
  for (size_t a = 0; a < to.size() && a < position_.size(); ++a)
    if (rotary(a)) rot2 += (to[a] - position_[a]) * (to[a] - position_[a]);
  if (rot2 == 0) return f;  // no rotary motion: F as it always was
  if (lin_len > 0) return f * std::sqrt(lin_len * lin_len + rot2) / lin_len;
  // F as set, deg/min (G20 scales it not); f has passed feed_mm_per_min's checks.
  const double deg = angular_feed_ * (feed_mode_ == FeedMode::kUnitsPerRev ? speed_rpm_ : 1.0);
  if (!(deg > 0) || !std::isfinite(deg)) throw Error(ref.column, "a feed move with no feed rate");
  return deg;
}

program::Block& BlockBuilder::begin(const SourceRef& ref, program::BlockKind kind) {
  // Whatever comes after a run of G1 moves held for blending ends the run first.
  if (!run_.empty() && !flushing_) flush_run();
  program::Block b;
  b.index = next_index_++;
  b.source_line = ref.line;
  b.source_column = ref.column;
  b.source_file = file_name_(ref.file);
  b.kind = kind;
  b.start = position_;
  b.end = position_;
  b.spindle_rpm = spindle_dir_ != 0 ? speed_rpm_ : 0.0;
  b.process = process_;
  b.path_tolerance_mm = path_tol_mm_;
  out_.push_back(std::move(b));
  return out_.back();
}

void BlockBuilder::event(const SourceRef& ref, program::EventKind kind, int32_t number, double value, std::string text) {
  program::Block& b = begin(ref, program::BlockKind::kEvent);
  b.event.kind = kind;
  b.event.number = number;
  b.event.value = value;
  b.event.text = std::move(text);
}

void BlockBuilder::use_length_units(const SourceRef&, Units u) {
  const double s = u == Units::kInch ? kMmPerInch : 1.0;
  feed_ *= scale_ / s;  // the feed keeps its value in mm/min
  scale_ = s;
}
void BlockBuilder::select_plane(const SourceRef&, Plane p) { plane_ = p; }
void BlockBuilder::set_g5x_offset(const SourceRef&, int, const Pose& p) {
  for (size_t i = 0; i < p.size(); ++i) g5x_[i] = linear(i) ? p[i] * scale_ : p[i];
}
void BlockBuilder::set_g92_offset(const SourceRef&, const Pose& p) {
  for (size_t i = 0; i < p.size(); ++i) g92_[i] = linear(i) ? p[i] * scale_ : p[i];
}
void BlockBuilder::set_xy_rotation(const SourceRef&, double deg) { rotation_deg_ = deg; }
void BlockBuilder::set_feed_rate(const SourceRef&, double rate) {
  feed_ = rate;
  angular_feed_ = rate;  // LinuxCNC's canon: the angular rate is the number as set, whatever the units later
}
void BlockBuilder::set_feed_mode(const SourceRef&, FeedMode m) {
  // Inverse-time rates arrive already as units per minute along each move.
  feed_mode_ = m == FeedMode::kUnitsPerRev ? m : FeedMode::kUnitsPerMinute;
}
void BlockBuilder::use_tool_length_offset(const SourceRef&, const Pose& p) {
  for (size_t i = 0; i < p.size(); ++i) tool_[i] = linear(i) ? p[i] * scale_ : p[i];
}

void BlockBuilder::straight_traverse(const SourceRef& ref, const Pose& end) {
  std::vector<double> e = to_machine(ref, end);
  program::Block& b = begin(ref, program::BlockKind::kRapid);
  b.end = e;
  position_ = std::move(e);
}

void BlockBuilder::set_motion_control_mode(const SourceRef&, PathMode mode, double tolerance) {
  if (!run_.empty()) flush_run();
  path_mode_ = mode;
  if (mode != PathMode::kContinuous)
    path_tol_mm_ = 0;
  else
    path_tol_mm_ = tolerance > 0 && std::isfinite(tolerance) ? tolerance * scale_ : setup_.default_path_tolerance_mm;
}

bool BlockBuilder::blending() const {
  return path_tol_mm_ > 0 && setup_.axis_names.size() >= 3 && axis_of_pose_[0] == 0 && axis_of_pose_[1] == 1 &&
         axis_of_pose_[2] == 2;
}

void BlockBuilder::straight_feed(const SourceRef& ref, const Pose& end) {
  if (sync_pitch_mm_ > 0) {
    synced_line(ref, end, program::kSyncG33, 1.0);
    return;
  }
  std::vector<double> e = to_machine(ref, end);
  double lin2 = 0;
  for (size_t a = 0; a < e.size(); ++a)
    if (!rotary(a)) lin2 += (e[a] - position_[a]) * (e[a] - position_[a]);
  const double f = rotary_feed(ref, e, std::sqrt(lin2), feed_mm_per_min(ref));
  if (hold_move(ref, e, f)) return;
  program::Block& b = begin(ref, program::BlockKind::kLine);
  b.end = e;
  b.feed_mm_per_min = f;
  position_ = std::move(e);
}

bool BlockBuilder::hold_move(const SourceRef& ref, std::vector<double>& e, double f) {
  if (blending()) {
    const double rpm = spindle_dir_ != 0 ? speed_rpm_ : 0.0;
    bool same = !run_.empty() && f == run_feed_ && rpm == run_rpm_ &&
                process_.ball_radius_mm == run_process_.ball_radius_mm && process_.flutes == run_process_.flutes &&
                process_.pick_feed_mm == run_process_.pick_feed_mm &&
                process_.target_rmax_um == run_process_.target_rmax_um;
    // Only X Y Z move in a run (the blends and fits are curves in X Y Z).
    bool xyz = true;
    for (size_t a = 3; a < e.size(); ++a) xyz = xyz && e[a] == position_[a];
    if (!run_.empty() && (!same || !xyz)) flush_run();
    if (xyz) {
      double len2 = 0;
      for (size_t a = 0; a < 3; ++a) len2 += (e[a] - position_[a]) * (e[a] - position_[a]);
      if (len2 == 0) return true;  // a move to where the tool stands: nothing to blend
      if (run_.empty()) {
        run_.push_back({position_, ref, {}, {}});
        run_feed_ = f;
        run_rpm_ = rpm;
        run_process_ = process_;
        run_sagitta_mm_ = 0;
      }
      run_.push_back({e, ref, {}, {}});
      position_ = std::move(e);
      return true;
    }
  }
  return false;
}

bool BlockBuilder::hold_arc(const SourceRef& ref, const program::Block& arc, int a1, int a2) {
  if (!blending() || !setup_.fit_runs) return false;
  for (size_t a = 3; a < arc.end.size(); ++a)
    if (arc.end[a] != position_[a]) return false;
  const double tol = program::shape_tolerance_mm(path_tol_mm_, setup_.chord_tolerance_mm);
  const motion::PathSegment seg(arc, static_cast<int>(setup_.axis_names.size()));
  if (seg.degenerate()) return false;
  // Chords with a sagitta of a tenth of the shape tolerance (L = sqrt(8·r·s)), each
  // short enough and turning little enough to stay in a fitted run; the run's fit and
  // blends then keep within the rest of it, so the path stays within P of the arc.
  const program::ArcGeometry& g = arc.arc;
  const size_t i1 = static_cast<size_t>(a1), i2 = static_cast<size_t>(a2);
  const double r0 = std::hypot(arc.start[i1] - g.center[i1], arc.start[i2] - g.center[i2]);
  const double r1 = std::hypot(arc.end[i1] - g.center[i1], arc.end[i2] - g.center[i2]);
  const double r = std::min(r0, r1);
  const double sag = 0.1 * tol;
  if (!(r > 0) || !(sag > 0)) return false;
  const double max_turn = 0.9 * setup_.fit_max_turn_deg * M_PI / 180.0;
  const double chord = std::min({std::sqrt(8.0 * r * sag), r * max_turn, setup_.fit_max_segment_mm});
  // A full circle or more (a helical bore) is left exact: it has no junction to smooth
  // but its two ends, and its chords' fit would turn at every one of them.
  const double sweep = seg.arc_sweep_rad();
  if (sweep >= 2.0 * M_PI * (1 - 1e-9)) return false;
  const size_t n = static_cast<size_t>(std::ceil(sweep * std::max(r0, r1) / chord));
  if (n == 0 || n > 100000) return false;
  auto tangent = [&](double u) {
    motion::AxisVec p{}, d1{}, d2{};
    seg.eval(u, &p, &d1, &d2);
    const Eigen::Vector3d t(d1[0], d1[1], d1[2]);
    return Eigen::Vector3d(t / t.norm());
  };
  const Eigen::Vector3d t_start = tangent(seg.u_begin()), t_end = tangent(seg.u_end());
  if (!t_start.allFinite() || !t_end.allFinite()) return false;
  for (size_t k = 1; k <= n; ++k) {
    std::vector<double> e = arc.end;
    if (k < n) {
      const double u = seg.u_begin() + (seg.u_end() - seg.u_begin()) * static_cast<double>(k) / static_cast<double>(n);
      const motion::AxisVec p = seg.point(u);
      for (size_t a = 0; a < e.size(); ++a) e[a] = p[a];
    }
    if (!hold_move(ref, e, arc.feed_mm_per_min)) return false;  // not for the first chord: the run takes all
    run_sagitta_mm_ = std::max(run_sagitta_mm_, sag);
    if (k == 1 && run_.size() >= 2) run_[run_.size() - 2].leave = t_start;
    if (k == n) run_.back().arrive = t_end;
  }
  return true;
}

program::Block& BlockBuilder::run_block(const SourceRef& ref, program::BlockKind kind, const std::vector<double>& from,
                                        const std::vector<double>& to) {
  program::Block& b = begin(ref, kind);
  b.start = from;
  b.end = to;
  b.feed_mm_per_min = run_feed_;
  b.spindle_rpm = run_rpm_;
  b.process = run_process_;
  return b;
}

bool BlockBuilder::resolvable_blend(double d, const Eigen::Vector3d& u_in, const Eigen::Vector3d& u_out,
                                    double feed_mm_s) const {
  if (!(d > 0)) return false;
  const double T = setup_.ipo_period_s;
  // The quartic blend's curvature at its middle (its largest): 3·sin(θ/2) / (4·d·cos²(θ/2))
  // for a turn θ; there its speed is at most sqrt((A/2)/κ).
  const double half = 0.5 * std::acos(std::clamp(u_in.dot(u_out), -1.0, 1.0));
  const double c = std::cos(half);
  const double kappa = 3.0 * std::sin(half) / (4.0 * d * c * c);
  double v = feed_mm_s;
  if (setup_.accel_mm_s2 > 0 && kappa > 0) v = std::min(v, std::sqrt(0.5 * setup_.accel_mm_s2 / kappa));
  const double step = std::max(v * T, setup_.jerk_mm_s3 * T * T * T / 6.0);
  // 1.5 steps: a 1 um blend the interpolation crossed in about one made 1.21x an axis's jerk.
  return 4.0 * d >= 1.5 * step;
}

// The run's moves as the flush sees them: vertices, each move's length, direction and
// end tangents, and the blend leg at each vertex (vertex j joins move j-1 and move j;
// 0: no blend there).
struct BlockBuilder::RunShape {
  double tol = 0;
  size_t n = 0;  // moves
  std::vector<Eigen::Vector3d> pts, dir, t_leave, t_arrive;
  std::vector<double> len, leg;
  // A stretch's ends: where it begins and ends, moved back along its end moves by the
  // blends there.
  Eigen::Vector3d stretch_start(size_t a) const { return pts[a] + 2.0 * leg[a] * dir[a]; }
  Eigen::Vector3d stretch_end(size_t b) const { return pts[b] - 2.0 * leg[b] * dir[b - 1]; }
};

// Moves [a, b) of the run fitted as one cubic spline.
struct BlockBuilder::Stretch {
  size_t a, b;
  geometry::CubicFit fit;
};

BlockBuilder::RunShape BlockBuilder::run_shape(double tol) const {
  RunShape r;
  r.tol = tol;
  r.n = run_.size() - 1;
  const size_t n = r.n;
  r.pts.resize(run_.size());
  for (size_t i = 0; i < run_.size(); ++i) r.pts[i] = Eigen::Vector3d(run_[i].pos[0], run_[i].pos[1], run_[i].pos[2]);
  r.len.resize(n);
  r.dir.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = r.pts[i + 1] - r.pts[i];
    r.len[i] = d.norm();
    r.dir[i] = d / r.len[i];
  }
  // Each move's tangent where it leaves and arrives: its direction, or an arc's own
  // tangent at the arc's first and last chord (a stretch then leaves and ends along the
  // arc, not its chord).
  r.t_leave = r.dir;
  r.t_arrive = r.dir;
  for (size_t i = 0; i < n; ++i) {
    if (run_[i].leave) r.t_leave[i] = *run_[i].leave;
    if (run_[i + 1].arrive) r.t_arrive[i] = *run_[i + 1].arrive;
  }
  // Blend legs, used where the vertex is not inside a fitted stretch: between two
  // lines, or where a stretch ends.
  r.leg.assign(n + 1, 0.0);
  for (size_t j = 1; j < n; ++j) {
    r.leg[j] = geometry::corner_blend_leg(r.dir[j - 1], r.dir[j], tol, 0.5 * std::min(r.len[j - 1], r.len[j]));
    const double v = run_feed_ / 60.0;
    // (At an arc's end the kink is the one between the arc's tangent and the move's.)
    if (setup_.corner_dv_mm_s >= v * (r.t_leave[j] - r.t_arrive[j - 1]).norm() ||
        !resolvable_blend(r.leg[j], r.dir[j - 1], r.dir[j], v))
      r.leg[j] = 0;
  }
  return r;
}

// Stretches of short, gently turning moves that the fit holds within tol, in order;
// the legs inside a stretch become 0 (no blend there).
std::vector<BlockBuilder::Stretch> BlockBuilder::fit_stretches(RunShape& r) const {
  std::vector<Stretch> stretches;
  const size_t n = r.n;
  constexpr size_t kMinMoves = 4;
  // A stretch the fit cannot hold within P (a sharp turn that is no corner by the
  // run's rule) is cut at its sharpest turn and each part tried again. It leaves and
  // ends along its end moves, so the blends or lines there join it smoothly.
  std::function<void(size_t, size_t)> fit_range = [&](size_t a, size_t b) {
    if (b - a < kMinMoves) return;
    std::vector<Eigen::Vector3d> sub(r.pts.begin() + static_cast<std::ptrdiff_t>(a),
                                     r.pts.begin() + static_cast<std::ptrdiff_t>(b + 1));
    sub.front() = r.stretch_start(a);
    sub.back() = r.stretch_end(b);
    geometry::CubicFit fit = geometry::fit_cubic(
        sub, r.tol, {r.leg[a] > 0 ? r.dir[a] : r.t_leave[a], r.leg[b] > 0 ? r.dir[b - 1] : r.t_arrive[b - 1]});
    if (fit.ok) {
      stretches.push_back({a, b, std::move(fit)});
      return;
    }
    size_t cut = a + 1;
    for (size_t j = a + 1; j < b; ++j)
      if (r.dir[j - 1].dot(r.dir[j]) < r.dir[cut - 1].dot(r.dir[cut])) cut = j;
    fit_range(a, cut);
    fit_range(cut, b);
  };
  if (setup_.fit_runs) {
    const double cos_turn = std::cos(setup_.fit_max_turn_deg * M_PI / 180.0);
    const double max_segment = std::max(setup_.fit_max_segment_mm, setup_.fit_max_segment_per_p * path_tol_mm_);
    for (size_t a = 0; a < n;) {
      if (r.len[a] > max_segment) {
        ++a;
        continue;
      }
      size_t b = a + 1;
      while (b < n && r.len[b] <= max_segment && r.dir[b - 1].dot(r.dir[b]) >= cos_turn) ++b;
      fit_range(a, b);
      a = b;
    }
  }
  std::sort(stretches.begin(), stretches.end(), [](const Stretch& x, const Stretch& y) { return x.a < y.a; });
  // fitted[i]: the stretch (from 1) move i belongs to; 0: a line.
  std::vector<size_t> fitted(n, 0);
  for (size_t k = 0; k < stretches.size(); ++k)
    for (size_t i = stretches[k].a; i < stretches[k].b; ++i) fitted[i] = k + 1;
  for (size_t j = 1; j < n; ++j)
    if (fitted[j - 1] != 0 && fitted[j - 1] == fitted[j]) r.leg[j] = 0;  // inside a stretch
  return stretches;
}

// The run's blocks: each stretch as NURBS pieces, each remaining move as a line cut
// short by the blends at its ends, each blend as a quartic NURBS.
void BlockBuilder::emit_run(const RunShape& r, const std::vector<Stretch>& stretches) {
  const size_t n = r.n;
  std::vector<double> cursor = run_[0].pos;
  auto at = [&](const Eigen::Vector3d& p) {
    std::vector<double> v = run_[0].pos;
    for (size_t k = 0; k < 3; ++k) v[k] = p[static_cast<Eigen::Index>(k)];
    return v;
  };
  auto nurbs_block = [&](const SourceRef& ref, int order, std::vector<double> knots,
                         const std::vector<Eigen::Vector3d>& ctrl, const std::vector<double>& end) {
    program::Block& b = run_block(ref, program::BlockKind::kNurbs, cursor, end);
    b.nurbs.order = order;
    b.nurbs.knots = std::move(knots);
    for (const auto& c : ctrl) {
      b.nurbs.control_points.push_back({c[0], c[1], c[2]});
      b.nurbs.weights.push_back(1.0);
    }
    if (const std::string why = program::check_nurbs_block(b); !why.empty())
      throw Error(file_name_(ref.file), ref, "G64 P: the fitted curve is not a valid NURBS (" + why + ")");
    cursor = end;
  };
  // The blend at vertex j, from the cursor (where the move before it was cut short).
  auto blend = [&](size_t j) {
    const double d = r.leg[j];
    const Eigen::Vector3d v = r.pts[j];
    const std::vector<Eigen::Vector3d> q = {v - 2 * d * r.dir[j - 1], v - d * r.dir[j - 1], v, v + d * r.dir[j],
                                            v + 2 * d * r.dir[j]};
    // Knots spanning the blend's approximate length, as the parameter of a G5.2 curve would.
    const double s = 4.0 * d;
    nurbs_block(run_[j].ref, 5, {0, 0, 0, 0, 0, s, s, s, s, s}, q, at(q.back()));
  };
  size_t next_stretch = 0;
  for (size_t i = 0; i < n;) {
    if (next_stretch < stretches.size() && stretches[next_stretch].a == i) {
      const Stretch& st = stretches[next_stretch++];
      const std::vector<geometry::CubicPiece> pieces =
          geometry::split_cubic(st.fit.knots, st.fit.ctrl, setup_.fit_max_spans);
      for (size_t k = 0; k < pieces.size(); ++k) {
        const geometry::CubicPiece& pc = pieces[k];
        // The piece's source: the move its start lies on.
        const double u0 = pc.knots.front();
        const auto it = std::upper_bound(st.fit.params.begin(), st.fit.params.end(), u0);
        size_t move = st.a + static_cast<size_t>(std::max<std::ptrdiff_t>(1, it - st.fit.params.begin()));
        move = std::min(move, st.b);
        // The last piece ends exactly where the stretch's last move ends, or its blend begins.
        const std::vector<double> end = k + 1 < pieces.size() ? at(pc.ctrl.back())
                                        : r.leg[st.b] > 0     ? at(r.stretch_end(st.b))
                                                              : run_[st.b].pos;
        nurbs_block(run_[move].ref, 4, pc.knots, pc.ctrl, end);
      }
      i = st.b;
      if (r.leg[i] > 0) blend(i);
      continue;
    }
    // A line, shortened by the blends at its ends, and the blend at its end.
    const Eigen::Vector3d to = r.pts[i + 1] - 2.0 * r.leg[i + 1] * r.dir[i];
    const std::vector<double> line_end = r.leg[i + 1] > 0 ? at(to) : run_[i + 1].pos;
    double d2 = 0;
    for (size_t k = 0; k < 3; ++k) d2 += (line_end[k] - cursor[k]) * (line_end[k] - cursor[k]);
    if (d2 > 0) {
      run_block(run_[i + 1].ref, program::BlockKind::kLine, cursor, line_end);
      cursor = line_end;
    }
    if (r.leg[i + 1] > 0) blend(i + 1);
    ++i;
  }
}

// A run of G1 moves under G64 P, as blocks: stretches of short, gently turning
// moves fitted to cubic splines (cut into NURBS blocks), the remaining lines with
// each corner between two of them rounded by a quartic blend, both within P less
// the interpolation's chord share (program::shape_tolerance_mm) at every point.
// The run's end is where the last move ends, exactly.
void BlockBuilder::flush_run() {
  if (run_.size() < 2) {
    run_.clear();
    return;
  }
  flushing_ = true;
  // Less the chords' sagitta where the run holds arcs.
  RunShape shape = run_shape(program::shape_tolerance_mm(path_tol_mm_, setup_.chord_tolerance_mm) - run_sagitta_mm_);
  const std::vector<Stretch> stretches = fit_stretches(shape);
  emit_run(shape, stretches);
  run_.clear();
  flushing_ = false;
}

void BlockBuilder::arc_feed(const SourceRef& ref, double, double, double first_axis, double second_axis, int rotation,
                            double, const Pose& end) {
  if (plane_ != Plane::kXY && plane_ != Plane::kXZ && plane_ != Plane::kYZ)
    throw Error(ref.column, "arcs in the UV, VW or UW plane are not supported");
  if (rotation_deg_ != 0 && plane_ != Plane::kXY)
    throw Error(ref.column, "an arc outside the XY plane in a rotated coordinate system (G10 L2 R) is not supported");
  int a1 = 0, a2 = 1, pl = 17;
  if (plane_ == Plane::kXZ) a1 = 2, a2 = 0, pl = 18;
  if (plane_ == Plane::kYZ) a1 = 1, a2 = 2, pl = 19;
  if (axis_of_pose_[0] != 0 || axis_of_pose_[1] != 1 || axis_of_pose_[2] != 2)
    throw Error(ref.column, "arcs need the machine's first three axes to be X, Y and Z");
  std::vector<double> e = to_machine(ref, end);
  // The centre: the end pose with the plane's two coordinates replaced.
  Pose c = end;
  c[static_cast<size_t>(a1)] = first_axis;
  c[static_cast<size_t>(a2)] = second_axis;
  const std::vector<double> center = to_machine(ref, c);
  double f = feed_mm_per_min(ref);
  if (rotary_moves(e)) {
    // Rotary axes turning along the arc: its linear length is the plane's sweep (at the
    // mean radius: exact for circles and helices) with the other linear axes' travel.
    program::Block arc;
    arc.kind = rotation < 0 ? program::BlockKind::kArcCw : program::BlockKind::kArcCcw;
    arc.start = position_;
    arc.end = e;
    arc.arc.center = center;
    arc.arc.plane = pl;
    arc.arc.turns = std::abs(rotation) - 1;
    if (program::check_arc_block(arc).empty()) {
      const motion::PathSegment seg(arc, static_cast<int>(setup_.axis_names.size()));
      const size_t i1 = static_cast<size_t>(a1), i2 = static_cast<size_t>(a2);
      const double r0 = std::hypot(position_[i1] - center[i1], position_[i2] - center[i2]);
      const double r1 = std::hypot(e[i1] - center[i1], e[i2] - center[i2]);
      double lin2 = std::pow(0.5 * (r0 + r1) * seg.arc_sweep_rad(), 2);
      for (size_t a = 0; a < e.size(); ++a)
        if (!rotary(a) && a != i1 && a != i2) lin2 += (e[a] - position_[a]) * (e[a] - position_[a]);
      f = rotary_feed(ref, e, std::sqrt(lin2), f);
    }
  }
  {
    // Under G64 P an arc joins the run of G1 moves as chords, to be fitted with them.
    program::Block arc;
    arc.kind = rotation < 0 ? program::BlockKind::kArcCw : program::BlockKind::kArcCcw;
    arc.start = position_;
    arc.end = e;
    arc.feed_mm_per_min = f;
    arc.arc.center = center;
    arc.arc.plane = pl;
    arc.arc.turns = std::abs(rotation) - 1;
    if (program::check_arc_block(arc).empty() && hold_arc(ref, arc, a1, a2)) return;
  }
  program::Block& b = begin(ref, rotation < 0 ? program::BlockKind::kArcCw : program::BlockKind::kArcCcw);
  b.end = e;
  b.feed_mm_per_min = f;
  b.arc.center = center;
  b.arc.plane = pl;
  b.arc.turns = std::abs(rotation) - 1;
  const std::string why = program::check_arc_block(b);
  if (!why.empty()) {
    out_.pop_back();
    --next_index_;
    throw Error(ref.column, "this arc cannot run on the cell: " + why);
  }
  position_ = std::move(e);
}

namespace {

// Cusps of a NURBS: parameters inside it where its tangent vanishes and reverses
// (control points in a line that turn back, as on a face of the travel): the curve
// comes to a point and goes back the way it came. Found where the tangent of two
// neighbouring samples (64 per knot span) points apart, located by bisection on the
// tangent's component along the direction before, and kept where the tangent
// there is nil against the span's (a smooth tight turn keeps its tangent).
std::vector<double> find_cusps(const program::NurbsGeometry& g) {
  std::vector<double> out;
  std::vector<geometry::Vec3> ctrl;
  for (const auto& c : g.control_points)
    ctrl.emplace_back(c[0] - g.control_points.front()[0], c[1] - g.control_points.front()[1],
                      c[2] - g.control_points.front()[2]);
  const geometry::NurbsCurve curve(g.order, g.knots, ctrl, g.weights);
  const std::vector<double> bp = curve.breakpoints();
  const double u_lo = curve.u_min(), u_hi = curve.u_max();
  auto tangent = [&](double u) {
    geometry::Vec3 d[2];
    curve.derivatives(u, 1, d);
    return d[1];
  };
  constexpr int kPerSpan = 64;
  for (size_t k = 0; k + 1 < bp.size(); ++k) {
    const double a = bp[k], b = bp[k + 1];
    // Inside the span (a knot is a corner's place: split_at_corners' business).
    geometry::Vec3 t0 = tangent(a + 1e-9 * (b - a));
    double u0 = a, top = t0.norm();
    for (int i = 1; i <= kPerSpan; ++i) {
      const double u1 = i == kPerSpan ? b - 1e-9 * (b - a) : a + (b - a) * i / kPerSpan;
      const geometry::Vec3 t1 = tangent(u1);
      top = std::max(top, t1.norm());
      if (t0.norm() > 0 && t1.norm() > 0 && t0.dot(t1) < 0) {
        const geometry::Vec3 dir = t0.normalized();
        double lo = u0, hi = u1;
        for (int it = 0; it < 200; ++it) {
          const double mid = 0.5 * (lo + hi);
          if (mid <= lo || mid >= hi) break;
          (tangent(mid).dot(dir) > 0 ? lo : hi) = mid;
        }
        const double uc = 0.5 * (lo + hi);
        const double near_end = 1e-9 * (u_hi - u_lo);
        if (tangent(uc).norm() <= 1e-6 * std::max(top, tangent(u0).norm()) && uc > u_lo + near_end &&
            uc < u_hi - near_end && (out.empty() || uc > out.back()))
          out.push_back(uc);
      }
      t0 = t1;
      u0 = u1;
    }
  }
  return out;
}

// Knot u inserted into g until its multiplicity is the degree (Boehm's insertion on
// the homogeneous control points, The NURBS Book A5.1, one knot at a time): the
// same curve, passing through a control point at u. Returns the index of u's first
// copy in the knot vector.
int insert_knot_to_degree(program::NurbsGeometry* g, double u) {
  const int p = g->order - 1;
  for (;;) {
    std::vector<double>& U = g->knots;
    const int n = static_cast<int>(g->control_points.size());
    const int first = static_cast<int>(std::lower_bound(U.begin(), U.end(), u) - U.begin());
    int mult = 0;
    while (first + mult < static_cast<int>(U.size()) && U[static_cast<size_t>(first + mult)] == u) ++mult;
    if (mult >= p) return first;
    const int k = first - 1;  // U[k] < u < U[k+1] (or u == U[k+1..]: the span before its copies)
    std::vector<std::array<double, 4>> q(static_cast<size_t>(n + 1));
    auto pw = [&](int i) {
      const auto& c = g->control_points[static_cast<size_t>(i)];
      const double w = g->weights[static_cast<size_t>(i)];
      return std::array<double, 4>{c[0] * w, c[1] * w, c[2] * w, w};
    };
    for (int i = 0; i <= n; ++i) {
      if (i <= k - p) {
        q[static_cast<size_t>(i)] = pw(i);
      } else if (i > k) {
        q[static_cast<size_t>(i)] = pw(i - 1);
      } else {
        const double alpha =
            (u - U[static_cast<size_t>(i)]) / (U[static_cast<size_t>(i + p)] - U[static_cast<size_t>(i)]);
        const auto A = pw(i), B = pw(i - 1);
        for (int c = 0; c < 4; ++c) q[static_cast<size_t>(i)][static_cast<size_t>(c)] = alpha * A[c] + (1 - alpha) * B[c];
      }
    }
    const std::vector<std::array<double, 3>> old_pts = g->control_points;
    U.insert(U.begin() + first, u);
    g->control_points.resize(static_cast<size_t>(n + 1));
    g->weights.resize(static_cast<size_t>(n + 1));
    for (int i = 0; i <= n; ++i) {
      const auto& h = q[static_cast<size_t>(i)];
      g->weights[static_cast<size_t>(i)] = h[3];
      auto& c = g->control_points[static_cast<size_t>(i)];
      c = {h[0] / h[3], h[1] / h[3], h[2] / h[3]};
      // A coordinate both blended points share stays exact (a plane's normal axis,
      // points on a face: no rounding noise for the curvature to see).
      if (i > k - p && i <= k)
        for (int a = 0; a < 3; ++a)
          if (old_pts[static_cast<size_t>(i)][static_cast<size_t>(a)] == old_pts[static_cast<size_t>(i - 1)][static_cast<size_t>(a)])
            c[static_cast<size_t>(a)] = old_pts[static_cast<size_t>(i)][static_cast<size_t>(a)];
    }
  }
}

// The curve in two at knot index i whose value has multiplicity = degree (the
// curve passes through control point i - 1 there): both pieces clamped.
void cut_at_knot(const program::NurbsGeometry& g, int cut_i, program::NurbsGeometry* left,
                 program::NurbsGeometry* right) {
  const int order = g.order, p = order - 1;
  const auto& U = g.knots;
  const int j = cut_i - 1;
  const double ub = U[static_cast<size_t>(cut_i)];
  left->order = right->order = order;
  left->knots.assign(U.begin(), U.begin() + cut_i + p);
  left->knots.push_back(ub);
  left->control_points.assign(g.control_points.begin(), g.control_points.begin() + j + 1);
  left->weights.assign(g.weights.begin(), g.weights.begin() + j + 1);
  right->knots.clear();
  right->knots.push_back(ub);
  right->knots.insert(right->knots.end(), U.begin() + cut_i, U.end());
  right->control_points.assign(g.control_points.begin() + j, g.control_points.end());
  right->weights.assign(g.weights.begin() + j, g.weights.end());
}

// A NURBS in pieces at its cusps (each cusp the end of one piece and the start of
// the next: a junction that turns back, which the planner takes as a stop).
std::vector<program::NurbsGeometry> split_at_cusps(const program::NurbsGeometry& g) {
  std::vector<program::NurbsGeometry> parts;
  if (g.order < 2) return {g};
  const std::vector<double> cusps = find_cusps(g);
  if (cusps.empty()) return {g};
  program::NurbsGeometry rest = g;
  for (double uc : cusps) {
    const int cut_i = insert_knot_to_degree(&rest, uc);
    program::NurbsGeometry left, right;
    cut_at_knot(rest, cut_i, &left, &right);
    parts.push_back(std::move(left));
    rest = std::move(right);
  }
  parts.push_back(std::move(rest));
  return parts;
}

// A NURBS with a sharp corner inside (a knot of multiplicity >= its degree where
// the control polygon turns: the curve passes through that control point with the
// tangent of the leg before it, and leaves along the leg after it) in pieces at
// those corners, so each corner is a junction between blocks, with the junction's
// corner speed or stop, as the planner treats a G1 corner. (A single block crossed
// it at full feed: the curvature samples cannot see a kink.) Each piece is the
// same curve on its own parameter range; a smooth knot (the legs in line) stays.
std::vector<program::NurbsGeometry> split_at_corners(const program::NurbsGeometry& g) {
  std::vector<program::NurbsGeometry> parts;
  program::NurbsGeometry rest = g;
  for (;;) {
    const int order = rest.order, p = order - 1;
    const int n = static_cast<int>(rest.control_points.size());
    const auto& U = rest.knots;
    int cut_i = -1, cut_m = 0;
    for (int i = order; i < n;) {
      int m = 1;
      while (i + m < n && U[static_cast<size_t>(i + m)] == U[static_cast<size_t>(i)]) ++m;
      if (m >= p && p >= 1) {
        const int j = i - 1;  // the curve passes through P_j at this knot
        if (j >= 1 && j + 1 < n) {
          // The legs to the nearest control points that differ from P_j (a doubled
          // point beside it is a leg of no length: the turn is to the next one).
          const auto& c = rest.control_points[static_cast<size_t>(j)];
          int ja = j - 1, jd = j + 1;
          while (ja > 0 && rest.control_points[static_cast<size_t>(ja)] == c) --ja;
          while (jd + 1 < n && rest.control_points[static_cast<size_t>(jd)] == c) ++jd;
          const auto& a = rest.control_points[static_cast<size_t>(ja)];
          const auto& d = rest.control_points[static_cast<size_t>(jd)];
          double l0 = 0, l1 = 0, dot = 0;
          for (int k = 0; k < 3; ++k) {
            const double e0 = c[static_cast<size_t>(k)] - a[static_cast<size_t>(k)];
            const double e1 = d[static_cast<size_t>(k)] - c[static_cast<size_t>(k)];
            l0 += e0 * e0;
            l1 += e1 * e1;
            dot += e0 * e1;
          }
          // Turns by more than 1e-9 rad (both legs of non-zero length).
          if (l0 > 0 && l1 > 0 && dot < std::sqrt(l0 * l1) * (1.0 - 5e-19)) {
            cut_i = i;
            cut_m = m;
            break;
          }
        }
      }
      i += m;
    }
    if (cut_i < 0 || cut_m != p) break;  // no corner (a multiplicity of `order` is a gap: refused before)
    const int j = cut_i - 1;
    const double ub = U[static_cast<size_t>(cut_i)];
    program::NurbsGeometry left, right;
    left.order = right.order = order;
    left.knots.assign(U.begin(), U.begin() + cut_i + p);
    left.knots.push_back(ub);
    left.control_points.assign(rest.control_points.begin(), rest.control_points.begin() + j + 1);
    left.weights.assign(rest.weights.begin(), rest.weights.begin() + j + 1);
    right.knots.push_back(ub);
    right.knots.insert(right.knots.end(), U.begin() + cut_i, U.end());
    right.control_points.assign(rest.control_points.begin() + j, rest.control_points.end());
    right.weights.assign(rest.weights.begin() + j, rest.weights.end());
    parts.push_back(std::move(left));
    rest = std::move(right);
  }
  parts.push_back(std::move(rest));
  return parts;
}

}  // namespace

void BlockBuilder::nurbs_feed(const SourceRef& ref, int order, const std::vector<NurbsPoint>& points,
                              const std::vector<double>& knots, const Pose& end) {
  if (axis_of_pose_[0] != 0 || axis_of_pose_[1] != 1 || axis_of_pose_[2] != 2)
    throw Error(ref.column, "NURBS need the machine's first three axes to be X, Y and Z");
  if (rotation_deg_ != 0) throw Error(ref.column, "a NURBS in a rotated coordinate system (G10 L2 R) is not supported");
  int a1 = 0, a2 = 1;
  if (plane_ == Plane::kXZ) a1 = 2, a2 = 0;
  if (plane_ == Plane::kYZ) a1 = 1, a2 = 2;
  std::vector<double> e = to_machine(ref, end);
  const double f = feed_mm_per_min(ref);
  program::Block& b = begin(ref, program::BlockKind::kNurbs);
  b.end = e;
  b.feed_mm_per_min = f;
  b.nurbs.order = order;
  b.nurbs.knots = knots;
  // Each control point as a program pose: the plane's two coordinates from the point
  // (Fanuc G6.2 points carry X Y Z), the others where the curve ends.
  for (size_t k = 0; k < points.size(); ++k) {
    const NurbsPoint& p = points[k];
    Pose q = end;
    if (p.has_z) {
      // Fanuc G6.2: X Y Z whatever the plane.
      q[0] = p.x;
      q[1] = p.y;
      q[2] = p.z;
    } else {
      // G5.2: the plane's two coordinates; the normal axis stays where the curve ends.
      q[static_cast<size_t>(a1)] = p.x;
      q[static_cast<size_t>(a2)] = p.y;
    }
    const std::vector<double> m = to_machine(ref, q);
    b.nurbs.control_points.push_back({m[0], m[1], m[2]});
    b.nurbs.weights.push_back(p.w);
  }
  const std::string why = program::check_nurbs_block(b);
  if (!why.empty()) {
    out_.pop_back();
    --next_index_;
    throw Error(ref.column, "NURBS: " + why);
  }
  std::vector<program::NurbsGeometry> parts;
  for (const program::NurbsGeometry& piece : split_at_cusps(b.nurbs))
    for (program::NurbsGeometry& q : split_at_corners(piece)) parts.push_back(std::move(q));
  if (parts.size() > 1) {
    out_.pop_back();
    --next_index_;
    for (program::NurbsGeometry& g : parts) {
      program::Block& piece = begin(ref, program::BlockKind::kNurbs);
      piece.feed_mm_per_min = f;
      piece.end = e;  // the axes besides X Y Z stay where the curve ends
      for (size_t k = 0; k < 3; ++k) piece.end[k] = g.control_points.back()[k];
      piece.nurbs = std::move(g);
      if (const std::string w = program::check_nurbs_block(piece); !w.empty())
        throw Error(ref.column, "NURBS (a piece between its corners): " + w);
      position_ = piece.end;
    }
  }
  position_ = std::move(e);
}

void BlockBuilder::straight_probe(const SourceRef& ref, const Pose& end, int kind) {
  std::vector<double> e = to_machine(ref, end);
  const double f = feed_mm_per_min(ref);
  program::Block& b = begin(ref, program::BlockKind::kLine);
  b.end = e;
  b.feed_mm_per_min = f;
  b.probe = static_cast<int8_t>(kind);
  position_ = std::move(e);
}

void BlockBuilder::start_speed_feed_sync(const SourceRef& ref, double feed_per_rev, bool velocity_mode) {
  if (velocity_mode) throw Error(ref.column, "spindle-synchronised motion in velocity mode is not supported");
  // G76 changes the pitch within one synchronised run (its tapers' longer pitch).
  if (!(feed_per_rev > 0) || !std::isfinite(feed_per_rev))
    throw Error(ref.column, "spindle-synchronised motion needs a distance per revolution > 0");
  sync_pitch_mm_ = feed_per_rev * scale_;
}
void BlockBuilder::stop_speed_feed_sync(const SourceRef&) { sync_pitch_mm_ = 0; }

void BlockBuilder::synced_line(const SourceRef& ref, const Pose& end, int8_t sync, double retract_scale) {
  if (!setup_.spindle_sync)
    throw Error(ref.column, "spindle-synchronised motion (G33, G33.1, G76): this machine's spindle has no encoder");
  std::vector<double> e = to_machine(ref, end);
  for (size_t a = 0; a < e.size(); ++a)
    if (rotary(a) && e[a] != position_[a]) throw Error(ref.column, "a rotary axis moves in spindle-synchronised motion");
  if (spindle_dir_ == 0 || !(speed_rpm_ > 0)) throw Error(ref.column, "spindle-synchronised motion with the spindle stopped");
  program::Block& b = begin(ref, program::BlockKind::kLine);
  b.end = e;
  b.sync = sync;
  b.sync_pitch_mm = sync_pitch_mm_;
  b.tap_retract_scale = retract_scale;
  b.feed_mm_per_min = sync_pitch_mm_ * speed_rpm_;  // the nominal rate; the spindle's position decides
  if (sync == program::kSyncG33) position_ = std::move(e);  // a rigid tap comes back to its start
}
void BlockBuilder::rigid_tap(const SourceRef& ref, const Pose& end, double retract_scale) {
  if (!(sync_pitch_mm_ > 0)) throw Error(ref.column, "RIGID_TAP outside START_SPEED_FEED_SYNCH");
  synced_line(ref, end, program::kSyncRigidTap, retract_scale);
}
void BlockBuilder::wait_orient_complete(const SourceRef&, double timeout_s) {
  // M19 Q: the orientation's event (just made) waits for it.
  if (!out_.empty() && out_.back().kind == program::BlockKind::kEvent &&
      out_.back().event.kind == program::EventKind::kSpindleOrient)
    out_.back().dwell_s = timeout_s;
}

void BlockBuilder::dwell(const SourceRef& ref, double seconds) {
  program::Block& b = begin(ref, program::BlockKind::kDwell);
  b.dwell_s = seconds;
}

void BlockBuilder::orient_spindle(const SourceRef& ref, double degrees, int mode) {
  // G87 (back boring) needs it too: without an oriented stop the boring bar would crash.
  if (!setup_.spindle_sync)
    throw Error(ref.column, "spindle orientation (G87 back boring, M19): this machine's spindle has no encoder");
  // M19's P (0 shortest way, 1 clockwise, 2 counterclockwise); G87 passes the turning
  // direction (2, 3), where the shortest way serves as well.
  spindle_dir_ = 0;  // an oriented spindle stands
  event(ref, program::EventKind::kSpindleOrient, mode >= 0 && mode <= 2 ? mode : 0, degrees);
}
void BlockBuilder::change_tool(const SourceRef& ref, int tool) { event(ref, program::EventKind::kToolChange, tool, 0); }
void BlockBuilder::set_spindle_speed(const SourceRef& ref, double rpm) {
  speed_rpm_ = rpm;
  if (spindle_dir_ != 0) event(ref, program::EventKind::kSpindle, spindle_dir_, rpm);
}
void BlockBuilder::start_spindle_clockwise(const SourceRef& ref) {
  spindle_dir_ = 1;
  event(ref, program::EventKind::kSpindle, 1, speed_rpm_);
}
void BlockBuilder::start_spindle_counterclockwise(const SourceRef& ref) {
  spindle_dir_ = -1;
  event(ref, program::EventKind::kSpindle, -1, speed_rpm_);
}
void BlockBuilder::stop_spindle_turning(const SourceRef& ref) {
  if (spindle_dir_ == 0) return;
  spindle_dir_ = 0;
  event(ref, program::EventKind::kSpindle, 0, 0);
}
void BlockBuilder::mist_on(const SourceRef& ref) {
  if (coolant_ & 1) return;
  coolant_ |= 1;
  event(ref, program::EventKind::kCoolant, coolant_, 0);
}
void BlockBuilder::mist_off(const SourceRef& ref) {
  if (!(coolant_ & 1)) return;
  coolant_ &= ~1;
  event(ref, program::EventKind::kCoolant, coolant_, 0);
}
void BlockBuilder::flood_on(const SourceRef& ref) {
  if (coolant_ & 2) return;
  coolant_ |= 2;
  event(ref, program::EventKind::kCoolant, coolant_, 0);
}
void BlockBuilder::flood_off(const SourceRef& ref) {
  if (!(coolant_ & 2)) return;
  coolant_ &= ~2;
  event(ref, program::EventKind::kCoolant, coolant_, 0);
}
void BlockBuilder::enable_feed_override(const SourceRef& ref, bool on) {
  overrides_ = on ? overrides_ | 1 : overrides_ & ~1;
  event(ref, program::EventKind::kOverrides, overrides_, 0);
}
void BlockBuilder::enable_speed_override(const SourceRef& ref, bool on) {
  overrides_ = on ? overrides_ | 2 : overrides_ & ~2;
  event(ref, program::EventKind::kOverrides, overrides_, 0);
}
void BlockBuilder::enable_adaptive_feed(const SourceRef& ref, bool on) {
  overrides_ = on ? overrides_ | 4 : overrides_ & ~4;
  event(ref, program::EventKind::kOverrides, overrides_, 0);
}
void BlockBuilder::enable_feed_hold(const SourceRef& ref, bool on) {
  overrides_ = on ? overrides_ | 8 : overrides_ & ~8;
  event(ref, program::EventKind::kOverrides, overrides_, 0);
}
void BlockBuilder::digital_output(const SourceRef& ref, int index, bool on, bool synchronised) {
  event(ref, program::EventKind::kDigitalOutput, index, (on ? 1 : 0) + (synchronised ? 2 : 0));
}
void BlockBuilder::analog_output(const SourceRef& ref, int index, double value, bool synchronised) {
  event(ref, program::EventKind::kAnalogOutput, index + (synchronised ? 1000 : 0), value);
}
void BlockBuilder::wait_input(const SourceRef& ref, int index, bool analog, int mode, double timeout_s) {
  event(ref, program::EventKind::kWaitInput, program::InputWait{index, analog, mode}.number(), timeout_s);
}
void BlockBuilder::set_process(const SourceRef&, const ProcessSettings& p) {
  // The program's first directive describes its cut: the keys it leaves out come
  // from the machine's process: section.
  if (!process_declared_) process_ = setup_.process;
  process_declared_ = true;
  if (p.has_ball_radius) process_.ball_radius_mm = p.ball_radius_mm;
  if (p.has_flutes) process_.flutes = p.flutes;
  if (p.has_pick_feed) process_.pick_feed_mm = p.pick_feed_mm;
  if (p.has_target_rmax) process_.target_rmax_um = p.target_rmax_um;
}
void BlockBuilder::message(const SourceRef& ref, const std::string& text) {
  event(ref, program::EventKind::kMessage, 0, 0, text);
}
void BlockBuilder::program_stop(const SourceRef& ref) { event(ref, program::EventKind::kProgramStop, 0, 0); }
void BlockBuilder::optional_program_stop(const SourceRef& ref) { event(ref, program::EventKind::kOptionalStop, 0, 0); }
// The cell has no pallet changer: M30's shuttle (LinuxCNC makes one) is no event;
// M60 still holds the program through its program stop.
void BlockBuilder::pallet_shuttle(const SourceRef&) {}
void BlockBuilder::program_end(const SourceRef& ref) {
  begin(ref, program::BlockKind::kEnd);
  ended_ = true;
}
void BlockBuilder::finish(const SourceRef& ref) { program_end(ref); }

}  // namespace cnc::rs274
