// The interpreter's core: set-up, the program's start, the line loop, coordinates
// and the program's end. The parts of a line live beside it: O-words and subprograms
// (interpreter_flow.cc), words and modal groups (interpreter_words.cc), the block's
// steps in LinuxCNC's order (interpreter_block.cc), tools, offsets and coordinate
// systems (interpreter_offsets.cc), motion (interpreter_motion.cc) and the parameters
// a program reads and sets (interpreter_params.cc).
#include "common/rs274/interpreter.h"

#include <filesystem>

#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

// ---- set-up ------------------------------------------------------------------------

Interpreter::Interpreter(MachineSetup setup, Canon& canon)
    : setup_(std::move(setup)),
      comp_filter_(std::make_unique<CutterComp>(canon)),
      canon_(*comp_filter_),
      reader_(std::make_unique<Reader>(*this)) {
  for (char& c : setup_.axes) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
}

Interpreter::~Interpreter() = default;

// Program coordinates (mm) ↔ machine coordinates (mm) in coordinate system `cs`:
// machine = rotate_z(program + G92, R) + G5x + tool offset (LinuxCNC's order).
Pose Interpreter::machine_of(const Pose& p, int cs) const {
  Pose m{};
  for (size_t i = 0; i < m.size(); ++i) m[i] = p[i] + g92_[i];
  const double r = params_.get(5210 + 20 * cs);
  if (r != 0) {
    const double t = r * M_PI / 180.0, c = std::cos(t), sn = std::sin(t);
    const double x = m[0] * c - m[1] * sn, y = m[0] * sn + m[1] * c;
    m[0] = x;
    m[1] = y;
  }
  for (int i = 0; i < kNumAxes; ++i) m[static_cast<size_t>(i)] += param_len(5201 + 20 * cs, i) + tool_offset_[static_cast<size_t>(i)];
  return m;
}

Pose Interpreter::program_of(const Pose& machine, int cs) const {
  Pose p{};
  for (int i = 0; i < kNumAxes; ++i)
    p[static_cast<size_t>(i)] = machine[static_cast<size_t>(i)] - param_len(5201 + 20 * cs, i) - tool_offset_[static_cast<size_t>(i)];
  const double r = params_.get(5210 + 20 * cs);
  if (r != 0) {
    const double t = -r * M_PI / 180.0, c = std::cos(t), sn = std::sin(t);
    const double x = p[0] * c - p[1] * sn, y = p[0] * sn + p[1] * c;
    p[0] = x;
    p[1] = y;
  }
  for (size_t i = 0; i < p.size(); ++i) p[i] -= g92_[i];
  return p;
}
void Interpreter::fail(int column, const std::string& detail) const {
  std::vector<std::string> chain;
  for (auto it = frames_.rbegin(); it != frames_.rend(); ++it) {
    chain.push_back(file_names_[static_cast<size_t>(it->return_file)] + ":" + std::to_string(it->return_line) + ":" +
                    std::to_string(it->call_column) + (it->fanuc ? " (M98 P" + it->sub + ")" : " (o<" + it->sub + "> call)"));
  }
  throw Error(file_names_.empty() ? std::string() : file_names_[static_cast<size_t>(file_)], ref(column), detail,
              std::move(chain));
}

void Interpreter::open(const std::string& path) {
  if (!setup_.var_file.empty() && std::filesystem::exists(setup_.var_file)) params_.read_var_file(setup_.var_file);
  mu_ = setup_.machine_units == Units::kInch ? kMmPerInch : 1.0;
  if (!setup_.tool_table.empty()) {
    tools_.read(setup_.tool_table);
    // The table is in machine units; tools_ holds mm.
    std::vector<Tool> scaled = tools_.tools();
    for (Tool& t : scaled) {
      for (int i = 0; i < kNumAxes; ++i)
        if (i < 3 || i >= 6) t.offset[static_cast<size_t>(i)] *= mu_;
      t.diameter *= mu_;
      tools_.put(t);
    }
  }
  auto f = std::make_unique<SourceFile>();
  f->path = path;
  f->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f->fd < 0) throw Error(path, SourceRef{}, std::string("cannot open the program: ") + std::strerror(errno));
  file_names_.push_back(path);
  files_.push_back(std::move(f));
  file_ = 0;
  line_no_ = 0;

  // The state a program starts in (LinuxCNC's defaults): G17 G21(metric machine)
  // G40 G49 G54 G64 G80 G90 G91.1 G94 G97 G99? LinuxCNC starts in G98... see below.
  units_ = Units::kMm;
  coord_ = static_cast<int>(std::lround(params_.get(5220)));
  if (coord_ < 1 || coord_ > 9) coord_ = 1;
  params_.set(5220, coord_);  // read as 1 in G54 without a var file (it read 0), as LinuxCNC's
  for (int i = 0; i < kNumAxes; ++i) g92_[static_cast<size_t>(i)] = param_len(5211, i);
  g92_active_ = params_.get(5210) != 0;
  if (!g92_active_) g92_.fill(0);
  rotation_deg_ = params_.get(5210 + 20 * coord_);
  // The start position, machine coordinates → program coordinates.
  position_ = program_of(setup_.start_position, coord_);
  const SourceRef r0{0, 0, 0};
  canon_.use_length_units(r0, units_);
  Pose g5x{};
  for (int i = 0; i < kNumAxes; ++i) g5x[static_cast<size_t>(i)] = to_program_axis(i, param_len(5201 + 20 * coord_, i));
  canon_.set_g5x_offset(r0, coord_, g5x);
  Pose g92p{};
  for (int i = 0; i < kNumAxes; ++i) g92p[static_cast<size_t>(i)] = to_program_axis(i, g92_[static_cast<size_t>(i)]);
  canon_.set_g92_offset(r0, g92p);
  canon_.set_xy_rotation(r0, rotation_deg_);
  canon_.set_feed_reference(r0);
  canon_.on_reset(r0);
  if (setup_.tool_in_var_file) {
    // The tool the last program left in the spindle (#5400, kept in the var file); a
    // number the tool table does not have any more leaves the spindle empty.
    params_.make_persistent(5400);
    const long t = std::lround(params_.get(5400));
    tool_ = t > 0 && tools_.find(static_cast<int>(t)) != nullptr ? static_cast<int>(t) : 0;
    if (tool_ > 0) canon_.change_tool_number(r0, tool_);
    set_tool_params();
  }
  if (setup_.initial_modes) {
    // An MDI line goes on in the modes the last one left (LinuxCNC's MDI shares the
    // interpreter's state between lines), through the calls that set them.
    const ModalState& m = *setup_.initial_modes;
    if (m.units != static_cast<int>(units_)) {
      units_ = static_cast<Units>(m.units);
      canon_.use_length_units(r0, units_);
    }
    if (m.plane != static_cast<int>(plane_)) {
      plane_ = static_cast<Plane>(m.plane);
      canon_.select_plane(r0, plane_);
    }
    incremental_ = m.incremental;
    arc_incremental_ = m.arc_incremental;
    lathe_diameter_ = m.lathe_diameter;
    motion_ = m.motion;
    if (m.feed_mode != static_cast<int>(feed_mode_)) {
      feed_mode_ = static_cast<FeedMode>(m.feed_mode);
      canon_.set_feed_mode(r0, feed_mode_);
    }
    if (m.feed != feed_) {
      feed_ = m.feed;
      canon_.set_feed_rate(r0, feed_);
    }
    if (m.coord >= 1 && m.coord <= 9 && m.coord != coord_) set_coord_system(m.coord);
    twp_ = m.tilted_plane;  // G68.2 stays until G69, from one MDI line to the next
    if (twp_) {
      std::copy(m.tilted_frame.begin(), m.tilted_frame.begin() + 9, twp_r_.begin());
      std::copy(m.tilted_frame.begin() + 9, m.tilted_frame.end(), twp_o_.begin());
    }
    speed_ = m.speed;
    spindle_ = m.spindle;
    mist_ = m.mist;
    flood_ = m.flood;
    canon_.restore_spindle_and_coolant(r0, spindle_, speed_, mist_, flood_);
    if (m.tool_length != 490) {  // G43 (H: the offset then), G43.1, G43.2 stay in effect
      tool_length_ = m.tool_length;
      tool_offset_ = m.tool_offset;
      Pose shown{};
      for (size_t i = 0; i < shown.size(); ++i) shown[i] = i < 3 || i >= 6 ? to_program(tool_offset_[i]) : tool_offset_[i];
      canon_.use_tool_length_offset(r0, shown);
    }
    position_ = program_of(setup_.start_position, coord_);
  }
  update_position_params();
}

// The current position in #5420-#5428.
void Interpreter::update_position_params() {
  const Pose p = twp_ ? frame_of(current_point()) : current_point();
  for (int i = 0; i < kNumAxes; ++i) params_.set(5420 + i, to_program_axis(i, p[static_cast<size_t>(i)]));
}

Pose Interpreter::current_point(bool after_g40) const {
  // LinuxCNC's current point is the compensated one while cutter compensation runs;
  // position_ keeps the programmed point. after_g40: where the tool stands after G40
  // (before the next move).
  Pose p = position_;
  Plane pl{};
  double u = 0, v = 0;
  if (comp_filter_->tool_point(after_g40, pl, u, v)) {
    const size_t iu = pl == Plane::kXZ ? 2 : 0, iv = pl == Plane::kXZ ? 0 : 1;
    p[iu] = u * length_scale();
    p[iv] = v * length_scale();
  }
  return p;
}

void Interpreter::reread_position() {
  // LinuxCNC re-reads its position from the machine at the block after a tool change
  // (M6, M61): after G40 without a move since, the tool stands at the compensated point,
  // which becomes the current point.
  if (comp_ == 400) position_ = current_point(true);
}

// ---- the main loop ------------------------------------------------------------------

bool Interpreter::read_line() {
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  if (!f.getline(text_)) return false;
  ++line_no_;
  // LinuxCNC reads at most LINELEN (255) characters a line ("Command too long").
  if (text_.size() > 255) fail(256, "line longer than 255 characters (LinuxCNC's limit: command too long)");
  return true;
}

bool Interpreter::execute_next() {
  if (ended_) return false;
  if (probe_wait_ || input_wait_) return true;  // LinuxCNC syncs at a probe and an M66: the next lines read the result
  if (!read_line()) {
    if (!frames_.empty()) fail(0, "the file ended inside o<" + frames_.back().sub + "> (no endsub)");
    if (nurbs_) fail(0, "the file ended inside a NURBS curve opened at line " + std::to_string(nurbs_->line));
    if (!loops_.empty()) fail(0, "the file ended inside o<" + loops_.back().name + "> (no end of its block)");
    fail(0, "the file ended with no percent sign or program end (M2, M30)");
  }
  ++lines_executed_;
  if (line_hook_) line_hook_(file_, line_no_);
  try {
    lex_line(text_, line_);
  } catch (const Error& e) {
    fail(e.column(), e.detail());
  }
  try {
    execute_line();
  } catch (const Error& e) {
    // A consumer of the canonical calls (the block builder) refuses with a column
    // only: the place is this line.
    if (!e.file_name().empty()) throw;
    fail(e.column(), e.detail());
  }
  return !ended_;
}

ModalState Interpreter::modal_state() const {
  ModalState m;
  m.motion = motion_;
  m.plane = static_cast<int>(plane_);
  m.incremental = incremental_;
  m.arc_incremental = arc_incremental_;
  m.lathe_diameter = lathe_diameter_;
  m.feed_mode = static_cast<int>(feed_mode_);
  m.units = static_cast<int>(units_);
  m.comp = comp_;
  m.comp_radius = comp_radius_;
  m.tool_length = tool_length_;
  m.coord = coord_;
  m.retract_r = retract_r_;
  m.path = static_cast<int>(path_);
  m.path_p = path_p_;
  m.path_q = path_q_;
  m.feed = feed_;
  m.speed = speed_;
  m.spindle = spindle_;
  m.mist = mist_;
  m.flood = flood_;
  m.feed_override = feed_override_;
  m.speed_override = speed_override_;
  m.adaptive_feed = adaptive_feed_;
  m.feed_hold = feed_hold_;
  m.tool = tool_;
  m.selected_tool = selected_tool_;
  m.tool_offset = tool_offset_;
  m.g92 = g92_;
  m.g92_active = g92_active_;
  m.tilted_plane = twp_;
  if (twp_) {
    std::copy(twp_r_.begin(), twp_r_.end(), m.tilted_frame.begin());
    std::copy(twp_o_.begin(), twp_o_.end(), m.tilted_frame.begin() + 9);
  }
  m.rotation_deg = rotation_deg_;
  m.position = position_;
  for (size_t i = 0; i < m.offsets.size(); ++i) m.offsets[i] = params_.get(5161 + static_cast<int>(i));
  return m;
}

void Interpreter::execute_line() {
  if (line_.percent) {
    // A '%' on the first line opens the program; a second one ends it.
    if (!started_) {
      started_ = true;
      percent_open_ = true;
      return;
    }
    if (!percent_open_)
      fail(1, "a '%' line ends the program only when the program's first line is '%' (LinuxCNC: bad character '%')");
    if (percent_open_) {
      canon_.finish(ref());
      ended_ = true;
      persist();
      return;
    }
  }
  started_ = true;
  if (line_.block_delete && setup_.block_delete) return;
  // LinuxCNC reads M98, and M99 inside a call, as O-word statements when they are
  // the line's first word: a Fanuc subprogram call / return.
  if (const int m = fanuc_m_code(); m == 98) {
    fanuc_call();
    return;
  } else if (m == 99 && !frames_.empty()) {
    fanuc_return();
    return;
  }
  if (line_.o.kind != OKind::kNone) {
    if (!line_.words.empty()) fail(line_.words.front().column, "an O-word statement holds no other words");
    execute_o(line_.o);
    return;
  }
  Words w;
  w.reset();
  collect_words(w);
  check_words(w);
  apply_settings();
  execute_block(w);
  update_position_params();
}

// ---- the end ----------------------------------------------------------------------------

void Interpreter::end_program(bool m30) {
  const SourceRef r = ref();
  comp_filter_->flush();
  comp_filter_->stop();
  // LinuxCNC's end of program (M2, M30): G54 with its rotation, the XY plane, G90,
  // G94 with no feed, feed and speed overrides on, spindle off, coolant off, G40, G1.
  // G92 and the tool length offset stay; the tilted work plane goes (Fanuc's reset).
  twp_ = twp_tool_tilted_ = false;
  if (coord_ != 1) {
    position_ = program_of(machine_of(position_, coord_), 1);
    coord_ = 1;
    params_.set(5220, 1);
  }
  rotation_deg_ = params_.get(5230);
  Pose g5x{};
  for (int i = 0; i < kNumAxes; ++i) g5x[static_cast<size_t>(i)] = to_program_axis(i, param_len(5221, i));
  canon_.set_g5x_offset(r, 1, g5x);
  canon_.set_xy_rotation(r, rotation_deg_);
  if (plane_ != Plane::kXY) {
    plane_ = Plane::kXY;
    canon_.select_plane(r, plane_);
  }
  incremental_ = false;
  feed_mode_ = FeedMode::kUnitsPerMinute;
  canon_.set_feed_mode(r, feed_mode_);
  feed_ = 0;
  canon_.set_feed_rate(r, 0);
  // LinuxCNC turns the feed override back on with a call, the speed override without one.
  if (!feed_override_) canon_.enable_feed_override(r, true);
  feed_override_ = speed_override_ = true;
  spindle_ = 0;
  canon_.stop_spindle_turning(r);
  canon_.set_spindle_mode(r, 0);
  if (mist_) canon_.mist_off(r);
  if (flood_) canon_.flood_off(r);
  mist_ = flood_ = false;
  comp_ = 400;
  motion_ = 10;
  if (m30) canon_.pallet_shuttle(r);
  canon_.program_end(r);
  // LinuxCNC (convert_stop): a program opened by '%' should close with a '%' line
  // after its end; it reads on in the file being run and says so when there is none.
  if (percent_open_) {
    SourceFile& f = *files_[static_cast<size_t>(file_)];
    std::string t;
    bool closed = false;
    while (!closed && f.getline(t)) {
      const size_t b = t.find_first_not_of(" \t\r\f\v");
      closed = b != std::string::npos && t[b] == '%' && t.find_first_not_of(" \t\r\f\v", b + 1) == std::string::npos;
    }
    if (!closed) canon_.comment(r, "interpreter: percent sign missing from end of file");
  }
  ended_ = true;
  persist();
}

void Interpreter::persist() {
  if (!setup_.write_var_file) return;
  if (!setup_.var_file.empty()) params_.write_var_file(setup_.var_file);
  if (tools_changed_ && setup_.write_tool_table && !setup_.tool_table.empty()) {
    std::vector<Tool> out = tools_.tools();
    for (Tool& t : out) {  // back to machine units
      for (int i = 0; i < kNumAxes; ++i)
        if (i < 3 || i >= 6) t.offset[static_cast<size_t>(i)] /= mu_;
      t.diameter /= mu_;
    }
    write_tool_table(setup_.tool_table, out);
    tools_changed_ = false;
  }
}

}  // namespace cnc::rs274
