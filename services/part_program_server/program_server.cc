#include "services/part_program_server/program_server.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string_view>
#include <utility>

#include "common/kinematics/kinematics.h"
#include "common/motion/corner.h"
#include "common/motion/path_segment.h"

namespace cnc::pps {

// A word at a time (a byte at a time was 29 % of a load's time): each step a
// bijection of the state for a given word, so one changed field always changes the
// chunk's hash; the rotation brings high bits down to where the next word lands.
uint64_t block_hash(const program::Block& b, uint64_t h) {
  const auto w = [&h](uint64_t v) { h = ((h << 23 | h >> 41) ^ v) * 0x9e3779b97f4a7c15ull; };
  const auto d = [&w](double v) {
    uint64_t u;
    std::memcpy(&u, &v, sizeof u);
    w(u);
  };
  const auto bytes = [&w](const void* p, size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    w(n);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
      uint64_t u;
      std::memcpy(&u, c + i, 8);
      w(u);
    }
    uint64_t tail = 0;
    for (size_t k = 0; i + k < n; ++k) tail |= uint64_t{c[i + k]} << (8 * k);
    if (i < n) w(tail);
  };
  const auto vec = [&](const std::vector<double>& v) {
    w(v.size());
    for (double x : v) d(x);
  };
  w(static_cast<uint64_t>(b.index));
  w(static_cast<uint64_t>(b.kind));
  w(static_cast<uint64_t>(static_cast<uint32_t>(b.source_line)) << 32 | static_cast<uint32_t>(b.source_column));
  bytes(b.source_file.data(), b.source_file.size());
  vec(b.start);
  vec(b.end);
  d(b.feed_mm_per_min);
  d(b.dwell_s);
  d(b.spindle_rpm);
  d(b.process.ball_radius_mm);
  w(static_cast<uint64_t>(b.process.flutes));
  d(b.process.pick_feed_mm);
  d(b.process.target_rmax_um);
  vec(b.arc.center);
  w(static_cast<uint64_t>(b.arc.plane));
  w(static_cast<uint64_t>(b.arc.turns));
  w(static_cast<uint64_t>(b.nurbs.order));
  vec(b.nurbs.knots);
  vec(b.nurbs.weights);
  w(b.nurbs.control_points.size());
  for (const auto& p : b.nurbs.control_points) bytes(p.data(), sizeof(double) * p.size());
  w(static_cast<uint64_t>(b.event.kind));
  w(static_cast<uint64_t>(b.event.number));
  d(b.event.value);
  bytes(b.event.text.data(), b.event.text.size());
  w(static_cast<uint64_t>(b.probe));
  return h;
}

// The travel check of the validation run: every point of the block's path within
// the axes' travel. Lines and rapids by their end points (the start is the last
// block's end); arcs, helices and NURBS sampled finely enough that their bulge
// between samples stays under 1 um (a runtime check in the drive bridge remains).
// Returns "" or the refusal.
std::string travel_error(const program::Block& b, const std::vector<std::pair<double, double>>& travel,
                         const std::vector<std::string>& names, const std::vector<bool>& rotary) {
  if (travel.empty()) return "";
  const bool arc = b.kind == program::BlockKind::kArcCw || b.kind == program::BlockKind::kArcCcw;
  const bool moves = b.kind == program::BlockKind::kRapid || b.kind == program::BlockKind::kLine || arc ||
                     b.kind == program::BlockKind::kNurbs;
  if (!moves) return "";
  const int n = static_cast<int>(
      std::min({travel.size(), b.end.size(), b.start.size(), names.size(), static_cast<size_t>(program::kMaxAxes)}));
  auto check = [&](const double* p, const char* where) -> std::string {
    for (int a = 0; a < n; ++a) {
      const auto [lo, hi] = travel[static_cast<size_t>(a)];
      if (!(p[a] >= lo - 1e-9 && p[a] <= hi + 1e-9)) {
        char buf[200];
        const bool deg = static_cast<size_t>(a) < rotary.size() && rotary[static_cast<size_t>(a)];
        std::snprintf(buf, sizeof buf, "%s %.4f %s (machine coordinates, %s) is outside the axis's travel [%g, %g]",
                      names[static_cast<size_t>(a)].c_str(), p[a], deg ? "deg" : "mm", where, lo, hi);
        return buf;
      }
    }
    return "";
  };
  if (std::string e = check(b.end.data(), "the block's end"); !e.empty()) return e;
  if (b.kind == program::BlockKind::kRapid || b.kind == program::BlockKind::kLine) return "";
  motion::PathSegment path(b, n);
  if (path.degenerate()) return "";
  int samples = 64;
  if (arc) {
    // Sagitta r(1 - cos(h/2)) <= 1 um for an angle step h.
    const int i0 = b.arc.plane == 18 ? 2 : b.arc.plane == 19 ? 1 : 0;
    const int i1 = b.arc.plane == 18 ? 0 : b.arc.plane == 19 ? 2 : 1;
    double r = 0;
    if (i0 < n && i1 < n && b.arc.center.size() > static_cast<size_t>(std::max(i0, i1)))
      r = std::hypot(b.start[static_cast<size_t>(i0)] - b.arc.center[static_cast<size_t>(i0)],
                     b.start[static_cast<size_t>(i1)] - b.arc.center[static_cast<size_t>(i1)]);
    const double h = r > 0 ? 2.0 * std::acos(std::max(-1.0, 1.0 - 1e-3 / r)) : 1.0;
    samples = static_cast<int>(std::clamp(std::ceil(path.arc_sweep_rad() / std::max(h, 1e-6)), 16.0, 20000.0));
  } else {
    samples = static_cast<int>(std::clamp(64.0 * static_cast<double>(path.nurbs_breakpoints().size()), 64.0, 20000.0));
  }
  for (int i = 1; i < samples; ++i) {
    const double u = path.u_begin() + (path.u_end() - path.u_begin()) * i / samples;
    const motion::AxisVec p = path.point(u);
    if (std::string e = check(p.data(), "on the way"); !e.empty()) return e;
  }
  return "";
}

// A dwell longer than this is accepted with a warning (a P in ms, or a typo).
constexpr double kLongDwell_s = 600.0;

// One pass of the interpreter through the program, block by block.
class ProgramServer::Run {
 public:
  Run(const ProgramSetup& s, const std::vector<double>& start, bool block_delete, bool validating,
      const std::optional<rs274::ModalState>& modes)
      : builder_(builder_setup(s.builder, start),
                 [this](int32_t f) -> const std::string& { return interp_->file_names()[static_cast<size_t>(f)]; }),
        max_lines_(validating ? s.max_validation_lines : -1), validating_(validating) {
    rs274::MachineSetup m = s.machine;
    m.machine_results_supplied = true;  // supply_result() gives each G38.x move and M66 its result
    m.block_delete = block_delete;
    m.initial_modes = modes;
    for (size_t i = 0; i < s.builder.axis_names.size(); ++i) {
      static const char kAxes[] = "XYZABCUVW";
      const char* at = s.builder.axis_names[i].size() == 1 ? std::strchr(kAxes, s.builder.axis_names[i][0]) : nullptr;
      pose_index_.push_back(at != nullptr && *at != '\0' ? static_cast<int>(at - kAxes) : -1);
      if (pose_index_.back() >= 0 && i < start.size()) m.start_position[static_cast<size_t>(pose_index_.back())] = start[i];
    }
    // Only the run that serves the program (and so runs it) keeps parameters.
    m.write_var_file = !validating && m.write_var_file;
    interp_ = std::make_unique<rs274::Interpreter>(std::move(m), builder_);
  }

  void open(const std::string& path) { interp_->open(path); }

  // The next block; false after the end block. Throws rs274::Error.
  bool next(program::Block* out) {
    auto& q = builder_.blocks();
    waiting_ = false;
    while (q.empty()) {
      if ((interp_->waiting_for_probe() || interp_->waiting_for_input()) && !supply_result()) {
        waiting_ = true;
        return false;
      }
      if (!interp_->execute_next() && q.empty()) return false;
      if (max_lines_ > 0 && interp_->lines_executed() > max_lines_)
        throw rs274::Error(interp_->file_names().front(), rs274::SourceRef{},
                           "the program ran more than " + std::to_string(max_lines_) +
                               " lines without ending: not validated (program.max_validation_lines)");
    }
    *out = std::move(q.front());
    q.pop_front();
    ++pulled_;
    return true;
  }

  int64_t lines() const { return interp_->lines_executed(); }
  // next() returned false because a probing move's or an input wait's result is not known yet.
  bool waiting() const { return waiting_; }
  // The machine's results, applied in order (nullptr: none known). Past them a
  // validating run (or one that may assume, the dry run's) takes the probe as tripped
  // at the move's end and an input as rs274 reads it; a serving one waits.
  void set_results(const std::vector<MachineResult>* r, bool may_assume) {
    results_ = r;
    may_assume_ = may_assume || validating_;
  }

  // Run from line N: the state before the main file's line N is first reached, and
  // the number of blocks made before it.
  void watch(int from_line) {
    interp_->set_line_hook([this, from_line](int32_t file, int32_t line) {
      if (reached_ || file != 0 || line < from_line) return;
      reached_ = true;
      blocks_before_ = pulled_ + static_cast<int64_t>(builder_.blocks().size());
      state_ = interp_->modal_state();
    });
  }
  bool reached() const { return reached_; }
  int64_t blocks_before() const { return blocks_before_; }
  const rs274::ModalState& state() const { return state_; }

 private:
  bool supply_result() {
    const auto k = static_cast<size_t>(supplied_);
    const bool probe = interp_->waiting_for_probe();
    rs274::Pose trip = interp_->probe_target_machine(), rest = trip;
    if (results_ == nullptr || k >= results_->size()) {
      if (!may_assume_) return false;
      if (probe) interp_->set_probe_result(true, trip, rest);
      else interp_->set_input_result(interp_->simulated_input());
      ++supplied_;
      return true;
    }
    const MachineResult& m = (*results_)[k];
    if (m.is_probe != probe)
      throw std::runtime_error(probe ? "a probing move where the machine answered an input wait (M66)"
                                     : "an input wait (M66) where the machine answered a probing move");
    ++supplied_;
    if (!probe) {
      interp_->set_input_result(m.input_value);
      return true;
    }
    const ProbeResult& r = m.probe;
    for (size_t i = 0; i < pose_index_.size(); ++i) {
      if (pose_index_[i] < 0) continue;
      if (i < r.trip_mm.size()) trip[static_cast<size_t>(pose_index_[i])] = r.trip_mm[i];
      if (i < r.rest_mm.size()) rest[static_cast<size_t>(pose_index_[i])] = r.rest_mm[i];
    }
    if (r.rest_mm.size() == pose_index_.size()) builder_.set_position(r.rest_mm);
    interp_->set_probe_result(r.tripped, trip, rest);
    return true;
  }

  static rs274::BuilderSetup builder_setup(rs274::BuilderSetup b, const std::vector<double>& start) {
    if (start.size() == b.axis_names.size()) b.start_position_mm = start;
    return b;
  }

  rs274::BlockBuilder builder_;
  std::unique_ptr<rs274::Interpreter> interp_;
  int64_t max_lines_;
  bool validating_;
  bool waiting_ = false;
  bool may_assume_ = true;
  const std::vector<MachineResult>* results_ = nullptr;
  int64_t supplied_ = 0;  // results given to the interpreter
  std::vector<int> pose_index_;  // builder axis -> interpreter pose index (-1: none)
  int64_t pulled_ = 0;
  bool reached_ = false;
  int64_t blocks_before_ = 0;
  rs274::ModalState state_;
};

namespace {

// G53.1 through the machine's kinematics: the rotary joints that point the tool along a
// direction of the workpiece, as kinematics.solution chooses (P0) or solution 0 / 1
// (P1: tilt >= 0, P2: tilt <= 0), refused naming the joint out of travel.
rs274::OrientTool orient_tool(const config::MachineConfig& cfg) {
  std::shared_ptr<const kinematics::Kinematics> kin = kinematics::make_kinematics(cfg);
  static constexpr std::string_view kLetters = "XYZABCUVW";
  std::vector<int> pose_index;  // the interpreter's Pose index of each machine axis
  for (const auto& a : cfg.axes) pose_index.push_back(static_cast<int>(kLetters.find(a.name)));
  return [kin, pose_index](const std::array<double, 3>& d, const rs274::Pose& machine, int choice) {
    kinematics::Pose joints{};
    for (size_t a = 0; a < pose_index.size(); ++a) joints[a] = machine[static_cast<size_t>(pose_index[a])];
    kinematics::Orientation o;
    kin->orient(kinematics::ToolDirection{d[0], d[1], d[2]}, joints, o);
    if (o.tilt_joint < 0 || o.rotary_joint < 0) throw std::invalid_argument("this machine cannot turn the tool");
    const auto& lim = kin->joint_limits();
    const auto outside = [&](const kinematics::RotaryAngles& r) {
      std::string why;
      char buf[160];
      for (const auto& [joint, deg] : {std::pair{o.tilt_joint, r.tilt_deg}, std::pair{o.rotary_joint, r.rotary_deg}}) {
        const kinematics::JointLimits& l = lim[static_cast<size_t>(joint)];
        if (deg >= l.min_mm && deg <= l.max_mm) continue;
        std::snprintf(buf, sizeof buf, "%sjoint %s would stand at %.3f degrees, outside its travel [%g, %g]",
                      why.empty() ? "" : "; ", l.name.c_str(), deg, l.min_mm, l.max_mm);
        why += buf;
      }
      return why;
    };
    int pick = choice == 0 ? o.chosen : choice - 1;
    if (pick < 0)
      throw std::invalid_argument("neither solution is in travel: tilt >= 0: " + outside(o.solution[0]) +
                                  "; tilt <= 0: " + outside(o.solution[1]));
    const kinematics::RotaryAngles& r = o.solution[static_cast<size_t>(pick)];
    if (!r.in_travel)
      throw std::invalid_argument(std::string(pick == 0 ? "the tilt >= 0 solution (P1): " : "the tilt <= 0 solution (P2): ") +
                                  outside(r));
    rs274::ToolOrientation t;
    t.tilt_axis = pose_index[static_cast<size_t>(o.tilt_joint)];
    t.rotary_axis = pose_index[static_cast<size_t>(o.rotary_joint)];
    t.tilt_deg = r.tilt_deg;
    t.rotary_deg = r.rotary_deg;
    return t;
  };
}

}  // namespace

ProgramSetup program_setup(const config::MachineConfig& cfg) {
  ProgramSetup s;
  s.machine.axes.clear();
  for (const auto& a : cfg.axes) {
    s.machine.axes += a.name;
    s.builder.axis_names.push_back(a.name);
    s.builder.start_position_mm.push_back(a.home_mm);
    s.builder.rotary.push_back(a.rotary);
    if (a.wrapped) s.machine.wrapped += a.name;
  }
  s.machine.machine_units = rs274::Units::kMm;
  s.machine.subroutine_path = cfg.program.subroutine_path;
  s.machine.m6_remap = cfg.program.m6_remap;
  s.machine.tool_table = cfg.program.tool_table;
  s.machine.var_file = cfg.program.var_file;
  // The tool in the spindle stays there across programs (#5400 in the var file), and a
  // G10 L1/L10/L11 (tool touch-off among them) is written back to the tool table.
  s.machine.tool_in_var_file = !cfg.program.var_file.empty();
  s.machine.write_tool_table = true;
  s.machine.has_probe = cfg.program.probe;
  s.machine.spindle_sync = s.builder.spindle_sync = cfg.spindle.measured_position();
  s.machine.orient_offset_deg = cfg.spindle.orient_offset_deg;
  s.machine.digital_inputs = cfg.program.digital_inputs;
  s.machine.analog_inputs = cfg.program.analog_inputs;
  s.machine.digital_outputs = cfg.program.digital_outputs;
  s.machine.analog_outputs = cfg.program.analog_outputs;
  s.machine.block_delete = cfg.program.block_delete;
  // Every M1 becomes an event: the interpolator holds there when its optional-stop
  // switch (initially program.optional_stop) is on when the path gets there.
  s.machine.optional_stop = true;
  s.builder.spindle_rpm = cfg.process.spindle_rpm;
  s.builder.process = program::ProcessParams{cfg.process.ball_radius_mm, cfg.process.flutes, cfg.process.pick_feed_mm,
                                             cfg.process.target_rmax_um};
  s.max_validation_lines = cfg.program.max_validation_lines;
  s.builder.fit_runs = cfg.program.g64_fit;
  s.builder.fit_max_segment_mm = cfg.program.g64_fit_max_segment_mm;
  s.builder.fit_max_segment_per_p = cfg.program.g64_fit_max_segment_per_p;
  s.builder.fit_max_turn_deg = cfg.program.g64_fit_max_turn_deg;
  s.builder.ipo_period_s = cfg.ipo_period_s;
  s.builder.chord_tolerance_mm = cfg.chord_tolerance_mm;
  s.builder.default_path_tolerance_mm = cfg.program.default_path_tolerance_mm;
  {
    // The planner's corner step (common/motion/corner.h) with the path's and every axis's limits.
    const double T = cfg.ipo_period_s;
    s.builder.corner_dv_mm_s = motion::corner_step_mm_s(cfg.path_accel_mm_s2, cfg.path_jerk_mm_s3, T);
    s.builder.accel_mm_s2 = cfg.path_accel_mm_s2;
    s.builder.jerk_mm_s3 = cfg.path_jerk_mm_s3;
    for (const auto& a : cfg.axes) {
      s.builder.corner_dv_mm_s = std::min(s.builder.corner_dv_mm_s, motion::corner_step_mm_s(a.max_accel_mm_s2, a.max_jerk_mm_s3, T));
      s.builder.accel_mm_s2 = std::min(s.builder.accel_mm_s2, a.max_accel_mm_s2);
      s.builder.jerk_mm_s3 = std::min(s.builder.jerk_mm_s3, a.max_jerk_mm_s3);
    }
  }
  for (const auto& a : cfg.axes) s.travel_mm.emplace_back(a.min_mm, a.max_mm);
  s.safe_z_mm = cfg.operator_.safe_z_mm;
  if (cfg.kinematics.type != "identity") s.machine.orient_tool = orient_tool(cfg);
  return s;
}

ProgramSetup dry_run_setup(const config::MachineConfig& cfg, const DryRunFiles& files) {
  config::MachineConfig c = cfg;
  if (!files.subroutine_path.empty()) c.program.subroutine_path = files.subroutine_path;
  if (!files.tool_table.empty()) c.program.tool_table = files.tool_table;
  ProgramSetup s = program_setup(c);
  s.machine.write_var_file = false;  // also keeps the tool table as it is (Interpreter::persist)
  return s;
}

std::string describe(const ProgramSetup& s) {
  std::string out;
  const auto line = [&out](const char* key, const std::string& value) {
    out += key;
    out += " = ";
    out += value;
    out += '\n';
  };
  const auto num = [](double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    return std::string(buf);
  };
  const auto flag = [](bool v) { return std::string(v ? "true" : "false"); };
  const auto list = [](const auto& items, const auto& one) {
    std::string t = "[";
    for (const auto& x : items) {
      if (t.size() > 1) t += ", ";
      t += one(x);
    }
    t += ']';
    return t;
  };
  const auto quoted = [](const std::string& v) {
    std::string t = "'";
    t += v;
    t += '\'';
    return t;
  };
  // Structured bindings name every member: a field added to one of these structs stops
  // the build here until it is described, and so compared (dry_run_agreement_test).
  const auto& [machine, builder, max_validation_lines, travel_mm, safe_z_mm] = s;
  const auto& [m_axes, m_wrapped, m_units, m_subroutine_path, m_tool_table, m_var_file, m_write_var_file,
               m_tool_in_var_file, m_write_tool_table, m_has_probe, m_spindle_sync, m_orient_offset_deg,
               m_machine_results_supplied, m_digital_inputs, m_analog_inputs, m_digital_outputs, m_analog_outputs,
               m_block_delete, m_optional_stop, m_start_position, m_max_call_depth, m_m6_remap, m_fanuc_subs,
               m_loop_on_main_m99, m_initial_modes, m_orient_tool] = machine;
  const auto& [b_axis_names, b_start_position_mm, b_rotary, b_spindle_rpm, b_process, b_fit_runs,
               b_fit_max_segment_mm, b_fit_max_segment_per_p, b_fit_max_turn_deg, b_fit_max_spans, b_ipo_period_s, b_corner_dv_mm_s,
               b_accel_mm_s2, b_jerk_mm_s3, b_chord_tolerance_mm, b_default_path_tolerance_mm, b_spindle_sync] = builder;
  const auto& [p_ball_radius_mm, p_flutes, p_pick_feed_mm, p_target_rmax_um] = b_process;
  line("machine.axes", quoted(m_axes));
  line("machine.wrapped", quoted(m_wrapped));
  line("machine.machine_units", m_units == rs274::Units::kMm ? "mm" : "inch");
  line("machine.subroutine_path", list(m_subroutine_path, quoted));
  line("machine.tool_table", quoted(m_tool_table));
  line("machine.var_file", quoted(m_var_file));
  line("machine.write_var_file", flag(m_write_var_file));
  line("machine.tool_in_var_file", flag(m_tool_in_var_file));
  line("machine.write_tool_table", flag(m_write_tool_table));
  line("machine.has_probe", flag(m_has_probe));
  line("machine.spindle_sync", flag(m_spindle_sync));
  line("machine.orient_offset_deg", num(m_orient_offset_deg));
  line("machine.machine_results_supplied", flag(m_machine_results_supplied));
  line("machine.digital_inputs", std::to_string(m_digital_inputs));
  line("machine.analog_inputs", std::to_string(m_analog_inputs));
  line("machine.digital_outputs", std::to_string(m_digital_outputs));
  line("machine.analog_outputs", std::to_string(m_analog_outputs));
  line("machine.block_delete", flag(m_block_delete));
  line("machine.optional_stop", flag(m_optional_stop));
  line("machine.start_position", list(m_start_position, num));
  line("machine.max_call_depth", std::to_string(m_max_call_depth));
  line("machine.m6_remap", quoted(m_m6_remap));
  line("machine.fanuc_subs", flag(m_fanuc_subs));
  line("machine.loop_on_main_m99", flag(m_loop_on_main_m99));
  // The modes an MDI line starts in: the server's own, per line, never a machine's setting.
  line("machine.initial_modes", m_initial_modes ? "given" : "none");
  // G53.1 through the machine's kinematics (made from kinematics.type, described there).
  line("machine.orient_tool", m_orient_tool ? "kinematics" : "none");
  line("builder.axis_names", list(b_axis_names, quoted));
  line("builder.start_position_mm", list(b_start_position_mm, num));
  line("builder.rotary", list(b_rotary, flag));
  line("builder.spindle_rpm", num(b_spindle_rpm));
  line("builder.process.ball_radius_mm", num(p_ball_radius_mm));
  line("builder.process.flutes", std::to_string(p_flutes));
  line("builder.process.pick_feed_mm", num(p_pick_feed_mm));
  line("builder.process.target_rmax_um", num(p_target_rmax_um));
  line("builder.fit_runs", flag(b_fit_runs));
  line("builder.fit_max_segment_mm", num(b_fit_max_segment_mm));
  line("builder.fit_max_segment_per_p", num(b_fit_max_segment_per_p));
  line("builder.fit_max_turn_deg", num(b_fit_max_turn_deg));
  line("builder.fit_max_spans", std::to_string(b_fit_max_spans));
  line("builder.ipo_period_s", num(b_ipo_period_s));
  line("builder.corner_dv_mm_s", num(b_corner_dv_mm_s));
  line("builder.accel_mm_s2", num(b_accel_mm_s2));
  line("builder.jerk_mm_s3", num(b_jerk_mm_s3));
  line("builder.chord_tolerance_mm", num(b_chord_tolerance_mm));
  line("builder.default_path_tolerance_mm", num(b_default_path_tolerance_mm));
  line("builder.spindle_sync", flag(b_spindle_sync));
  line("max_validation_lines", std::to_string(max_validation_lines));
  line("travel_mm", list(travel_mm, [&num](const std::pair<double, double>& t) {
         std::string r = "[";
         r += num(t.first);
         r += ", ";
         r += num(t.second);
         r += ']';
         return r;
       }));
  line("safe_z_mm", num(safe_z_mm));
  return out;
}

ProgramServer::ProgramServer(const config::MachineConfig& cfg, ServerLimits limits)
    : ProgramServer(program_setup(cfg), limits) {}

ProgramServer::ProgramServer(ProgramSetup setup, ServerLimits limits) : setup_(std::move(setup)), limits_(limits) {
  limits_.blocks_per_chunk = std::max(1, limits_.blocks_per_chunk);
  limits_.cached_chunks = std::max(1, limits_.cached_chunks);
}

ProgramServer::~ProgramServer() = default;

const std::string& ProgramServer::path() const {
  static const std::string kNone;
  return program_ ? program_->path : kNone;
}

const std::string& ProgramServer::approach_text() const {
  static const std::string kNone;
  return program_ ? program_->approach_text : kNone;
}

std::unique_ptr<ProgramServer::Run> ProgramServer::start_run(const Loaded& p, bool validating) const {
  auto run = std::make_unique<Run>(setup_, p.start, p.block_delete, validating, p.modes_in);
  run->set_results(&p.results, !live_probing_);
  if (p.from_line > 0) run->watch(p.from_line);
  if (p.line) run->watch(3);  // MDI: the state after the line (at its closing '%')
  run->open(p.path);
  return run;
}

LoadResult ProgramServer::load(const std::string& path, int64_t token, const std::vector<double>& start_position_mm) {
  return load_from(path, token, start_position_mm, 0);
}

LoadResult ProgramServer::load_from(const std::string& path, int64_t token,
                                    const std::vector<double>& start_position_mm, int from_line) {
  LoadResult r;
  auto next = std::make_unique<Loaded>();
  next->path = path;
  next->token = token;
  next->from_line = std::max(0, from_line);
  next->line = next_is_line_;
  next->modes_in = std::move(next_modes_);
  next_is_line_ = false;
  next_modes_.reset();
  next->block_delete = setup_.machine.block_delete;
  next->start = start_position_mm.size() == setup_.builder.axis_names.size() ? start_position_mm
                                                                              : setup_.builder.start_position_mm;
  if (!validate(*next, r)) return r;
  install(std::move(next));
  r.ok = true;
  return r;
}

bool ProgramServer::validate(Loaded& p, LoadResult& r) const {
  Loaded* next = &p;
  const std::string& path = p.path;
  p.result_blocks.clear();
  p.result_is_probe.clear();
  p.result_hashes.clear();
  p.chunk_hashes.clear();
  p.approach.clear();
  // Run from line N: the tool, spindle and coolant the program had set before it, and
  // where line N's first block starts.
  const program::Block* last_tool = nullptr;
  const program::Block* last_spindle = nullptr;
  const program::Block* last_coolant = nullptr;
  program::Block tool_b, spindle_b, coolant_b;
  std::vector<double> from_start;
  try {
    std::unique_ptr<Run> run = start_run(*next, true);
    program::Block b;
    uint64_t h = 14695981039346656037ull;
    int64_t n = 0;
    if (progress_) progress_(0);
    while (run->next(&b)) {
      if (next->from_line > 0) {
        if (!run->reached() || n < run->blocks_before()) {
          if (b.kind == program::BlockKind::kEvent && b.event.kind == program::EventKind::kToolChange)
            last_tool = &(tool_b = b);
          if (b.kind == program::BlockKind::kEvent && b.event.kind == program::EventKind::kSpindle)
            last_spindle = &(spindle_b = b);
          if (b.kind == program::BlockKind::kEvent && b.event.kind == program::EventKind::kCoolant)
            last_coolant = &(coolant_b = b);
        } else if (n == run->blocks_before()) {
          from_start = b.start;
        }
      }
      const std::string e = travel_error(b, setup_.travel_mm, setup_.builder.axis_names, setup_.builder.rotary);
      if (!e.empty()) {
        r.error = (b.source_file.empty() ? path : b.source_file) + ":" + std::to_string(b.source_line) + ":" +
                  std::to_string(b.source_column) + ": " + e;
        r.file = b.source_file.empty() ? path : b.source_file;
        r.line = b.source_line;
        r.column = b.source_column;
        return false;
      }
      if (b.kind == program::BlockKind::kDwell && b.dwell_s > kLongDwell_s) {
        if (r.warnings.size() < 20) {
          char buf[160];
          std::snprintf(buf, sizeof buf, "a dwell of %.0f s (%.1f hours): the machine waits that long", b.dwell_s,
                        b.dwell_s / 3600.0);
          r.warnings.push_back((b.source_file.empty() ? path : b.source_file) + ":" + std::to_string(b.source_line) +
                               ":" + std::to_string(b.source_column) + ": " + buf);
        } else if (r.warnings.size() == 20) {
          r.warnings.push_back("(more warnings left out)");
        }
      }
      h = block_hash(b, h);
      if (b.awaits_result()) {
        next->result_blocks.push_back(n);
        next->result_is_probe.push_back(b.probe != 0);
        next->result_hashes.push_back(h);
      }
      ++n;
      if (progress_ && (n & 0xfff) == 0) progress_(n);
      if (n % limits_.blocks_per_chunk == 0) {
        next->chunk_hashes.push_back(h);
        h = 14695981039346656037ull;
      }
    }
    if (n % limits_.blocks_per_chunk != 0) next->chunk_hashes.push_back(h);
    next->num_blocks = next->full_blocks = n;
    next->lines = run->lines();
    if (next->line && run->reached()) next->modes_after = run->state();
    if (next->from_line > 0) {
      if (!run->reached() || from_start.empty()) {
        r.error = path + ":" + std::to_string(next->from_line) + ":1: run from line " +
                  std::to_string(next->from_line) + ": the program never gets there (it ends before, or the line makes no block after it)";
        r.file = path;
        r.line = next->from_line;
        r.column = 1;
        return false;
      }
      next->from_block = run->blocks_before();
      next->state_at_from = run->state();
      if (std::string e = make_approach(*next, from_start, last_tool, last_spindle, last_coolant); !e.empty()) {
        r.error = path + ":" + std::to_string(next->from_line) + ":1: run from line " +
                  std::to_string(next->from_line) + ": the approach: " + e;
        r.file = path;
        r.line = next->from_line;
        r.column = 1;
        return false;
      }
      next->num_blocks = static_cast<int64_t>(next->approach.size()) + n - next->from_block;
    }
  } catch (const rs274::Error& e) {
    r.error = e.what();
    r.file = e.file_name().empty() ? path : e.file_name();
    r.line = e.where().line;
    r.column = e.where().column;
    return false;
  } catch (const std::exception& e) {
    r.error = path + ": " + e.what();
    r.file = path;
    return false;
  }
  return true;
}

void ProgramServer::install(std::unique_ptr<Loaded> next) {
  program_ = std::move(next);
  serving_.reset();
  cache_.clear();
  serving_error_.clear();
  serving_reached_ = false;
}

std::string ProgramServer::make_approach(Loaded& p, const std::vector<double>& target, const program::Block* tool,
                                         const program::Block* spindle, const program::Block* coolant) const {
  const auto& names = setup_.builder.axis_names;
  const size_t n = names.size();
  std::vector<double> cur = p.start;
  int iz = -1;
  for (size_t a = 0; a < n; ++a)
    if (names[a] == "Z") iz = static_cast<int>(a);
  auto add = [&](program::Block b) {
    b.index = static_cast<int64_t>(p.approach.size());
    b.source_file = p.path;
    b.source_line = p.from_line;
    b.source_column = 1;
    p.approach.push_back(std::move(b));
  };
  char buf[160];
  std::string text;
  auto where = [&](const std::vector<double>& v) {
    std::string s;
    for (size_t a = 0; a < n; ++a) {
      std::snprintf(buf, sizeof buf, "%s%s %.4f", a ? " " : "", names[a].c_str(), v[a]);
      s += buf;
    }
    return s;
  };
  auto rapid = [&](const std::vector<double>& to, const char* what) -> std::string {
    double d = 0;
    for (size_t a = 0; a < n; ++a) d = std::max(d, std::fabs(to[a] - cur[a]));
    if (!(d > 1e-9)) return "";
    program::Block b;
    b.kind = program::BlockKind::kRapid;
    b.start = cur;
    b.end = to;
    if (std::string e = travel_error(b, setup_.travel_mm, names, setup_.builder.rotary); !e.empty()) return e;
    add(std::move(b));
    text += (text.empty() ? "" : "; ") + std::string(what) + " to " + where(to);
    cur = to;
    return "";
  };
  auto event = [&](const program::Block* e, const std::string& what) {
    if (e == nullptr) return;
    program::Block b = *e;
    b.start = b.end = cur;
    add(std::move(b));
    text += "; " + what;
  };
  if (iz >= 0) {
    const double top = setup_.travel_mm.size() > static_cast<size_t>(iz) ? setup_.travel_mm[static_cast<size_t>(iz)].second : cur[static_cast<size_t>(iz)];
    const double safe = std::isfinite(setup_.safe_z_mm) ? setup_.safe_z_mm : top;
    std::vector<double> up = cur;
    up[static_cast<size_t>(iz)] = std::max(cur[static_cast<size_t>(iz)], safe);
    if (std::string e = rapid(up, "rapid up (safe height)"); !e.empty()) return e;
    std::vector<double> across = target;
    across[static_cast<size_t>(iz)] = up[static_cast<size_t>(iz)];
    if (std::string e = rapid(across, "rapid across"); !e.empty()) return e;
  }
  if (tool != nullptr) event(tool, "tool change T" + std::to_string(tool->event.number) + " (holds until RESUME)");
  if (spindle != nullptr) {
    std::snprintf(buf, sizeof buf, "spindle %s %.0f rpm",
                  spindle->event.number > 0 ? "cw" : spindle->event.number < 0 ? "ccw" : "off", spindle->event.value);
    event(spindle, buf);
  }
  if (coolant != nullptr)
    event(coolant, std::string("coolant ") + ((coolant->event.number & 3) == 0 ? "off"
                                              : (coolant->event.number & 2) != 0 ? ((coolant->event.number & 1) ? "flood and mist" : "flood")
                                                                                 : "mist"));
  if (std::string e = rapid(target, "rapid down to the start of the line"); !e.empty()) return e;
  program::Block rest;  // at rest on the start point: line N starts from a stop, as after an event
  rest.kind = program::BlockKind::kDwell;
  rest.start = rest.end = cur;
  rest.dwell_s = 0;
  add(std::move(rest));
  p.approach_text = "from line " + std::to_string(p.from_line) + ": " + text;
  return "";
}

const program::Block* ProgramServer::block(int64_t index) {
  if (!program_ || index < 0 || index >= program_->num_blocks) return nullptr;
  if (program_->from_line > 0) {
    // The approach, then the program's blocks from line N renumbered after it.
    const auto a = static_cast<int64_t>(program_->approach.size());
    if (index < a) return &program_->approach[static_cast<size_t>(index)];
    const program::Block* b = full_block(index - a + program_->from_block);
    if (b == nullptr) return nullptr;
    renumbered_ = *b;
    renumbered_.index = index;
    return &renumbered_;
  }
  const program::Block* b = full_block(index);
  if (b != nullptr && program_->line && b->kind == program::BlockKind::kEnd) {
    renumbered_ = *b;  // the MDI file's closing '%' (or an M2 of the line's own)
    renumbered_.event.number = program::kEndOfOperatorLine;
    return &renumbered_;
  }
  return b;
}

int64_t ProgramServer::awaited_result_block() const {
  if (!program_ || !live_probing_) return -1;
  const size_t k = program_->results.size();
  return k < program_->result_blocks.size() ? program_->result_blocks[k] : -1;
}

bool ProgramServer::awaited_result_is_probe() const {
  if (awaited_result_block() < 0) return false;
  return program_->result_is_probe[program_->results.size()];
}

bool ProgramServer::awaiting_result(int64_t index) const {
  if (!program_) return false;
  if (program_->from_line > 0) index = index - static_cast<int64_t>(program_->approach.size()) + program_->from_block;
  const int64_t p = awaited_result_block();
  return p >= 0 && index > p;
}

LoadResult ProgramServer::probe_result(int64_t index, const ProbeResult& result) {
  MachineResult m;
  m.is_probe = true;
  m.probe = result;
  return add_result(index, m);
}

LoadResult ProgramServer::input_result(int64_t index, double value) {
  MachineResult m;
  m.input_value = value;
  return add_result(index, m);
}

LoadResult ProgramServer::add_result(int64_t index, const MachineResult& result) {
  LoadResult r;
  const char* what = result.is_probe ? "a probe result" : "an input value (M66)";
  if (!program_) {
    r.error = std::string(what) + " with no program loaded";
    return r;
  }
  const int64_t full = program_->from_line > 0
                           ? index - static_cast<int64_t>(program_->approach.size()) + program_->from_block
                           : index;
  if (full != awaited_result_block() || result.is_probe != awaited_result_is_probe()) {
    r.error = program_->path + ": " + what + " for block " + std::to_string(index) + ", which is not the block awaiting one";
    return r;
  }
  auto next = std::make_unique<Loaded>();
  next->path = program_->path;
  next->token = program_->token;
  next->start = program_->start;
  next->block_delete = program_->block_delete;
  next->from_line = program_->from_line;
  next->line = program_->line;
  next->modes_in = program_->modes_in;
  next->results = program_->results;
  next->results.push_back(result);
  next->probes_known = program_->probes_known + (result.is_probe ? 1 : 0);
  if (!validate(*next, r)) {
    program_.reset();
    serving_.reset();
    cache_.clear();
    return r;
  }
  install(std::move(next));
  r.ok = true;
  return r;
}

const program::Block* ProgramServer::full_block(int64_t index) {
  if (!program_ || index < 0 || index >= program_->full_blocks) return nullptr;
  // After a probing move or an input wait nothing is served before its result.
  if (const int64_t p = awaited_result_block(); p >= 0 && index > p) return nullptr;
  const Chunk* c = chunk_for(index);
  if (c == nullptr) return nullptr;
  const int64_t k = index - c->first;
  if (k < 0 || k >= static_cast<int64_t>(c->blocks.size())) return nullptr;
  return &c->blocks[static_cast<size_t>(k)];
}

const ProgramServer::Chunk* ProgramServer::chunk_for(int64_t index) {
  const int64_t per = limits_.blocks_per_chunk;
  const int64_t first = index / per * per;
  for (Chunk& ch : cache_) {
    if (ch.first == first) {
      ch.last_use = ++use_clock_;
      return &ch;
    }
  }
  const std::string changed = program_->path + ": the program no longer interprets as when it was loaded";
  try {
    // The serving interpreter is at block `serving_next_`; an earlier chunk means
    // starting over.
    if (!serving_ || serving_next_ > first) {
      if (serving_) ++restarts_;
      serving_ = start_run(*program_, false);
      serving_next_ = 0;
    }
    Chunk fresh;
    program::Block b;
    while (serving_next_ < first + per && serving_next_ < program_->full_blocks) {
      const int64_t c = serving_next_ / per;
      if (serving_next_ % per == 0) {
        ++chunk_reads_;
        fresh.first = serving_next_;
        fresh.blocks.clear();
        chunk_hash_ = 14695981039346656037ull;
      }
      if (!serving_->next(&b)) {
        const size_t k = program_->results.size();
        if (serving_->waiting() && serving_next_ > first && k < program_->result_blocks.size() &&
            serving_next_ - 1 == program_->result_blocks[k]) {
          // At a probing move or an input wait, awaiting its result: the chunk so far, checked up to it.
          if (chunk_hash_ != program_->result_hashes[k]) {
            serving_error_ = changed;
            program_.reset();
            cache_.clear();
            return nullptr;
          }
          break;
        }
        serving_error_ = changed + (serving_->waiting() ? " (a probing move or an input wait where none was)" : " (it ended early)");
        program_.reset();
        cache_.clear();
        return nullptr;
      }
      chunk_hash_ = block_hash(b, chunk_hash_);
      if (!serving_reached_ && serving_->reached()) {
        serving_reached_ = true;
        serving_state_ = serving_->state();
      }
      ++serving_next_;
      if (serving_next_ > first) fresh.blocks.push_back(std::move(b));
      if (serving_next_ % per == 0 || serving_next_ == program_->full_blocks) {
        if (chunk_hash_ != program_->chunk_hashes[static_cast<size_t>(c)]) {
          serving_error_ = changed;
          program_.reset();
          cache_.clear();
          return nullptr;
        }
      }
    }
    fresh.last_use = ++use_clock_;
    if (static_cast<int>(cache_.size()) < limits_.cached_chunks) {
      cache_.push_back(std::move(fresh));
      return &cache_.back();
    }
    Chunk& victim = *std::min_element(cache_.begin(), cache_.end(),
                                      [](const Chunk& a, const Chunk& b2) { return a.last_use < b2.last_use; });
    victim = std::move(fresh);
    return &victim;
  } catch (const std::exception& e) {
    serving_error_ = changed + " (" + e.what() + ")";
    program_.reset();
    cache_.clear();
    return nullptr;
  }
}

}  // namespace cnc::pps
