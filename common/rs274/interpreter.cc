#include "common/rs274/interpreter.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "common/rs274/cycles.h"
#include "common/rs274/process_directive.h"

namespace cnc::rs274 {

namespace {

constexpr double kMmPerInch = 25.4;
constexpr char kAxisLetters[] = "XYZABCUVW";
constexpr double kToleranceEqual = 1e-6;  // LinuxCNC 2.9's TOLERANCE_EQUAL (2.9.0-pre1: 1e-4)
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

// Word slots: A..Z, then @ (polar distance) and ^ (polar angle).
int letter_index(char c) { return c == '@' ? 26 : c == '^' ? 27 : c - 'A'; }
uint32_t bit(char c) { return 1u << letter_index(c); }

int axis_of_letter(char c) {
  for (int i = 0; i < kNumAxes; ++i)
    if (kAxisLetters[i] == c) return i;
  return -1;
}

// G-code modal groups (LinuxCNC's numbering), by G code in tenths.
int g_group(int g) {
  switch (g) {
    case 40: case 100: case 280: case 281: case 300: case 301: case 520: case 530: case 920: case 921: case 922: case 923:
      return 0;
    case 0: case 10: case 20: case 30: case 50: case 51: case 52: case 53: case 62: case 330: case 331: case 382:
    case 383: case 384: case 385: case 730: case 740: case 760: case 800: case 810: case 820: case 830: case 840:
    case 850: case 860: case 870: case 880: case 890:
      return 1;
    case 170: case 180: case 190: return 2;
    case 900: case 910: return 3;
    case 901: case 911: return 4;
    case 930: case 940: case 950: return 5;
    case 200: case 210: return 6;
    case 400: case 410: case 411: case 420: case 421: return 7;
    case 430: case 431: case 432: case 490: return 8;
    case 980: case 990: return 10;
    case 540: case 550: case 560: case 570: case 580: case 590: case 591: case 592: case 593: return 12;
    case 610: case 611: case 640: return 13;
    case 960: case 970: return 14;
    case 70: case 80: return 15;
    default: return -1;
  }
}

int m_group(int m) {
  switch (m) {
    case 0: case 1: case 2: case 30: case 60: case 99: return 4;
    case 62: case 63: case 64: case 65: case 66: case 67: case 68: return 5;
    case 6: case 61: return 6;
    case 3: case 4: case 5: case 19: return 7;
    case 7: case 8: case 9: return 8;
    case 48: case 49: case 50: case 51: case 52: case 53: return 9;
    case 70: case 71: case 72: case 73: return 10;
    default: return -1;
  }
}

std::string g_text(int g) {
  char buf[16];
  if (g % 10 == 0)
    std::snprintf(buf, sizeof buf, "G%d", g / 10);
  else
    std::snprintf(buf, sizeof buf, "G%d.%d", g / 10, g % 10);
  return buf;
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  return buf;
}

// o-word kinds as bits, for skip_to's targets.
uint32_t kbit(OKind k) { return 1u << static_cast<int>(k); }

}  // namespace

// ---- files -------------------------------------------------------------------------

// A program file read line by line through one buffer, seekable to the start of any
// line read before (loops, subroutine calls). The file stays open while the program
// runs, so a file replaced by rename reads as it was.
struct Interpreter::SourceFile {
  std::string path;
  int fd = -1;
  std::vector<char> buf = std::vector<char>(1 << 16);
  size_t pos = 0, len = 0;
  int64_t buf_start = 0;   // file offset of buf[0]
  int64_t line_start = 0;  // offset of the line last read

  ~SourceFile() {
    if (fd >= 0) ::close(fd);
  }
  int64_t offset() const { return buf_start + static_cast<int64_t>(pos); }
  void seek(int64_t off) {
    if (off >= buf_start && off <= buf_start + static_cast<int64_t>(len)) {
      pos = static_cast<size_t>(off - buf_start);
      return;
    }
    if (::lseek(fd, off, SEEK_SET) < 0) throw Error(path, SourceRef{}, std::string("cannot seek: ") + std::strerror(errno));
    buf_start = off;
    pos = len = 0;
  }
  // Reads the next line without its newline; false at the end of the file.
  bool getline(std::string& out) {
    out.clear();
    line_start = offset();
    bool any = false;
    for (;;) {
      if (pos == len) {
        buf_start += static_cast<int64_t>(len);
        pos = 0;
        const ssize_t n = ::read(fd, buf.data(), buf.size());
        if (n < 0) throw Error(path, SourceRef{}, std::string("cannot read: ") + std::strerror(errno));
        len = static_cast<size_t>(n);
        if (n == 0) return any;
      }
      const char* start = buf.data() + pos;
      const void* nl = std::memchr(start, '\n', len - pos);
      if (nl != nullptr) {
        const size_t k = static_cast<size_t>(static_cast<const char*>(nl) - start);
        out.append(start, k);
        pos += k + 1;
        if (!out.empty() && out.back() == '\r') out.pop_back();
        return true;
      }
      out.append(start, len - pos);
      pos = len;
      any = true;
    }
  }
};

struct Interpreter::Frame {
  std::string sub;
  int32_t return_file = 0;
  int64_t return_offset = 0;
  int32_t return_line = 0;
  int32_t call_column = 0;
  size_t loops = 0;  // loops_ size at the call
  bool fanuc = false;      // an M98 call: ends with M99, shares #1..#30
  bool again = false;      // M98 L: M99 goes back to the M98 line, which runs again
  int64_t call_start = 0;  // the M98 line's start in return_file
};

struct Interpreter::Loop {
  OKind kind = OKind::kNone;  // kWhile, kDo, kRepeat, kIf
  std::string name;
  int32_t file = 0;
  int64_t offset = 0;   // while: the while line; do/repeat: the line after
  int32_t line = 0;     // line number matching offset (lines before it)
  double remaining = 0; // repeat
  bool taken = false;   // if: a branch ran
};

struct Interpreter::Words {
  std::array<double, 28> v{};
  std::array<int32_t, 28> col{};
  uint32_t has = 0;
  std::array<int, 16> g{};
  std::array<int32_t, 16> gcol{};
  std::array<int, 12> m{};
  std::array<int32_t, 12> mcol{};
  bool m7 = false, m8 = false;
  uint32_t axes = 0;  // bits of kAxisLetters present

  void reset() {
    has = 0;
    axes = 0;
    g.fill(-1);
    m.fill(-1);
    m7 = m8 = false;
  }
  bool on(char c) const { return (has & bit(c)) != 0; }
  double operator[](char c) const { return v[static_cast<size_t>(letter_index(c))]; }
  int32_t column(char c) const { return col[static_cast<size_t>(letter_index(c))]; }
};

struct Interpreter::NurbsCollect {
  bool fanuc = false;
  int order = 0;
  int32_t column = 0;
  int32_t line = 0;
  std::vector<NurbsPoint> points;
  std::vector<double> knots;
  bool knots_only = false;
  Pose start{};
  Pose last{};  // last control point (program coordinates)
};

struct Interpreter::SavedModes {
  int32_t call_level = 0;
  bool valid = true;
  int motion;
  Plane plane;
  bool incremental, arc_incremental;
  FeedMode feed_mode;
  Units units;
  int coord;
  bool retract_r;
  PathMode path;
  double path_p, path_q, feed, speed;
  int spindle;
  bool mist, flood;
};

class Interpreter::Reader : public ParamReader {
 public:
  explicit Reader(const Interpreter& in) : in_(in) {}
  double numbered(double index, int column) const override {
    return in_.params_.get(Parameters::index_of(index, column), column);
  }
  double named(const std::string& name, int column) const override { return in_.named_value(name, column); }
  bool exists(const std::string& name) const override { return in_.named_exists(name); }

 private:
  const Interpreter& in_;
};

// ---- set-up ------------------------------------------------------------------------

Interpreter::Interpreter(MachineSetup setup, Canon& canon)
    : setup_(std::move(setup)),
      comp_filter_(std::make_unique<CutterComp>(canon)),
      canon_(*comp_filter_),
      reader_(std::make_unique<Reader>(*this)) {
  for (char& c : setup_.axes) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
}

Interpreter::~Interpreter() = default;

double Interpreter::length_scale() const { return units_ == Units::kInch ? kMmPerInch : 1.0; }
double Interpreter::to_program(double mm) const { return mm / length_scale(); }
// Axis i's value in program units: lengths scale, the angles of A B C do not.
double Interpreter::to_program_axis(int i, double v) const { return i < 3 || i >= 6 ? to_program(v) : v; }

// A pose in mm (degrees for A B C) in program units.
Pose Interpreter::program_pose(const Pose& mm) const {
  Pose p{};
  for (size_t i = 0; i < p.size(); ++i) p[i] = i < 3 || i >= 6 ? to_program(mm[i]) : mm[i];
  return p;
}

// Lengths in parameters and the tool table are in machine units (LinuxCNC's rule);
// the interpreter works in mm. Axis i of a group that starts at `base`.
double Interpreter::param_len(int base, int i) const {
  return params_.get(base + i) * (i < 3 || i >= 6 ? mu_ : 1.0);
}
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

void Interpreter::set_param_len(int base, int i, double mm) {
  params_.set(base + i, mm / (i < 3 || i >= 6 ? mu_ : 1.0));
}

SourceRef Interpreter::ref(int column) const { return SourceRef{file_, line_no_, column}; }

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

void Interpreter::update_position_params() {
  const Pose p = current_point();
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

// ---- parameters ---------------------------------------------------------------------

double Interpreter::named_value(const std::string& name, int column) const {
  double v = 0;
  if (!name.empty() && name[0] == '_') {
    const Pose cur = current_point();
    const auto axis = [&](int i) { return to_program_axis(i, cur[static_cast<size_t>(i)]); };
    static const char* kPos[] = {"_x", "_y", "_z", "_a", "_b", "_c", "_u", "_v", "_w"};
    for (int i = 0; i < kNumAxes; ++i)
      if (name == kPos[i]) return axis(i);
    static const char* kAbs[] = {"_abs_x", "_abs_y", "_abs_z", "_abs_a", "_abs_b", "_abs_c", "_abs_u", "_abs_v", "_abs_w"};
    for (int i = 0; i < kNumAxes; ++i)
      if (name == kAbs[i]) {
        const size_t k = static_cast<size_t>(i);
        return to_program_axis(i, machine_of(cur, coord_)[k]);
      }
    if (name == "_line") return line_no_;
    if (name == "_motion_mode") return motion_ < 0 ? 800 : motion_;
    if (name == "_plane") return plane_ == Plane::kXY ? 170 : plane_ == Plane::kXZ ? 180 : 190;
    if (name == "_ccomp") return comp_;
    if (name == "_metric") return units_ == Units::kMm;
    if (name == "_imperial") return units_ == Units::kInch;
    if (name == "_absolute") return !incremental_;
    if (name == "_incremental") return incremental_;
    if (name == "_inverse_time") return feed_mode_ == FeedMode::kInverseTime;
    if (name == "_units_per_minute") return feed_mode_ == FeedMode::kUnitsPerMinute;
    if (name == "_units_per_rev") return feed_mode_ == FeedMode::kUnitsPerRev;
    if (name == "_coord_system") {
      static const int kCs[] = {540, 550, 560, 570, 580, 590, 591, 592, 593};
      return kCs[coord_ - 1];
    }
    if (name == "_tool_offset") return tool_length_ != 490;
    if (name == "_retract_r_plane") return retract_r_;
    if (name == "_retract_old_z") return !retract_r_;
    if (name == "_spindle_rpm_mode") return 1;
    if (name == "_spindle_css_mode") return 0;
    if (name == "_ijk_absolute_mode") return !arc_incremental_;
    if (name == "_lathe_diameter_mode") return 0;
    if (name == "_lathe_radius_mode") return 1;
    if (name == "_spindle_on") return spindle_ != 0;
    if (name == "_spindle_cw") return spindle_ == 1;
    if (name == "_mist") return mist_;
    if (name == "_flood") return flood_;
    if (name == "_speed_override") return speed_override_;
    if (name == "_feed_override") return feed_override_;
    if (name == "_adaptive_feed") return adaptive_feed_;
    if (name == "_feed_hold") return feed_hold_;
    if (name == "_feed") return feed_;
    if (name == "_rpm") return speed_;
    if (name == "_current_tool") return tool_;
    if (name == "_current_pocket") return tool_;
    if (name == "_selected_tool") return selected_tool_;
    if (name == "_selected_pocket") return selected_tool_;
    if (name == "_value") return last_returned_;
    if (name == "_call_level") return static_cast<double>(frames_.size());
    if (name == "_remap_level") return 0;
    if (name == "_task") return 0;  // not milltask: the standalone interpreter
    if (name == "_vmajor") return 2.9;
    if (name == "_vminor") return 0;
  }
  if (params_.find_named(name, &v)) return v;
  (void)column;
  return params_.get_named(name, column);  // throws "not defined"
}

bool Interpreter::named_exists(const std::string& name) const {
  double v = 0;
  if (params_.find_named(name, &v)) return true;
  try {
    (void)named_value(name, 0);
    return true;
  } catch (const Error&) {
    return false;
  }
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

// ---- O-words ------------------------------------------------------------------------

std::string Interpreter::o_name(const OStatement& o) {
  if (o.number_expr < 0) return o.name;
  const double v = evaluate(line_.arena, o.number_expr, *reader_);
  const double r = std::nearbyint(v);
  if (std::fabs(v - r) > 1e-4 || r < 0) fail(o.column, "an O-word number must be a whole number, got " + num(v));
  return std::to_string(static_cast<int64_t>(r));
}

// Skips lines until an O-statement named `name` of one of `kinds`; the line found is
// left in line_ (its line number in line_no_), not executed.
void Interpreter::skip_to(const std::string& name, uint32_t kinds) {
  const int32_t from_line = line_no_;
  const bool defining = kinds == kbit(OKind::kEndsub);
  for (;;) {
    if (!read_line()) fail(0, "o<" + name + "> opened at line " + std::to_string(from_line) + " has no matching end");
    ++lines_executed_;  // a skipped line is read and lexed too: it counts against the caller's bound
    try {
      lex_line(text_, line_);
    } catch (const Error&) {
      continue;  // LinuxCNC reads skipped lines only for their O-word
    }
    if (line_.o.kind == OKind::kNone) continue;
    // LinuxCNC's read_o refuses a sub head or a bare O-word while a definition is read.
    if (defining && (line_.o.kind == OKind::kSub || line_.o.kind == OKind::kProgram))
      fail(line_.o.column, "nested subroutine definition: " +
                               std::string(line_.o.kind == OKind::kSub ? "a sub" : "a Fanuc subprogram head") +
                               " inside the definition of o<" + name + "> sub (line " + std::to_string(from_line) +
                               "), before its endsub");
    if (line_.o.number_expr >= 0) continue;  // computed O-numbers only act when executed
    if (line_.o.name == name && (kinds & kbit(line_.o.kind)) != 0) return;
  }
}

void Interpreter::execute_o(const OStatement& o) {
  const std::string name = o_name(o);
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  auto cond = [&]() -> double {
    if (o.args.empty()) fail(o.keyword_column, "expected a condition in [ ] after the keyword");
    return evaluate(line_.arena, o.args.front(), *reader_);
  };
  switch (o.kind) {
    case OKind::kSub: {
      // A definition read in the program's flow: remember it and skip its body.
      if (nurbs_) fail(o.column, "a subroutine definition inside a NURBS curve");
      if (!frames_.empty()) fail(o.column, "o<" + name + "> sub: a subroutine may not be defined inside another");
      subs_[name] = SubDef{file_, f.offset(), line_no_, f.line_start, false};
      skip_to(name, kbit(OKind::kEndsub));
      return;
    }
    case OKind::kEndsub:
    case OKind::kReturn: {
      // LinuxCNC lets a return carry any O-number (often its if's); endsub must match.
      if (frames_.empty()) fail(o.column, "o<" + name + (o.kind == OKind::kEndsub ? "> endsub" : "> return") + " outside a subroutine");
      if (frames_.back().fanuc)
        fail(o.column, "o<" + name + (o.kind == OKind::kEndsub ? "> endsub" : "> return") + " inside Fanuc subprogram O" +
                           frames_.back().sub + ", which M98 called: it ends with M99");
      if (o.kind == OKind::kEndsub && frames_.back().sub != name)
        fail(o.column, "o<" + name + "> endsub inside o<" + frames_.back().sub + ">");
      double value = 0;
      bool has_value = false;
      if (!o.args.empty()) {
        value = evaluate(line_.arena, o.args.front(), *reader_);
        has_value = true;
      }
      return_from_call(value, has_value, o.column);
      return;
    }
    case OKind::kProgram: {
      // A bare O-word. In the main program's flow it is the program's number or name
      // (LinuxCNC: nothing to do); running into one inside a Fanuc subprogram goes on
      // into it (LinuxCNC 2.9 does); an O-word subroutine may not run into one.
      if (!setup_.fanuc_subs)
        fail(o.column, "bare O-word O" + name + ": Fanuc-style subprograms are disabled (DISABLE_FANUC_STYLE_SUB)");
      if (!frames_.empty() && !frames_.back().fanuc)
        fail(o.column, "Fanuc subprogram head O" + name + " inside o<" + frames_.back().sub +
                           "> sub (a Fanuc subprogram is called with M98, an O-word subroutine ends with endsub)");
      return;
    }
    case OKind::kCall: {
      if (static_cast<int64_t>(frames_.size()) >= setup_.max_call_depth)
        fail(o.column, "o<" + name + "> call: calls nested deeper than " + std::to_string(setup_.max_call_depth));
      std::array<double, 30> args{};
      if (o.args.size() > 30) fail(o.column, "more than 30 arguments to o<" + name + ">");
      for (size_t i = 0; i < o.args.size(); ++i) args[i] = evaluate(line_.arena, o.args[i], *reader_);
      auto it = subs_.find(name);
      if (it == subs_.end()) {
        find_sub(name, o.column);
        it = subs_.find(name);
      }
      Frame fr;
      fr.sub = name;
      fr.return_file = file_;
      fr.return_offset = files_[static_cast<size_t>(file_)]->offset();
      fr.return_line = line_no_;
      fr.call_column = o.column;
      fr.loops = loops_.size();
      params_.push_call();
      for (size_t i = 0; i < 30; ++i)
        if (i < o.args.size()) params_.set(static_cast<int>(i) + 1, args[i]);
      frames_.push_back(std::move(fr));
      if (it->second.fanuc)
        fail_at_def(it->second, "Fanuc subprogram O" + name + " is called with M98 P" + name + ", not o<" + name + "> call");
      file_ = it->second.file;
      files_[static_cast<size_t>(file_)]->seek(it->second.offset);
      line_no_ = it->second.line;
      return;
    }
    case OKind::kDo: {
      loops_.push_back(Loop{OKind::kDo, name, file_, f.offset(), line_no_, 0, false});
      return;
    }
    case OKind::kWhile: {
      // Either the end of a do-while, or the head of a while loop.
      if (!loops_.empty() && loops_.back().kind == OKind::kDo && loops_.back().name == name) {
        if (cond() != 0) {
          f.seek(loops_.back().offset);
          line_no_ = loops_.back().line;
        } else {
          loops_.pop_back();
        }
        return;
      }
      if (cond() != 0) {
        if (loops_.empty() || loops_.back().name != name || loops_.back().kind != OKind::kWhile)
          loops_.push_back(Loop{OKind::kWhile, name, file_, f.line_start, line_no_ - 1, 0, false});
        return;
      }
      if (!loops_.empty() && loops_.back().name == name && loops_.back().kind == OKind::kWhile) loops_.pop_back();
      skip_to(name, kbit(OKind::kEndwhile));
      return;
    }
    case OKind::kEndwhile: {
      if (loops_.empty() || loops_.back().name != name || loops_.back().kind != OKind::kWhile)
        fail(o.column, "o<" + name + "> endwhile without its while");
      f.seek(loops_.back().offset);
      line_no_ = loops_.back().line;
      return;
    }
    case OKind::kRepeat: {
      const double n = cond();
      if (n < 1) {
        skip_to(name, kbit(OKind::kEndrepeat));
        return;
      }
      loops_.push_back(Loop{OKind::kRepeat, name, file_, f.offset(), line_no_, std::floor(n), false});
      return;
    }
    case OKind::kEndrepeat: {
      if (loops_.empty() || loops_.back().name != name || loops_.back().kind != OKind::kRepeat)
        fail(o.column, "o<" + name + "> endrepeat without its repeat");
      Loop& l = loops_.back();
      if (--l.remaining >= 1) {
        f.seek(l.offset);
        line_no_ = l.line;
      } else {
        loops_.pop_back();
      }
      return;
    }
    case OKind::kIf: {
      if (cond() != 0) {
        loops_.push_back(Loop{OKind::kIf, name, file_, 0, 0, 0, true});
        return;
      }
      loops_.push_back(Loop{OKind::kIf, name, file_, 0, 0, 0, false});
      // Find the next branch that runs.
      for (;;) {
        skip_to(name, kbit(OKind::kElseif) | kbit(OKind::kElse) | kbit(OKind::kEndif));
        if (line_.o.kind == OKind::kEndif) {
          loops_.pop_back();
          return;
        }
        if (line_.o.kind == OKind::kElse) {
          loops_.back().taken = true;
          return;
        }
        if (evaluate(line_.arena, line_.o.args.empty() ? -1 : line_.o.args.front(), *reader_) != 0) {
          loops_.back().taken = true;
          return;
        }
      }
    }
    case OKind::kElseif:
    case OKind::kElse: {
      // Reached by running the branch before it: the if is done.
      if (loops_.empty() || loops_.back().name != name || loops_.back().kind != OKind::kIf)
        fail(o.column, "o<" + name + "> " + (o.kind == OKind::kElse ? "else" : "elseif") + " without its if");
      loops_.pop_back();
      skip_to(name, kbit(OKind::kEndif));
      return;
    }
    case OKind::kEndif: {
      if (loops_.empty() || loops_.back().name != name || loops_.back().kind != OKind::kIf)
        fail(o.column, "o<" + name + "> endif without its if");
      loops_.pop_back();
      return;
    }
    case OKind::kBreak:
    case OKind::kContinue: {
      // The innermost loop of this name.
      auto it = std::find_if(loops_.rbegin(), loops_.rend(), [&](const Loop& l) {
        return l.name == name && (l.kind == OKind::kWhile || l.kind == OKind::kDo || l.kind == OKind::kRepeat);
      });
      if (it == loops_.rend())
        fail(o.column, "o<" + name + "> " + (o.kind == OKind::kBreak ? "break" : "continue") + " outside its loop");
      const size_t keep = static_cast<size_t>(loops_.rend() - it);  // index + 1 of the loop
      loops_.resize(keep);
      Loop& l = loops_.back();
      if (o.kind == OKind::kContinue) {
        if (l.kind == OKind::kRepeat) {
          if (--l.remaining < 1) {
            loops_.pop_back();
            skip_to(name, kbit(OKind::kEndrepeat));
            return;
          }
          f.seek(l.offset);
          line_no_ = l.line;
          return;
        }
        if (l.kind == OKind::kWhile) {
          f.seek(l.offset);
          line_no_ = l.line;
          return;
        }
        // do-while: continue jumps to the test at its end.
        skip_to(name, kbit(OKind::kWhile));
        loops_.pop_back();
        loops_.push_back(Loop{OKind::kDo, name, file_, l.offset, l.line, 0, false});
        execute_o(line_.o);
        return;
      }
      const OKind k = l.kind;
      loops_.pop_back();
      skip_to(name, k == OKind::kRepeat ? kbit(OKind::kEndrepeat)
                    : k == OKind::kWhile ? kbit(OKind::kEndwhile)
                                         : kbit(OKind::kWhile));
      return;
    }
    case OKind::kNone: return;
  }
}

// Where subroutine files are looked for: the subroutine path, then the main
// program's folder (LinuxCNC's program prefix).
// LinuxCNC keeps the first 10 directories of SUBROUTINE_PATH that exist
// (MAX_SUB_DIRS in rs274ngc_pre.cc) and ignores the rest.
constexpr size_t kMaxSubDirs = 10;

std::vector<std::string> Interpreter::subroutine_dirs() const {
  std::vector<std::string> dirs;
  for (const std::string& d : setup_.subroutine_path) {
    if (dirs.size() >= kMaxSubDirs) break;
    std::error_code ec;
    if (std::filesystem::is_directory(d, ec)) dirs.push_back(d);
  }
  std::string folder = std::filesystem::path(file_names_.front()).parent_path().string();
  dirs.push_back(folder.empty() ? std::string(".") : std::move(folder));
  return dirs;
}

// When `file` is in a directory of the subroutine path past the 10 that count: says so.
std::string Interpreter::beyond_sub_dirs(const std::string& file) const {
  size_t n = 0;
  for (const std::string& d : setup_.subroutine_path) {
    std::error_code ec;
    if (!std::filesystem::is_directory(d, ec)) continue;
    if (++n <= kMaxSubDirs) continue;
    if (std::filesystem::exists(d + "/" + file, ec))
      return d + "/" + file + " is in directory " + std::to_string(n) +
             " of the subroutine path, which LinuxCNC does not search (only the first " +
             std::to_string(kMaxSubDirs) + " that exist count)";
  }
  return {};
}

// Leaves the innermost call: endsub / return (value as given), M99 (value 0).
void Interpreter::return_from_call(double value, bool has_value, int column) {
  Frame fr = std::move(frames_.back());
  frames_.pop_back();
  loops_.resize(fr.loops);
  params_.pop_call();
  last_returned_ = value;
  params_.set_named("_value", value);
  params_.set_named("_value_returned", has_value ? 1.0 : 0.0);
  // M73 states saved at this call level come back on return.
  while (!saved_.empty() && saved_.back().call_level > static_cast<int32_t>(frames_.size()) &&
         saved_.back().call_level < 1000000) {
    const SavedModes sm = saved_.back();
    saved_.pop_back();
    if (sm.valid) restore_modes(sm, column);
  }
  file_ = fr.return_file;
  files_[static_cast<size_t>(file_)]->seek(fr.return_offset);
  line_no_ = fr.return_line;
}

// ---- Fanuc-style subprograms (M98 / M99) ------------------------------------------------

// 98 or 99 when the line opens with that M code (after '/' and N): LinuxCNC's
// read_items reads such a line as an O-word statement (M99 only inside a call).
int Interpreter::fanuc_m_code() {
  if (line_.o.kind != OKind::kNone || line_.words.empty()) return -1;
  const Word& mw = line_.words.front();
  if (mw.letter != 'M') return -1;
  for (const ParamSetting& st : line_.settings)
    if (st.column < mw.column) return -1;
  for (const Comment& c : line_.comments)
    if (c.column < mw.column) return -1;
  double v = 0;
  try {
    v = evaluate(line_.arena, mw.expr, *reader_);
  } catch (const Error& e) {
    fail(e.column() > 0 ? e.column() : mw.column, e.detail());
  }
  if (std::fabs(v - 98) <= 1e-4) return 98;
  if (std::fabs(v - 99) <= 1e-4) return 99;
  return -1;
}

// Where o<name> sub starts for a call not met before (LinuxCNC 2.9's control_back_to):
// a file <name>.ngc on the subroutine path or in the program's folder (its first
// `o<name> sub` or `O<name>` head), else the first such head further down the file
// being read, from the call on, up to its end or its closing '%' (definitions before
// the call that the flow did not pass are not seen, as in LinuxCNC). Fails when there
// is none.
void Interpreter::find_sub(const std::string& name, int column) {
  std::string t;
  Line probe;
  for (const std::string& dir : subroutine_dirs()) {
    const std::string p = dir + "/" + name + ".ngc";
    if (!std::filesystem::exists(p)) continue;
    auto sf = std::make_unique<SourceFile>();
    sf->path = p;
    sf->fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
    if (sf->fd < 0) continue;
    const int32_t idx = static_cast<int32_t>(files_.size());
    int32_t ln = 0;
    bool found = false;
    while (sf->getline(t)) {
      ++ln;
      try {
        lex_line(t, probe);
      } catch (const Error&) {
        continue;
      }
      if ((probe.o.kind == OKind::kSub || probe.o.kind == OKind::kProgram) && probe.o.number_expr < 0 &&
          probe.o.name == name) {
        subs_[name] = SubDef{idx, sf->offset(), ln, sf->line_start, probe.o.kind == OKind::kProgram};
        found = true;
        break;
      }
    }
    if (!found) fail(column, p + " does not define o<" + name + "> sub");
    file_names_.push_back(p);
    files_.push_back(std::move(sf));
    return;
  }
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  const int64_t here = f.offset();
  int32_t ln = line_no_;
  while (f.getline(t)) {
    ++ln;
    try {
      lex_line(t, probe);
    } catch (const Error&) {
      continue;
    }
    if (probe.percent) break;  // the program's closing '%': nothing after it counts
    if (probe.o.number_expr >= 0 || probe.o.name != name) continue;
    if (probe.o.kind == OKind::kSub || probe.o.kind == OKind::kProgram) {
      subs_[name] = SubDef{file_, f.offset(), ln, f.line_start, probe.o.kind == OKind::kProgram};
      f.seek(here);
      return;
    }
  }
  f.seek(here);
  std::string why = "o<" + name + "> call: no file " + name + ".ngc on the subroutine path nor o<" + name +
                    "> sub further down " + file_names_[static_cast<size_t>(file_)] +
                    " (a definition before the call counts only once the program has run through it)";
  if (const std::string far = beyond_sub_dirs(name + ".ngc"); !far.empty())
    why += "; " + far;
  fail(column, why);
}

// Where subprogram O<name> starts, for M98 (LinuxCNC's control_back_to): one met
// before, else a file <name>.ngc on the subroutine path or in the program's folder
// (LinuxCNC looks for the file first), else further down the file being read, up to
// its end or its closing '%'. The first head of that number found counts, `O<name>`
// or `O<name> sub` (the caller refuses the latter).
Interpreter::SubDef Interpreter::find_fanuc_sub(const std::string& name, int column) {
  if (auto it = subs_.find(name); it != subs_.end()) return it->second;
  std::string t;
  Line probe;
  const auto is_head = [&](const Line& l) {
    return (l.o.kind == OKind::kProgram || l.o.kind == OKind::kSub) && l.o.number_expr < 0 && l.o.name == name;
  };
  for (const std::string& dir : subroutine_dirs()) {
    const std::string p = dir + "/" + name + ".ngc";
    if (!std::filesystem::exists(p)) continue;
    auto sf = std::make_unique<SourceFile>();
    sf->path = p;
    sf->fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
    if (sf->fd < 0) continue;
    int32_t ln = 0;
    while (sf->getline(t)) {
      ++ln;
      try {
        lex_line(t, probe);
      } catch (const Error&) {
        continue;
      }
      if (!is_head(probe)) continue;
      const int32_t idx = static_cast<int32_t>(files_.size());
      const SubDef d{idx, sf->offset(), ln, sf->line_start, probe.o.kind == OKind::kProgram};
      file_names_.push_back(p);
      files_.push_back(std::move(sf));
      subs_[name] = d;
      return d;
    }
    fail(column, "M98 P" + name + ": " + p + " does not hold subprogram O" + name);
  }
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  const int64_t here = f.offset();
  int32_t ln = line_no_;
  while (f.getline(t)) {
    ++ln;
    try {
      lex_line(t, probe);
    } catch (const Error&) {
      continue;
    }
    if (probe.percent) break;  // the program's end: LinuxCNC stops looking there
    if (!is_head(probe)) continue;
    const SubDef d{file_, f.offset(), ln, f.line_start, probe.o.kind == OKind::kProgram};
    f.seek(here);
    subs_[name] = d;
    return d;
  }
  f.seek(here);
  std::string far = beyond_sub_dirs(name + ".ngc");
  fail(column, "M98 P" + name + ": no subprogram O" + name + " further down " + file_names_[static_cast<size_t>(file_)] +
                   " (before its end) nor a file " + name + ".ngc on the subroutine path" +
                   (far.empty() ? "" : "; " + far));
}

// Refuses at a subroutine's head line (LinuxCNC refuses a call of the wrong style
// when it reaches the definition), with the call in the chain.
void Interpreter::fail_at_def(const SubDef& def, const std::string& detail) {
  file_ = def.file;
  files_[static_cast<size_t>(file_)]->seek(def.start);
  line_no_ = def.line - 1;
  int column = 1;
  if (read_line()) {
    try {
      lex_line(text_, line_);
      column = line_.o.column;
    } catch (const Error&) {
    }
  }
  fail(column, detail);
}

// M98 P<n> [L<k>]: calls Fanuc subprogram O<n> k times (default once; L0: not at all).
// The subprogram shares #1..#30 with its caller; named locals get a scope per run.
void Interpreter::fanuc_call() {
  const Word& mw = line_.words.front();
  if (!setup_.fanuc_subs) fail(mw.column, "M98: Fanuc-style subprograms are disabled (DISABLE_FANUC_STYLE_SUB)");
  if (!line_.settings.empty())
    fail(line_.settings.front().column, "a parameter setting on an M98 line (the line is a subprogram call only)");
  double p = 0, l = 1;
  int32_t pcol = 0, lcol = 0;
  for (size_t i = 1; i < line_.words.size(); ++i) {
    const Word& w = line_.words[i];
    if (w.letter != 'P' && w.letter != 'L')
      fail(w.column, std::string(1, w.letter) + " word on an M98 line (M98 takes P, the subprogram number, and L, the repeat count)");
    if ((w.letter == 'P' && pcol != 0) || (w.letter == 'L' && lcol != 0))
      fail(w.column, std::string("word '") + w.letter + "' given twice on one line");
    double v = 0;
    try {
      v = evaluate(line_.arena, w.expr, *reader_);
    } catch (const Error& e) {
      fail(e.column() > 0 ? e.column() : w.column, e.detail());
    }
    if (w.letter == 'P') {
      p = v;
      pcol = w.column;
    } else {
      l = v;
      lcol = w.column;
    }
  }
  if (pcol == 0) fail(mw.column, "M98 without a P word (the number of the subprogram to call)");
  // LinuxCNC's read_integer_value: within 1e-4 of a whole number.
  double n = std::floor(p);
  if (p - n > 0.9999) n = std::ceil(p);
  else if (p - n > 0.0001) fail(pcol, "M98 P" + num(p) + ": a subprogram number is a whole number");
  if (n < 0 || n > 2147483647.0) fail(pcol, "M98 P" + num(p) + ": a subprogram number is 0 or more");
  const std::string name = std::to_string(static_cast<int64_t>(n));
  const double runs = std::nearbyint(l);
  if (std::fabs(l - runs) > 1e-4 || runs < 0)
    fail(lcol, "M98 L" + num(l) + ": the repeat count is a whole number, 0 or more");
  if (!(runs <= 2147483647.0)) fail(lcol, "M98 L" + num(l) + ": the repeat count is at most 2147483647");
  // LinuxCNC's execute_call: with L, a counter of the caller's level takes L when it
  // is idle (-1) and counts down; while runs remain, M99 returns to the M98 line
  // itself, which is read and evaluated again (so P#n can name another subprogram
  // each run; L is read only at the first).
  bool again = false;
  if (lcol != 0) {
    const size_t level = frames_.size();
    if (m98_runs_left_.size() <= level) m98_runs_left_.resize(level + 1, -1);
    int64_t& left = m98_runs_left_[level];
    if (left == -1) left = static_cast<int64_t>(runs);
    if (--left > 0) again = true;
    else left = -1;
  }
  if (runs == 0) return;  // LinuxCNC: "M98 L0 instruction; skipping call"
  if (static_cast<int64_t>(frames_.size()) >= setup_.max_call_depth)
    fail(mw.column, "M98 P" + name + ": calls nested deeper than " + std::to_string(setup_.max_call_depth));
  const int64_t call_start = files_[static_cast<size_t>(file_)]->line_start;
  const SubDef def = find_fanuc_sub(name, mw.column);
  Frame fr;
  fr.sub = name;
  fr.return_file = file_;
  fr.return_offset = files_[static_cast<size_t>(file_)]->offset();
  fr.return_line = line_no_;
  fr.call_column = mw.column;
  fr.loops = loops_.size();
  fr.fanuc = true;
  fr.again = again;
  fr.call_start = call_start;
  params_.push_call(false);
  frames_.push_back(std::move(fr));
  if (!def.fanuc)
    fail_at_def(def, "o<" + name + "> sub is called with o<" + name + "> call, not M98 P" + name +
                         " (M98 calls Fanuc subprograms headed by a bare O" + name + ")");
  file_ = def.file;
  files_[static_cast<size_t>(file_)]->seek(def.offset);
  line_no_ = def.line;
}

// M99 opening a line inside a call: the end of a Fanuc subprogram's run.
void Interpreter::fanuc_return() {
  const Word& mw = line_.words.front();
  Frame& fr = frames_.back();
  if (!setup_.fanuc_subs) fail(mw.column, "M99: Fanuc-style subprograms are disabled (DISABLE_FANUC_STYLE_SUB)");
  if (!fr.fanuc)
    fail(mw.column, "M99 inside o<" + fr.sub + "> sub: an O-word subroutine ends with o<" + fr.sub +
                        "> endsub or return (M99 ends subprograms that M98 called)");
  if (line_.words.size() > 1)
    fail(line_.words[1].column, "only comments may follow M99 ending a subprogram");
  if (!line_.settings.empty())
    fail(line_.settings.front().column, "only comments may follow M99 ending a subprogram");
  const bool again = fr.again;
  const int64_t call_start = fr.call_start;
  const int32_t call_line = fr.return_line;
  return_from_call(0, false, mw.column);
  if (again) {
    // M98 L: back to the M98 line (LinuxCNC returns there and reads it again).
    files_[static_cast<size_t>(file_)]->seek(call_start);
    line_no_ = call_line - 1;
  }
}

// ---- blocks ---------------------------------------------------------------------------

void Interpreter::collect_words(Words& w) {
  for (const Word& word : line_.words) {
    const char c = word.letter;
    const size_t i = static_cast<size_t>(letter_index(c));
    double v = 0;
    try {
      v = evaluate(line_.arena, word.expr, *reader_);
    } catch (const Error& e) {
      fail(e.column() > 0 ? e.column() : word.column, e.detail());
    }
    if (c == 'G') {
      const double t = v * 10;
      const int g = static_cast<int>(std::lround(t));
      if (std::fabs(t - g) > 1e-3) fail(word.column, "unknown G code G" + num(v));
      const int grp = g_group(g);
      if (grp < 0) fail(word.column, "unknown or unsupported G code " + g_text(g));
      // LinuxCNC's read_g: G80 with another code of its group in one block gives way to it
      // ("G80 G0", "G0 G80" are G0).
      if (g == 800 && w.g[static_cast<size_t>(grp)] >= 0) continue;
      if (w.g[static_cast<size_t>(grp)] >= 0 && w.g[static_cast<size_t>(grp)] != 800)
        fail(word.column, "two G codes from the same modal group: " + g_text(w.g[static_cast<size_t>(grp)]) + " and " + g_text(g));
      w.g[static_cast<size_t>(grp)] = g;
      w.gcol[static_cast<size_t>(grp)] = word.column;
      continue;
    }
    if (c == 'M') {
      const int m = static_cast<int>(std::lround(v));
      if (std::fabs(v - m) > 1e-4) fail(word.column, "unknown M code M" + num(v));
      if (m == 98) fail(word.column, "M98 calls a subprogram only as the first word of its line (LinuxCNC: unknown M code)");
      const int grp = m_group(m);
      if (grp < 0) fail(word.column, "unknown M code M" + std::to_string(m));
      if (grp == 8 && (m == 7 || m == 8)) {
        // M7 and M8 may share a line (LinuxCNC).
        if (m == 7) w.m7 = true; else w.m8 = true;
        if (w.m[8] == 9) fail(word.column, "two M codes from the same modal group: M9 and M" + std::to_string(m));
        w.m[8] = m;
        w.mcol[8] = word.column;
        continue;
      }
      if (w.m[static_cast<size_t>(grp)] >= 0)
        fail(word.column, "two M codes from the same modal group: M" + std::to_string(w.m[static_cast<size_t>(grp)]) +
                              " and M" + std::to_string(m));
      w.m[static_cast<size_t>(grp)] = m;
      w.mcol[static_cast<size_t>(grp)] = word.column;
      continue;
    }
    if (w.on(c)) fail(word.column, std::string("word '") + c + "' given twice on one line");
    const int ax = axis_of_letter(c);
    if (ax >= 0 && setup_.axes.find(c) == std::string::npos) {
      // I J K R are not axes; axis letters the machine lacks are refused.
      fail(word.column, std::string(1, c) + " word, but the machine has no " + c + " axis (axes: " + setup_.axes + ")");
    }
    if (ax >= 0) w.axes |= 1u << ax;
    if (c == '@' || c == '^') w.axes |= 3u;  // polar coordinates set X and Y
    w.has |= bit(c);
    w.v[i] = v;
    w.col[i] = word.column;
  }
}

void Interpreter::check_words(const Words& w) {
  if (w.m[4] == 99 && !frames_.empty())
    fail(w.mcol[4], "M99 ends a subprogram only as the first word of its line");
  const int motion = w.g[1] >= 0 ? w.g[1] : motion_;
  const int g0 = w.g[0];
  const bool uses_axes = w.axes != 0;
  // The fanuc NURBS continuation lines carry K X Y Z R without a G code.
  if (nurbs_ && nurbs_->fanuc) return;
  if (nurbs_ && !nurbs_->fanuc && w.g[1] < 0) return;
  if (uses_axes && (motion == 800 || motion < 0) && g0 != 100 && g0 != 280 && g0 != 300 && g0 != 520 &&
      g0 != 920 && g0 != 530)
    fail(w.column(kAxisLetters[std::countr_zero(w.axes)]), "axis words without a G code that uses them (motion mode is G80)");
  if (g0 == 530 && !(motion == 0 || motion == 10) ) fail(w.gcol[0], "G53 is only allowed with G0 or G1");
  if (g0 == 530 && incremental_) fail(w.gcol[0], "G53 with G91 (incremental) is not allowed");
  if (w.g[0] >= 0 && w.g[1] >= 0 && uses_axes && g0 != 530) {
    if (g0 == 100 || g0 == 280 || g0 == 300 || g0 == 520 || g0 == 920)
      fail(w.gcol[1], g_text(g0) + " and " + g_text(w.g[1]) + " both use axis words: only one per line");
  }
  const auto not_with = [&](char c, const char* what) {
    if (w.on(c)) fail(w.column(c), std::string(1, c) + " word " + what);
  };
  const bool arc = motion == 20 || motion == 30;
  const bool cyc = motion >= 730 && motion != 800 && (motion <= 890);
  const bool nurbs_g = motion == 52 || motion == 62 || motion == 50 || motion == 51;
  if (!arc && !cyc && !nurbs_g && g0 != 100) {
    if (w.on('R')) not_with('R', "with no G code that uses it (G2/G3, a canned cycle, G10)");
    if (w.on('I') || w.on('J')) not_with(w.on('I') ? 'I' : 'J', "with no G code that uses it (G2/G3, G5, G87)");
  }
  const bool synced = motion == 330 || motion == 331 || motion == 760;
  if (w.on('K') && fanuc_closed_line_ > 0 && fanuc_closed_line_ == line_no_ - 1 && w.g[1] < 0)
    fail(w.column('K'),
         "a knot after the G6.2 curve's knots were complete (control points + order) at line " +
             std::to_string(fanuc_closed_line_));
  if (!arc && !cyc && g0 != 100 && !nurbs_g && !synced && w.on('K')) not_with('K', "with no G code that uses it (G2/G3, G33, G73/G83 ...)");
  if (w.on('P') && !(g0 == 40 || g0 == 100 || arc || cyc || nurbs_g || w.g[13] == 640 || w.g[7] == 410 ||
                     w.g[7] == 420 || w.m[5] >= 0 || w.g[8] == 432))
    not_with('P', "with no G code or M code that uses it");
  if (w.on('Q') && !(cyc || nurbs_g || w.g[13] == 640 || w.m[5] >= 0 || w.m[6] == 61 || g0 == 100))
    not_with('Q', "with no G code or M code that uses it");
  if (w.on('L') && !(g0 == 100 || cyc || nurbs_g)) not_with('L', "with no G code that uses it (G10, canned cycles)");
  if (w.on('H') && !(w.g[8] == 430 || w.g[8] == 432 || g0 == 100)) not_with('H', "with no G43 that uses it");
  if (w.on('D') && !(w.g[7] == 410 || w.g[7] == 420 || w.g[7] == 411 || w.g[7] == 421))
    not_with('D', "with no G41/G42 that uses it");
  if (w.on('E') && w.m[5] < 0) not_with('E', "with no M code that uses it (M66, M67, M68)");
  if (w.on('F') && w.v[static_cast<size_t>(letter_index('F'))] < 0) fail(w.column('F'), "negative feed rate");
  if (w.on('S') && w.v[static_cast<size_t>(letter_index('S'))] < 0) fail(w.column('S'), "negative spindle speed");
  if (w.on('T') && w.v[static_cast<size_t>(letter_index('T'))] < 0) fail(w.column('T'), "negative tool number");
}

void Interpreter::apply_settings() {
  for (const ParamSetting& s : line_.settings) {
    double v = 0;
    try {
      v = evaluate(line_.arena, s.value_expr, *reader_);
      if (s.index_expr >= 0) {
        const double idx = evaluate(line_.arena, s.index_expr, *reader_);
        params_.set(Parameters::index_of(idx, s.column), v, s.column);
      } else {
        if (!s.name.empty() && s.name[0] == '_') {
          // Predefined names are read-only.
          static const char* kRo[] = {"_x", "_y", "_z", "_a", "_b", "_c", "_u", "_v", "_w", "_line", "_motion_mode",
                                      "_current_tool", "_feed", "_rpm", "_value", "_call_level", "_vmajor", "_vminor"};
          for (const char* r : kRo)
            if (s.name == r) fail(s.column, "#<" + s.name + "> is a read-only predefined parameter");
        }
        params_.set_named(s.name, v);
      }
    } catch (const Error& e) {
      if (!e.file_name().empty()) throw;
      fail(e.column() > 0 ? e.column() : s.column, e.detail());
    }
  }
}

void Interpreter::comments_of_line() {
  // LinuxCNC keeps one comment per block: each ( ) comment read replaces the one
  // before, so only the line's last ( ) comment runs (';' comments never do), and
  // an empty "()" makes no call. This controller's PROCESS directive, a plain
  // comment to LinuxCNC, still applies wherever it stands on the line.
  int last = -1;
  for (size_t i = 0; i < line_.comments.size(); ++i) {
    const size_t open = static_cast<size_t>(line_.comments[i].column - 1);
    if (open < text_.size() && text_[open] == '(') last = static_cast<int>(i);
  }
  for (size_t ci = 0; ci < line_.comments.size(); ++ci) {
    const Comment& c = line_.comments[ci];
    const SourceRef r = ref(c.column);
    if (static_cast<int>(ci) != last) {
      if (c.kind != CommentKind::kProcess) continue;
      const size_t open = static_cast<size_t>(c.column - 1);
      const size_t close = text_.find(')', open);
      const std::string_view body(text_.data() + open + 1, (close == std::string::npos ? text_.size() : close) - open - 1);
      ProcessSettings ps;
      try {
        if (!parse_process_directive(body, c.column + 1, &ps)) continue;
      } catch (const Error& e) {
        fail(e.column(), e.detail());
      }
      if (nurbs_)
        fail(c.column + 1, "process parameters cannot change inside a NURBS curve (opened at line " +
                               std::to_string(nurbs_->line) + ")");
      canon_.set_process(r, ps);
      continue;
    }
    if (c.kind != CommentKind::kProcess && static_cast<size_t>(c.column) < text_.size() &&
        text_[static_cast<size_t>(c.column)] == ')')
      continue;  // "()": LinuxCNC's block has no comment
    switch (c.kind) {
      case CommentKind::kMsg: canon_.message(r, c.text); break;
      case CommentKind::kPlain:
      case CommentKind::kProcess: {
        // LinuxCNC makes COMMENT calls of ( ) comments only, not of ';' ones.
        const size_t open = static_cast<size_t>(c.column - 1);
        if (open >= text_.size() || text_[open] != '(') break;
        const size_t close = text_.find(')', open);
        const std::string_view body(text_.data() + open + 1, (close == std::string::npos ? text_.size() : close) - open - 1);
        ProcessSettings ps;
        bool directive = false;
        try {
          directive = parse_process_directive(body, c.column + 1, &ps);
        } catch (const Error& e) {
          fail(e.column(), e.detail());
        }
        if (directive && nurbs_)
          fail(c.column + 1, "process parameters cannot change inside a NURBS curve (opened at line " +
                                 std::to_string(nurbs_->line) + ")");
        canon_.comment(r, c.kind == CommentKind::kProcess ? std::string(body.substr(body.find_first_not_of(" \t"))) : c.text);
        if (directive) canon_.set_process(r, ps);
        break;
      }
      case CommentKind::kPrint:
      case CommentKind::kDebug: {
        // #n and #<name> in the text are replaced by their values, as LinuxCNC's
        // convert_param_comment: "%lf" until a %d (%.0f), %f (%.4f) or %.Nf changes the
        // format for the rest of the text; a value within TOLERANCE_EQUAL of 0 prints as 0
        // (no "-0.000000"); a parameter that does not exist prints "######".
        std::string out;
        std::string format = "%lf";
        const std::string& t = c.text;
        const auto put_value = [&](bool found, double v) {
          if (!found) {
            out += "######";
            return;
          }
          if (std::fabs(v) < kToleranceEqual) v = 0.0;
          char buf[400];
          const int n = std::snprintf(buf, sizeof buf, format.c_str(), v);
          out += (n < 0 || n >= 350) ? "######" : buf;  // LinuxCNC's VAL_LEN is 350
        };
        for (size_t i = 0; i < t.size(); ++i) {
          if (t[i] == '%') {
            const char f = i + 1 < t.size() ? t[i + 1] : '\0';
            if (f == 'd') {
              format = "%.0f";
              ++i;
            } else if (f == 'f') {
              format = "%.4f";
              ++i;
            } else if (f == '.') {
              ++i;
              if (i + 2 < t.size() && std::isdigit(static_cast<unsigned char>(t[i + 1])) && t[i + 2] == 'f') {
                format = std::string("%.") + t[i + 1] + "f";
                i += 2;
              } else {
                out += '.';  // LinuxCNC drops the '%' of a "%." that is no format
              }
            } else {
              out += '%';
            }
            continue;
          }
          if (t[i] != '#') {
            out += t[i];
            continue;
          }
          const size_t j = i + 1;
          if (j >= t.size()) fail(c.column + 1, "named parameter not terminated in a DEBUG/PRINT comment");
          if (t[j] == '<') {
            const size_t e = t.find('>', j);
            if (e == std::string::npos) fail(c.column + 1, "named parameter not terminated in a DEBUG/PRINT comment");
            std::string name;
            for (size_t k = j + 1; k < e; ++k)
              if (!std::isspace(static_cast<unsigned char>(t[k])))
                name += static_cast<char>(std::tolower(static_cast<unsigned char>(t[k])));
            const bool found = named_exists(name);
            put_value(found, found ? named_value(name, c.column) : 0.0);
            i = e;
            continue;
          }
          size_t k = j;
          while (k < t.size() && std::isdigit(static_cast<unsigned char>(t[k]))) ++k;
          if (k == j) {
            out += t[i];
            continue;
          }
          const long n = std::strtol(t.substr(j, k - j).c_str(), nullptr, 10);
          const bool found = n >= 0 && n <= kMaxParameter;
          put_value(found, n >= 1 && found ? params_.get(static_cast<int>(n)) : 0.0);
          i = k - 1;
        }
        if (c.kind == CommentKind::kDebug)
          canon_.message(r, out);
        else
          std::fprintf(stderr, "%s\n", out.c_str());
        break;
      }
      case CommentKind::kLogOpen: case CommentKind::kLogAppend: case CommentKind::kLogClose: case CommentKind::kLog:
        break;  // file logging from a program is not supported: the cell's logger records messages
      case CommentKind::kAbort:
        fail(c.column, "program aborted: " + c.text);
    }
  }
}

Pose Interpreter::axis_target(const Words& w, bool machine) const {
  Pose p = position_;
  const double s = length_scale();
  const bool polar = w.on('@') || w.on('^');
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
    if (!w.on(c)) continue;
    const size_t k = static_cast<size_t>(i);
    const double lin = i < 3 || i >= 6 ? s : 1.0;  // A B C are degrees
    const double v = w[c] * lin;
    if (machine) {
      p[k] = v;  // machine coordinates, turned into program ones below
    } else if (incremental_) {
      p[k] += v;
    } else {
      p[k] = v;
    }
  }
  if (machine) {
    // Axes not named keep their machine position.
    Pose m = machine_of(position_, coord_);
    for (int i = 0; i < kNumAxes; ++i)
      if (w.on(kAxisLetters[i])) m[static_cast<size_t>(i)] = p[static_cast<size_t>(i)];
    return program_of(m, coord_);
  }
  return p;
}

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
  const double s = length_scale();
  if (l == 2 || l == 20) {
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
    return;
  }
  if (l == 1 || l == 10 || l == 11) {
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
    return;
  }
  fail(w.column('L'), "G10 L" + std::to_string(l) + " is not supported (L1, L2, L10, L11, L20)");
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
  for (int i = 0; i < kNumAxes; ++i) {
    const size_t k = static_cast<size_t>(i);
    if (w.axes != 0 && !w.on(kAxisLetters[i])) continue;
    if (setup_.axes.find(kAxisLetters[i]) == std::string::npos) continue;
    home_m[k] = param_len(base, i);
  }
  const Pose home = program_of(home_m, coord_);
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

void Interpreter::motion(Words& w) {
  const int m = motion_;
  const int col = w.g[1] >= 0 ? w.gcol[1] : (w.axes ? w.column(kAxisLetters[std::countr_zero(w.axes)]) : 0);
  if (m < 0 || m == 800) {
    if (w.axes != 0) fail(col, "axis words without a G code that uses them (motion mode is G80)");
    return;
  }
  const bool g53 = w.g[0] == 530;
  if (!(m >= 730 && m <= 890)) in_cycle_ = false;
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
  if (m >= 730 && m <= 890) {
    cycle(w);
    return;
  }
  if (m == 50 || m == 51) {
    spline(w, m == 50, col);
    return;
  }
  if (m == 330 || m == 331 || m == 760) fail(col, g_text(m) + " needs spindle synchronisation, which this machine lacks");
  if (m >= 382 && m <= 385) fail(col, g_text(m) + " probes, and this machine's config has no probe input");
  fail(col, "motion " + g_text(m) + " is not supported");
}

void Interpreter::arc(Words& w, bool cw, const Pose& end) {
  int a1 = 0, a2 = 1, a3 = 2;  // plane axes: first, second, normal
  char o1 = 'I', o2 = 'J';
  if (plane_ == Plane::kXZ) {
    a1 = 2; a2 = 0; a3 = 1; o1 = 'K'; o2 = 'I';
  } else if (plane_ == Plane::kYZ) {
    a1 = 1; a2 = 2; a3 = 0; o1 = 'J'; o2 = 'K';
  }
  const double s = length_scale();
  const double c1 = to_program(position_[static_cast<size_t>(a1)]), c2 = to_program(position_[static_cast<size_t>(a2)]);
  const double e1 = to_program(end[static_cast<size_t>(a1)]), e2 = to_program(end[static_cast<size_t>(a2)]);
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
  (void)s;
  if (feed_mode_ == FeedMode::kInverseTime) {
    const double r = std::hypot(c1 - cen1, c2 - cen2);
    double a0 = std::atan2(c2 - cen2, c1 - cen1), a1e = std::atan2(e2 - cen2, e1 - cen1);
    double sweep = cw ? a0 - a1e : a1e - a0;
    if (sweep <= 0) sweep += 2 * M_PI;
    sweep += 2 * M_PI * (turns - 1);
    const double dz = to_program(end[static_cast<size_t>(a3)] - position_[static_cast<size_t>(a3)]);
    const double length = std::hypot(r * sweep, dz);
    feed_ = length == 0 ? 0.1 : length * w['F'];
    canon_.set_feed_rate(ref(col), feed_);
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
  // The depth-axis level where a run of cycle blocks started (G98 returns to it).
  if (!in_cycle_) cycle_old_z_ = to_program(position_[static_cast<size_t>(a3)]);
  const bool continuing = prev_motion_ == m;
  CycleInput in;
  in.g = m;
  in.plane = plane_;
  in.incremental = incremental_;
  in.retract_to_r = retract_r_;
  in.start = program_pose(position_);
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
  try {
    res = run_cycle(in, ref(col), canon_);
  } catch (const Error& e) {
    if (!e.file_name().empty()) throw;
    fail(e.column() > 0 ? e.column() : col, e.detail());
  }
  for (size_t i = 0; i < res.end.size(); ++i) position_[i] = i < 3 || i >= 6 ? res.end[i] * length_scale() : res.end[i];
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

// ---- the end ----------------------------------------------------------------------------

void Interpreter::end_program(bool m30) {
  const SourceRef r = ref();
  comp_filter_->flush();
  comp_filter_->stop();
  // LinuxCNC's end of program (M2, M30): G54 with its rotation, the XY plane, G90,
  // G94 with no feed, feed and speed overrides on, spindle off, coolant off, G40, G1.
  // G92 and the tool length offset stay.
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
  if (!feed_override_ || !speed_override_) {
    canon_.enable_feed_override(r, true);
    canon_.enable_speed_override(r, true);
  }
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
