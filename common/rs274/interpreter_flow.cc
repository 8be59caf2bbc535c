// O-word control flow (sub, call, return, do/while, repeat, if) and subprograms:
// O-word subroutines and Fanuc-style M98/M99, and where their definitions are found.
#include <algorithm>
#include <filesystem>

#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

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
  switch (o.kind) {
    case OKind::kSub: o_sub(o, name); return;
    case OKind::kEndsub:
    case OKind::kReturn: o_return(o, name); return;
    case OKind::kProgram: o_program(o, name); return;
    case OKind::kCall: o_call(o, name); return;
    case OKind::kDo:
    case OKind::kWhile:
    case OKind::kEndwhile:
    case OKind::kRepeat:
    case OKind::kEndrepeat: o_loop(o, name); return;
    case OKind::kIf:
    case OKind::kElseif:
    case OKind::kElse:
    case OKind::kEndif: o_if(o, name); return;
    case OKind::kBreak:
    case OKind::kContinue: o_break_continue(o, name); return;
    case OKind::kNone: return;
  }
}

// The condition in [ ] after a while, if, elseif or repeat keyword.
double Interpreter::o_condition(const OStatement& o) {
  if (o.args.empty()) fail(o.keyword_column, "expected a condition in [ ] after the keyword");
  return evaluate(line_.arena, o.args.front(), *reader_);
}

// o<name> sub read in the program's flow: remembered, its body skipped.
void Interpreter::o_sub(const OStatement& o, const std::string& name) {
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  if (nurbs_) fail(o.column, "a subroutine definition inside a NURBS curve");
  if (!frames_.empty()) fail(o.column, "o<" + name + "> sub: a subroutine may not be defined inside another");
  subs_[name] = SubDef{file_, f.offset(), line_no_, f.line_start, false};
  skip_to(name, kbit(OKind::kEndsub));
}

// o<name> endsub / return: back to the caller.
void Interpreter::o_return(const OStatement& o, const std::string& name) {
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
}

// A bare O-word. In the main program's flow it is the program's number or name
// (LinuxCNC: nothing to do); running into one inside a Fanuc subprogram goes on
// into it (LinuxCNC 2.9 does); an O-word subroutine may not run into one.
void Interpreter::o_program(const OStatement& o, const std::string& name) {
  if (!setup_.fanuc_subs)
    fail(o.column, "bare O-word O" + name + ": Fanuc-style subprograms are disabled (DISABLE_FANUC_STYLE_SUB)");
  if (!frames_.empty() && !frames_.back().fanuc)
    fail(o.column, "Fanuc subprogram head O" + name + " inside o<" + frames_.back().sub +
                       "> sub (a Fanuc subprogram is called with M98, an O-word subroutine ends with endsub)");
}

// o<name> call [args]: into the subroutine, found on first use.
void Interpreter::o_call(const OStatement& o, const std::string& name) {
  if (static_cast<int64_t>(frames_.size()) >= setup_.max_call_depth)
    fail(o.column, "o<" + name + "> call: calls nested deeper than " + std::to_string(setup_.max_call_depth));
  std::array<double, 30> args{};
  if (o.args.size() > 30) fail(o.column, "more than 30 arguments to o<" + name + ">");
  for (size_t i = 0; i < o.args.size(); ++i) args[i] = evaluate(line_.arena, o.args[i], *reader_);
  const SubDef def = find_sub(name, o.column, false);
  Frame fr = call_frame(name, o.column);
  params_.push_call();
  for (size_t i = 0; i < 30; ++i)
    if (i < o.args.size()) params_.set(static_cast<int>(i) + 1, args[i]);
  enter_sub(std::move(fr), def);
}

// The frame of a call of `name` from the line being executed.
Interpreter::Frame Interpreter::call_frame(const std::string& name, int column) const {
  Frame fr;
  fr.sub = name;
  fr.return_file = file_;
  fr.return_offset = files_[static_cast<size_t>(file_)]->offset();
  fr.return_line = line_no_;
  fr.call_column = column;
  fr.loops = loops_.size();
  return fr;
}

// Into the subroutine `def` with its frame pushed; an O-word sub called by M98, or a
// Fanuc subprogram by o<> call, is refused at its definition.
void Interpreter::enter_sub(Frame fr, const SubDef& def) {
  const std::string name = fr.sub;
  const bool m98 = fr.fanuc;
  frames_.push_back(std::move(fr));
  if (def.fanuc && !m98)
    fail_at_def(def, "Fanuc subprogram O" + name + " is called with M98 P" + name + ", not o<" + name + "> call");
  if (!def.fanuc && m98)
    fail_at_def(def, "o<" + name + "> sub is called with o<" + name + "> call, not M98 P" + name +
                         " (M98 calls Fanuc subprograms headed by a bare O" + name + ")");
  file_ = def.file;
  files_[static_cast<size_t>(file_)]->seek(def.offset);
  line_no_ = def.line;
}

// do, while (a loop's head or a do's end), endwhile, repeat, endrepeat.
void Interpreter::o_loop(const OStatement& o, const std::string& name) {
  SourceFile& f = *files_[static_cast<size_t>(file_)];
  switch (o.kind) {
    case OKind::kDo: {
      loops_.push_back(Loop{OKind::kDo, name, file_, f.offset(), line_no_, 0, false});
      return;
    }
    case OKind::kWhile: {
      // Either the end of a do-while, or the head of a while loop.
      if (!loops_.empty() && loops_.back().kind == OKind::kDo && loops_.back().name == name) {
        if (o_condition(o) != 0) {
          f.seek(loops_.back().offset);
          line_no_ = loops_.back().line;
        } else {
          loops_.pop_back();
        }
        return;
      }
      if (o_condition(o) != 0) {
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
      const double n = o_condition(o);
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
    default: return;
  }
}

// if, elseif, else, endif.
void Interpreter::o_if(const OStatement& o, const std::string& name) {
  switch (o.kind) {
    case OKind::kIf: {
      if (o_condition(o) != 0) {
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
    default: return;
  }
}

// break / continue: the innermost loop of this name.
void Interpreter::o_break_continue(const OStatement& o, const std::string& name) {
  SourceFile& f = *files_[static_cast<size_t>(file_)];
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
  if (fr.remap_rest) {
    // The remapped M6 returned: a negative value aborts it (LinuxCNC's change_epilog),
    // else its block goes on after the M6 step.
    if (has_value && value < 0)
      fail(fr.call_column, "M6 aborted (o<" + fr.sub + "> returned " + std::to_string(value) + ")");
    execute_block_after_m6(*fr.remap_rest);
  }
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

// Where subroutine `name` starts (LinuxCNC 2.9's control_back_to), for an o<name>
// call (m98 false) or M98 P<name> (m98 true): one met before, else a file <name>.ngc
// on the subroutine path or in the program's folder (LinuxCNC looks for the file
// first), else further down the file being read, from the call on, up to its end or
// its closing '%' (definitions before the call that the flow did not pass are not
// seen, as in LinuxCNC). The first head of that name found counts, `o<name> sub` or
// a bare `O<name>` (the caller refuses the other style's). Fails when there is none.
Interpreter::SubDef Interpreter::find_sub(const std::string& name, int column, bool m98) {
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
    fail(column, m98 ? "M98 P" + name + ": " + p + " does not hold subprogram O" + name
                     : p + " does not define o<" + name + "> sub");
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
    if (!is_head(probe)) continue;
    const SubDef d{file_, f.offset(), ln, f.line_start, probe.o.kind == OKind::kProgram};
    f.seek(here);
    subs_[name] = d;
    return d;
  }
  f.seek(here);
  const std::string far = beyond_sub_dirs(name + ".ngc");
  const std::string& file = file_names_[static_cast<size_t>(file_)];
  if (m98)
    fail(column, "M98 P" + name + ": no subprogram O" + name + " further down " + file +
                     " (before its end) nor a file " + name + ".ngc on the subroutine path" +
                     (far.empty() ? "" : "; " + far));
  fail(column, "o<" + name + "> call: no file " + name + ".ngc on the subroutine path nor o<" + name +
                   "> sub further down " + file +
                   " (a definition before the call counts only once the program has run through it)" +
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
  const SubDef def = find_sub(name, mw.column, true);
  Frame fr = call_frame(name, mw.column);
  fr.fanuc = true;
  fr.again = again;
  fr.call_start = call_start;
  params_.push_call(false);
  enter_sub(std::move(fr), def);
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

}  // namespace cnc::rs274
