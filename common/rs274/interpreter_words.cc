// A block's words: evaluated into their slots with the modal-group rules, checked
// against the G and M codes that use them, and the line's comments.
#include "common/rs274/interpreter_impl.h"
#include "common/rs274/process_directive.h"

namespace cnc::rs274 {

using namespace interp;

namespace {

// G-code modal groups (LinuxCNC's numbering), by G code in tenths.
int g_group(int g) {
  switch (g) {
    case 40: case 100: case 280: case 281: case 300: case 301: case 520: case 530: case 920: case 921: case 922: case 923:
    case 531:
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
    case 682: case 690: return 16;  // Fanuc's group 16: the tilted work plane
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

}  // namespace

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
    if (c == 'H' || c == 'L') {
      // LinuxCNC reads H and L as integers (read_integer_value): a value within 1e-4
      // of one is that integer, any other is refused, whatever code uses the word.
      double n = std::floor(v);
      if (v - n > 0.9999)
        n = std::ceil(v);
      else if (v - n > 0.0001)
        fail(word.column, "Non integer value for integer");
      v = n;
      if (c == 'H' && v < -1) fail(word.column, "Negative h word used");
      if (c == 'L' && v < 0) fail(word.column, "Negative l word used");
    }
    const int ax = axis_of_letter(c);
    if (ax >= 0 && setup_.axes.find(c) == std::string::npos) {
      // I J K R are not axes; axis letters the machine lacks are refused.
      fail(word.column, std::string(1, c) + " word, but the machine has no " + c + " axis (axes: " + setup_.axes + ")");
    }
    if (ax >= 0) w.axes |= 1u << ax;
    if (c == 'X' && lathe_diameter_) v /= 2;  // LinuxCNC's read_x in G7: the radius
    if (c == '@' || c == '^') w.axes |= 3u;  // polar coordinates set X and Y
    w.has |= bit(c);
    w.v[i] = v;
    w.col[i] = word.column;
  }
}

// LinuxCNC's motion_to_be: the block's motion code, or the modal one when the block
// has axis words that no G10/G28/G30/G52/G92 takes.
int Interpreter::motion_to_be(const Words& w) const {
  const int g0 = w.g[0];
  // G68.2's X Y Z are its frame's origin.
  const bool g0_takes_axes = g0 == 100 || g0 == 280 || g0 == 300 || g0 == 520 || g0 == 920 || w.g[16] == 682;
  return w.g[1] >= 0 ? w.g[1] : (w.axes != 0 && !g0_takes_axes ? motion_ : -1);
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
  // LinuxCNC's enhance_block: these motion codes move only with an axis word.
  if ((w.g[1] == 330 || w.g[1] == 331 || w.g[1] == 760) && w.axes == 0)
    fail(w.gcol[1], "All axes missing with motion code");
  // The motion this block makes (LinuxCNC's motion_to_be): its G code, or the modal
  // one when it has axis words that no G10/G28/G30/G52/G92 takes.
  const int to_be = motion_to_be(w);
  const bool g76 = to_be == 760;
  const bool synced_to_be = to_be == 330 || to_be == 331 || g76;
  const bool g682 = w.g[16] == 682;
  if (uses_axes && (motion == 800 || motion < 0) && g0 != 100 && g0 != 280 && g0 != 300 && g0 != 520 &&
      g0 != 920 && g0 != 530 && !g682)
    fail(w.column(kAxisLetters[std::countr_zero(w.axes)]), "axis words without a G code that uses them (motion mode is G80)");
  if (g0 == 530 && !(motion == 0 || motion == 10) ) fail(w.gcol[0], "G53 is only allowed with G0 or G1");
  // The distance mode the block leaves (LinuxCNC's check_g_codes: G90 on the line allows it).
  if (g0 == 530 && (w.g[3] == 910 || (w.g[3] != 900 && incremental_)))
    fail(w.gcol[0], "G53 with G91 (incremental) is not allowed");
  if (g682 && uses_axes && (w.g[1] >= 0 || (g0 >= 0 && g0 != 531)))
    fail(w.gcol[16], "G68.2's X Y Z are its origin: no motion or other code that uses axis words on its line");
  if (w.g[0] >= 0 && w.g[1] >= 0 && uses_axes && g0 != 530) {
    if (g0 == 100 || g0 == 280 || g0 == 300 || g0 == 520 || g0 == 920)
      fail(w.gcol[1], g_text(g0) + " and " + g_text(w.g[1]) + " both use axis words: only one per line");
  }
  const auto not_with = [&](char c, const char* what) {
    if (w.on(c)) fail(w.column(c), std::string(1, c) + " word " + what);
  };
  const bool arc = motion == 20 || motion == 30;
  const bool cyc = motion >= 730 && motion != 800 && motion != 760 && motion <= 890;
  const bool nurbs_g = motion == 52 || motion == 62 || motion == 50 || motion == 51;
  const bool m19 = w.m[7] == 19;
  if (!arc && !cyc && !nurbs_g && g0 != 100 && !g682) {
    if (w.on('R') && !m19 && !g76) not_with('R', "with no G code that uses it (G2/G3, a canned cycle, G10, G76, M19)");
    if (w.on('I') && motion != 331 && !g76) not_with('I', "with no G code that uses it (G2/G3, G5, G33.1, G76, G87)");
    if (w.on('J') && !g76) not_with('J', "with no G code that uses it (G2/G3, G5, G76, G87)");
  }
  if (w.on('R') && m19 && (w['R'] > 360.0 || w['R'] < 0.0)) fail(w.column('R'), "R value must be within 0..360 with M19");
  // LinuxCNC's check_other_codes: no rotary axis word with a canned cycle (also a modal one).
  if (cyc)
    for (const char c : {'A', 'B', 'C'})
      if (w.on(c))
        fail(w.column(c), c == 'A' ? std::string("Cannot put an a in canned cycle")
                                   : std::string("Cannot put a ") + static_cast<char>(c - 'A' + 'a') + " in canned cycle");
  const bool synced = motion == 330 || motion == 331 || motion == 760;
  if (w.on('K') && fanuc_closed_line_ > 0 && fanuc_closed_line_ == line_no_ - 1 && w.g[1] < 0)
    fail(w.column('K'),
         "a knot after the G6.2 curve's knots were complete (control points + order) at line " +
             std::to_string(fanuc_closed_line_));
  if (!arc && !cyc && g0 != 100 && !nurbs_g && !synced && !g682 && w.on('K')) not_with('K', "with no G code that uses it (G2/G3, G33, G76, G73/G83 ...)");
  if (w.on('P') && !(g0 == 40 || g0 == 100 || g0 == 531 || g682 || arc || cyc || nurbs_g || w.g[13] == 640 || w.g[7] == 410 ||
                     w.g[7] == 420 || w.m[5] >= 0 || w.g[8] == 432 || m19 || g76 || w.m[9] >= 50))
    not_with('P', "with no G code or M code that uses it");
  if (w.on('Q') && !(cyc || nurbs_g || g682 || w.g[13] == 640 || w.m[5] >= 0 || w.m[6] == 61 || g0 == 100 || m19 || g76))
    not_with('Q', "with no G code or M code that uses it");
  if (w.on('L') && !(g0 == 100 || cyc || nurbs_g || w.m[5] == 66 || g76))
    not_with('L', "with no G code or M code that uses it (G10, canned cycles, G76, M66)");
  // G76's H is its spring passes, not a tool number.
  if (w.on('H') && !(w.g[8] == 430 || w.g[8] == 432 || g0 == 100 || g76)) not_with('H', "with no G43 or G76 that uses it");
  if (w.on('D') && !(w.g[7] == 410 || w.g[7] == 420 || w.g[7] == 411 || w.g[7] == 421))
    not_with('D', "with no G41/G42 that uses it");
  if (w.on('E') && w.m[5] < 0 && !synced_to_be) not_with('E', "with no G76 or M code that uses it (M66, M67, M68)");
  // LinuxCNC's spindle selection; this machine has one spindle, $0 (and $-1, all of
  // them, where LinuxCNC takes it), checked where each code runs.
  if (w.on('$') && !(synced_to_be || (w.m[7] >= 3 && w.m[7] <= 5) || m19 || w.m[9] == 51 || w.on('S')))
    fail(w.column('$'), "$ (spindle selection) word with no M3, M4, M5, M19, M51, G33, G33.1, G76, G95, G96 or G97 to use it");
  if (g76) {
    // LinuxCNC's check_other_codes: P-1 is its mark of an absent P.
    const int col = w.g[1] >= 0 ? w.gcol[1] : w.column(kAxisLetters[std::countr_zero(w.axes)]);
    if (!w.on('P') || w['P'] == -1) fail(col, "P word missing with G76");
    if (!w.on('I') || !w.on('J') || !w.on('K')) fail(col, "I J or K words missing with G76");
  }
  if (w.on('F') && w.v[static_cast<size_t>(letter_index('F'))] < 0) fail(w.column('F'), "negative feed rate");
  if (w.on('S') && w.v[static_cast<size_t>(letter_index('S'))] < 0) fail(w.column('S'), "negative spindle speed");
  if (w.on('T') && w.v[static_cast<size_t>(letter_index('T'))] < 0) fail(w.column('T'), "negative tool number");
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
      case CommentKind::kDebug:
      case CommentKind::kLog: {
        std::string out;
        try {
          out = expand_parameters(c.text, c.column + 1, *reader_);
        } catch (const Error& e) {
          fail(e.column(), e.detail());
        }
        if (c.kind == CommentKind::kDebug) canon_.message(r, out);
        else if (c.kind == CommentKind::kLog) canon_.log_line(r, out);
        else std::fprintf(stderr, "%s\n", out.c_str());
        break;
      }
      case CommentKind::kLogOpen: canon_.log_open(r, c.text, false); break;
      case CommentKind::kLogAppend: canon_.log_open(r, c.text, true); break;
      case CommentKind::kLogClose: canon_.log_close(r); break;
      case CommentKind::kAbort:
        fail(c.column, "program aborted: " + c.text);
    }
  }
}

}  // namespace cnc::rs274
