// One block's steps, in LinuxCNC's order of execution (its convert_* sequence).
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

// LinuxCNC's order of execution (its execute_block): one step per group of codes,
// each made when the block has a code of its group.
void Interpreter::execute_block(Words& w) {
  comments_of_line();
  if (nurbs_ && continue_nurbs(w)) return;
  // G96/G97 (LinuxCNC's spindle mode step; this controller keeps G97) select with $.
  if (w.g[14] >= 0 && w.on('$') && spindle_number(w) != 0)
    fail(w.column('$'), "Invalid spindle ($) number in Spindle Mode command");
  if (w.g[5] >= 0) g93_g95(w);
  if ((w.has & (bit('F') | bit('S') | bit('T'))) != 0) f_s_t(w);
  if (w.m[5] >= 0) m62_m68(w);
  if (w.m[6] >= 0) m6_m61(w);
  if (remap_called_) {
    remap_called_ = false;
    return;  // into M6's remap: the rest when it returns
  }
  execute_block_after_m6(w);
}

void Interpreter::execute_block_after_m6(Words& w) {
  if (w.m[7] >= 0) m3_m5(w);
  if (w.m[10] >= 0) m70_m73(w);
  if (w.m[8] >= 0) m7_m9(w);
  if (w.m[9] >= 0) m48_m53(w);
  if (w.g[0] == 40) g4(w);
  if (w.g[2] >= 0) g17_g19(w);
  if (w.g[6] >= 0) g20_g21(w);
  if (w.g[15] >= 0) g7_g8(w);
  if (w.g[7] >= 0) g40_g42(w);
  if (w.g[8] >= 0) g43_g49(w);
  if (twp_) refuse_in_tilted_plane(w);
  if (w.g[12] >= 0) g54_g59(w);
  if (w.g[13] >= 0) g61_g64(w);
  if (w.g[3] >= 0 || w.g[4] >= 0) g90_g91(w);
  if (w.g[10] >= 0) g98_g99(w);
  if (w.g[0] >= 0) homes_and_offsets(w);
  if (w.g[16] >= 0) g68_2_g69(w);
  if (w.g[0] == 531) g53_1(w);
  motion_block(w);
  if (w.m[4] >= 0) stops(w);
}

// Feed mode (G93, G94, G95).
void Interpreter::g93_g95(const Words& w) {
  const SourceRef r = ref(w.gcol[5]);
  if (w.on('$') && spindle_number(w) != 0) fail(w.column('$'), "Invalid spindle ($) number in Spindle Feed command");
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

// Feed rate, spindle speed and tool selection (F, S, T).
void Interpreter::f_s_t(const Words& w) {
  if (w.on('F')) {
    feed_ = w['F'];
    if (feed_mode_ != FeedMode::kInverseTime) canon_.set_feed_rate(ref(w.column('F')), feed_);
  }
  // Spindle speed ($-1: every spindle, here the one).
  if (w.on('S')) {
    if (w.on('$') && (spindle_number(w) < -1 || spindle_number(w) > 0))
      fail(w.column('$'), "Invalid spindle ($) number in Spindle speed command");
    speed_ = w['S'];
    canon_.set_spindle_speed(ref(w.column('S')), speed_);
  }
  // Tool selection.
  if (w.on('T')) {
    const int t = static_cast<int>(std::lround(w['T']));
    if (t != 0 && !setup_.tool_table.empty() && tools_.find(t) == nullptr)
      fail(w.column('T'), "tool T" + std::to_string(t) + " is not in the tool table " + setup_.tool_table);
    selected_tool_ = t;
    canon_.select_tool(ref(w.column('T')), t);
  }
}

// Outputs and inputs (M62-M68).
void Interpreter::m62_m68(const Words& w) {
  const int m = w.m[5];
  const SourceRef r = ref(w.mcol[5]);
  if (m == 66) return wait_input(w);
  if (m >= 67 && comp_ != 400)
    fail(w.mcol[5], std::string("cannot set ") + (m == 67 ? "motion" : "auxiliary") +
                        " analog output with cutter radius compensation on");
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

// Spindle (M3, M4, M5, M19).
void Interpreter::m3_m5(const Words& w) {
  const SourceRef r = ref(w.mcol[7]);
  if (w.on('$')) {
    // $-1 (every spindle) starts and stops the one there is; M19 orients one.
    const int d = spindle_number(w);
    if (w.m[7] == 19 && d != 0) fail(w.column('$'), "Spindle ($) number out of range in M19 Command");
    if (w.m[7] != 19 && (d < -1 || d > 0)) {
      std::string what = "Spindle ($) number out of range in M";
      what += std::to_string(w.m[7]);
      what += " Command (num_spindles = 1, $ = ";
      what += std::to_string(d);
      what += ")";
      fail(w.column('$'), what);
    }
  }
  switch (w.m[7]) {
    case 3: spindle_ = 1; canon_.start_spindle_clockwise(r); break;
    case 4: spindle_ = -1; canon_.start_spindle_counterclockwise(r); break;
    case 5: spindle_ = 0; canon_.stop_spindle_turning(r); break;
    default: {
      // M19 R (angle) Q (timeout, s) P (0 shortest, 1 clockwise, 2 counterclockwise):
      // LinuxCNC's orientation, which leaves the spindle counted as stopped and, with
      // neither R nor P, orients nothing.
      if (!setup_.spindle_sync)
        fail(w.mcol[7], "M19 (spindle orientation) needs a spindle whose position the machine measures "
                        "(spindle.encoder_counts_per_rev)");
      spindle_ = 0;
      if (w.on('P')) {
        // LinuxCNC's check_other_codes: within 0.001 of an integer, that integer 0..2.
        const double p = w['P'];
        const double n = std::round(p);
        if (std::fabs(n - p) > 0.001) fail(w.column('P'), "P value not an integer with M19 G2 or G3");
        if (n < 0 || n > 2) fail(w.column('P'), "P value must be 0,1,or 2 with M19");
      }
      // The angle is R from the spindle's orientation offset (LinuxCNC's ORIENT_OFFSET).
      if (w.on('R') || w.on('P'))
        canon_.orient_spindle(r, w.on('R') ? w['R'] + setup_.orient_offset_deg : setup_.orient_offset_deg,
                              w.on('P') ? static_cast<int>(w['P']) : 0);
      if (w.on('Q')) {
        if (w['Q'] <= 0) fail(w.column('Q'), "Q word with M19 requires a value > 0");
        canon_.wait_orient_complete(r, w['Q']);
      }
    }
  }
}

// Modal state saved and restored (M70-M73).
void Interpreter::m70_m73(const Words& w) {
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

// Coolant (M7, M8, M9).
void Interpreter::m7_m9(const Words& w) {
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

// Overrides (M48-M53).
void Interpreter::m48_m53(const Words& w) {
  const SourceRef r = ref(w.mcol[9]);
  const bool p_on = !w.on('P') || w['P'] != 0;
  // LinuxCNC takes M51's $ from 1 up: with one spindle no $ is valid there.
  if (w.m[9] == 51 && w.on('$')) fail(w.column('$'), "Invalid spindle ($) number in M51 command");
  switch (w.m[9]) {
    case 48: feed_override_ = speed_override_ = true; canon_.enable_feed_override(r, true); canon_.enable_speed_override(r, true); break;
    case 49: feed_override_ = speed_override_ = false; canon_.enable_feed_override(r, false); canon_.enable_speed_override(r, false); break;
    case 50: feed_override_ = p_on; canon_.enable_feed_override(r, p_on); break;
    case 51: speed_override_ = p_on; canon_.enable_speed_override(r, p_on); break;
    case 52: adaptive_feed_ = p_on; canon_.enable_adaptive_feed(r, p_on); break;
    case 53: feed_hold_ = p_on; canon_.enable_feed_hold(r, p_on); break;
    default: break;
  }
}

// Dwell (G4).
void Interpreter::g4(const Words& w) {
  if (!w.on('P')) fail(w.gcol[0], "G4 needs a P word (seconds)");
  const double p = w['P'];
  if (p < 0) fail(w.column('P'), "negative dwell time");
  canon_.dwell(ref(w.gcol[0]), p);
}

// Plane (G17, G18, G19).
void Interpreter::g17_g19(const Words& w) {
  const Plane p = w.g[2] == 170 ? Plane::kXY : w.g[2] == 180 ? Plane::kXZ : Plane::kYZ;
  if (comp_ != 400 && p != plane_) fail(w.gcol[2], "cannot change planes with cutter radius compensation on");
  plane_ = p;
  canon_.select_plane(ref(w.gcol[2]), plane_);
}

// Units (G20, G21).
void Interpreter::g20_g21(const Words& w) {
  const Units u = w.g[6] == 200 ? Units::kInch : Units::kMm;
  if (comp_ != 400 && u != units_) fail(w.gcol[6], "cannot change units with cutter radius compensation on");
  if (u != units_) {
    // The feed keeps its meaning in the new units (LinuxCNC converts it).
    feed_ = u == Units::kInch ? feed_ / kMmPerInch : feed_ * kMmPerInch;
  }
  units_ = u;
  canon_.use_length_units(ref(w.gcol[6]), units_);
}

// Lathe diameter mode (G7) and radius mode (G8, the default). The block's X was read
// in the mode before it: LinuxCNC scales it (and a G76's I J K) to the new mode here,
// so a G76 on a G7 line halves them twice (once here, once in the cycle).
void Interpreter::g7_g8(Words& w) {
  const bool diameter = w.g[15] == 70;
  if (diameter == lathe_diameter_) return;
  const double f = diameter ? 0.5 : 2.0;
  w.v[static_cast<size_t>(letter_index('X'))] *= f;
  if (motion_to_be(w) == 760)
    for (const char c : {'I', 'J', 'K'}) w.v[static_cast<size_t>(letter_index(c))] *= f;
  canon_.comment(ref(w.gcol[15]), diameter ? "interpreter: Lathe diameter mode changed to diameter"
                                           : "interpreter: Lathe diameter mode changed to radius");
  lathe_diameter_ = diameter;
}

// Path control (G61, G61.1, G64).
void Interpreter::g61_g64(const Words& w) {
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

// Distance modes (G90, G91, G90.1, G91.1).
void Interpreter::g90_g91(const Words& w) {
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
}

// Retract mode (G98, G99).
void Interpreter::g98_g99(const Words& w) {
  if (comp_ != 400) fail(w.gcol[10], "cannot change retract mode with cutter radius compensation on");
  retract_r_ = w.g[10] == 990;
  canon_.comment(ref(w.gcol[10]), retract_r_ ? "interpreter: retract mode set to r_plane"
                                             : "interpreter: retract mode set to old_z");
}

// Stops and the program's end (M0, M1, M2, M30, M60, M99).
void Interpreter::stops(const Words& w) {
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
