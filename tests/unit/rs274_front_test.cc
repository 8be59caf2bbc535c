// The RS274NGC front end: lexing with columns, expression values and precedence
// as LinuxCNC 2.9 computes them, every refusal with its column, parameters with
// call scoping, and the var file.
//
// Values marked "rs274:" were read from LinuxCNC's own interpreter
// (linuxcnc-uspace 2.9.0~pre1, `rs274 -g`), e.g. "G1 X[1+2*3**2] F1" printed
// STRAIGHT_FEED(19.0000, ...).
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <new>
#include <sstream>
#include <string>

#include "common/rs274/lexer.h"
#include "common/rs274/parameters.h"

// Counts heap allocations while `g_counting` is set, to prove a reused Line
// lexes without allocating.
namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace

// GCC pairs the inlined library new with this free() and warns; both are malloc's.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace cnc::rs274 {
namespace {

constexpr double kTol = 1e-12;

// Evaluation reads the parameter table the way the interpreter will.
class TableReader : public ParamReader {
 public:
  explicit TableReader(Parameters& p) : p_(p) {}
  double numbered(double index, int column) const override { return p_.get(Parameters::index_of(index, column), column); }
  double named(const std::string& name, int column) const override { return p_.get_named(name, column); }
  bool exists(const std::string& name) const override { return p_.find_named(name, nullptr); }

 private:
  Parameters& p_;
};

Line lex(const std::string& text) {
  Line l;
  lex_line(text, l);
  return l;
}

// The value of the first word on `text`, e.g. value("X[1+2]").
double value(const std::string& text, Parameters& p) {
  const Line l = lex(text);
  EXPECT_EQ(l.words.size(), 1u) << text;
  if (l.words.empty()) return NAN;
  return evaluate(l.arena, l.words[0].expr, TableReader(p));
}
double value(const std::string& text) {
  Parameters p;
  return value(text, p);
}

// The lexer refuses `text` at `column` with a message containing `fragment`.
void expect_lex_error(const std::string& text, int column, const std::string& fragment) {
  try {
    lex(text);
    ADD_FAILURE() << "no error for: " << text;
  } catch (const Error& e) {
    EXPECT_EQ(e.column(), column) << text << " -> " << e.what();
    EXPECT_NE(e.detail().find(fragment), std::string::npos) << text << " -> " << e.detail();
  }
}

// Lexing succeeds and evaluation refuses at `column`.
void expect_eval_error(const std::string& text, int column, const std::string& fragment, Parameters* params = nullptr) {
  Parameters local;
  Parameters& p = params ? *params : local;
  const Line l = lex(text);
  ASSERT_FALSE(l.words.empty()) << text;
  try {
    const double v = evaluate(l.arena, l.words[0].expr, TableReader(p));
    ADD_FAILURE() << "no error for: " << text << " (gave " << v << ")";
  } catch (const Error& e) {
    EXPECT_EQ(e.column(), column) << text << " -> " << e.what();
    EXPECT_NE(e.detail().find(fragment), std::string::npos) << text << " -> " << e.detail();
  }
}

// ---- lexing ------------------------------------------------------------------------

TEST(Rs274Lex, WordsKeepLetterColumnAndValue) {
  const Line l = lex("G1 X10.5 y-2 F100");
  ASSERT_EQ(l.words.size(), 4u);
  const char letters[] = {'G', 'X', 'Y', 'F'};
  const int columns[] = {1, 4, 10, 14};
  const double values[] = {1, 10.5, -2, 100};
  Parameters p;
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(l.words[i].letter, letters[i]);
    EXPECT_EQ(l.words[i].column, columns[i]);
    EXPECT_NEAR(evaluate(l.arena, l.words[i].expr, TableReader(p)), values[i], kTol);
  }
  EXPECT_FALSE(l.block_delete);
  EXPECT_FALSE(l.has_line_number);
  EXPECT_EQ(l.o.kind, OKind::kNone);
}

TEST(Rs274Lex, EveryWordLetterIsAccepted) {
  const Line l = lex("A1 B2 C3 D4 F5 G6 H7 I8 J9 K10 L11 M12 P13 Q14 R15 S16 T17 U18 V19 W20 X21 Y22 Z23");
  ASSERT_EQ(l.words.size(), 23u);
  EXPECT_EQ(std::string(1, l.words[4].letter), "F");
  EXPECT_EQ(std::string(1, l.words[22].letter), "Z");
  EXPECT_EQ(l.words[22].column, 80);
}

// LinuxCNC removes blanks before reading: "X1 2" is X12 (rs274: X[1 2] gave 12).
TEST(Rs274Lex, BlanksAndCaseAreIgnoredOutsideComments) {
  const Line l = lex("g 0 1\tx 1 2 . 5");
  ASSERT_EQ(l.words.size(), 2u);
  EXPECT_EQ(l.words[0].letter, 'G');
  EXPECT_EQ(l.words[1].letter, 'X');
  EXPECT_EQ(l.words[1].column, 7);
  Parameters p;
  EXPECT_NEAR(evaluate(l.arena, l.words[0].expr, TableReader(p)), 1.0, kTol);
  EXPECT_NEAR(evaluate(l.arena, l.words[1].expr, TableReader(p)), 12.5, kTol);
  EXPECT_NEAR(value("X[1 2]"), 12.0, kTol);
  EXPECT_NEAR(value("X[1 a n d 1]"), 1.0, kTol);  // rs274: 1
}

TEST(Rs274Lex, NumbersInLinuxCncSyntax) {
  EXPECT_NEAR(value("X.5"), 0.5, kTol);
  EXPECT_NEAR(value("X5."), 5.0, kTol);
  EXPECT_NEAR(value("X+3"), 3.0, kTol);
  EXPECT_NEAR(value("X-0.25"), -0.25, kTol);
  EXPECT_NEAR(value("X007"), 7.0, kTol);
}

TEST(Rs274Lex, BlockDeleteAndLineNumber) {
  Line l = lex("/N0010 G0 X1");
  EXPECT_TRUE(l.block_delete);
  EXPECT_TRUE(l.has_line_number);
  EXPECT_EQ(l.line_number, 10);
  ASSERT_EQ(l.words.size(), 2u);
  EXPECT_EQ(l.words[0].column, 8);
  l = lex("N10.5 G1");  // LinuxCNC accepts and ignores the fraction
  EXPECT_EQ(l.line_number, 10);
  ASSERT_EQ(l.words.size(), 1u);
  l = lex("  / n 2 3 m2");
  EXPECT_TRUE(l.block_delete);
  EXPECT_EQ(l.line_number, 23);
}

TEST(Rs274Lex, PercentLine) {
  EXPECT_TRUE(lex("%").percent);
  EXPECT_TRUE(lex("  %\t").percent);
  EXPECT_FALSE(lex("G0").percent);
  expect_lex_error("% foo", 1, "unexpected '%'");    // rs274: Bad character '%' used
  expect_lex_error("G1 X1 %", 7, "unexpected '%'");
}

TEST(Rs274Lex, EmptyAndCommentOnlyLines) {
  Line l = lex("");
  EXPECT_TRUE(l.words.empty());
  EXPECT_TRUE(l.comments.empty());
  l = lex("   ");
  EXPECT_TRUE(l.words.empty());
  l = lex("; all of this ( is ignored");
  ASSERT_EQ(l.comments.size(), 1u);
  EXPECT_EQ(l.comments[0].text, " all of this ( is ignored");
  EXPECT_EQ(l.comments[0].column, 1);
  EXPECT_EQ(l.comments[0].text_column, 2);
}

TEST(Rs274Lex, CommentsAmongWordsKeepTextAndColumns) {
  const Line l = lex("G0 (first) X1 (  MSG,Hello World ) ;tail");
  ASSERT_EQ(l.words.size(), 2u);
  EXPECT_EQ(l.words[1].column, 12);
  ASSERT_EQ(l.comments.size(), 3u);
  EXPECT_EQ(l.comments[0].kind, CommentKind::kPlain);
  EXPECT_EQ(l.comments[0].text, "first");
  EXPECT_EQ(l.comments[0].column, 4);
  EXPECT_EQ(l.comments[0].text_column, 5);
  EXPECT_EQ(l.comments[1].kind, CommentKind::kMsg);
  EXPECT_EQ(l.comments[1].text, "Hello World ");  // rs274: MESSAGE("Hello World ")
  EXPECT_EQ(l.comments[1].column, 15);
  EXPECT_EQ(l.comments[1].text_column, 22);
  EXPECT_EQ(l.comments[2].kind, CommentKind::kPlain);
  EXPECT_EQ(l.comments[2].text, "tail");
}

TEST(Rs274Lex, CommentKeywordsAsLinuxCncDetectsThem) {
  struct Case {
    const char* line;
    CommentKind kind;
    const char* text;
  };
  const Case cases[] = {
      {"(msg,hi)", CommentKind::kMsg, "hi"},
      {"(DEBUG, #1)", CommentKind::kDebug, " #1"},  // rs274: "(debug, #<ab>)" printed " 2.000000"
      {"( Print,x=#1)", CommentKind::kPrint, "x=#1"},
      {"(LOG,v #2)", CommentKind::kLog, "v #2"},
      {"(LogOpen,/tmp/a.txt)", CommentKind::kLogOpen, "/tmp/a.txt"},
      {"(LOGAPPEND,b.txt)", CommentKind::kLogAppend, "b.txt"},
      {"(LOGCLOSE)", CommentKind::kLogClose, ""},
      {"(ABORT,tool broken)", CommentKind::kAbort, "tool broken"},
      {"(PROCESS, FLUTES=2)", CommentKind::kProcess, " FLUTES=2"},
      {"(process , FLUTES=2)", CommentKind::kProcess, " FLUTES=2"},
      // The comma must follow the keyword (rs274: "( MSG ,hi)" gave COMMENT("MSG ,hi")),
      // and LOGCLOSE must stand alone (rs274: "(logclose )" gave COMMENT).
      {"( MSG ,hi)", CommentKind::kPlain, "MSG ,hi"},
      {"(logclose )", CommentKind::kPlain, "logclose "},
      {"(message)", CommentKind::kPlain, "message"},
      {"(PROCESS the part)", CommentKind::kPlain, "PROCESS the part"},
  };
  for (const Case& c : cases) {
    const Line l = lex(c.line);
    ASSERT_EQ(l.comments.size(), 1u) << c.line;
    EXPECT_EQ(l.comments[0].kind, c.kind) << c.line;
    EXPECT_EQ(l.comments[0].text, c.text) << c.line;
  }
}

TEST(Rs274Lex, ParameterSettingsAnywhereOnTheLine) {
  const Line l = lex("#1=2 #<Foo Bar>=[#1+1] G1 #[2+3]=4 ##2=5 X#1");
  ASSERT_EQ(l.settings.size(), 4u);
  ASSERT_EQ(l.words.size(), 2u);
  Parameters p;
  p.set(2, 7);
  TableReader r(p);
  EXPECT_EQ(l.settings[0].column, 1);
  EXPECT_TRUE(l.settings[0].name.empty());
  EXPECT_NEAR(evaluate(l.arena, l.settings[0].index_expr, r), 1, kTol);
  EXPECT_NEAR(evaluate(l.arena, l.settings[0].value_expr, r), 2, kTol);
  EXPECT_EQ(l.settings[1].name, "foobar");
  EXPECT_EQ(l.settings[1].index_expr, -1);
  EXPECT_EQ(l.settings[1].column, 6);
  EXPECT_NEAR(evaluate(l.arena, l.settings[2].index_expr, r), 5, kTol);
  EXPECT_NEAR(evaluate(l.arena, l.settings[3].index_expr, r), 7, kTol);  // ##2 -> #7
  EXPECT_NEAR(evaluate(l.arena, l.settings[3].value_expr, r), 5, kTol);
  EXPECT_EQ(l.settings[3].column, 36);
}

TEST(Rs274Lex, ParameterReferences) {
  Parameters p;
  p.set(1, 3);
  p.set(3, 7);
  p.set_named("_g", 4.5);
  EXPECT_NEAR(value("X#1", p), 3, kTol);
  EXPECT_NEAR(value("X##1", p), 7, kTol);            // the parameter whose index #1 holds
  EXPECT_NEAR(value("X#[1+2]", p), 7, kTol);
  EXPECT_NEAR(value("X[#1+2]", p), 5, kTol);         // '#' binds tighter than '+'
  EXPECT_NEAR(value("X#<_G>", p), 4.5, kTol);        // names compare in lower case
  EXPECT_NEAR(value("X#< _ g >", p), 4.5, kTol);     // and lose their blanks
  const Line l = lex("X#1");
  const Node& n = l.arena.nodes[static_cast<size_t>(l.words[0].expr)];
  EXPECT_EQ(n.op, Op::kParam);
  EXPECT_EQ(n.column, 2);
  // rs274: "G1 X#1+2 F1" -> Bad character '+' used: outside [ ] there is no expression.
  expect_lex_error("G1 X#1+2", 7, "unexpected '+'");
}

TEST(Rs274Lex, SignsBeforeValues) {
  Parameters p;
  p.set(1, 2);
  EXPECT_NEAR(value("X-#1", p), -2, kTol);
  EXPECT_NEAR(value("X-[1+2]"), -3, kTol);   // rs274: -3
  EXPECT_NEAR(value("X--1"), 1, kTol);       // rs274: 1
  EXPECT_NEAR(value("X+-1"), -1, kTol);      // rs274: -1
  EXPECT_NEAR(value("X-ABS[-4]"), -4, kTol);
  const Line l = lex("X-#1");
  EXPECT_EQ(l.arena.nodes[static_cast<size_t>(l.words[0].expr)].op, Op::kNeg);
  EXPECT_EQ(l.arena.nodes[static_cast<size_t>(l.words[0].expr)].column, 2);
}

TEST(Rs274Lex, OStatementsOfEveryKind) {
  struct Case {
    const char* line;
    OKind kind;
    size_t args;
  };
  const Case cases[] = {
      {"O100 sub", OKind::kSub, 0},           {"O100 endsub", OKind::kEndsub, 0},
      {"O100 endsub [5]", OKind::kEndsub, 1}, {"O100 call", OKind::kCall, 0},
      {"O100 do", OKind::kDo, 0},             {"O100 while [#1 LT 3]", OKind::kWhile, 1},
      {"O100 endwhile", OKind::kEndwhile, 0}, {"O100 if [1]", OKind::kIf, 1},
      {"O100 elseif [0]", OKind::kElseif, 1}, {"O100 else", OKind::kElse, 0},
      {"O100 endif", OKind::kEndif, 0},       {"O100 break", OKind::kBreak, 0},
      {"O100 continue", OKind::kContinue, 0}, {"O100 return", OKind::kReturn, 0},
      {"O100 return [2]", OKind::kReturn, 1}, {"O100 repeat [3]", OKind::kRepeat, 1},
      {"O100 endrepeat", OKind::kEndrepeat, 0}, {"o100 END SUB", OKind::kEndsub, 0},
      // A bare O-word (LinuxCNC 2.9): a program title or a Fanuc subprogram's head.
      {"O100 (head)", OKind::kProgram, 0},    {"O100 ; head", OKind::kProgram, 0},
  };
  for (const Case& c : cases) {
    const Line l = lex(c.line);
    EXPECT_EQ(l.o.kind, c.kind) << c.line;
    EXPECT_EQ(l.o.name, "100") << c.line;
    EXPECT_EQ(l.o.args.size(), c.args) << c.line;
    EXPECT_EQ(l.o.column, 1) << c.line;
    EXPECT_EQ(l.o.keyword_column, 6) << c.line;
    EXPECT_TRUE(l.words.empty()) << c.line;
  }
}

TEST(Rs274Lex, OCallWithArgumentsNamesAndComments) {
  Parameters p;
  p.set(1, 10);
  Line l = lex("N5 o<My Sub> call [1][2] (between) [#1+1] ; done");
  EXPECT_EQ(l.line_number, 5);
  EXPECT_EQ(l.o.kind, OKind::kCall);
  EXPECT_EQ(l.o.name, "mysub");
  EXPECT_EQ(l.o.column, 4);
  EXPECT_EQ(l.o.keyword_column, 14);
  ASSERT_EQ(l.o.args.size(), 3u);
  EXPECT_NEAR(evaluate(l.arena, l.o.args[2], TableReader(p)), 11, kTol);
  ASSERT_EQ(l.comments.size(), 2u);
  EXPECT_EQ(l.comments[0].text, "between");
  EXPECT_EQ(l.comments[1].text, " done");

  l = lex("O0100 sub");  // the name is the number without leading zeros
  EXPECT_EQ(l.o.name, "100");
  EXPECT_EQ(l.o.number_expr, -1);
  l = lex("O#1 call [4]");  // evaluated when the line runs
  EXPECT_TRUE(l.o.name.empty());
  ASSERT_GE(l.o.number_expr, 0);
  EXPECT_NEAR(evaluate(l.arena, l.o.number_expr, TableReader(p)), 10, kTol);
  l = lex("O[10+5] call");
  EXPECT_NEAR(evaluate(l.arena, l.o.number_expr, TableReader(p)), 15, kTol);
  l = lex("/O100 if [1] (why)");
  EXPECT_TRUE(l.block_delete);
  EXPECT_EQ(l.o.kind, OKind::kIf);
  EXPECT_EQ(l.comments.size(), 1u);
}

TEST(Rs274Lex, ThirtyCallArgumentsAtMost) {
  std::string line = "O1 call";
  for (int i = 0; i < 30; ++i) line.append("[").append(std::to_string(i)).append("]");
  EXPECT_EQ(lex(line).o.args.size(), 30u);
  expect_lex_error(line + "[30]", static_cast<int>(line.size()) + 1, "too many subroutine arguments");
}

// A reused Line lexes without touching the heap: vectors keep their capacity.
TEST(Rs274Lex, ReusedLineDoesNotAllocate) {
  const std::string text = "N20 G1 X[#1+2*SIN[30]] Y-#<_y> Z##2 F[100/3] #3=[#4 EQ 2] (short) ;tail";
  Line l;
  lex_line(text, l);
  lex_line("O7 call [1][2][3] (c)", l);
  lex_line(text, l);
  g_allocations = 0;
  g_counting = true;
  lex_line(text, l);
  lex_line("O7 call [1][2][3] (c)", l);
  lex_line(text, l);
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0);
  // The counter does count: a fresh Line must grow its vectors.
  g_allocations = 0;
  g_counting = true;
  {
    Line fresh;
    lex_line(text, fresh);
  }
  g_counting = false;
  EXPECT_GT(g_allocations.load(), 0);
  EXPECT_EQ(l.words.size(), 5u);
}

// ---- evaluation ----------------------------------------------------------------------

TEST(Rs274Eval, EveryFunction) {
  const double tol = 1e-9;
  EXPECT_NEAR(value("X ABS[-2.5]"), 2.5, tol);
  EXPECT_NEAR(value("X ACOS[0.5]"), 60, tol);
  EXPECT_NEAR(value("X ASIN[0.5]"), 30, tol);
  EXPECT_NEAR(value("X ATAN[1]/[-1]"), 135, tol);  // atan2(y, x) in degrees
  EXPECT_NEAR(value("X ATAN[-1]/[0]"), -90, tol);
  EXPECT_NEAR(value("X COS[60]"), 0.5, tol);
  EXPECT_NEAR(value("X EXP[1]"), std::exp(1.0), tol);
  EXPECT_NEAR(value("X FIX[-1.5]"), -2, tol);  // rs274: -2 (floor)
  EXPECT_NEAR(value("X FUP[-1.5]"), -1, tol);  // rs274: -1 (ceil)
  EXPECT_NEAR(value("X LN[1]"), 0, tol);
  EXPECT_NEAR(value("X LN[EXP[2]]"), 2, tol);
  EXPECT_NEAR(value("X ROUND[2.5]"), 3, tol);
  EXPECT_NEAR(value("X ROUND[-2.5]"), -3, tol);  // rs274: -3 (half away from zero)
  EXPECT_NEAR(value("X ROUND[2.4999]"), 2, tol);
  // rs274: 1; LinuxCNC adds 0.5 before truncating, and 0.49999999999999994 + 0.5 is 1.
  EXPECT_NEAR(value("X ROUND[0.49999999999999994]"), 1, tol);
  EXPECT_NEAR(value("X SIN[30]"), 0.5, tol);
  EXPECT_NEAR(value("X SQRT[16]"), 4, tol);
  EXPECT_NEAR(value("X TAN[45]"), 1, tol);
  EXPECT_NEAR(value("X sin[-90]"), -1, tol);
}

TEST(Rs274Eval, Exists) {
  Parameters p;
  p.set_named("here", 0);
  EXPECT_EQ(value("X EXISTS[#<here>]", p), 1.0);
  EXPECT_EQ(value("X EXISTS[#<there>]", p), 0.0);   // rs274: 0
  EXPECT_EQ(value("X EXISTS[#5]", p), 1.0);          // rs274: EXISTS[#5] 1, EXISTS[#0] 0
  EXPECT_EQ(value("X EXISTS[#0]", p), 0.0);
  EXPECT_EQ(value("X EXISTS[#5602]", p), 0.0);
}

TEST(Rs274Eval, EveryBinaryOperator) {
  EXPECT_NEAR(value("X[2**3]"), 8, kTol);
  EXPECT_NEAR(value("X[2**-1]"), 0.5, kTol);  // rs274: 0.5
  EXPECT_NEAR(value("X[6*7]"), 42, kTol);
  EXPECT_NEAR(value("X[7/2]"), 3.5, kTol);
  EXPECT_NEAR(value("X[7 MOD 3]"), 1, kTol);
  EXPECT_NEAR(value("X[-7 MOD 3]"), 2, kTol);    // rs274: 2 (fmod -1, plus |3|)
  EXPECT_NEAR(value("X[7 MOD -3]"), 1, kTol);    // rs274: 1
  EXPECT_NEAR(value("X[-0.5 MOD 1]"), 0.5, kTol);  // rs274: 0.5
  EXPECT_NEAR(value("X[5.5 MOD 2]"), 1.5, kTol);   // rs274: 1.5
  EXPECT_NEAR(value("X[2+3]"), 5, kTol);
  EXPECT_NEAR(value("X[2-3]"), -1, kTol);
  EXPECT_EQ(value("X[1 EQ 1]"), 1.0);
  EXPECT_EQ(value("X[1 EQ 2]"), 0.0);
  EXPECT_EQ(value("X[1 NE 2]"), 1.0);
  EXPECT_EQ(value("X[1 NE 1]"), 0.0);
  EXPECT_EQ(value("X[2 GT 1]"), 1.0);
  EXPECT_EQ(value("X[1 GT 1]"), 0.0);
  EXPECT_EQ(value("X[1 GE 1]"), 1.0);
  EXPECT_EQ(value("X[0 GE 1]"), 0.0);
  EXPECT_EQ(value("X[0 LT 1]"), 1.0);
  EXPECT_EQ(value("X[1 LT 1]"), 0.0);
  EXPECT_EQ(value("X[1 LE 1]"), 1.0);
  EXPECT_EQ(value("X[2 LE 1]"), 0.0);
  EXPECT_EQ(value("X[2 AND 3]"), 1.0);
  EXPECT_EQ(value("X[2 AND 0]"), 0.0);
  EXPECT_EQ(value("X[0 OR 0]"), 0.0);
  EXPECT_EQ(value("X[0 OR -1]"), 1.0);
  EXPECT_EQ(value("X[1 XOR 1]"), 0.0);
  EXPECT_EQ(value("X[1 XOR 0]"), 1.0);
  EXPECT_EQ(value("X[0.5 XOR 0]"), 1.0);
}

// LinuxCNC's TOLERANCE_EQUAL (1e-6) for EQ, NE (rs274: 1 EQ 1.0000005 gave 1) and,
// since 2.9.0 (commit 014777a816), for GE and LE; GT and LT stay exact.
TEST(Rs274Eval, ComparisonTolerance) {
  EXPECT_EQ(value("X[1 EQ 1.0000005]"), 1.0);
  EXPECT_EQ(value("X[1 EQ 1.000002]"), 0.0);
  EXPECT_EQ(value("X[1 NE 1.0000005]"), 0.0);
  EXPECT_EQ(value("X[1 NE 1.000002]"), 1.0);
  EXPECT_EQ(value("X[1 GE 1.0000005]"), 1.0);
  EXPECT_EQ(value("X[1.0000005 LE 1]"), 1.0);
  EXPECT_EQ(value("X[1 GE 1.000002]"), 0.0);
  EXPECT_EQ(value("X[1 GT 0.9999995]"), 1.0);
  EXPECT_EQ(value("X[1 LT 1.0000005]"), 1.0);
}

// Every value here is what rs274 printed for the same expression.
TEST(Rs274Eval, PrecedenceAndLeftToRight) {
  EXPECT_NEAR(value("X[2.0/3*1.5-5.5/11.0]"), 0.5, 1e-12);
  EXPECT_NEAR(value("X[1+2*3**2]"), 19, kTol);
  EXPECT_EQ(value("X[1 EQ 1 AND 0]"), 0.0);
  EXPECT_NEAR(value("X[2**3**2]"), 64, kTol);      // (2**3)**2
  EXPECT_EQ(value("X[1 OR 0 AND 0]"), 0.0);        // AND, OR, XOR are one level
  EXPECT_EQ(value("X[1 XOR 1 OR 1]"), 1.0);
  EXPECT_NEAR(value("X[3-2-1]"), 0, kTol);
  EXPECT_NEAR(value("X[12/3/2]"), 2, kTol);
  EXPECT_NEAR(value("X[2*3 MOD 4]"), 2, kTol);
  EXPECT_NEAR(value("X[4/2 MOD 3]"), 2, kTol);
  EXPECT_EQ(value("X[1 LT 2 EQ 1]"), 1.0);
  EXPECT_EQ(value("X[2+3*4 EQ 14]"), 1.0);
  EXPECT_NEAR(value("X[-2**2]"), 4, kTol);         // the sign belongs to the value
  EXPECT_NEAR(value("X[0-2**2]"), -4, kTol);
  EXPECT_NEAR(value("X[1 - -2]"), 3, kTol);
  EXPECT_NEAR(value("X[1 ++ 2]"), 3, kTol);
  EXPECT_NEAR(value("X[9+8*7/6+5-4*3**2+1]"), 9 + 8.0 * 7 / 6 + 5 - 36 + 1, 1e-12);
  EXPECT_NEAR(value("X[[1+2]*3]"), 9, kTol);
  EXPECT_NEAR(value("X[1 + 2 GT 2 AND 3 LT 2 * 2]"), 1, kTol);
}

TEST(Rs274Eval, ErrorsNameTheColumn) {
  expect_eval_error("X[1/0]", 4, "division by zero");                       // rs274: Attempt to divide by zero
  expect_eval_error("X[1 MOD 0]", 5, "MOD by zero");                        // rs274: 'not a number'
  expect_eval_error("X SQRT[-1]", 3, "negative argument to SQRT");
  expect_eval_error("X LN[0]", 3, "argument to LN");
  expect_eval_error("X ACOS[1.0000001]", 3, "ACOS out of range");
  expect_eval_error("X ASIN[-2]", 3, "ASIN out of range");
  expect_eval_error("X[[-8]**[1/3]]", 7, "negative number to a non-integer power");
  expect_eval_error("X[-8**[1/3]]", 5, "non-integer power");               // rs274: same error
  expect_eval_error("X[2**1024]", 4, "infinity");                           // rs274: 'infinity'
  expect_eval_error("X EXP[1000]", 3, "infinity");
  expect_eval_error("X[0**-1]", 4, "infinity");
  expect_eval_error("X#0", 2, "out of range");                              // rs274: ##1 with #1=0
  expect_eval_error("X#5602", 2, "out of range");
  expect_eval_error("X#1.5", 2, "not an integer");
  expect_eval_error("X[1+#<nowhere>]", 5, "#<nowhere> not defined");
}

TEST(Rs274Eval, ToTextShowsTheExpression) {
  const auto text = [](const std::string& line) {
    const Line l = lex(line);
    return to_text(l.arena, l.words[0].expr);
  };
  EXPECT_EQ(text("X[#1+2]"), "[#1+2]");
  EXPECT_EQ(text("X[1+2*3]"), "[1+2*3]");
  EXPECT_EQ(text("X[[1+2]*3]"), "[[1+2]*3]");
  EXPECT_EQ(text("X[1-[2-3]]"), "[1-[2-3]]");
  EXPECT_EQ(text("X[1 eq 2 and 3]"), "[1 EQ 2 AND 3]");
  EXPECT_EQ(text("X##1"), "##1");
  EXPECT_EQ(text("X#[1+2]"), "#[1+2]");
  EXPECT_EQ(text("X-[1+2]"), "-[1+2]");
  EXPECT_EQ(text("X#<Foo>"), "#<foo>");
  EXPECT_EQ(text("Xsin[30]"), "SIN[30]");
  EXPECT_EQ(text("Xatan[1]/[#2]"), "ATAN[1]/[#2]");
  EXPECT_EQ(text("Xexists[#<a>]"), "EXISTS[#<a>]");
  EXPECT_EQ(text("X2.5"), "2.5");
}

// ---- lexing errors ------------------------------------------------------------------

TEST(Rs274LexError, EveryRefusalNamesItsColumn) {
  // rs274 reads "X1e400" as X1 and an E word; right after a number E is refused here,
  // and the message says why the number stopped. E is a word elsewhere (M66-M68).
  expect_lex_error("G1 X1e400", 6, "unknown word 'E'");
  expect_lex_error("G1 X1e400", 6, "no exponent");
  Line e5;
  lex_line("M67 E5 Q2", e5);
  ASSERT_EQ(e5.words.size(), 3u);
  EXPECT_EQ(e5.words[1].letter, 'E');
  expect_lex_error("G1 X1 &2", 7, "unexpected '&'");
  expect_lex_error("G1 N10", 4, "unknown word 'N'");                // rs274: Bad character 'n' used
  expect_lex_error("G1 X1.2.3", 8, "second decimal point");          // rs274: bad number format
  expect_lex_error("G1 X.", 5, "number has no digits");              // rs274: conversion failed '.'
  expect_lex_error("G1 X-", 5, "number has no digits");
  expect_lex_error("G1 X", 4, "word 'X' has no value");
  expect_lex_error("G1 X*2", 5, "expected a value, found '*'");
  expect_lex_error("G1 X(c)1", 5, "expected a value, found '('");   // rs274: conversion failed ''
  expect_lex_error("(abc", 1, "unclosed comment");                  // rs274: Unclosed comment found
  expect_lex_error("G1 (a(b))", 6, "nested comment");               // rs274: Nested comment found
  expect_lex_error("G1 X[1+2", 5, "missing ']'");
  expect_lex_error("G1 X[1+2 F1", 10, "unknown operator 'F'");       // rs274: Unknown operation
  expect_lex_error("G1 X[1+foo[2]]", 8, "unknown function 'FOO'");  // rs274: Unknown word starting with f
  expect_lex_error("G1 X[1 (c) 2]", 8, "expected an operator or ']', found '('");
  expect_lex_error("G1 X SIN 30", 10, "expected '[' after SIN");
  expect_lex_error("G1 X ATAN[1]", 13, "expected '/' after ATAN");
  expect_lex_error("G1 X ATAN[1]/2", 14, "expected '[' after ATAN");
  expect_lex_error("G1 X EXISTS[1]", 13, "expected '#' inside EXISTS");
  expect_lex_error("G1 X EXISTS[#<a>", 17, "expected ']' to close EXISTS");
  expect_lex_error("G1 X#<abc", 6, "name not closed");
  expect_lex_error("#<>=1", 2, "empty name");
  expect_lex_error("#1 2", 5, "expected '='");
  expect_lex_error("#1=", 1, "no value");
  expect_lex_error("#=1", 2, "expected a value, found '='");
  expect_lex_error("G1 X#", 5, "'#' without a parameter number");
}

TEST(Rs274Lex, BareOWordIsAProgramStatement) {
  const Line l = lex("O0042");
  EXPECT_EQ(l.o.kind, OKind::kProgram);
  EXPECT_EQ(l.o.name, "42");
  EXPECT_EQ(l.o.column, 1);
  const Line n = lex("o<My Program>");
  EXPECT_EQ(n.o.kind, OKind::kProgram);
  EXPECT_EQ(n.o.name, "myprogram");
}

TEST(Rs274LexError, OStatementRefusals) {
  expect_lex_error("O100 foo", 6, "unknown O-word command");
  expect_lex_error("O100 if 1", 9, "expected '['");                  // rs274: Left bracket missing after 'if'
  expect_lex_error("O100 while", 11, "expected '['");
  expect_lex_error("O100 endif G1", 12, "after the O-word statement");  // rs274: Unexpected character after O-word
  expect_lex_error("O100 sub X1", 10, "after the O-word statement");
  expect_lex_error("O1.5 sub", 2, "not an integer");
  expect_lex_error("O<> sub", 2, "empty name");
  expect_lex_error("O<abc sub", 2, "name not closed");
}

TEST(Rs274LexError, DeepNestingIsRefusedNotOverflowed) {
  std::string line = "X";
  for (int i = 0; i < 5000; ++i) line += "[";
  line += "1";
  for (int i = 0; i < 5000; ++i) line += "]";
  try {
    lex(line);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(e.detail().find("nested too deeply"), std::string::npos);
    EXPECT_GT(e.column(), 100);
  }
}

TEST(Rs274LexError, ErrorWithFileAndCallChain) {
  const Error e("main.ngc", SourceRef{0, 12, 7}, "division by zero", {"sub.ngc:3"});
  EXPECT_STREQ(e.what(), "main.ngc:12:7: division by zero\n  called from sub.ngc:3");
  EXPECT_EQ(e.column(), 7);
  EXPECT_EQ(e.where().line, 12);
  EXPECT_EQ(e.file_name(), "main.ngc");
  EXPECT_EQ(e.call_chain().size(), 1u);
}

// ---- parameters -----------------------------------------------------------------------

TEST(Rs274Params, NumberedRangeAndIndex) {
  Parameters p;
  p.set(1, 1.5);
  p.set(kMaxParameter, 2.5);
  EXPECT_EQ(p.get(1), 1.5);
  EXPECT_EQ(p.get(kMaxParameter), 2.5);
  EXPECT_EQ(p.get(31), 0.0);
  try {
    p.get(0, 9);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.column(), 9);
  }
  EXPECT_THROW(p.set(kMaxParameter + 1, 1), Error);
  EXPECT_EQ(Parameters::index_of(5.00005, 1), 5);
  EXPECT_EQ(Parameters::index_of(4.99995, 1), 5);
  EXPECT_THROW(Parameters::index_of(5.001, 1), Error);
  EXPECT_THROW(Parameters::index_of(1e300, 1), Error);
  EXPECT_THROW(Parameters::index_of(NAN, 1), Error);
}

TEST(Rs274Params, NamedLocalsAreScopedPerCallGlobalsAreNot) {
  Parameters p;
  p.set_named("depth", 1);
  p.set_named("_tool", 7);
  EXPECT_EQ(p.get_named("depth"), 1.0);
  p.push_call();
  EXPECT_EQ(p.call_depth(), 1);
  double v = 0;
  EXPECT_FALSE(p.find_named("depth", &v));  // the caller's locals are not visible
  EXPECT_THROW(p.get_named("depth", 4), Error);
  EXPECT_EQ(p.get_named("_tool"), 7.0);
  p.set_named("depth", 2);
  p.set_named("_tool", 8);
  p.push_call();
  EXPECT_FALSE(p.find_named("depth", &v));
  p.set_named("depth", 3);
  p.pop_call();
  EXPECT_EQ(p.get_named("depth"), 2.0);
  p.pop_call();
  EXPECT_EQ(p.call_depth(), 0);
  EXPECT_EQ(p.get_named("depth"), 1.0);
  EXPECT_EQ(p.get_named("_tool"), 8.0);     // globals keep what the callee set
  EXPECT_THROW(p.pop_call(), std::logic_error);
  try {
    p.get_named("nothing", 12);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.column(), 12);
    EXPECT_NE(e.detail().find("#<nothing> not defined"), std::string::npos);
  }
}

TEST(Rs274Params, CallArgumentsAreLocalToEachCall) {
  Parameters p;
  for (int i = 1; i <= 31; ++i) p.set(i, 100 + i);
  p.push_call();
  for (int i = 1; i <= 30; ++i) EXPECT_EQ(p.get(i), 0.0) << i;  // args not given are zero
  EXPECT_EQ(p.get(31), 131.0);                                  // #31 on is global
  p.set(1, 5);
  p.set(31, 7);
  p.pop_call();
  for (int i = 1; i <= 30; ++i) EXPECT_EQ(p.get(i), 100.0 + i) << i;
  EXPECT_EQ(p.get(31), 7.0);
}

TEST(Rs274Params, PersistentSetIsLinuxCncs) {
  Parameters p;
  EXPECT_TRUE(p.persistent(5161));
  EXPECT_TRUE(p.persistent(5169));
  EXPECT_FALSE(p.persistent(5170));
  EXPECT_TRUE(p.persistent(5181));
  EXPECT_TRUE(p.persistent(5210));
  EXPECT_TRUE(p.persistent(5220));
  EXPECT_TRUE(p.persistent(5230));
  EXPECT_FALSE(p.persistent(5231));
  EXPECT_TRUE(p.persistent(5241));
  EXPECT_TRUE(p.persistent(5390));
  EXPECT_FALSE(p.persistent(5391));
  EXPECT_FALSE(p.persistent(31));
  EXPECT_FALSE(p.persistent(0));
}

class Rs274VarFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("rs274_front_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    path_ = (dir_ / "sim.var").string();
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void write(const std::string& text) const { std::ofstream(path_) << text; }
  std::string read() const {
    std::ifstream in(path_);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
  int files_in_dir() const {
    int n = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir_)) ++n;
    return n;
  }

  std::filesystem::path dir_;
  std::string path_;
};

TEST_F(Rs274VarFile, ReadsLinuxCncFormat) {
  write("5161\t1.500000\n"
        "# a remark\n"
        "\n"
        "5181  -2\n"
        "   5220\t1.000000\n"
        "5221\t10.456000 trailing words are ignored\n"
        "text mentioning 5161 9 is a remark\n");
  Parameters p;
  p.set(5162, 9);  // not in the file: a persistent parameter becomes zero
  p.set(100, 4);   // not persistent: left alone
  p.read_var_file(path_);
  EXPECT_EQ(p.get(5161), 1.5);
  EXPECT_EQ(p.get(5181), -2.0);
  EXPECT_EQ(p.get(5220), 1.0);
  EXPECT_NEAR(p.get(5221), 10.456, 1e-12);
  EXPECT_EQ(p.get(5162), 0.0);
  EXPECT_EQ(p.get(100), 4.0);
}

TEST_F(Rs274VarFile, UserParametersListedInTheFileBecomePersistent) {
  write("31\t2.5\n5161\t0\n");
  Parameters p;
  p.read_var_file(path_);
  EXPECT_TRUE(p.persistent(31));
  EXPECT_FALSE(p.persistent(32));
  p.set(31, 3.25);
  p.write_var_file(path_);
  const std::string text = read();
  EXPECT_EQ(text.rfind("31\t3.250000\n5161\t0.000000\n", 0), 0u) << text;
}

TEST_F(Rs274VarFile, RoundTripKeepsEveryBit) {
  Parameters a;
  a.set(5161, 1.0 / 3.0);
  a.set(5221, -123.456);
  a.set(5390, 1e-20);
  a.set(5220, 2);
  a.write_var_file(path_);
  Parameters b;
  b.read_var_file(path_);
  for (int i = 1; i <= kMaxParameter; ++i) {
    EXPECT_EQ(a.persistent(i), b.persistent(i)) << i;
    if (a.persistent(i)) {
      EXPECT_EQ(a.get(i), b.get(i)) << i;
    }
  }
  EXPECT_EQ(b.get(5161), 1.0 / 3.0);
  EXPECT_EQ(b.get(5390), 1e-20);
}

TEST_F(Rs274VarFile, WritesAscendingLinuxCncLines) {
  Parameters p;
  p.set(5221, 10.456);
  p.write_var_file(path_);
  const std::string text = read();
  std::istringstream in(text);
  std::string line;
  int last = 0;
  int count = 0;
  while (std::getline(in, line)) {
    const size_t tab = line.find('\t');
    ASSERT_NE(tab, std::string::npos) << line;
    const int index = std::stoi(line.substr(0, tab));
    EXPECT_GT(index, last);
    EXPECT_TRUE(p.persistent(index)) << index;
    last = index;
    ++count;
  }
  EXPECT_EQ(count, 9 + 9 + 21 + 8 * 10);  // LinuxCNC's required_parameters
  EXPECT_NE(text.find("\n5221\t10.456000\n"), std::string::npos);
  EXPECT_NE(text.find("\n5220\t0.000000\n"), std::string::npos);
  EXPECT_EQ(files_in_dir(), 1);  // no temporary left behind
}

TEST_F(Rs274VarFile, MissingFileIsFine) {
  Parameters p;
  p.set(5161, 3);
  EXPECT_NO_THROW(p.read_var_file(path_));
  EXPECT_EQ(p.get(5161), 3.0);
}

TEST_F(Rs274VarFile, RefusesBadFilesNamingTheLineAndChangesNothing) {
  struct Case {
    const char* text;
    const char* where;
    const char* what;
  };
  const Case cases[] = {
      {"5161\t1\n5162\t2\n5161\t3\n", ":3:1:", "out of order"},
      {"5161\t1\n5161\t2\n", ":2:1:", "out of order"},
      {"5161\t1\n0\t2\n", ":2:1:", "out of range"},
      {"5602\t2\n", ":1:1:", "out of range"},
      {"5161\tabc\n", ":1:6:", "bad value"},
      {"5161\tnan\n", ":1:6:", "bad value"},
      {"5161\n", ":1:5:", "no value"},
      {"5161.5 2\n", ":1:5:", "expected blanks"},
      {"5161 1.5x\n", ":1:9:", "unexpected text"},
  };
  for (const Case& c : cases) {
    write(c.text);
    Parameters p;
    p.set(5161, 42);
    try {
      p.read_var_file(path_);
      ADD_FAILURE() << "no error for " << c.text;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path_ + c.where), std::string::npos) << what;
      EXPECT_NE(what.find(c.what), std::string::npos) << what;
    }
    EXPECT_EQ(p.get(5161), 42.0) << c.text;
  }
}

// A write that fails midway (here the file size limit) leaves the old file whole
// and no temporary beside it. Run in a child: the limit is process-wide.
TEST_F(Rs274VarFile, FailedWriteLeavesTheOldFile) {
  const std::string old = "5161\t1.000000\n";
  write(old);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::signal(SIGXFSZ, SIG_IGN);
    rlimit lim{};
    lim.rlim_cur = 64;
    lim.rlim_max = 64;
    if (::setrlimit(RLIMIT_FSIZE, &lim) != 0) ::_exit(3);
    Parameters p;
    p.set(5161, 2);
    try {
      p.write_var_file(path_);
    } catch (const std::runtime_error& e) {
      ::_exit(std::string(e.what()).find(dir_.string()) != std::string::npos ? 0 : 4);
    }
    ::_exit(5);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_EQ(read(), old);
  EXPECT_EQ(files_in_dir(), 1);
}

TEST_F(Rs274VarFile, UnwritableFolderThrowsWithThePath) {
  Parameters p;
  const std::string nowhere = (dir_ / "no" / "such" / "dir" / "x.var").string();
  try {
    p.write_var_file(nowhere);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(nowhere), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cnc::rs274
