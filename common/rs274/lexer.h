#pragma once
// RS274NGC front end, as LinuxCNC 2.9 documents it: one source line in, one Line out.
// The lexer does not evaluate: numbers, parameter references and [expressions] become
// nodes of a small expression tree (an arena per line), so the interpreter evaluates
// them with the parameter values in force when the line runs, and a loop body is
// lexed once per pass, not once per file. Every node and word keeps its column.
//
// What a line may hold (LinuxCNC's order of reading):
//   [/] [N<int>] ( O-word statement | words, parameter settings, comments )
// Case and spaces are ignored outside comments and outside #<names> (LinuxCNC
// removes spaces inside names too; names compare in lower case).
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace cnc::rs274 {

// Where something is: file index into the interpreter's file table, 1-based line
// and column. Column counts bytes of the original line from 1.
struct SourceRef {
  int32_t file = 0;
  int32_t line = 0;
  int32_t column = 0;
};

// Every refusal of the language: the place, and what was found and expected.
// `what()` is "file:line:column: detail" once the interpreter has filled in the
// file name and call chain; the lexer and evaluator throw with only column set.
class Error : public std::runtime_error {
 public:
  Error(int column, std::string detail);
  Error(std::string file_name, SourceRef where, std::string detail, std::vector<std::string> call_chain = {});
  int column() const { return where_.column; }
  const SourceRef& where() const { return where_; }
  const std::string& file_name() const { return file_name_; }
  const std::string& detail() const { return detail_; }
  const std::vector<std::string>& call_chain() const { return call_chain_; }

 private:
  SourceRef where_;
  std::string file_name_;
  std::string detail_;
  std::vector<std::string> call_chain_;
};

// ---- expressions -----------------------------------------------------------------

enum class Op : uint8_t {
  kNumber,        // value
  kParam,         // #<a>: a is the index expression (numbered parameter)
  kNamedParam,    // #<name>: name
  kExists,        // EXISTS[#<name>]: name; EXISTS[#n] (name empty): a is the index expression,
                  // true when the index is 1..5601 (LinuxCNC's rule)
  kNeg,           // unary minus (LinuxCNC allows a sign before a value in a real value)
  // unary functions of a (argument in [ ]); trigonometry in degrees as LinuxCNC
  kAbs, kAcos, kAsin, kAtan /* ATAN[a]/[b], two args */, kCos, kExp, kFix, kFup, kLn, kRound, kSin, kSqrt, kTan,
  // binary a op b
  kPow, kMul, kDiv, kMod, kAdd, kSub, kEq, kNe, kGt, kGe, kLt, kLe, kAnd, kOr, kXor,
};

struct Node {
  Op op = Op::kNumber;
  int32_t a = -1;  // child node index
  int32_t b = -1;
  int32_t column = 0;
  double value = 0;   // kNumber
  std::string name;   // kNamedParam, kExists: lower case, spaces removed, without < >
};

// Node storage of one line; expressions refer to nodes by index.
struct ExprArena {
  std::vector<Node> nodes;
  void clear() { nodes.clear(); }
};

// ---- lines ------------------------------------------------------------------------

struct Word {
  char letter = 0;    // upper case
  int32_t expr = -1;  // value expression in the line's arena
  int32_t column = 0;
};

// #n=value or #<name>=value; LinuxCNC applies all of a line's settings after the
// line is read, in order, so reads on the same line see the old values.
struct ParamSetting {
  int32_t index_expr = -1;  // numbered: the index expression; -1 when named
  std::string name;         // named: lower case, without < >
  int32_t value_expr = -1;
  int32_t column = 0;
};

// kAbort: LinuxCNC 2.9's (ABORT,text), which ends the program with text as the error.
enum class CommentKind : uint8_t { kPlain, kMsg, kPrint, kDebug, kProcess, kLogOpen, kLogAppend, kLogClose, kLog, kAbort };

struct Comment {
  CommentKind kind = CommentKind::kPlain;
  std::string text;  // after the keyword and its comma for MSG/PRINT/DEBUG/LOG*/PROCESS, as written
                     // (plain: without the leading blanks, as LinuxCNC's COMMENT shows it)
  int32_t column = 0;       // of the '(' or ';'
  int32_t text_column = 0;  // of text's first character (one past the end when text is empty)
};

enum class OKind : uint8_t {
  kNone, kSub, kEndsub, kCall, kDo, kWhile, kEndwhile, kIf, kElseif, kElse, kEndif,
  kBreak, kContinue, kReturn, kRepeat, kEndrepeat,
  kProgram,  // a bare O-word: a program title, or a Fanuc subprogram's head (M98 calls, M99 ends)
};

// O<number> or O<name> followed by its keyword. LinuxCNC allows an O-word's
// number to be an expression ("O#1 call"); `name` is its text: decimal digits of
// the number without leading zeros, or the lower-case name in < >.
struct OStatement {
  OKind kind = OKind::kNone;
  std::string name;
  int32_t number_expr = -1;        // O[expr] / O#1: evaluated at run time; -1 when literal
  std::vector<int32_t> args;       // call: [a] [b] ...; while/if/elseif/repeat: one condition/count;
                                   // return/endsub: optional value
  int32_t column = 0;              // of the 'O'
  int32_t keyword_column = 0;
};

struct Line {
  bool block_delete = false;  // leading '/'
  bool has_line_number = false;
  int64_t line_number = 0;    // N word
  OStatement o;               // o.kind != kNone: the line is an O-word statement (comments may follow)
  std::vector<Word> words;
  std::vector<ParamSetting> settings;
  std::vector<Comment> comments;
  bool percent = false;       // a line holding only '%' (program delimiters)
  ExprArena arena;
  void clear();
};

// Lexes one line (without its newline). Throws Error with the column on anything
// LinuxCNC's reader refuses: unknown letter, a number without digits, unclosed
// comment or bracket, bad function name, a word letter given twice is NOT checked
// here (the interpreter knows which letters may repeat: G and M).
// Reuses `out`'s storage: lexing a line allocates nothing once capacities settle.
void lex_line(std::string_view text, Line& out);

// ---- evaluation -------------------------------------------------------------------

// What evaluation reads; the interpreter implements it (numbered, named local and
// global, predefined #<_x> ... read-only values).
class ParamReader {
 public:
  virtual ~ParamReader() = default;
  // Throws Error(column, ...) for an index outside 1..5601 or a non-integer index.
  virtual double numbered(double index, int column) const = 0;
  // Throws Error for a name that was never set ("named parameter #<foo> not defined").
  virtual double named(const std::string& name, int column) const = 0;
  virtual bool exists(const std::string& name) const = 0;
};

// Evaluates node `root` of `arena`. LinuxCNC's rules: degrees, ATAN[y]/[x] as
// atan2 in degrees, comparisons give 1.0/0.0, AND/OR/XOR treat non-zero as true,
// MOD takes the sign LinuxCNC gives it (fmod, then made non-negative), division by
// zero, LN/SQRT of out-of-domain values and ACOS/ASIN outside [-1, 1] are errors
// naming the column. The result is finite or an Error is thrown.
double evaluate(const ExprArena& arena, int32_t root, const ParamReader& params);

// The text of a (PRINT,...) or (DEBUG,...) comment with the values of the #n and
// #<name> in it, as LinuxCNC's convert_param_comment makes it. Throws
// Error(column, ...) for a parameter reference left open.
std::string expand_parameters(const std::string& text, int column, const ParamReader& params);

// Text of an expression as written, for messages: "[#1+2]".
std::string to_text(const ExprArena& arena, int32_t root);

}  // namespace cnc::rs274
