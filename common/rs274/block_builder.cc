#include "common/rs274/block_builder.h"

#include <cmath>

#include "common/program/block_check.h"

namespace cnc::rs274 {

namespace {

constexpr double kMmPerInch = 25.4;
constexpr char kPoseLetters[] = "XYZABCUVW";
bool linear(size_t i) { return i < 3 || i >= 6; }

}  // namespace

BlockBuilder::BlockBuilder(BuilderSetup setup, std::function<const std::string&(int32_t)> file_name)
    : setup_(std::move(setup)), file_name_(std::move(file_name)) {
  axis_of_pose_.assign(kNumAxes, -1);
  for (size_t a = 0; a < setup_.axis_names.size(); ++a) {
    const std::string& n = setup_.axis_names[a];
    for (int i = 0; i < kNumAxes; ++i)
      if (n.size() == 1 && n[0] == kPoseLetters[i]) axis_of_pose_[static_cast<size_t>(i)] = static_cast<int>(a);
  }
  position_ = setup_.start_position_mm;
  position_.resize(setup_.axis_names.size(), 0.0);
  speed_rpm_ = setup_.spindle_rpm;
  process_ = setup_.process;
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

program::Block& BlockBuilder::begin(const SourceRef& ref, program::BlockKind kind) {
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
void BlockBuilder::set_feed_rate(const SourceRef&, double rate) { feed_ = rate; }
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

void BlockBuilder::straight_feed(const SourceRef& ref, const Pose& end) {
  std::vector<double> e = to_machine(ref, end);
  const double f = feed_mm_per_min(ref);
  program::Block& b = begin(ref, program::BlockKind::kLine);
  b.end = e;
  b.feed_mm_per_min = f;
  position_ = std::move(e);
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
  const double f = feed_mm_per_min(ref);
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
          const auto& a = rest.control_points[static_cast<size_t>(j - 1)];
          const auto& c = rest.control_points[static_cast<size_t>(j)];
          const auto& d = rest.control_points[static_cast<size_t>(j + 1)];
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
  std::vector<program::NurbsGeometry> parts = split_at_corners(b.nurbs);
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

void BlockBuilder::dwell(const SourceRef& ref, double seconds) {
  program::Block& b = begin(ref, program::BlockKind::kDwell);
  b.dwell_s = seconds;
}

void BlockBuilder::orient_spindle(const SourceRef& ref, double, int) {
  // G87 (back boring) needs it: without an oriented stop the boring bar would crash.
  throw Error(ref.column, "spindle orientation (G87 back boring, M19): this machine's spindle has no orientation");
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
void BlockBuilder::digital_output(const SourceRef& ref, int index, bool on, bool) {
  event(ref, program::EventKind::kDigitalOutput, index, on ? 1 : 0);
}
void BlockBuilder::analog_output(const SourceRef& ref, int index, double value, bool) {
  event(ref, program::EventKind::kAnalogOutput, index, value);
}
void BlockBuilder::set_process(const SourceRef&, const ProcessSettings& p) {
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
