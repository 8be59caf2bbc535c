#include "common/program/gcode_parser.h"

#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>

namespace cnc::program {

const char* to_string(BlockKind kind) {
  switch (kind) {
    case BlockKind::kRapid: return "rapid";
    case BlockKind::kLine: return "line";
    case BlockKind::kArcCw: return "arc_cw";
    case BlockKind::kArcCcw: return "arc_ccw";
    case BlockKind::kNurbs: return "nurbs";
    case BlockKind::kDwell: return "dwell";
    case BlockKind::kEnd: return "end";
  }
  return "?";
}

ProgramError::ProgramError(SourceLocation where, const std::string& what)
    : std::runtime_error(where.str() + ": " + what), where_(std::move(where)), detail_(what) {}

namespace {

constexpr double kMaxMagnitude = 1e6;  // mm, mm/min, rpm, s: anything larger is a typo or an attack

struct Word {
  char letter;
  double value;
  std::string text;  // as written, for messages
  int column;
};

// Lexes one line into words; comments in ( ) and after ; are dropped.
std::vector<Word> lex_line(const std::string& line, const std::string& file, int line_no) {
  std::vector<Word> words;
  size_t i = 0;
  const size_t n = line.size();
  auto where = [&](size_t col) { return SourceLocation{file, line_no, static_cast<int>(col) + 1}; };
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
      i = close + 1;
      continue;
    }
    if (c == '%' && words.empty()) {
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
    const size_t num_start = i;
    if (i < n && (line[i] == '+' || line[i] == '-')) ++i;
    size_t digits = 0;
    while (i < n && std::isdigit(static_cast<unsigned char>(line[i]))) ++i, ++digits;
    if (i < n && line[i] == '.') {
      ++i;
      while (i < n && std::isdigit(static_cast<unsigned char>(line[i]))) ++i, ++digits;
    }
    if (digits == 0) {
      throw ProgramError(where(num_start), std::string("expected a number after '") + letter + "'");
    }
    std::string text = line.substr(num_start, i - num_start);
    std::string clean;
    for (char d : text)
      if (d != ' ') clean += d;
    const double value = std::strtod(clean.c_str(), nullptr);
    if (!std::isfinite(value) || std::fabs(value) > kMaxMagnitude) {
      throw ProgramError(where(num_start), "number '" + clean + "' out of range: expected a magnitude of at most 1e6");
    }
    words.push_back(Word{letter, value, std::string(1, letter) + clean, static_cast<int>(letter_col) + 1});
  }
  return words;
}

// G and M numbers are written with at most one decimal (G5.2): compare them in tenths.
std::optional<int> code_tenths(double v) {
  const double t = v * 10.0;
  if (std::fabs(t - std::round(t)) > 1e-6 || v < 0) return std::nullopt;
  return static_cast<int>(std::lround(t));
}

}  // namespace

GcodeParser::GcodeParser(ParserSettings settings) : settings_(std::move(settings)) {
  if (settings_.start_position_mm.size() != settings_.axis_names.size())
    settings_.start_position_mm.assign(settings_.axis_names.size(), 0.0);
}

Program GcodeParser::parse_file(const std::string& path) const {
  std::ifstream in(path);
  if (!in) throw ProgramError(SourceLocation{path, 0, 0}, "cannot open the program file");
  return parse(in, path);
}

Program GcodeParser::parse(std::istream& in, const std::string& file) const {
  Program prog;
  prog.file = file;
  const size_t naxes = settings_.axis_names.size();
  std::vector<double> pos = settings_.start_position_mm;

  // Modal state.
  std::optional<int> motion;  // 0 or 10 (tenths: G0, G1)
  double unit_mm = 1.0;
  bool absolute = true;
  double feed = settings_.default_feed_mm_per_min;
  double spindle_speed = settings_.spindle_rpm;
  bool spindle_on = false;
  ProcessParams process = settings_.process;

  std::string line;
  int line_no = 0;
  bool ended = false;
  while (!ended && std::getline(in, line)) {
    ++line_no;
    const auto words = lex_line(line, file, line_no);
    if (words.empty()) continue;
    auto at = [&](const Word& w) { return SourceLocation{file, line_no, w.column}; };

    std::map<char, const Word*> seen;
    std::optional<int> motion_word;
    const Word* motion_src = nullptr;
    bool dwell = false;
    const Word* dwell_src = nullptr;
    std::vector<std::optional<double>> target(naxes);
    bool any_axis = false;
    std::optional<int> m_end;

    // G20/G21 hold for the whole block, whatever the order of its words (RS274):
    // set them before any F or axis word of the block is scaled.
    for (const Word& w : words) {
      if (w.letter != 'G') continue;
      const auto code = code_tenths(w.value);
      if (code == 200) unit_mm = 25.4;
      if (code == 210) unit_mm = 1.0;
    }

    for (const Word& w : words) {
      if (w.letter != 'G' && w.letter != 'M') {
        if (seen.count(w.letter)) throw ProgramError(at(w), std::string("word '") + w.letter + "' appears twice in one block");
        seen[w.letter] = &w;
      }
      switch (w.letter) {
        case 'N':
          if (w.value < 0 || w.value != std::floor(w.value)) throw ProgramError(at(w), "expected a non-negative whole line number after N");
          continue;
        case 'F':
          if (w.value <= 0) throw ProgramError(at(w), "expected a positive feed rate after F");
          feed = w.value * unit_mm;
          continue;
        case 'S':
          if (w.value < 0) throw ProgramError(at(w), "expected a non-negative spindle speed after S");
          spindle_speed = w.value;
          continue;
        case 'P':
          if (w.value < 0) throw ProgramError(at(w), "expected a non-negative dwell time after P");
          continue;
        case 'G': {
          const auto code = code_tenths(w.value);
          if (!code) throw ProgramError(at(w), "malformed G code '" + w.text + "'");
          switch (*code) {
            case 0:
            case 10:
              if (motion_word) throw ProgramError(at(w), "two motion codes in one block");
              motion_word = *code;
              motion_src = &w;
              break;
            case 40:
              dwell = true;
              dwell_src = &w;
              break;
            case 170: case 180: case 190: break;  // plane: only matters for arcs
            case 200: case 210: break;  // units: set before this loop
            case 900: absolute = true; break;
            case 910: absolute = false; break;
            default:
              throw ProgramError(at(w), "unsupported G code '" + w.text +
                                            "': expected one of G0 G1 G4 G17 G18 G19 G20 G21 G90 G91");
          }
          continue;
        }
        case 'M': {
          const auto code = code_tenths(w.value);
          if (!code) throw ProgramError(at(w), "malformed M code '" + w.text + "'");
          switch (*code) {
            case 30: spindle_on = true; break;   // M3
            case 50: spindle_on = false; break;  // M5
            case 20: case 300: m_end = *code; break;  // M2, M30
            default:
              throw ProgramError(at(w), "unsupported M code '" + w.text + "': expected one of M2 M3 M5 M30");
          }
          continue;
        }
        default: break;
      }
      // Axis words, by the machine's axis names.
      bool is_axis = false;
      for (size_t a = 0; a < naxes; ++a) {
        if (settings_.axis_names[a].size() == 1 && settings_.axis_names[a][0] == w.letter) {
          target[a] = w.value * unit_mm;
          any_axis = true;
          is_axis = true;
        }
      }
      if (!is_axis) {
        std::string expected = "N G M F S P";
        for (const auto& nm : settings_.axis_names) expected += " " + nm;
        throw ProgramError(at(w), std::string("unknown word '") + w.letter + "': expected one of " + expected);
      }
    }

    // G4 P: dwell.
    if (dwell) {
      if (!seen.count('P')) throw ProgramError(at(*dwell_src), "G4 needs a dwell time: expected a P word");
      if (any_axis) throw ProgramError(at(*dwell_src), "G4 cannot be combined with axis words");
      Block b;
      b.index = static_cast<int64_t>(prog.blocks.size());
      b.source_line = line_no;
      b.kind = BlockKind::kDwell;
      b.start = pos;
      b.end = pos;
      b.dwell_s = seen['P']->value;
      b.spindle_rpm = spindle_on ? spindle_speed : 0.0;
      b.process = process;
      prog.blocks.push_back(std::move(b));
    } else if (seen.count('P')) {
      throw ProgramError(at(*seen['P']), "P word without G4");
    }

    if (motion_word) motion = motion_word;
    if (any_axis) {
      if (!motion) throw ProgramError(at(words.front()), "axis words without a motion mode: expected G0 or G1 first");
      std::vector<double> end = pos;
      for (size_t a = 0; a < naxes; ++a)
        if (target[a]) end[a] = absolute ? *target[a] : pos[a] + *target[a];
      Block b;
      b.index = static_cast<int64_t>(prog.blocks.size());
      b.source_line = line_no;
      b.kind = *motion == 0 ? BlockKind::kRapid : BlockKind::kLine;
      if (b.kind == BlockKind::kLine && feed <= 0) {
        const Word& w = motion_src ? *motion_src : words.front();
        throw ProgramError(at(w), "feed rate not set: expected an F word before or in this G1 block");
      }
      b.start = pos;
      b.end = end;
      b.feed_mm_per_min = feed;
      b.spindle_rpm = spindle_on ? spindle_speed : 0.0;
      b.process = process;
      prog.blocks.push_back(std::move(b));
      pos = end;
    }
    if (m_end) ended = true;
  }
  Block end;
  end.index = static_cast<int64_t>(prog.blocks.size());
  end.source_line = line_no;
  end.kind = BlockKind::kEnd;
  end.start = pos;
  end.end = pos;
  prog.blocks.push_back(std::move(end));
  return prog;
}

}  // namespace cnc::program
