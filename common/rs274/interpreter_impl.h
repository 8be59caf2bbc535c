#pragma once
// The interpreter's insides, shared by its source files (interpreter.cc and the
// interpreter_*.cc beside it) and by nothing else: word slots, the program files and
// the state of calls and loops, and the small unit conversions every part uses.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstring>
#include <memory>

#include "common/rs274/interpreter.h"

namespace cnc::rs274 {
namespace interp {

inline constexpr double kMmPerInch = 25.4;
inline constexpr char kAxisLetters[] = "XYZABCUVW";

// Word slots: A..Z, then @ (polar distance), ^ (polar angle) and $ (spindle).
inline int letter_index(char c) { return c == '@' ? 26 : c == '^' ? 27 : c == '$' ? 28 : c - 'A'; }
inline uint32_t bit(char c) { return 1u << letter_index(c); }

inline int axis_of_letter(char c) {
  for (int i = 0; i < kNumAxes; ++i)
    if (kAxisLetters[i] == c) return i;
  return -1;
}

inline std::string g_text(int g) {
  char buf[16];
  if (g % 10 == 0)
    std::snprintf(buf, sizeof buf, "G%d", g / 10);
  else
    std::snprintf(buf, sizeof buf, "G%d.%d", g / 10, g % 10);
  return buf;
}

inline std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  return buf;
}

// o-word kinds as bits, for skip_to's targets.
inline uint32_t kbit(OKind k) { return 1u << static_cast<int>(k); }

}  // namespace interp

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
  // A remapped M6's call: the rest of its block, run after the return.
  std::shared_ptr<Words> remap_rest;
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
  std::array<double, 29> v{};
  std::array<int32_t, 29> col{};
  uint32_t has = 0;
  std::array<int, 17> g{};
  std::array<int32_t, 17> gcol{};
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
  bool on(char c) const { return (has & interp::bit(c)) != 0; }
  double operator[](char c) const { return v[static_cast<size_t>(interp::letter_index(c))]; }
  int32_t column(char c) const { return col[static_cast<size_t>(interp::letter_index(c))]; }
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

// LinuxCNC stores the $ word in an int (truncated towards 0).
inline int Interpreter::spindle_number(const Words& w) const {
  const double d = std::trunc(w['$']);
  return d < -1e6 ? -1000000 : d > 1e6 ? 1000000 : static_cast<int>(d);
}

// Small conversions used on every line: defined here so that each part inlines them.
inline double Interpreter::length_scale() const { return units_ == Units::kInch ? interp::kMmPerInch : 1.0; }
inline double Interpreter::to_program(double mm) const { return mm / length_scale(); }
// Axis i's value in program units: lengths scale, the angles of A B C do not.
inline double Interpreter::to_program_axis(int i, double v) const { return i < 3 || i >= 6 ? to_program(v) : v; }

// A pose in mm (degrees for A B C) in program units.
inline Pose Interpreter::program_pose(const Pose& mm) const {
  Pose p{};
  for (size_t i = 0; i < p.size(); ++i) p[i] = i < 3 || i >= 6 ? to_program(mm[i]) : mm[i];
  return p;
}

// Lengths in parameters and the tool table are in machine units (LinuxCNC's rule);
// the interpreter works in mm. Axis i of a group that starts at `base`.
inline double Interpreter::param_len(int base, int i) const {
  return params_.get(base + i) * (i < 3 || i >= 6 ? mu_ : 1.0);
}

inline void Interpreter::set_param_len(int base, int i, double mm) {
  params_.set(base + i, mm / (i < 3 || i >= 6 ? mu_ : 1.0));
}

inline SourceRef Interpreter::ref(int column) const { return SourceRef{file_, line_no_, column}; }

}  // namespace cnc::rs274
