#include "common/program/gcode_parser.h"

#include <array>
#include <cctype>
#include <cmath>
#include <fstream>
#include <optional>

#include "common/program/block_check.h"

namespace cnc::program {

ProgramError::ProgramError(SourceLocation where, const std::string& what)
    : std::runtime_error(where.str() + ": " + what), where_(std::move(where)), detail_(what) {}

namespace {

constexpr double kMaxMagnitude = 1e6;  // mm, mm/min, rpm, s: anything larger is a typo or an attack
constexpr size_t kMaxLineLength = 4096;
constexpr uint64_t kFnvPrime = 1099511628211ull;

uint64_t fnv1a(uint64_t h, const char* p, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(p[i]);
    h *= kFnvPrime;
  }
  return h;
}

// ---- lexer ----------------------------------------------------------------------------

struct Word {
  char letter;
  double value;
  int column;        // of the letter, 1-based
  std::string text;  // as written, for messages
};

struct Comment {
  int body_column;   // column of the first character after '('
  std::string body;  // between the parentheses
};

struct LexedLine {
  std::vector<Word> words;
  std::vector<Comment> comments;
};

// The number grammar of a word: [+-] digits [. digits], at least one digit.
// Returns the length matched (0: no number); `value` gets the value.
size_t scan_number(const std::string& s, size_t i, double* value, std::string* clean) {
  const size_t start = i, n = s.size();
  clean->clear();
  if (i < n && (s[i] == '+' || s[i] == '-')) *clean += s[i++];
  size_t digits = 0;
  auto take_digits = [&] {
    while (i < n && std::isdigit(static_cast<unsigned char>(s[i]))) *clean += s[i++], ++digits;
  };
  take_digits();
  if (i < n && s[i] == '.') {
    *clean += s[i++];
    take_digits();
  }
  if (digits == 0) return 0;
  *value = std::strtod(clean->c_str(), nullptr);
  return i - start;
}

// Lexes one line into words; comments in ( ) are kept (they may be directives),
// comments after ; are dropped.
void lex_line(const std::string& line, const std::string& file, int line_no, LexedLine* out) {
  out->words.clear();
  out->comments.clear();
  size_t i = 0;
  const size_t n = line.size();
  auto where = [&](size_t col) { return SourceLocation{file, line_no, static_cast<int>(col) + 1}; };
  std::string clean;
  while (i < n) {
    const char c = line[i];
    if (c == ' ' || c == '\t' || c == '\r') {
      ++i;
      continue;
    }
    if (c == ';') break;
    if (c == '(') {
      const size_t close = line.find(')', i);
      if (close == std::string::npos) throw ProgramError(where(i), "unterminated comment: expected ')' before the end of the line");
      const size_t nested = line.find('(', i + 1);
      if (nested != std::string::npos && nested < close) throw ProgramError(where(nested), "nested comment: '(' inside a comment");
      out->comments.push_back(Comment{static_cast<int>(i) + 2, line.substr(i + 1, close - i - 1)});
      i = close + 1;
      continue;
    }
    if (c == '%' && out->words.empty()) {
      ++i;
      continue;
    }
    if (!std::isalpha(static_cast<unsigned char>(c))) {
      throw ProgramError(where(i), std::string("unexpected character '") + c + "': expected a word (a letter and a number)");
    }
    const size_t letter_col = i;
    const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    ++i;
    while (i < n && (line[i] == ' ' || line[i] == '\t')) ++i;
    double value = 0;
    const size_t len = scan_number(line, i, &value, &clean);
    if (len == 0) {
      size_t e = i;
      while (e < n && std::isalpha(static_cast<unsigned char>(line[e]))) ++e;
      std::string found = e > i ? ", found '" + line.substr(i, e - i) + "'" : "";
      throw ProgramError(where(i), std::string("expected a number after '") + letter + "'" + found);
    }
    if (!std::isfinite(value) || std::fabs(value) > kMaxMagnitude) {
      throw ProgramError(where(i), "number '" + clean + "' out of range: expected a magnitude of at most 1e6");
    }
    i += len;
    out->words.push_back(Word{letter, value, static_cast<int>(letter_col) + 1, std::string(1, letter) + clean});
  }
}

// Reads one line of at most kMaxLineLength characters. Returns false at the end of
// the input; `newline` tells whether a '\n' ended the line.
bool read_line(std::istream& in, std::string* line, bool* newline, bool* too_long) {
  line->clear();
  *newline = false;
  *too_long = false;
  std::streambuf* sb = in.rdbuf();
  bool any = false;
  for (;;) {
    const int ch = sb->sbumpc();
    if (ch == std::char_traits<char>::eof()) {
      in.setstate(std::ios::eofbit);
      return any;
    }
    any = true;
    if (ch == '\n') {
      *newline = true;
      return true;
    }
    if (line->size() >= kMaxLineLength) {
      *too_long = true;
      return true;
    }
    line->push_back(static_cast<char>(ch));
  }
}

// G and M numbers are written with at most one decimal (G5.2): compare them in tenths.
std::optional<int> code_tenths(double v) {
  const double t = v * 10.0;
  if (std::fabs(t - std::round(t)) > 1e-6 || v < 0) return std::nullopt;
  return static_cast<int>(std::lround(t));
}

bool is_whole(double v) { return v == std::floor(v); }

std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

// ---- the line interpreter -----------------------------------------------------------

// Motion codes in tenths.
constexpr int kG0 = 0, kG1 = 10, kG2 = 20, kG3 = 30, kG5_2 = 52, kG5_3 = 53, kG6_2 = 62;

std::string motion_name(int code) {
  switch (code) {
    case kG0: return "G0";
    case kG1: return "G1";
    case kG2: return "G2";
    case kG3: return "G3";
    case kG5_2: return "G5.2";
    case kG5_3: return "G5.3";
    case kG6_2: return "G06.2";
    default: return "G?";
  }
}

// Words of one block by letter (G and M may repeat and are not kept here).
struct Seen {
  std::array<const Word*, 26> w{};
  const Word* operator[](char letter) const { return w[static_cast<size_t>(letter - 'A')]; }
  const Word*& at(char letter) { return w[static_cast<size_t>(letter - 'A')]; }
};

// A NURBS curve being read over several lines, with where each of its numbers came
// from so that a fault found at the end still names its word.
struct Curve {
  enum class Dialect { kFanuc, kLinuxCnc } dialect;
  SourceLocation opened;  // the G06.2 / G5.2 word
  Block block;            // start, feed, spindle, process: as at the opening line
  NurbsGeometry g;
  std::vector<SourceLocation> knot_at, weight_at, point_at;
  std::array<double, 3> programmed{};  // Fanuc: the last control point, for G91 and omitted axes
  bool knots_only = false;             // Fanuc: the closing knot-only blocks have begun
};

class Engine {
 public:
  Engine(const ParserSettings& settings, const std::string& file, const ParserState& from, BlockSink& sink)
      : settings_(settings), file_(file), st_(from), sink_(sink) {
    const size_t naxes = settings_.axis_names.size();
    if (st_.position_mm.size() != naxes) st_.position_mm.assign(naxes, 0.0);
    axis_of_.fill(-1);
    for (size_t a = 0; a < naxes; ++a) {
      const std::string& nm = settings_.axis_names[a];
      if (nm.size() == 1 && std::isalpha(static_cast<unsigned char>(nm[0])))
        axis_of_[static_cast<size_t>(std::toupper(static_cast<unsigned char>(nm[0])) - 'A')] = static_cast<int>(a);
    }
  }

  void run(std::istream& in) {
    std::string line;
    bool newline = false, too_long = false;
    while (!stop_ && !ended_) {
      if (!curve_ && !sink_.resume_point(st_)) return;
      if (!read_line(in, &line, &newline, &too_long)) break;
      ++st_.line;
      if (too_long)
        throw ProgramError(SourceLocation{file_, st_.line, static_cast<int>(kMaxLineLength) + 1},
                           "line longer than " + std::to_string(kMaxLineLength) + " characters");
      st_.content_hash = fnv1a(st_.content_hash, line.data(), line.size());
      if (newline) st_.content_hash = fnv1a(st_.content_hash, "\n", 1);
      st_.offset += static_cast<int64_t>(line.size()) + (newline ? 1 : 0);
      interpret(line);
    }
    if (in.bad()) throw ProgramError(SourceLocation{file_, st_.line, 0}, "read error in the program file");
    if (stop_) return;
    if (!ended_) end_of_input();
    if (!stop_) sink_.finished(st_);
  }

 private:
  SourceLocation at(const Word& w) const { return SourceLocation{file_, st_.line, w.column}; }
  SourceLocation at_column(int column) const { return SourceLocation{file_, st_.line, column}; }
  [[noreturn]] void fail(const Word& w, const std::string& what) const { throw ProgramError(at(w), what); }

  size_t naxes() const { return settings_.axis_names.size(); }
  int axis_of(char letter) const { return axis_of_[static_cast<size_t>(letter - 'A')]; }
  // Machine axis `index` is the one named by `letter` (X, Y, Z at 0, 1, 2: the
  // convention of arcs and NURBS in Block).
  bool axis_is(int index, char letter) const { return index < static_cast<int>(naxes()) && axis_of(letter) == index; }
  bool has_xyz() const { return axis_is(0, 'X') && axis_is(1, 'Y') && axis_is(2, 'Z'); }

  Block new_block(BlockKind kind) const {
    Block b;
    b.source_line = st_.line;
    b.kind = kind;
    b.start = st_.position_mm;
    b.end = st_.position_mm;
    b.feed_mm_per_min = st_.feed_mm_per_min;
    b.spindle_rpm = st_.spindle_on ? st_.spindle_speed_rpm : 0.0;
    b.process = st_.process;
    return b;
  }

  void emit(Block&& b) {
    b.index = st_.next_index++;
    if (!sink_.block(std::move(b))) stop_ = true;
  }

  void interpret(const std::string& line) {
    lex_line(line, file_, st_.line, &lx_);
    if (lx_.words.empty() && !any_directive()) return;
    if (curve_ && curve_->dialect == Curve::Dialect::kLinuxCnc) {
      linuxcnc_line();
      return;
    }
    if (curve_) {
      bool has_k = false, has_g = false;
      for (const Word& w : lx_.words) {
        has_k |= w.letter == 'K';
        has_g |= w.letter == 'G';
      }
      if (has_k && !has_g) {
        fanuc_line();
        return;
      }
      fanuc_missing_knot();
      close_fanuc(lx_.words.empty() ? at_column(lx_.comments.front().body_column - 1) : at(lx_.words.front()));
      if (stop_) return;
    }
    plain_line();
  }

  // ---- ordinary blocks ----

  void plain_line() {
    // G20/G21 hold for the whole block, whatever the order of its words (RS274):
    // set them before any F or axis word of the block is scaled.
    for (const Word& w : lx_.words) {
      if (w.letter != 'G') continue;
      const auto code = code_tenths(w.value);
      if (code == 200) st_.unit_mm = 25.4;
      if (code == 210) st_.unit_mm = 1.0;
    }
    for (const Comment& c : lx_.comments) apply_directive(c);

    Seen seen;
    std::optional<int> motion_word;
    const Word* motion_src = nullptr;
    const Word* dwell_src = nullptr;
    bool any_axis = false;
    const Word* end_program = nullptr;

    for (const Word& w : lx_.words) {
      if (w.letter != 'G' && w.letter != 'M') {
        if (seen[w.letter]) fail(w, std::string("word '") + w.letter + "' appears twice in one block");
        seen.at(w.letter) = &w;
      }
      switch (w.letter) {
        case 'N':
          if (w.value < 0 || !is_whole(w.value)) fail(w, "expected a non-negative whole line number after N");
          continue;
        case 'F':
          if (w.value <= 0) fail(w, "expected a positive feed rate after F");
          st_.feed_mm_per_min = w.value * st_.unit_mm;
          continue;
        case 'S':
          if (w.value < 0) fail(w, "expected a non-negative spindle speed after S");
          st_.spindle_speed_rpm = w.value;
          continue;
        case 'G': {
          const auto code = code_tenths(w.value);
          if (!code) fail(w, "malformed G code '" + w.text + "'");
          switch (*code) {
            case kG0: case kG1: case kG2: case kG3: case kG5_2: case kG5_3: case kG6_2:
              if (motion_word) fail(w, "two motion codes in one block");
              motion_word = *code;
              motion_src = &w;
              break;
            case 40: dwell_src = &w; break;
            case 170: st_.plane = 17; break;
            case 180: st_.plane = 18; break;
            case 190: st_.plane = 19; break;
            case 200: case 210: break;  // units: set before this loop
            case 900: st_.absolute = true; break;
            case 910: st_.absolute = false; break;
            default:
              fail(w, "unsupported G code '" + w.text +
                          "': expected one of G0 G1 G2 G3 G4 G5.2 G5.3 G06.2 G17 G18 G19 G20 G21 G90 G91");
          }
          continue;
        }
        case 'M': {
          const auto code = code_tenths(w.value);
          if (!code) fail(w, "malformed M code '" + w.text + "'");
          switch (*code) {
            case 30: st_.spindle_on = true; break;   // M3
            case 50: st_.spindle_on = false; break;  // M5
            case 20: case 300: end_program = &w; break;  // M2, M30
            default: fail(w, "unsupported M code '" + w.text + "': expected one of M2 M3 M5 M30");
          }
          continue;
        }
        case 'P': case 'I': case 'J': case 'K': case 'R': case 'L':
          if (axis_of(w.letter) < 0) continue;  // parameters: their motion code uses them
          break;
        default: break;
      }
      if (axis_of(w.letter) >= 0) {
        any_axis = true;
        continue;
      }
      std::string expected = "N G M F S P I J K R L";
      for (const auto& nm : settings_.axis_names) expected += " " + nm;
      fail(w, std::string("unknown word '") + w.letter + "': expected one of " + expected);
    }

    std::string used;  // parameter letters this block consumes
    if (dwell_src) {
      if (motion_word && *motion_word != kG0 && *motion_word != kG1)
        fail(*dwell_src, "G4 cannot share a block with " + motion_name(*motion_word) + ": P would mean two things");
      const Word* p = seen['P'];
      if (!p) fail(*dwell_src, "G4 needs a dwell time: expected a P word");
      if (any_axis) fail(*dwell_src, "G4 cannot be combined with axis words");
      if (p->value < 0) fail(*p, "expected a non-negative dwell time after P");
      Block b = new_block(BlockKind::kDwell);
      b.dwell_s = p->value;
      emit(std::move(b));
      used = "P";
    }

    if (motion_word == kG5_3) fail(*motion_src, "G5.3 without G5.2 first: expected G5.2 to open a NURBS curve");
    if (motion_word) st_.motion = *motion_word;
    const bool arc_mode = st_.motion == kG2 || st_.motion == kG3;
    const bool arc_words = seen['I'] || seen['J'] || seen['K'] || seen['R'];
    // The word a refusal of this block's motion points at (a block with a motion has words).
    const Word* anchor = motion_src ? motion_src : lx_.words.empty() ? nullptr : &lx_.words.front();
    if (motion_word == kG6_2) {
      open_fanuc(*motion_src, seen);
      used = "PKR";
    } else if (motion_word == kG5_2) {
      open_linuxcnc(*motion_src, seen);
      used = "PL";
    } else if (any_axis || (arc_mode && arc_words)) {
      if (st_.motion < 0)
        fail(lx_.words.front(), "axis words without a motion mode: expected G0, G1, G2 or G3 first");
      const std::vector<double> end = target(seen, st_.position_mm);
      if (arc_mode) {
        arc(*anchor, seen, end);
        used = "IJKRP";
      } else {
        Block b = new_block(st_.motion == kG0 ? BlockKind::kRapid : BlockKind::kLine);
        if (b.kind == BlockKind::kLine && st_.feed_mm_per_min <= 0)
          fail(*anchor, "feed rate not set: expected an F word before or in this G1 block");
        b.end = end;
        st_.position_mm = end;
        emit(std::move(b));
      }
    }
    for (const char letter : {'P', 'I', 'J', 'K', 'R', 'L'}) {
      const Word* w = seen[letter];
      if (!w || axis_of(letter) >= 0 || used.find(letter) != std::string::npos) continue;
      switch (letter) {
        case 'P': fail(*w, "P word without G4 (dwell), G2/G3 (turns), G06.2 (order) or G5.2 (weight)");
        case 'I': case 'J': fail(*w, std::string(1, letter) + " word without G2 or G3 (centre offset)");
        case 'K': fail(*w, "K word without G2 or G3 (centre offset) or G06.2 (knot)");
        case 'R': fail(*w, "R word without G2 or G3 (radius) or G06.2 (weight)");
        default: fail(*w, "L word without G5.2 (order)");
      }
    }
    if (end_program && curve_) fail(*end_program, "the program cannot end on the line that opens a NURBS curve");
    if (end_program && !stop_) end_block();
  }

  // Axis words to a target position under G90/G91 and G20/G21.
  std::vector<double> target(const Seen& seen, const std::vector<double>& from) const {
    std::vector<double> end = from;
    for (size_t a = 0; a < naxes(); ++a) {
      const std::string& nm = settings_.axis_names[a];
      if (nm.size() != 1 || !std::isalpha(static_cast<unsigned char>(nm[0]))) continue;
      const Word* w = seen[static_cast<char>(std::toupper(static_cast<unsigned char>(nm[0])))];
      if (!w) continue;
      const double v = w->value * st_.unit_mm;
      end[a] = st_.absolute ? v : from[a] + v;
    }
    return end;
  }

  // ---- arcs ----

  // G2/G3 in the active plane. The centre comes from I J K (offsets from the start,
  // incremental whatever G90/G91 says, as in RS274) or from R (R < 0: the arc of
  // more than 180°). The axis normal to the plane, and any other axis, moves
  // linearly: a helix.
  void arc(const Word& anchor, const Seen& seen, const std::vector<double>& end) {
    const bool ccw = st_.motion == kG3;
    const std::string name = motion_name(st_.motion);
    const PlaneAxes p = plane_axes(st_.plane);
    if (!axis_is(p.first, "XYZ"[p.first]) || !axis_is(p.second, "XYZ"[p.second]))
      fail(anchor, "arcs in the G" + std::to_string(st_.plane) + " plane need machine axes " +
                       std::string(1, "XYZ"[p.first]) + " and " + std::string(1, "XYZ"[p.second]) +
                       " as axes " + std::to_string(p.first + 1) + " and " + std::to_string(p.second + 1));
    if (st_.feed_mm_per_min <= 0) fail(anchor, "feed rate not set: expected an F word before or in this " + name + " block");
    const char off1 = "IJK"[p.first], off2 = "IJK"[p.second], off_normal = "IJK"[p.normal];
    const bool has_ijk = seen['I'] || seen['J'] || seen['K'];
    const Word* r_word = seen['R'];
    if (r_word && has_ijk) fail(*r_word, "R and I J K in one arc: expected either the centre (I J K) or the radius (R)");
    if (!r_word && !has_ijk) fail(anchor, name + " needs its centre or radius: expected I J K or R");
    if (seen[off_normal])
      fail(*seen[off_normal], std::string(1, off_normal) + " is not a centre offset in the G" + std::to_string(st_.plane) +
                                  " plane: expected " + off1 + " and " + off2);
    const double s1 = st_.position_mm[p.first], s2 = st_.position_mm[p.second];
    const double e1 = end[p.first], e2 = end[p.second];
    double c1 = 0, c2 = 0;
    if (has_ijk) {
      const Word* first_offset = nullptr;
      for (const Word& w : lx_.words)
        if (w.letter == off1 || w.letter == off2) {
          first_offset = &w;
          break;
        }
      c1 = s1 + (seen[off1] ? seen[off1]->value * st_.unit_mm : 0.0);
      c2 = s2 + (seen[off2] ? seen[off2]->value * st_.unit_mm : 0.0);
      const double r0 = std::hypot(s1 - c1, s2 - c2);
      const double r1 = std::hypot(e1 - c1, e2 - c2);
      if (!(r0 > 0)) fail(*first_offset, "the arc's centre is its start point: expected a non-zero centre offset");
      if (std::fabs(r1 - r0) > arc_radius_tolerance_mm(r0))
        fail(*first_offset, "arc radius mismatch: " + fmt_number(r0) + " mm at the start, " + fmt_number(r1) +
                                " mm at the end: expected the end point on the circle (tolerance " +
                                fmt_number(arc_radius_tolerance_mm(r0)) + " mm)");
    } else {
      const double r = r_word->value * st_.unit_mm;
      if (r == 0) fail(*r_word, "radius R0: expected a non-zero radius");
      const double d1 = e1 - s1, d2 = e2 - s2;
      const double chord = std::hypot(d1, d2);
      if (chord <= 1e-9) fail(*r_word, "an R-form arc cannot be a full circle (its end is its start): expected I J K");
      const double half = chord / 2;
      if (half - std::fabs(r) > arc_radius_tolerance_mm(std::fabs(r)))
        fail(*r_word, "radius " + r_word->text + " is smaller than half the chord (" + fmt_number(half) +
                          " mm): expected |R| >= " + fmt_number(half));
      const double h = std::sqrt(std::max(0.0, r * r - half * half));
      // Centre to the left of the chord for a short counter-clockwise arc (and a long
      // clockwise one), to the right otherwise.
      const double side = (ccw == (r > 0)) ? 1.0 : -1.0;
      c1 = (s1 + e1) / 2 - side * h * d2 / chord;
      c2 = (s2 + e2) / 2 + side * h * d1 / chord;
    }
    int turns = 0;
    if (const Word* pw = seen['P']) {
      if (!is_whole(pw->value) || pw->value < 1 || pw->value > kMaxArcTurns + 1)
        fail(*pw, "expected a whole number of turns from 1 to " + std::to_string(kMaxArcTurns + 1) + " after P");
      turns = static_cast<int>(pw->value) - 1;
    }
    Block b = new_block(ccw ? BlockKind::kArcCcw : BlockKind::kArcCw);
    b.end = end;
    b.arc.center = st_.position_mm;
    b.arc.center[p.first] = c1;
    b.arc.center[p.second] = c2;
    b.arc.plane = st_.plane;
    b.arc.turns = turns;
    st_.position_mm = end;
    emit(std::move(b));
  }

  // ---- NURBS, common ----

  void require_nurbs_start(const Word& g) {
    if (!has_xyz()) fail(g, "a NURBS needs machine axes X, Y and Z as axes 1, 2 and 3");
    if (st_.feed_mm_per_min <= 0) fail(g, "feed rate not set: expected an F word before or in this " + g.text + " block");
  }

  // The curve's geometry is complete: check it as a whole, name the word of its first
  // fault, and emit the block.
  void finish_curve(const SourceLocation& closing) {
    Curve& c = *curve_;
    const GeometryFault f = check_nurbs(c.g);
    if (!f.ok()) {
      using P = GeometryFault::Part;
      SourceLocation where = closing;
      if (f.part == P::kKnot && f.index < static_cast<int>(c.knot_at.size())) where = c.knot_at[f.index];
      if (f.part == P::kWeight && f.index < static_cast<int>(c.weight_at.size())) where = c.weight_at[f.index];
      if (f.part == P::kControlPoint && f.index < static_cast<int>(c.point_at.size())) where = c.point_at[f.index];
      throw ProgramError(where, f.what);
    }
    Block b = std::move(c.block);
    b.kind = BlockKind::kNurbs;
    for (int a = 0; a < 3; ++a) b.end[a] = c.g.control_points.back()[a];
    b.nurbs = std::move(c.g);
    st_.position_mm = b.end;
    curve_.reset();
    emit(std::move(b));
  }

  Curve& new_curve(Curve::Dialect dialect, const Word& g) {
    curve_.emplace();
    Curve& c = *curve_;
    c.dialect = dialect;
    c.opened = at(g);
    c.block = new_block(BlockKind::kNurbs);
    for (int a = 0; a < 3; ++a) c.programmed[a] = st_.position_mm[a];
    // After a curve no motion mode is active (LinuxCNC sets none after G5.3; a
    // Fanuc curve ends with its knots): the next move names its G code.
    st_.motion = -1;
    return c;
  }

  // ---- Fanuc G06.2 ----
  //
  //   G06.2 P<order> K<knot> X Y Z [R<weight>] [F]   the first control point
  //   K X Y Z [R]                                    the further control points
  //   K                                              `order` knot-only blocks
  //
  // (Fanuc Series 15i/150i-MA programming manual, NURBS interpolation.) The knots
  // number control points + order; the first control point is where the tool is
  // (under G91 it is written X0 Y0 Z0); omitted axes keep the previous control
  // point's value; R defaults to 1. G91 applies: each control point is then
  // relative to the one before. The curve ends at the first block without K or with
  // a G code. Departures from Fanuc: P is required (Fanuc assumes 4) and may be 2..8
  // (Fanuc: 2..4); only X, Y, Z take part (Fanuc allows any axes).

  void open_fanuc(const Word& g, const Seen& seen) {
    const Word* p = seen['P'];
    if (!p) fail(g, "G06.2 needs the curve's order: expected a P word (2 to 8)");
    if (!is_whole(p->value) || p->value < kMinNurbsOrder || p->value > kMaxNurbsOrder)
      fail(*p, "order " + p->text + " out of range: expected a whole number from 2 to 8 (degree 1 to 7)");
    require_nurbs_start(g);
    for (const Word& w : lx_.words)
      if (axis_of(w.letter) > 2) fail(w, std::string("a NURBS moves X, Y and Z only: found '") + w.letter + "'");
    Curve& c = new_curve(Curve::Dialect::kFanuc, g);
    c.g.order = static_cast<int>(p->value);
    fanuc_point(seen, g, true);
  }

  // A block with a K word inside the curve: a control point or a closing knot.
  void fanuc_line() {
    Curve& c = *curve_;
    Seen seen;
    bool any_axis = false;
    for (const Word& w : lx_.words) {
      if (seen[w.letter]) fail(w, std::string("word '") + w.letter + "' appears twice in one block");
      seen.at(w.letter) = &w;
      if (w.letter == 'N') {
        if (w.value < 0 || !is_whole(w.value)) fail(w, "expected a non-negative whole line number after N");
        continue;
      }
      if (w.letter == 'K' || w.letter == 'R') continue;
      const int a = axis_of(w.letter);
      if (a >= 0 && a <= 2) {
        any_axis = true;
        continue;
      }
      fail(w, std::string("'") + w.letter + "' inside a G06.2 NURBS curve: expected K, X, Y, Z and R (or the end of the curve)");
    }
    if (!lx_.comments.empty() && any_directive())
      throw ProgramError(at_column(lx_.comments.front().body_column), "process parameters cannot change inside a NURBS curve");
    if (any_axis) {
      if (c.knots_only)
        for (const Word& w : lx_.words)
          if (axis_of(w.letter) >= 0) fail(w, "control point after the closing knots: expected K alone until the curve ends");
      fanuc_point(seen, *seen['K'], false);
      return;
    }
    if (seen['R']) fail(*seen['R'], "weight R without a control point: expected X, Y or Z with it");
    const Word& k = *seen['K'];
    const int n_ctrl = static_cast<int>(c.g.control_points.size());
    if (!c.knots_only && n_ctrl < c.g.order)
      fail(k, "a NURBS of order " + std::to_string(c.g.order) + " needs at least " + std::to_string(c.g.order) +
                  " control points, found " + std::to_string(n_ctrl));
    c.knots_only = true;
    if (static_cast<int>(c.g.knots.size()) == n_ctrl + c.g.order)
      fail(k, "one knot too many: " + std::to_string(n_ctrl) + " control points of order " +
                  std::to_string(c.g.order) + " take " + std::to_string(n_ctrl + c.g.order) + " knots (control points + order)");
    fanuc_knot(k);
  }

  // A control point block without K: Fanuc refuses it (alarm PS1002).
  void fanuc_missing_knot() const {
    if (curve_->knots_only || lx_.words.empty()) return;
    bool has_g = false;
    const Word* axis = nullptr;
    for (const Word& w : lx_.words) {
      has_g |= w.letter == 'G';
      if (!axis && axis_of(w.letter) >= 0) axis = &w;
    }
    if (axis && !has_g)
      fail(lx_.words.front(), "control point without a knot inside the NURBS curve opened at line " +
                                  std::to_string(curve_->opened.line) + ": expected a K word");
  }

  void fanuc_point(const Seen& seen, const Word& anchor, bool first) {
    Curve& c = *curve_;
    const Word* k = seen['K'];
    if (!k) fail(anchor, "expected a K word (knot) with each control point of a G06.2 curve");
    std::array<double, 3> p{};
    const Word* first_axis = nullptr;
    for (int a = 0; a < 3; ++a) {
      const Word* w = seen["XYZ"[a]];
      if (!w) {
        p[a] = c.programmed[a];
        continue;
      }
      if (!first_axis) first_axis = w;
      const double v = w->value * st_.unit_mm;
      p[a] = st_.absolute ? v : c.programmed[a] + v;
      if (first && std::fabs(p[a] - st_.position_mm[a]) > kNurbsContinuityMm)
        fail(*w, "the first control point " + w->text + " is not where the tool is (" + std::string(1, "XYZ"[a]) +
                     fmt_number(st_.position_mm[a] / st_.unit_mm) +
                     "): expected the curve to start at the current position (within 1e-6 mm)");
    }
    double weight = 1.0;
    if (const Word* r = seen['R']) {
      if (!(r->value > 0)) fail(*r, "weight " + r->text + ": expected a positive weight");
      weight = r->value;
    }
    if (static_cast<int>(c.g.control_points.size()) == kMaxNurbsControlPoints)
      fail(anchor, "more than " + std::to_string(kMaxNurbsControlPoints) + " control points in one NURBS curve: split it");
    c.programmed = p;
    c.g.control_points.push_back(p);
    c.g.weights.push_back(weight);
    c.point_at.push_back(at(first_axis ? *first_axis : *k));
    c.weight_at.push_back(at(seen['R'] ? *seen['R'] : *k));
    fanuc_knot(*k);
  }

  void fanuc_knot(const Word& k) {
    Curve& c = *curve_;
    const size_t i = c.g.knots.size();
    if (i > 0 && k.value < c.g.knots.back())
      fail(k, "knot " + k.text + " is smaller than the knot before it (" + fmt_number(c.g.knots.back()) +
                  "): expected non-decreasing knots");
    if (i > 0 && static_cast<int>(i) < c.g.order && k.value != c.g.knots.front())
      fail(k, "knot vector is not clamped: expected the first " + std::to_string(c.g.order) + " knots equal (" +
                  fmt_number(c.g.knots.front()) + "), found " + k.text);
    c.g.knots.push_back(k.value);
    c.knot_at.push_back(at(k));
  }

  void close_fanuc(const SourceLocation& closing) {
    Curve& c = *curve_;
    const size_t want = c.g.control_points.size() + static_cast<size_t>(c.g.order);
    if (c.g.knots.size() != want)
      throw ProgramError(closing, "the NURBS curve opened at line " + std::to_string(c.opened.line) + " ends with " +
                                      std::to_string(c.g.knots.size()) + " knots for " +
                                      std::to_string(c.g.control_points.size()) + " control points of order " +
                                      std::to_string(c.g.order) + ": expected " + std::to_string(want) +
                                      " (control points + order)");
    finish_curve(closing);
  }

  // ---- LinuxCNC G5.2 / G5.3 ----
  //
  //   G5.2 [P<w0>] [X Y P<w>] [L<order>]   opens; the current position is control point 0
  //   X Y P<w>                             further control points
  //   G5.3                                 closes
  //
  // Found in LinuxCNC's source (src/emc/rs274ngc/interp_convert.cc, convert_nurbs;
  // nurbs_additional_functions.cc, knot_vector_creator; NURBS_FEED in
  // emccanon.cc) and its G-code reference (docs/src/gcode/g-code.adoc, "G5.2 G5.3
  // NURBS Block"):
  // * The position before G5.2 is always the first control point; its weight is the
  //   P of a first G5.2 line without X and Y, else 1. Hence the curve is continuous.
  // * Each further control point needs both X and Y and a weight P > 0 ("Must specify
  //   positive weight P for every Control Point"); P without X Y is allowed only on
  //   the first line. Coordinates go through find_ends, so G20 and G91 apply; under
  //   G91 the offsets are from the curve's start, since LinuxCNC moves the current
  //   position only at G5.3.
  // * L is the order (degree + 1), default 3; LinuxCNC takes L only when L > 3.
  // * G5.3 needs at least `order` control points (the start point counts); it sets
  //   the position to the last control point and leaves no motion mode active.
  //   "Cannot use G5.3 without G5.2 first".
  // * The knots are not programmed: knot_vector_creator(n = points - 1, k = order)
  //   builds the uniform clamped vector 0 (k times), 1, 2, ..., n-k+1, n-k+2 (k
  //   times), of n + k + 1 = points + order knots.
  // * The curve lies in XY (NURBS_FEED emits X Y only; Z stays).
  // Departures, to refuse rather than guess: L is accepted only on the opening line
  // and only from 3 to 8 (LinuxCNC silently turns L1, L2 into 3); Z, another plane
  // than G17, and words other than X Y P inside the curve are refused (LinuxCNC
  // ignores Z); an unterminated G5.2 is refused (LinuxCNC would drop the points).

  void open_linuxcnc(const Word& g, const Seen& seen) {
    if (st_.plane != 17) fail(g, "G5.2 draws in the XY plane only (LinuxCNC): expected G17, not G" + std::to_string(st_.plane));
    require_nurbs_start(g);
    int order = 3;
    if (const Word* l = seen['L']) {
      if (!is_whole(l->value) || l->value < 3 || l->value > kMaxNurbsOrder)
        fail(*l, "order " + l->text + " out of range: expected a whole number from 3 to 8 (LinuxCNC uses 3 for any L below 4)");
      order = static_cast<int>(l->value);
    }
    for (const Word& w : lx_.words)
      if (axis_of(w.letter) >= 2) fail(w, std::string("G5.2 moves X and Y only (LinuxCNC): found '") + w.letter + "'");
    Curve& c = new_curve(Curve::Dialect::kLinuxCnc, g);
    c.g.order = order;
    const Word* p = seen['P'];
    const bool xy = seen['X'] || seen['Y'];
    double w0 = 1.0;
    if (p && !xy) {
      if (!(p->value > 0)) fail(*p, "weight " + p->text + ": expected a positive weight");
      w0 = p->value;
    }
    c.g.control_points.push_back({st_.position_mm[0], st_.position_mm[1], st_.position_mm[2]});
    c.g.weights.push_back(w0);
    c.point_at.push_back(at(g));
    c.weight_at.push_back(p && !xy ? at(*p) : at(g));
    if (xy) linuxcnc_point(seen);
  }

  void linuxcnc_point(const Seen& seen) {
    Curve& c = *curve_;
    const Word* x = seen['X'];
    const Word* y = seen['Y'];
    if (!x || !y) fail(x ? *x : *y, "a G5.2 control point needs both X and Y (LinuxCNC)");
    const Word* p = seen['P'];
    if (!p) fail(*x, "expected a weight P with every G5.2 control point (LinuxCNC requires one)");
    if (!(p->value > 0)) fail(*p, "weight " + p->text + ": expected a positive weight");
    if (static_cast<int>(c.g.control_points.size()) == kMaxNurbsControlPoints)
      fail(*x, "more than " + std::to_string(kMaxNurbsControlPoints) + " control points in one NURBS curve: split it");
    const auto coord = [&](const Word& w, int a) {
      const double v = w.value * st_.unit_mm;
      return st_.absolute ? v : st_.position_mm[a] + v;
    };
    c.g.control_points.push_back({coord(*x, 0), coord(*y, 1), st_.position_mm[2]});
    c.g.weights.push_back(p->value);
    c.point_at.push_back(at(x->column < y->column ? *x : *y));
    c.weight_at.push_back(at(*p));
  }

  void linuxcnc_line() {
    Curve& c = *curve_;
    const std::string opened = " the G5.2 curve opened at line " + std::to_string(c.opened.line);
    if (any_directive())
      throw ProgramError(at_column(lx_.comments.front().body_column), "process parameters cannot change inside" + opened);
    Seen seen;
    const Word* close = nullptr;
    for (const Word& w : lx_.words) {
      if (w.letter == 'G' || w.letter == 'M') {
        const auto code = code_tenths(w.value);
        if (w.letter == 'G' && code == kG5_3) {
          close = &w;
          continue;
        }
        if (w.letter == 'G' && code == kG5_2) continue;  // repeating G5.2 continues the curve, as in LinuxCNC
        fail(w, "expected G5.3 to close" + opened + " before '" + w.text + "'");
      }
      if (seen[w.letter]) fail(w, std::string("word '") + w.letter + "' appears twice in one block");
      seen.at(w.letter) = &w;
      switch (w.letter) {
        case 'N':
          if (w.value < 0 || !is_whole(w.value)) fail(w, "expected a non-negative whole line number after N");
          continue;
        case 'X': case 'Y': case 'P': continue;
        case 'L': fail(w, "the order L belongs on the G5.2 line that opens the curve");
        case 'Z': fail(w, "G5.2 moves X and Y only (LinuxCNC): found 'Z'");
        default: fail(w, std::string("'") + w.letter + "' inside" + opened + ": expected X Y P control points or G5.3");
      }
    }
    if (close) {
      for (const char letter : {'X', 'Y', 'P'})
        if (seen[letter]) fail(*seen[letter], "G5.3 takes no control point: put it on a line of its own");
      const int n = static_cast<int>(c.g.control_points.size());
      if (n < c.g.order)
        fail(*close, "a G5.2 curve of order L" + std::to_string(c.g.order) + " needs at least " +
                         std::to_string(c.g.order) + " control points (the start point counts), found " + std::to_string(n));
      // LinuxCNC's knot_vector_creator(n - 1, order).
      for (int i = 0; i < n + c.g.order; ++i)
        c.g.knots.push_back(i < c.g.order ? 0.0 : i < n ? static_cast<double>(i - c.g.order + 1)
                                                       : static_cast<double>(n - c.g.order + 1));
      finish_curve(at(*close));
      return;
    }
    if (seen['X'] || seen['Y']) {
      linuxcnc_point(seen);
    } else if (seen['P']) {
      fail(*seen['P'], "P without X and Y: only the first G5.2 line may weight the start point");
    }
  }

  // ---- process directive ----
  //
  // (PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67): any subset, any
  // case, in mm and µm whatever G20/G21 say; RMAX_UM=0 switches the roughness law off.

  static bool is_directive(const Comment& c, size_t* after) {
    size_t i = 0;
    const std::string& s = c.body;
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    if (upper(s.substr(i, 7)) != "PROCESS") return false;
    i += 7;
    if (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) return false;
    *after = i;
    return true;
  }

  bool any_directive() const {
    size_t after = 0;
    for (const Comment& c : lx_.comments)
      if (is_directive(c, &after)) return true;
    return false;
  }

  void apply_directive(const Comment& c) {
    size_t i = 0;
    if (!is_directive(c, &i)) return;
    const std::string& s = c.body;
    const auto col = [&](size_t k) { return at_column(c.body_column + static_cast<int>(k)); };
    const auto skip = [&] {
      while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    };
    skip();
    if (i >= s.size() || s[i] != ',') {
      // "(PROCESS the part)" is a remark; "(PROCESS BALL_RADIUS=5)" is a mistake.
      if (s.find('=') == std::string::npos) return;
      throw ProgramError(col(i), "expected ',' after PROCESS: (PROCESS, KEY=VALUE, ...)");
    }
    ++i;
    ProcessParams p = st_.process;
    std::string done;
    for (;;) {
      skip();
      const size_t key_at = i;
      while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) ++i;
      const std::string key = upper(s.substr(key_at, i - key_at));
      if (key.empty()) throw ProgramError(col(key_at), "expected KEY=VALUE in the PROCESS directive");
      const SourceLocation where = col(key_at);
      if (done.find("," + key + ",") != std::string::npos)
        throw ProgramError(where, key + " appears twice in the PROCESS directive");
      done += "," + key + ",";
      skip();
      if (i >= s.size() || s[i] != '=') throw ProgramError(where, "expected '=' and a value after " + key);
      ++i;
      skip();
      double v = 0;
      std::string clean;
      const size_t len = scan_number(s, i, &v, &clean);
      if (len == 0) {
        size_t e = i;
        while (e < s.size() && s[e] != ',') ++e;
        throw ProgramError(where, key + ": expected a number, found '" + s.substr(i, e - i) + "'");
      }
      if (!std::isfinite(v) || std::fabs(v) > kMaxMagnitude)
        throw ProgramError(where, key + ": number '" + clean + "' out of range: expected a magnitude of at most 1e6");
      i += len;
      if (key == "BALL_RADIUS") {
        if (!(v > 0)) throw ProgramError(where, "BALL_RADIUS " + clean + ": expected a positive radius in mm");
        p.ball_radius_mm = v;
      } else if (key == "FLUTES") {
        if (!is_whole(v) || v < 1 || v > 100) throw ProgramError(where, "FLUTES " + clean + ": expected a whole number from 1 to 100");
        p.flutes = static_cast<int>(v);
      } else if (key == "PICK_FEED") {
        if (!(v > 0)) throw ProgramError(where, "PICK_FEED " + clean + ": expected a positive pick feed in mm");
        p.pick_feed_mm = v;
      } else if (key == "RMAX_UM") {
        if (v < 0) throw ProgramError(where, "RMAX_UM " + clean + ": expected a target R_max >= 0 in um (0: law off)");
        p.target_rmax_um = v;
      } else {
        throw ProgramError(where, "unknown process parameter '" + key +
                                      "': expected BALL_RADIUS, FLUTES, PICK_FEED or RMAX_UM");
      }
      skip();
      if (i >= s.size()) break;
      if (s[i] != ',') throw ProgramError(col(i), "expected ',' or ')' after the value of " + key);
      ++i;
    }
    st_.process = p;
  }

  // ---- the end ----

  void end_block() {
    emit(new_block(BlockKind::kEnd));
    ended_ = true;
  }

  void end_of_input() {
    if (curve_ && curve_->dialect == Curve::Dialect::kLinuxCnc)
      throw ProgramError(curve_->opened, "the G5.2 curve is never closed: expected G5.3 before the end of the file");
    if (curve_) close_fanuc(curve_->opened);
    if (!stop_) end_block();
  }

  const ParserSettings& settings_;
  const std::string& file_;
  ParserState st_;
  BlockSink& sink_;
  std::array<int, 26> axis_of_{};
  LexedLine lx_;
  std::optional<Curve> curve_;
  bool stop_ = false;
  bool ended_ = false;
};

class Collect : public BlockSink {
 public:
  explicit Collect(Program* p) : p_(p) {}
  bool block(Block&& b) override {
    p_->blocks.push_back(std::move(b));
    return true;
  }

 private:
  Program* p_;
};

}  // namespace

GcodeParser::GcodeParser(ParserSettings settings) : settings_(std::move(settings)) {
  if (settings_.start_position_mm.size() != settings_.axis_names.size())
    settings_.start_position_mm.assign(settings_.axis_names.size(), 0.0);
}

ParserState GcodeParser::initial_state() const {
  ParserState s;
  s.position_mm = settings_.start_position_mm;
  s.feed_mm_per_min = settings_.default_feed_mm_per_min;
  s.spindle_speed_rpm = settings_.spindle_rpm;
  s.process = settings_.process;
  return s;
}

void GcodeParser::stream(std::istream& in, const std::string& file, const ParserState& from, BlockSink& sink) const {
  Engine(settings_, file, from, sink).run(in);
}

Program GcodeParser::parse(std::istream& in, const std::string& file) const {
  Program prog;
  prog.file = file;
  Collect sink(&prog);
  stream(in, file, initial_state(), sink);
  return prog;
}

Program GcodeParser::parse_file(const std::string& path) const {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ProgramError(SourceLocation{path, 0, 0}, "cannot open the program file");
  return parse(in, path);
}

}  // namespace cnc::program
