// One block's steps, in LinuxCNC's order of execution (its convert_* sequence).
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

void Interpreter::execute_block(Words& w) {
  // 1. Comments and messages.
  comments_of_line();
  // NURBS curve collection takes the lines until it closes; a line of comments only
  // (or an empty one) leaves the curve open.
  if (nurbs_ && line_.words.empty()) return;
  if (nurbs_ && nurbs_->fanuc) {
    // LinuxCNC's newer G6.2 repeats the G code on its knot-only lines ("G6.2 K29").
    if (w.on('K') && (w.g[1] < 0 || w.g[1] == 62)) {
      nurbs_fanuc_line(w);
      // A curve whose knots are complete (control points + order) ends here.
      if (nurbs_->knots.size() == nurbs_->points.size() + static_cast<size_t>(nurbs_->order)) {
        nurbs_fanuc_close();
        fanuc_closed_line_ = line_no_;
      }
      return;
    }
    nurbs_fanuc_close();
  }
  if (nurbs_ && !nurbs_->fanuc) {
    if (w.g[1] == 53) {
      w53_column_ = w.gcol[1];
      nurbs_g5_close();
      return;
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
      return;
    }
    fail(w.g[1] >= 0 ? w.gcol[1] : 0, "inside a G5.2 curve: expected X Y P control points or G5.3");
  }
  // 3. Feed mode.
  if (w.g[5] >= 0) {
    const SourceRef r = ref(w.gcol[5]);
    feed_mode_ = w.g[5] == 930 ? FeedMode::kInverseTime : w.g[5] == 950 ? FeedMode::kUnitsPerRev : FeedMode::kUnitsPerMinute;
    canon_.comment(r, feed_mode_ == FeedMode::kInverseTime   ? "interpreter: feed mode set to inverse time"
                      : feed_mode_ == FeedMode::kUnitsPerRev ? "interpreter: feed mode set to units per revolution"
                                                             : "interpreter: feed mode set to units per minute");
    canon_.set_feed_mode(r, feed_mode_);
    if (feed_mode_ != FeedMode::kInverseTime) {
      feed_ = 0;
      canon_.set_feed_rate(r, 0);
    }
  }
  // 4. Feed rate.
  if (w.on('F')) {
    feed_ = w['F'];
    if (feed_mode_ != FeedMode::kInverseTime) canon_.set_feed_rate(ref(w.column('F')), feed_);
  }
  // 5. Spindle speed.
  if (w.on('S')) {
    speed_ = w['S'];
    canon_.set_spindle_speed(ref(w.column('S')), speed_);
  }
  // 6. Tool selection.
  if (w.on('T')) {
    const int t = static_cast<int>(std::lround(w['T']));
    if (t != 0 && !setup_.tool_table.empty() && tools_.find(t) == nullptr)
      fail(w.column('T'), "tool T" + std::to_string(t) + " is not in the tool table " + setup_.tool_table);
    selected_tool_ = t;
    canon_.select_tool(ref(w.column('T')), t);
  }
  // 7. Outputs and inputs.
  if (w.m[5] >= 0) {
    const int m = w.m[5];
    const SourceRef r = ref(w.mcol[5]);
    if (m == 66) fail(w.mcol[5], setup_.digital_inputs + setup_.analog_inputs == 0
                                     ? "M66 waits on an input, and this machine's config has none"
                                     : "M66 is not supported yet");
    if (!w.on(m >= 67 ? 'E' : 'P')) fail(w.mcol[5], "M" + std::to_string(m) + (m >= 67 ? " needs an E word (output index)" : " needs a P word (output index)"));
    const int idx = static_cast<int>(std::lround(m >= 67 ? w['E'] : w['P']));
    const int n = m >= 67 ? setup_.analog_outputs : setup_.digital_outputs;
    if (idx < 0 || idx >= n) fail(w.mcol[5], "output index " + std::to_string(idx) + " outside 0.." + std::to_string(n - 1));
    if (m <= 65) {
      canon_.digital_output(r, idx, m == 62 || m == 64, m == 62 || m == 63);
    } else {
      if (!w.on('Q')) fail(w.mcol[5], "M" + std::to_string(m) + " needs a Q word (the value)");
      canon_.analog_output(r, idx, w['Q'], m == 67);
    }
  }
  // 8. Tool change.
  if (w.m[6] == 6) {
    tool_change(w);
  } else if (w.m[6] == 61) {
    if (!w.on('Q')) fail(w.mcol[6], "M61 needs a Q word (the tool number)");
    const int t = static_cast<int>(std::lround(w['Q']));
    if (t < 0) fail(w.column('Q'), "negative tool number");
    tool_ = t;
    canon_.change_tool_number(ref(w.mcol[6]), t);
    set_tool_params();
    reread_position();
  }
  // 9. Spindle.
  if (w.m[7] >= 0) {
    const SourceRef r = ref(w.mcol[7]);
    switch (w.m[7]) {
      case 3: spindle_ = 1; canon_.start_spindle_clockwise(r); break;
      case 4: spindle_ = -1; canon_.start_spindle_counterclockwise(r); break;
      case 5: spindle_ = 0; canon_.stop_spindle_turning(r); break;
      default: fail(w.mcol[7], "M19 (spindle orientation) is not supported: this machine has no spindle encoder");
    }
  }
  // 10. Modal state save/restore (M70-M73).
  if (w.m[10] >= 0) {
    const int m = w.m[10];
    if (m == 70 || m == 73) {
      SavedModes s{static_cast<int32_t>(frames_.size()) + (m == 73 ? 0 : 1000000), true, motion_, plane_, incremental_,
                   arc_incremental_, feed_mode_, units_, coord_, retract_r_, path_, path_p_, path_q_, feed_, speed_,
                   spindle_, mist_, flood_};
      if (m == 73) {
        if (frames_.empty()) fail(w.mcol[10], "M73 outside a subroutine");
      }
      saved_.push_back(s);
    } else if (m == 71) {
      if (!saved_.empty()) saved_.back().valid = false;
    } else {  // M72
      if (saved_.empty() || !saved_.back().valid) fail(w.mcol[10], "M72 without a valid state saved by M70");
      restore_modes(saved_.back(), w.mcol[10]);
    }
  }
  // 11. Coolant.
  if (w.m[8] >= 0) {
    const SourceRef r = ref(w.mcol[8]);
    if (w.m[8] == 9) {
      canon_.mist_off(r);
      canon_.flood_off(r);
      mist_ = flood_ = false;
    } else {
      if (w.m7) {
        mist_ = true;
        canon_.mist_on(r);
      }
      if (w.m8) {
        flood_ = true;
        canon_.flood_on(r);
      }
    }
  }
  // 12. Overrides.
  if (w.m[9] >= 0) {
    const SourceRef r = ref(w.mcol[9]);
    const bool p_on = !w.on('P') || w['P'] != 0;
    switch (w.m[9]) {
      case 48: feed_override_ = speed_override_ = true; canon_.enable_speed_override(r, true); canon_.enable_feed_override(r, true); break;
      case 49: feed_override_ = speed_override_ = false; canon_.enable_speed_override(r, false); canon_.enable_feed_override(r, false); break;
      case 50: feed_override_ = p_on; canon_.enable_feed_override(r, p_on); break;
      case 51: speed_override_ = p_on; canon_.enable_speed_override(r, p_on); break;
      case 52: adaptive_feed_ = p_on; canon_.enable_adaptive_feed(r, p_on); break;
      case 53: feed_hold_ = p_on; canon_.enable_feed_hold(r, p_on); break;
      default: break;
    }
  }
  // 14. Dwell.
  if (w.g[0] == 40) {
    if (!w.on('P')) fail(w.gcol[0], "G4 needs a P word (seconds)");
    const double p = w['P'];
    if (p < 0) fail(w.column('P'), "negative dwell time");
    canon_.dwell(ref(w.gcol[0]), p);
  }
  // 15. Plane.
  if (w.g[2] >= 0) {
    const Plane p = w.g[2] == 170 ? Plane::kXY : w.g[2] == 180 ? Plane::kXZ : Plane::kYZ;
    if (comp_ != 400 && p != plane_) fail(w.gcol[2], "cannot change planes with cutter radius compensation on");
    plane_ = p;
    canon_.select_plane(ref(w.gcol[2]), plane_);
  }
  // 16. Units.
  if (w.g[6] >= 0) {
    const Units u = w.g[6] == 200 ? Units::kInch : Units::kMm;
    if (comp_ != 400 && u != units_) fail(w.gcol[6], "cannot change units with cutter radius compensation on");
    if (u != units_) {
      // The feed keeps its meaning in the new units (LinuxCNC converts it).
      feed_ = u == Units::kInch ? feed_ / kMmPerInch : feed_ * kMmPerInch;
    }
    units_ = u;
    canon_.use_length_units(ref(w.gcol[6]), units_);
  }
  // 17. Cutter radius compensation.
  if (w.g[7] >= 0) {
    const int g = w.g[7];
    if (g == 400) {
      canon_.comment(ref(w.gcol[7]), "interpreter: cutter radius compensation off");
      comp_filter_->stop();
      comp_ = 400;
      comp_radius_ = 0;
    } else {
      if (comp_ != 400) fail(w.gcol[7], "cannot turn cutter radius compensation on when it is already on");
      if (plane_ != Plane::kXY && plane_ != Plane::kXZ) fail(w.gcol[7], "cutter radius compensation needs the XY or XZ plane");
      double radius = 0;
      if (g == 411 || g == 421) {
        if (!w.on('D')) fail(w.gcol[7], g_text(g) + " needs a D word (the tool diameter)");
        radius = w['D'] * length_scale() / 2;
      } else {
        int t = tool_;
        if (w.on('D')) t = static_cast<int>(std::lround(w['D']));
        const Tool* tool = tools_.find(t);
        if (t != 0 && tool == nullptr) fail(w.on('D') ? w.column('D') : w.gcol[7], "tool " + std::to_string(t) + " is not in the tool table");
        radius = tool ? tool->diameter / 2 : 0;
      }
      // A negative radius (G41.1 D-) swaps the side, as in LinuxCNC.
      int side = g == 410 || g == 411 ? 1 : -1;
      if (radius < 0) {
        radius = -radius;
        side = -side;
      }
      comp_ = g;
      comp_radius_ = radius;
      canon_.comment(ref(w.gcol[7]), side < 0 ? "interpreter: cutter radius compensation on right"
                                              : "interpreter: cutter radius compensation on left");
      const Pose programmed = program_pose(position_);
      comp_filter_->start(side, to_program(radius), plane_, programmed);
    }
  }
  // 18. Tool length compensation.
  if (w.g[8] >= 0) {
    const int g = w.g[8];
    const SourceRef r = ref(w.gcol[8]);
    Pose off{};
    if (g == 430) {
      int t = tool_;
      if (w.on('H')) t = static_cast<int>(std::lround(w['H']));
      if (t == 0) t = tool_;  // H0: LinuxCNC's table entry 0, the tool in the spindle
      if (t != 0) {
        const Tool* tool = tools_.find(t);
        if (tool == nullptr) fail(w.on('H') ? w.column('H') : w.gcol[8], "tool " + std::to_string(t) + " is not in the tool table");
        off = tool->offset;
      }
    } else if (g == 431) {
      for (int i = 0; i < kNumAxes; ++i)
        if (w.on(kAxisLetters[i])) off[static_cast<size_t>(i)] = w[kAxisLetters[i]] * (i < 3 || i >= 6 ? length_scale() : 1.0);
      w.axes = 0;  // the axis words were G43.1's
      for (int i = 0; i < kNumAxes; ++i) w.has &= ~bit(kAxisLetters[i]);
    } else if (g == 432) {
      off = tool_offset_;
      if (w.on('H')) {
        const int t = static_cast<int>(std::lround(w['H']));
        const Tool* tool = tools_.find(t);
        if (tool == nullptr) fail(w.column('H'), "tool " + std::to_string(t) + " is not in the tool table");
        for (size_t i = 0; i < off.size(); ++i) off[i] += tool->offset[i];
      }
    }
    // The program position moves by the change of offset; the machine stays. The
    // offset acts in the machine's frame: X and Y turn into a rotated system's frame
    // (LinuxCNC's convert_tool_length_offset).
    Pose delta{};
    for (size_t i = 0; i < off.size(); ++i) delta[i] = tool_offset_[i] - off[i];
    if (rotation_deg_ != 0) {
      const double a = -rotation_deg_ * M_PI / 180.0, co = std::cos(a), sn = std::sin(a);
      const double dx = delta[0] * co - delta[1] * sn;
      delta[1] = delta[0] * sn + delta[1] * co;
      delta[0] = dx;
    }
    for (size_t i = 0; i < off.size(); ++i) position_[i] += delta[i];
    tool_offset_ = off;
    tool_length_ = g;
    Pose shown{};
    for (size_t i = 0; i < off.size(); ++i) shown[i] = i < 3 || i >= 6 ? to_program(off[i]) : off[i];
    canon_.use_tool_length_offset(r, shown);
  }
  // 19. Coordinate system.
  if (w.g[12] >= 0) {
    static const int kCs[] = {540, 550, 560, 570, 580, 590, 591, 592, 593};
    int idx = 1;
    for (int i = 0; i < 9; ++i)
      if (kCs[i] == w.g[12]) idx = i + 1;
    if (idx == coord_)
      canon_.comment(ref(w.gcol[12]), "interpreter: continuing to use same coordinate system");
    else
      set_coord_system(idx);
  }
  // 20. Path control.
  if (w.g[13] >= 0) {
    const SourceRef r = ref(w.gcol[13]);
    if (w.g[13] == 610) {
      path_ = PathMode::kExactPath;
      canon_.set_motion_control_mode(r, path_, 0);
    } else if (w.g[13] == 611) {
      path_ = PathMode::kExactStop;
      canon_.set_motion_control_mode(r, path_, 0);
    } else {
      path_ = PathMode::kContinuous;
      path_p_ = w.on('P') ? w['P'] : 0;
      path_q_ = w.on('Q') ? w['Q'] : path_p_;
      if (path_p_ < 0) fail(w.column('P'), "G64 P must not be negative");
      canon_.set_motion_control_mode(r, path_, path_p_);
      canon_.set_naivecam_tolerance(r, path_q_);
    }
  }
  // 21. Distance modes.
  if (w.g[3] >= 0 && incremental_ != (w.g[3] == 910)) {
    incremental_ = w.g[3] == 910;
    canon_.comment(ref(w.gcol[3]), incremental_ ? "interpreter: distance mode changed to incremental"
                                                : "interpreter: distance mode changed to absolute");
  }
  if (w.g[4] >= 0 && arc_incremental_ != (w.g[4] == 911)) {
    arc_incremental_ = w.g[4] == 911;
    canon_.comment(ref(w.gcol[4]), arc_incremental_ ? "interpreter: IJK distance mode changed to incremental"
                                                    : "interpreter: IJK distance mode changed to absolute");
  }
  // 22. Retract mode.
  if (w.g[10] >= 0) {
    if (comp_ != 400) fail(w.gcol[10], "cannot change retract mode with cutter radius compensation on");
    retract_r_ = w.g[10] == 990;
    canon_.comment(ref(w.gcol[10]), retract_r_ ? "interpreter: retract mode set to r_plane"
                                               : "interpreter: retract mode set to old_z");
  }
  // 23. Home, G10, G92.
  if (w.g[0] == 100) g10(w);
  if (w.g[0] == 280 || w.g[0] == 300) g28_g30(w, w.g[0] == 300);
  if (w.g[0] == 281 || w.g[0] == 301) {
    const int base = w.g[0] == 281 ? 5161 : 5181;
    for (int i = 0; i < kNumAxes; ++i) {
      const size_t k = static_cast<size_t>(i);
      set_param_len(base, i, machine_of(position_, coord_)[k]);
    }
    if (w.axes != 0) fail(w.gcol[0], g_text(w.g[0]) + " takes no axis words");
  }
  if (w.g[0] == 520 || (w.g[0] >= 920 && w.g[0] <= 923)) g92(w);
  // 24. Motion.
  prev_motion_ = motion_;
  if (w.g[1] >= 0) {
    motion_ = w.g[1];
    if (motion_ == 800) {
      in_cycle_ = false;
      canon_.comment(ref(w.gcol[1]), "interpreter: motion mode set to none");
    }
  }
  const bool axis_g0 = w.g[0] == 100 || w.g[0] == 280 || w.g[0] == 300 || w.g[0] == 520 || w.g[0] == 920 ||
                       w.g[0] == 431;
  if (w.g[1] == 52) {
    nurbs_g5_open(w);
  } else if (w.g[1] == 62) {
    nurbs_fanuc_open(w);
  } else if (w.g[1] == 53) {
    fail(w.gcol[1], "G5.3 without G5.2");
  } else if (w.g[1] >= 0 || (w.axes != 0 && !axis_g0)) {
    motion(w);
  }
  // 25. Stops.
  if (w.m[4] >= 0) {
    const SourceRef r = ref(w.mcol[4]);
    switch (w.m[4]) {
      case 0: canon_.program_stop(r); break;
      case 1: if (setup_.optional_stop) canon_.optional_program_stop(r); break;
      case 60: canon_.pallet_shuttle(r); canon_.program_stop(r); break;
      case 2: end_program(false); break;
      case 30: end_program(true); break;
      case 99:
        // M99 in the main program (a call's M99 opens its line: fanuc_return).
        if (!setup_.loop_on_main_m99) {
          end_program(false);  // LinuxCNC's standalone rs274: as M2
          break;
        }
        // LinuxCNC's task: back to the first line, forever.
        comp_filter_->flush();
        canon_.finish(r);
        file_ = 0;
        files_[0]->seek(0);
        line_no_ = 0;
        started_ = false;
        percent_open_ = false;
        loops_.clear();
        break;
      default: break;
    }
  }
}

// M72 and the return from a subroutine that ran M73: the saved modes come back
// through the same calls that set them, in LinuxCNC's order (F, S, G codes, M codes).
void Interpreter::restore_modes(const SavedModes& sm, int column) {
  const SourceRef r = ref(column);
  if (units_ != sm.units) {
    feed_ = sm.units == Units::kInch ? feed_ / kMmPerInch : feed_ * kMmPerInch;
    units_ = sm.units;
    canon_.use_length_units(r, units_);
  }
  if (feed_ != sm.feed) {
    feed_ = sm.feed;
    canon_.set_feed_rate(r, feed_);
  }
  if (speed_ != sm.speed) {
    speed_ = sm.speed;
    canon_.set_spindle_speed(r, speed_);
  }
  motion_ = sm.motion;
  if (plane_ != sm.plane) {
    plane_ = sm.plane;
    canon_.select_plane(r, plane_);
  }
  if (incremental_ != sm.incremental) {
    incremental_ = sm.incremental;
    canon_.comment(r, incremental_ ? "interpreter: distance mode changed to incremental"
                                   : "interpreter: distance mode changed to absolute");
  }
  if (arc_incremental_ != sm.arc_incremental) {
    arc_incremental_ = sm.arc_incremental;
    canon_.comment(r, arc_incremental_ ? "interpreter: IJK distance mode changed to incremental"
                                       : "interpreter: IJK distance mode changed to absolute");
  }
  if (feed_mode_ != sm.feed_mode) {
    feed_mode_ = sm.feed_mode;
    canon_.set_feed_mode(r, feed_mode_);
  }
  if (coord_ != sm.coord) set_coord_system(sm.coord);
  if (retract_r_ != sm.retract_r) {
    retract_r_ = sm.retract_r;
    canon_.comment(r, retract_r_ ? "interpreter: retract mode set to r_plane" : "interpreter: retract mode set to old_z");
  }
  if (path_ != sm.path || path_p_ != sm.path_p || path_q_ != sm.path_q) {
    path_ = sm.path;
    path_p_ = sm.path_p;
    path_q_ = sm.path_q;
    canon_.set_motion_control_mode(r, path_, path_p_);
    if (path_ == PathMode::kContinuous) canon_.set_naivecam_tolerance(r, path_q_);
  }
  if (spindle_ != sm.spindle) {
    spindle_ = sm.spindle;
    if (spindle_ == 1) canon_.start_spindle_clockwise(r);
    else if (spindle_ == -1) canon_.start_spindle_counterclockwise(r);
    else canon_.stop_spindle_turning(r);
  }
  if (mist_ != sm.mist || flood_ != sm.flood) {
    if (!sm.mist && !sm.flood) {
      canon_.mist_off(r);
      canon_.flood_off(r);
    } else {
      if (sm.mist && !mist_) canon_.mist_on(r);
      if (sm.flood && !flood_) canon_.flood_on(r);
    }
    mist_ = sm.mist;
    flood_ = sm.flood;
  }
}

}  // namespace cnc::rs274
