// Tools, offsets and coordinate systems: M6/M61, G10, G28/G30, G52/G92, G54-G59.3.
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

void Interpreter::set_coord_system(int index) {
  if (comp_ != 400) fail(0, "cannot change the coordinate system with cutter radius compensation on");
  // The machine position stays; the program position moves with the origin.
  position_ = program_of(machine_of(position_, coord_), index);
  coord_ = index;
  params_.set(5220, index);
  rotation_deg_ = params_.get(5210 + 20 * index);
  Pose g5x{};
  for (int i = 0; i < kNumAxes; ++i) g5x[static_cast<size_t>(i)] = to_program_axis(i, param_len(5201 + 20 * index, i));
  canon_.set_g5x_offset(ref(), index, g5x);
  Pose g92p{};
  for (int i = 0; i < kNumAxes; ++i) g92p[static_cast<size_t>(i)] = to_program_axis(i, g92_[static_cast<size_t>(i)]);
  canon_.set_g92_offset(ref(), g92p);
  canon_.set_xy_rotation(ref(), rotation_deg_);
}

void Interpreter::tool_change(Words& w) {
  const SourceRef r = ref(w.mcol[6]);
  if (comp_ != 400) fail(w.mcol[6], "cannot change tools with cutter radius compensation on");
  if (selected_tool_ < 0) selected_tool_ = 0;  // LinuxCNC changes to tool 0 (an empty spindle)
  canon_.start_change(r);
  if (spindle_ != 0) {
    // LinuxCNC stops the spindle for the change and leaves it stopped.
  }
  canon_.stop_spindle_turning(r);
  spindle_ = 0;
  canon_.change_tool(r, selected_tool_);
  tool_ = selected_tool_;
  set_tool_params();
  reread_position();
}

void Interpreter::set_tool_params() {
  // LinuxCNC 2.9's set_tool_parameters / default_tool_parameters (M6, M61, G10 L1/L10/L11):
  // #5400 the tool in the spindle, #5401-#5409 its table offsets and #5410 its diameter
  // in machine units (not the offset G43 applies), #5411-#5413 angles and orientation;
  // all 0 without a tool.
  const Tool* t = tool_ > 0 ? tools_.find(tool_) : nullptr;
  params_.set(5400, tool_ > 0 ? tool_ : 0);
  for (int i = 0; i < kNumAxes; ++i) {
    const double lin = i < 3 || i >= 6 ? mu_ : 1.0;
    params_.set(5401 + i, t != nullptr ? t->offset[static_cast<size_t>(i)] / lin : 0.0);
  }
  params_.set(5410, t != nullptr ? t->diameter / mu_ : 0.0);
  params_.set(5411, t != nullptr ? t->front_angle : 0.0);
  params_.set(5412, t != nullptr ? t->back_angle : 0.0);
  params_.set(5413, t != nullptr ? t->orientation : 0.0);
}

void Interpreter::g10(Words& w) {
  if (!w.on('L')) fail(w.gcol[0], "G10 needs an L word (1, 2, 10, 11 or 20)");
  const int l = static_cast<int>(std::lround(w['L']));
  if (!w.on('P')) fail(w.gcol[0], "G10 L" + std::to_string(l) + " needs a P word");
  const int p = static_cast<int>(std::lround(w['P']));
  if (l == 2 || l == 20) {
    g10_coord_system(w, l, p);
    return;
  }
  if (l == 1 || l == 10 || l == 11) {
    g10_tool(w, l, p);
    return;
  }
  fail(w.column('L'), "G10 L" + std::to_string(l) + " is not supported (L1, L2, L10, L11, L20)");
}

// G10 L2 (the offset given) and L20 (the current point becomes the values given):
// coordinate system P's origin and rotation.
void Interpreter::g10_coord_system(Words& w, int l, int p) {
  const double s = length_scale();
  if (p < 0 || p > 9) fail(w.column('P'), "G10 L" + std::to_string(l) + " P must be 0 to 9 (coordinate system)");
  const int cs = p == 0 ? coord_ : p;
  if (comp_ != 400 && cs == coord_) fail(w.gcol[0], "cannot change the active coordinate system with cutter radius compensation on");
  if (w.on('R') && l == 20) fail(w.column('R'), "R not allowed in G10 L20");
  // The tool does not move: the current position is re-expressed in the changed system
  // (LinuxCNC's convert_setup; it differs only when G10 L2 R changes the rotation of the
  // active system while a G92 offset is on, where LinuxCNC's formula leaves the G92 offset
  // rotated: expected-differences.md).
  const Pose machine = machine_of(position_, coord_);
  if (w.on('R')) params_.set(5210 + 20 * cs, w['R']);
  for (int i = 0; i < kNumAxes; ++i) {
    const char c = kAxisLetters[i];
    if (!w.on(c) || (l == 20 && i < 2)) continue;
    const size_t k = static_cast<size_t>(i);
    const double lin = i < 3 || i >= 6 ? s : 1.0;
    double off = w[c] * lin;
    if (l == 20) off = machine[k] - g92_[k] - tool_offset_[k] - w[c] * lin;  // the current position becomes the value
    set_param_len(5201 + 20 * cs, i, off);
  }
  if (l == 20 && (w.on('X') || w.on('Y'))) {
    // X and Y are values in the rotated frame of system cs: the offset is the machine point
    // less the rotated (value + G92), so both offsets change when the system is rotated.
    const Pose cur = program_of(machine, cs);
    const double x = (w.on('X') ? w['X'] * s : cur[0]) + g92_[0];
    const double y = (w.on('Y') ? w['Y'] * s : cur[1]) + g92_[1];
    const double t = params_.get(5210 + 20 * cs) * M_PI / 180.0, co = std::cos(t), sn = std::sin(t);
    set_param_len(5201 + 20 * cs, 0, machine[0] - tool_offset_[0] - (x * co - y * sn));
    set_param_len(5201 + 20 * cs, 1, machine[1] - tool_offset_[1] - (x * sn + y * co));
  }
  if (cs == coord_) position_ = program_of(machine, coord_);
  w.axes = 0;
  if (cs == coord_) {
    rotation_deg_ = params_.get(5210 + 20 * cs);
    Pose g5x{};
    for (int i = 0; i < kNumAxes; ++i) g5x[static_cast<size_t>(i)] = to_program_axis(i, param_len(5201 + 20 * cs, i));
    canon_.set_g5x_offset(ref(w.gcol[0]), cs, g5x);
    canon_.set_xy_rotation(ref(w.gcol[0]), rotation_deg_);
  } else {
    canon_.comment(ref(w.gcol[0]), "interpreter: setting coordinate system origin");
  }
}

// G10 L1 (the table's values), L10 and L11 (the current point becomes the values
// given): tool P's entry.
void Interpreter::g10_tool(Words& w, int l, int p) {
  const double s = length_scale();
  Tool t;
  if (const Tool* old = tools_.find(p)) t = *old;
  t.number = p;
  if (t.pocket == 0) t.pocket = p;
  // L10/L11 (LinuxCNC's convert_setup_tool): the offset that makes the current point
  // read as the values given in the current system (L10) or in G59.3 without G92
  // (L11). `cur` is that point as the system shows it with no tool offset; X and Y
  // are in the system's rotated frame, so the offset is rotated back, and an X (Y)
  // alone keeps the part of the old offset along the rotated Y (X).
  const int cs = l == 11 ? 9 : coord_;
  const double rot = params_.get(5210 + 20 * cs);
  const auto turn = [](double& x, double& y, double deg) {
    if (deg == 0) return;
    const double a = deg * M_PI / 180.0, co = std::cos(a), sn = std::sin(a);
    const double x1 = x * co - y * sn;
    y = x * sn + y * co;
    x = x1;
  };
  Pose cur{};
  if (l != 1) {
    const Pose machine = machine_of(position_, coord_);
    for (int i = 0; i < kNumAxes; ++i) cur[static_cast<size_t>(i)] = machine[static_cast<size_t>(i)] - param_len(5201 + 20 * cs, i);
    turn(cur[0], cur[1], -rot);
    if (l == 10)
      for (size_t k = 0; k < cur.size(); ++k) cur[k] -= g92_[k];
  }
  const auto value = [&](char c) { return w[c] * (axis_of_letter(c) < 3 || axis_of_letter(c) >= 6 ? s : 1.0); };
  for (int i = 0; i < kNumAxes; ++i) {
    const char c = kAxisLetters[i];
    if (!w.on(c)) continue;
    const size_t k = static_cast<size_t>(i);
    if (l == 1) t.offset[k] = value(c);
    else if (i >= 2) t.offset[k] = cur[k] - value(c);
  }
  if (l != 1 && (w.on('X') || w.on('Y'))) {
    double ox = t.offset[0], oy = t.offset[1];  // the old offset, kept across the axis not given
    turn(ox, oy, -rot);
    if (w.on('X')) ox = 0;
    if (w.on('Y')) oy = 0;
    turn(ox, oy, rot);
    double tx = w.on('X') ? cur[0] - value('X') : 0, ty = w.on('Y') ? cur[1] - value('Y') : 0;
    turn(tx, ty, rot);
    t.offset[0] = tx + ox;
    t.offset[1] = ty + oy;
  }
  if (w.on('R')) t.diameter = 2 * w['R'] * s;
  if (w.on('I')) t.front_angle = w['I'];
  if (w.on('J')) t.back_angle = w['J'];
  if (w.on('Q')) t.orientation = static_cast<int>(std::lround(w['Q']));
  tools_.put(t);
  tools_changed_ = true;
  // LinuxCNC hands the changed entry to the canon, and again as entry 0 when the
  // tool is in the spindle (a non-random tool changer).
  int index = 0;
  for (size_t i = 0; i < tools_.tools().size(); ++i)
    if (tools_.tools()[i].number == p) index = static_cast<int>(i) + 1;
  Pose shown = t.offset;
  for (int i = 0; i < kNumAxes; ++i)
    if (i < 3 || i >= 6) shown[static_cast<size_t>(i)] /= mu_;
  const SourceRef r = ref(w.gcol[0]);
  canon_.set_tool_table_entry(r, index, p, shown, t.diameter / mu_, t.front_angle, t.back_angle, t.orientation);
  if (tool_ == p && p > 0)
    canon_.set_tool_table_entry(r, 0, p, shown, t.diameter / mu_, t.front_angle, t.back_angle, t.orientation);
  set_tool_params();
  w.axes = 0;
}

void Interpreter::g28_g30(Words& w, bool g30) {
  const int base = g30 ? 5181 : 5161;
  // The intermediate point in program coordinates (the current point when no axis is
  // named: LinuxCNC's convert_home makes that move all the same, of length zero),
  // then the stored home of the named axes (all axes when none are named).
  Pose via = axis_target(w, false);
  const SourceRef r = ref(w.gcol[0]);
  canon_.straight_traverse(r, program_pose(via));
  position_ = via;
  Pose home_m = machine_of(position_, coord_);
  std::array<bool, kNumAxes> stored{};
  for (int i = 0; i < kNumAxes; ++i) {
    const size_t k = static_cast<size_t>(i);
    if (w.axes != 0 && !w.on(kAxisLetters[i])) continue;
    if (setup_.axes.find(kAxisLetters[i]) == std::string::npos) continue;
    home_m[k] = param_len(base, i);
    stored[k] = true;
  }
  Pose home = program_of(home_m, coord_);
  for (int i = 3; i < 6; ++i) {
    // A wrapped axis reaches its stored home the way LinuxCNC's convert_home does: the
    // way the stored value's sign says, from where the axis stands.
    const size_t k = static_cast<size_t>(i);
    if (stored[k] && wrapped(kAxisLetters[i]))
      home[k] = unwrap_rotary(w.gcol[0], kAxisLetters[i], home[k], position_[k], home_m[k]);
  }
  const Pose shown = program_pose(home);
  canon_.straight_traverse(r, shown);
  position_ = home;
  w.axes = 0;
}

// G52 and G92 share one offset (LinuxCNC 2.9's convert_axis_offsets): G92 shifts it
// so the current point gets the values given; G52 sets it to the values given for the
// axes named, the current point moving with it. Both set #5210 to 1 and #5211-#5219
// to the whole offset; G92.1 and G92.2 clear the offset and #5210 (G92.1 also
// #5211-#5219); G92.3 takes the offset back from #5211-#5219 and sets #5210.
void Interpreter::g92(Words& w) {
  const int g = w.g[0];
  const SourceRef r = ref(w.gcol[0]);
  if (comp_ != 400)
    fail(w.gcol[0], "cannot change axis offsets (" + g_text(g) + ") with cutter radius compensation on");
  if (g == 920 || g == 520) {
    if (w.on('@') || w.on('^'))
      fail(w.column(w.on('@') ? '@' : '^'), "polar coordinates (@ ^) are for motion only, not with " + g_text(g));
    if (w.axes == 0) fail(w.gcol[0], g_text(g) + " needs at least one axis word");
    const double s = length_scale();
    for (int i = 0; i < kNumAxes; ++i) {
      const char c = kAxisLetters[i];
      if (!w.on(c)) continue;
      const size_t k = static_cast<size_t>(i);
      const double lin = i < 3 || i >= 6 ? s : 1.0;
      const double v = w[c] * lin;
      if (g == 920) {
        g92_[k] = position_[k] + g92_[k] - v;
        position_[k] = v;
      } else {
        position_[k] += g92_[k] - v;
        g92_[k] = v;
      }
    }
    for (int i = 0; i < kNumAxes; ++i) set_param_len(5211, i, g92_[static_cast<size_t>(i)]);
    params_.set(5210, 1);
    g92_active_ = true;
    w.axes = 0;
  } else if (g == 921 || g == 922) {
    for (int i = 0; i < kNumAxes; ++i) {
      const size_t k = static_cast<size_t>(i);
      position_[k] += g92_[k];
      g92_[k] = 0;
      if (g == 921) set_param_len(5211, i, 0);
    }
    params_.set(5210, 0);
    g92_active_ = false;
  } else {  // G92.3
    for (int i = 0; i < kNumAxes; ++i) {
      const size_t k = static_cast<size_t>(i);
      const double v = param_len(5211, i);
      position_[k] += g92_[k] - v;
      g92_[k] = v;
    }
    params_.set(5210, 1);
    g92_active_ = true;
  }
  const Pose p = program_pose(g92_);
  canon_.set_g92_offset(r, p);
}

// Tool change (M6), and the tool in the spindle set (M61).
void Interpreter::m6_m61(Words& w) {
  const bool in_remap = std::any_of(frames_.begin(), frames_.end(), [](const Frame& f) { return f.remap_rest != nullptr; });
  if (w.m[6] == 6 && !setup_.m6_remap.empty() && !in_remap) {
    // LinuxCNC's REMAP=M6 with an ngc body: its change_prolog's locals, the call, and
    // the rest of this block after the return (return_from_call).
    const std::string& name = setup_.m6_remap;
    if (static_cast<int64_t>(frames_.size()) >= setup_.max_call_depth)
      fail(w.mcol[6], "M6 (remapped to o<" + name + ">): calls nested deeper than " + std::to_string(setup_.max_call_depth));
    const SubDef def = find_sub(name, w.mcol[6], false);
    Frame fr = call_frame(name, w.mcol[6]);
    fr.remap_rest = std::make_shared<Words>(w);
    fr.remap_rest->m[6] = -1;
    params_.push_call();
    const int selected = selected_tool_ < 0 ? tool_ : selected_tool_;
    params_.set_named("selected_tool", selected);
    params_.set_named("tool_in_spindle", tool_);
    params_.set_named("selected_pocket", selected);
    params_.set_named("current_pocket", tool_);
    enter_sub(std::move(fr), def);
    remap_called_ = true;
  } else if (w.m[6] == 6) {
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
}

// Cutter radius compensation (G40, G41, G42, G41.1, G42.1).
void Interpreter::g40_g42(const Words& w) {
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

// Tool length compensation (G43, G43.1, G43.2, G49).
void Interpreter::g43_g49(Words& w) {
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
  if (twp_tool_tilted_ && (off[0] != 0 || off[1] != 0 || off[2] != 0))
    fail(w.gcol[8], g_text(g) + " with the tool turned by G53.1: the offset would act along the part's Z, not the "
                    "tool's (G69 first)");
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

// Coordinate system (G54-G59.3).
void Interpreter::g54_g59(const Words& w) {
  static const int kCs[] = {540, 550, 560, 570, 580, 590, 591, 592, 593};
  int idx = 1;
  for (int i = 0; i < 9; ++i)
    if (kCs[i] == w.g[12]) idx = i + 1;
  if (idx == coord_)
    canon_.comment(ref(w.gcol[12]), "interpreter: continuing to use same coordinate system");
  else
    set_coord_system(idx);
}

// Homes and offsets (G10, G28, G30, G28.1, G30.1, G52, G92).
void Interpreter::homes_and_offsets(Words& w) {
  if (w.g[0] == 100) g10(w);
  if (w.g[0] == 280 || w.g[0] == 300) g28_g30(w, w.g[0] == 300);
  if (w.g[0] == 281 || w.g[0] == 301) {
    const int base = w.g[0] == 281 ? 5161 : 5181;
    for (int i = 0; i < kNumAxes; ++i) {
      const size_t k = static_cast<size_t>(i);
      double v = machine_of(position_, coord_)[k];
      if (wrapped(kAxisLetters[i])) {
        v = std::fmod(v, 360.0);  // LinuxCNC stores a wrapped axis's home in [0, 360)
        if (v < 0) v += 360.0;
      }
      set_param_len(base, i, v);
    }
    if (w.axes != 0) fail(w.gcol[0], g_text(w.g[0]) + " takes no axis words");
  }
  if (w.g[0] == 520 || (w.g[0] >= 920 && w.g[0] <= 923)) g92(w);
}

}  // namespace cnc::rs274
