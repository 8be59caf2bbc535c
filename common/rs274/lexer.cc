#include "common/rs274/lexer.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <string>
#include <utility>

namespace cnc::rs274 {

Error::Error(int column, std::string detail)
    : std::runtime_error(column > 0 ? "column " + std::to_string(column) + ": " + detail : detail),
      detail_(std::move(detail)) {
  where_.column = column;
}

namespace {

// "file:line:column: detail" and the call chain, one caller a line.
std::string located(const std::string& file_name, const SourceRef& where, const std::string& detail,
                    const std::vector<std::string>& call_chain) {
  std::string w = file_name;
  w.append(":").append(std::to_string(where.line));
  if (where.column > 0) w.append(":").append(std::to_string(where.column));
  w.append(": ").append(detail);
  for (const std::string& c : call_chain) w.append("\n  called from ").append(c);
  return w;
}

}  // namespace

Error::Error(std::string file_name, SourceRef where, std::string detail, std::vector<std::string> call_chain)
    : std::runtime_error(located(file_name, where, detail, call_chain)),
      where_(where),
      file_name_(std::move(file_name)),
      detail_(std::move(detail)),
      call_chain_(std::move(call_chain)) {}

void Line::clear() {
  block_delete = false;
  has_line_number = false;
  line_number = 0;
  o.kind = OKind::kNone;
  o.name.clear();
  o.number_expr = -1;
  o.args.clear();
  o.column = 0;
  o.keyword_column = 0;
  words.clear();
  settings.clear();
  comments.clear();
  percent = false;
  arena.clear();
}

namespace {

// LinuxCNC's close_and_downcase drops these outside comments before reading,
// so "X1 2" is X12 and "a n d" is AND.
bool blank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

char lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }
char upper(char c) { return (c >= 'a' && c <= 'z') ? static_cast<char>(c - 'a' + 'A') : c; }
bool is_digit(char c) { return c >= '0' && c <= '9'; }
bool is_letter(char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); }

// A character as messages show it: letters in upper case (the reader is
// case-insensitive), control characters as octal like LinuxCNC.
std::string shown(char c) {
  if (is_letter(c)) return std::string(1, upper(c));
  const auto u = static_cast<unsigned char>(c);
  if (u < 0x20 || u >= 0x7f) {
    char buf[8];
    const int d0 = (u >> 6) & 7, d1 = (u >> 3) & 7, d2 = u & 7;
    buf[0] = '\\';
    buf[1] = static_cast<char>('0' + d0);
    buf[2] = static_cast<char>('0' + d1);
    buf[3] = static_cast<char>('0' + d2);
    buf[4] = 0;
    return buf;
  }
  return std::string(1, c);
}

// Built by appending: GCC 12 warns falsely (-Wrestrict) on "'" + std::string&&.
std::string quoted(char c) {
  std::string q(1, '\'');
  q.append(shown(c)).push_back('\'');
  return q;
}

// The letters LinuxCNC 2.9 reads as words, with @ and ^ (polar distance and angle)
// and $ (spindle selection).
bool word_letter(char c) {
  switch (c) {
    case 'a': case 'b': case 'c': case 'd': case 'e': case 'f': case 'g': case 'h': case 'i': case 'j': case 'k':
    case 'l': case 'm': case 'p': case 'q': case 'r': case 's': case 't': case 'u': case 'v': case 'w':
    case 'x': case 'y': case 'z': case '@': case '^': case '$':
      return true;
    default:
      return false;
  }
}

// Numbers: below 2^53 an integer is an exact double, as is every power of ten to 1e22.
constexpr uint64_t kMaxExactMantissa = (uint64_t{1} << 53) - 1;
constexpr double kPowersOf10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                  1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

// Deeper nesting than this is no part program; the limit keeps the recursive
// reader's stack bounded whatever the line holds.
constexpr int kMaxNesting = 200;

constexpr int kMaxCallArgs = 30;  // LinuxCNC's INTERP_SUB_PARAMS

struct FunctionName {
  const char* name;
  Op op;
};
constexpr FunctionName kFunctions[] = {
    {"abs", Op::kAbs}, {"acos", Op::kAcos}, {"asin", Op::kAsin}, {"atan", Op::kAtan}, {"cos", Op::kCos},
    {"exp", Op::kExp}, {"fix", Op::kFix},   {"fup", Op::kFup},   {"ln", Op::kLn},     {"round", Op::kRound},
    {"sin", Op::kSin}, {"sqrt", Op::kSqrt}, {"tan", Op::kTan},   {"exists", Op::kExists},
};

struct CommentKeyword {
  const char* word;  // lower case, with its comma; LOGCLOSE stands alone
  CommentKind kind;
};
// LinuxCNC's convert_comment order; PROCESS is this controller's directive.
constexpr CommentKeyword kCommentKeywords[] = {
    {"msg,", CommentKind::kMsg},         {"debug,", CommentKind::kDebug},         {"print,", CommentKind::kPrint},
    {"log,", CommentKind::kLog},         {"logopen,", CommentKind::kLogOpen},     {"logappend,", CommentKind::kLogAppend},
    {"abort,", CommentKind::kAbort},
};

struct OKeyword {
  const char* word;
  OKind kind;
};
// LinuxCNC's read_o compares prefixes in this order ("elseif" before "else").
constexpr OKeyword kOKeywords[] = {
    {"sub", OKind::kSub},           {"endsub", OKind::kEndsub},     {"call", OKind::kCall},
    {"do", OKind::kDo},             {"while", OKind::kWhile},       {"repeat", OKind::kRepeat},
    {"if", OKind::kIf},             {"elseif", OKind::kElseif},     {"else", OKind::kElse},
    {"endif", OKind::kEndif},       {"break", OKind::kBreak},       {"continue", OKind::kContinue},
    {"endwhile", OKind::kEndwhile}, {"endrepeat", OKind::kEndrepeat}, {"return", OKind::kReturn},
};

// Binary operators by LinuxCNC's precedence levels (interp_internal.cc precedence()).
int precedence(Op op) {
  switch (op) {
    case Op::kPow: return 6;
    case Op::kMul: case Op::kDiv: case Op::kMod: return 5;
    case Op::kAdd: case Op::kSub: return 4;
    case Op::kEq: case Op::kNe: case Op::kGt: case Op::kGe: case Op::kLt: case Op::kLe: return 3;
    case Op::kAnd: case Op::kOr: case Op::kXor: return 2;
    default: return 0;
  }
}

class Reader {
 public:
  Reader(std::string_view text, Line& out) : s_(text), out_(out) {}

  void line() {
    check_comments();
    skip();
    if (at_percent_line()) {
      out_.percent = true;
      return;
    }
    if (peek() == '/') {
      out_.block_delete = true;
      advance();
    }
    if (peek() == 'n') line_number();
    if (peek() == 'o') {
      o_statement();
      return;
    }
    while (!end()) item();
  }

 private:
  // ---- the cursor: always on a non-blank character or at the end ----

  bool end() const { return i_ >= s_.size(); }
  char peek() const { return end() ? '\0' : lower(s_[i_]); }
  // The k-th non-blank character from here (0: this one).
  char peek_at(int k) const {
    size_t j = i_;
    for (;;) {
      while (j < s_.size() && blank(s_[j])) ++j;
      if (j >= s_.size()) return '\0';
      if (k == 0) return lower(s_[j]);
      --k;
      ++j;
    }
  }
  int col() const { return static_cast<int>(i_) + 1; }
  void skip() {
    while (!end() && blank(s_[i_])) ++i_;
  }
  void advance() {
    ++i_;
    skip();
  }
  // Consumes `word` (lower case) when the next non-blank characters spell it.
  bool match(const char* word) {
    size_t j = i_;
    for (const char* w = word; *w; ++w) {
      while (j < s_.size() && blank(s_[j])) ++j;
      if (j >= s_.size() || lower(s_[j]) != *w) return false;
      ++j;
    }
    i_ = j;  // as advance() once per character: past the last one and the blanks after it
    skip();
    return true;
  }

  [[noreturn]] void fail(int column, std::string what) const { throw Error(column, std::move(what)); }

  std::string found_here() const { return end() ? "the end of the line" : quoted(s_[i_]); }

  // LinuxCNC checks comments over the whole line before reading anything, so an
  // unclosed or nested comment is reported whatever precedes it.
  void check_comments() const {
    size_t open = 0;
    bool in = false;
    for (size_t j = 0; j < s_.size(); ++j) {
      const char c = s_[j];
      if (in) {
        if (c == ')') in = false;
        else if (c == '(') fail(static_cast<int>(j) + 1, "nested comment: '(' inside the comment opened at column " +
                                                           std::to_string(open + 1));
      } else if (c == ';') {
        return;
      } else if (c == '(') {
        in = true;
        open = j;
      }
    }
    if (in) fail(static_cast<int>(open) + 1, "unclosed comment: no ')' after this '('");
  }

  bool at_percent_line() const {
    if (peek() != '%') return false;
    for (size_t j = i_ + 1; j < s_.size(); ++j)
      if (!blank(s_[j])) return false;
    return true;
  }

  // ---- line structure ----

  void line_number() {
    const int at = col();
    advance();
    const int64_t n = unsigned_digits(at, "line number");
    out_.has_line_number = true;
    out_.line_number = n;
    if (peek() == '.') {  // LinuxCNC accepts and ignores a fraction ("N10.5")
      advance();
      unsigned_digits(at, "line number fraction");
    }
  }

  int64_t unsigned_digits(int word_column, const char* what) {
    if (!is_digit(peek())) fail(col(), std::string(what) + " has no digits: found " + found_here());
    int64_t n = 0;
    while (is_digit(peek())) {
      n = n * 10 + (peek() - '0');
      if (n > 2147483647) fail(word_column, std::string(what) + " too large");
      advance();
    }
    return n;
  }

  void item() {
    const char c = peek();
    if (c == '(') {
      paren_comment();
    } else if (c == ';') {
      semicolon_comment();
    } else if (c == '#') {
      setting();
    } else if (c == 'e' && i_ > 0 && (is_digit(s_[i_ - 1]) || s_[i_ - 1] == '.')) {
      // E is M66/M67/M68's word; right after a number it is an exponent, which
      // RS274NGC does not have (LinuxCNC would read X1e400 as X1 E400).
      fail(col(), "unknown word 'E' (RS274NGC numbers have no exponent)");
    } else if (word_letter(c)) {
      Word w;
      w.letter = upper(c);
      w.column = col();
      advance();
      if (end()) fail(w.column, std::string("word '") + w.letter + "' has no value");
      w.expr = real_value(0);
      out_.words.push_back(w);
    } else if (c == 'n') {
      fail(col(), "unknown word 'N' (a line number must begin the line)");
    } else if (is_letter(c)) {
      fail(col(), "unknown word " + quoted(c));
    } else {
      fail(col(), "unexpected " + quoted(s_[i_]));
    }
  }

  void setting() {
    ParamSetting p;
    p.column = col();
    advance();
    if (peek() == '<') {
      name(&p.name);
    } else {
      if (end()) fail(p.column, "'#' without a parameter number");
      p.index_expr = real_value(0);
    }
    if (peek() != '=') fail(col(), "expected '=' in the parameter setting, found " + found_here());
    advance();
    if (end()) fail(p.column, "parameter setting has no value after '='");
    p.value_expr = real_value(0);
    out_.settings.push_back(std::move(p));
  }

  // #<name>: blanks removed and lower case, as LinuxCNC stores names.
  void name(std::string* into) {
    const int at = col();
    advance();
    into->clear();
    while (!end() && s_[i_] != '>') {
      if (s_[i_] == '(') fail(col(), "'(' inside a name");
      into->push_back(lower(s_[i_]));
      advance();
    }
    if (end()) fail(at, "name not closed: no '>' after this '<'");
    if (into->empty()) fail(at, "empty name '<>'");
    advance();
  }

  void paren_comment() {
    Comment c;
    c.column = col();
    size_t close = i_ + 1;
    while (s_[close] != ')') ++close;  // check_comments() guarantees the ')'
    const std::string_view body = s_.substr(i_ + 1, close - i_ - 1);
    size_t start = 0;
    while (start < body.size() && (blank(body[start]) || body[start] == '\n' || body[start] == '\f' || body[start] == '\v'))
      ++start;
    const std::string_view rest = body.substr(start);
    size_t text_at = start;
    c.kind = CommentKind::kPlain;
    for (const CommentKeyword& k : kCommentKeywords) {
      if (starts_with_lower(rest, k.word)) {
        c.kind = k.kind;
        text_at = start + std::char_traits<char>::length(k.word);
        break;
      }
    }
    if (c.kind == CommentKind::kPlain) {
      size_t after = 0;
      if (equals_lower(rest, "logclose")) {  // LinuxCNC wants it alone, nothing after it
        c.kind = CommentKind::kLogClose;
        text_at = body.size();
      } else if (process_directive(rest, &after)) {
        c.kind = CommentKind::kProcess;
        text_at = start + after;
      }
    }
    c.text.assign(body.substr(text_at));
    c.text_column = c.column + 1 + static_cast<int>(text_at);
    out_.comments.push_back(std::move(c));
    i_ = close;
    advance();
  }

  void semicolon_comment() {
    Comment c;
    c.kind = CommentKind::kPlain;
    c.column = col();
    c.text.assign(s_.substr(i_ + 1));
    c.text_column = c.column + 1;
    out_.comments.push_back(std::move(c));
    i_ = s_.size();
  }

  static bool starts_with_lower(std::string_view s, const char* word) {
    size_t k = 0;
    for (; word[k]; ++k)
      if (k >= s.size() || lower(s[k]) != word[k]) return false;
    return true;
  }
  static bool equals_lower(std::string_view s, const char* word) {
    return s.size() == std::char_traits<char>::length(word) && starts_with_lower(s, word);
  }
  // "PROCESS" then blanks then ','; this controller's existing dialect allows the blanks.
  static bool process_directive(std::string_view s, size_t* after) {
    if (!starts_with_lower(s, "process")) return false;
    size_t k = 7;
    while (k < s.size() && blank(s[k])) ++k;
    if (k >= s.size() || s[k] != ',') return false;
    *after = k + 1;
    return true;
  }

  // ---- O-word statements ----

  void o_statement() {
    OStatement& o = out_.o;
    o.column = col();
    advance();
    if (peek() == '<') {
      name(&o.name);
    } else {
      if (end()) fail(o.column, "O-word has no number or <name>");
      const int at = col();
      const int32_t e = real_value(0);
      const Node& n = out_.arena.nodes[static_cast<size_t>(e)];
      if (n.op == Op::kNumber) {
        o.name = std::to_string(integer_of(n.value, at, "O-word number"));
      } else {
        o.number_expr = e;
      }
    }
    o.keyword_column = col();
    for (const OKeyword& k : kOKeywords) {
      if (match(k.word)) {
        o.kind = k.kind;
        break;
      }
    }
    if (o.kind == OKind::kNone) {
      // A bare O-word (LinuxCNC 2.9): a program number / name, or the head of a Fanuc
      // subprogram that M98 calls and M99 ends.
      if (end() || peek() == '(' || peek() == ';') o.kind = OKind::kProgram;
      else fail(o.keyword_column, "unknown O-word command starting with " + found_here());
    }
    switch (o.kind) {
      case OKind::kCall:
        while (peek() == '[' || peek() == '(') {
          if (peek() == '(') {
            paren_comment();
            continue;
          }
          if (static_cast<int>(o.args.size()) >= kMaxCallArgs)
            fail(col(), "too many subroutine arguments (" + std::to_string(kMaxCallArgs) + " at most)");
          o.args.push_back(expression(0));
        }
        break;
      case OKind::kWhile:
      case OKind::kIf:
      case OKind::kElseif:
      case OKind::kRepeat:
        if (peek() != '[') fail(col(), "expected '[' and a condition after the O-word command, found " + found_here());
        o.args.push_back(expression(0));
        break;
      case OKind::kEndsub:
      case OKind::kReturn:
        if (peek() == '[') o.args.push_back(expression(0));
        break;
      default:
        break;
    }
    while (!end()) {
      if (peek() == '(') paren_comment();
      else if (peek() == ';') semicolon_comment();
      else fail(col(), "unexpected " + found_here() + " after the O-word statement (only comments may follow)");
    }
  }

  // LinuxCNC's read_integer_value: within 1e-4 of an integer.
  int integer_of(double v, int column, const char* what) const {
    if (!(std::fabs(v) < 2147483647.0)) fail(column, std::string(what) + " out of range");
    double f = std::floor(v);
    if (v - f > 0.9999) f = std::ceil(v);
    else if (v - f > 0.0001) fail(column, std::string(what) + " is not an integer");
    return static_cast<int>(f);
  }

  // ---- values and expressions ----

  int32_t add(Op op, int column, int32_t a = -1, int32_t b = -1) {
    Node n;
    n.op = op;
    n.column = column;
    n.a = a;
    n.b = b;
    out_.arena.nodes.push_back(std::move(n));
    return static_cast<int32_t>(out_.arena.nodes.size() - 1);
  }

  // LinuxCNC's read_real_value: a number, #parameter, [expression] or function,
  // with any number of signs before it.
  int32_t real_value(int depth) {
    if (depth > kMaxNesting) fail(col(), "expression nested too deeply");
    const char c = peek();
    const int at = col();
    if (c == '\0') fail(at, "expected a value, found the end of the line");
    if (c == '[') return expression(depth + 1);
    if (c == '#') return parameter(depth + 1);
    const char c1 = peek_at(1);
    // A sign before a digit or '.' belongs to the number; before anything else
    // it applies to the value that follows ("X-#1", "X-[1+2]", "X--1").
    if ((c == '+' || c == '-') && c1 != '\0' && !is_digit(c1) && c1 != '.') {
      advance();
      const int32_t v = real_value(depth + 1);
      return c == '-' ? add(Op::kNeg, at, v) : v;
    }
    if (is_letter(c)) return function(depth + 1);
    return number();
  }

  int32_t number() {
    const int at = col();
    if (const int32_t id = contiguous_number(at); id >= 0) return id;
    char buf[320];
    size_t n = 0;
    const auto put = [&](char ch) {
      if (n + 1 >= sizeof buf) fail(at, "number too long");
      buf[n++] = ch;
    };
    if (peek() == '+' || peek() == '-') {
      put(peek());
      advance();
    }
    // The digits as an integer and the count of decimals, while they fit exactly.
    int digits = 0, decimals = 0;
    uint64_t mantissa = 0;
    bool exact = true;
    const auto digit = [&](char ch) {
      put(ch);
      ++digits;
      if (mantissa > (kMaxExactMantissa - 9) / 10) exact = false;
      else mantissa = mantissa * 10 + static_cast<uint64_t>(ch - '0');
    };
    while (is_digit(peek())) {
      digit(peek());
      advance();
    }
    if (peek() == '.') {
      put('.');
      advance();
      while (is_digit(peek())) {
        digit(peek());
        ++decimals;
        advance();
      }
      if (peek() == '.') fail(col(), "number has a second decimal point");
    }
    if (digits == 0) {
      if (n == 0) fail(at, "expected a value, found " + found_here());
      fail(at, "number has no digits");
    }
    double v = 0;
    if (exact && decimals < static_cast<int>(std::size(kPowersOf10))) {
      // Clinger's fast path: an integer below 2^53 and a power of ten up to 1e22 are
      // both exact doubles, so their one correctly rounded quotient is the correctly
      // rounded value of the decimal, the very double from_chars gives.
      v = static_cast<double>(mantissa) / kPowersOf10[decimals];
      if (buf[0] == '-') v = -v;
    } else {
      const char* first = buf[0] == '+' ? buf + 1 : buf;
      const auto r = std::from_chars(first, buf + n, v);
      if (r.ec != std::errc() || !std::isfinite(v)) fail(at, "number out of range");
    }
    const int32_t id = add(Op::kNumber, at);
    out_.arena.nodes[static_cast<size_t>(id)].value = v;
    return id;
  }

  // The common case read in one pass: a number written without blanks inside it,
  // short enough to be exact by Clinger's fast path (see below), and not continued
  // after blanks ("X1 2" is X12) or by a second '.'. -1: any other number, for the
  // general reader.
  int32_t contiguous_number(int at) {
    size_t j = i_;
    const bool negative = s_[j] == '-';
    if (s_[j] == '+' || s_[j] == '-') ++j;
    uint64_t mantissa = 0;
    int digits = 0, decimals = 0;
    for (; j < s_.size() && is_digit(s_[j]); ++j, ++digits) mantissa = mantissa * 10 + static_cast<uint64_t>(s_[j] - '0');
    if (j < s_.size() && s_[j] == '.') {
      for (++j; j < s_.size() && is_digit(s_[j]); ++j, ++digits, ++decimals)
        mantissa = mantissa * 10 + static_cast<uint64_t>(s_[j] - '0');
    }
    if (digits == 0 || digits > 15 || decimals >= static_cast<int>(std::size(kPowersOf10))) return -1;
    size_t next = j;  // the cursor's rule: on the next non-blank character
    while (next < s_.size() && blank(s_[next])) ++next;
    if (next < s_.size() && (is_digit(s_[next]) || s_[next] == '.')) return -1;
    double v = static_cast<double>(mantissa) / kPowersOf10[decimals];  // 15 digits: below 2^53
    if (negative) v = -v;
    i_ = next;
    const int32_t id = add(Op::kNumber, at);
    out_.arena.nodes[static_cast<size_t>(id)].value = v;
    return id;
  }

  // '#' binds tighter than any operator: "#1+2" is (#1)+2 and "##2" reads #2 first.
  int32_t parameter(int depth) {
    const int at = col();
    advance();
    if (peek() == '<') {
      const int32_t id = add(Op::kNamedParam, at);
      std::string nm;
      name(&nm);
      out_.arena.nodes[static_cast<size_t>(id)].name = std::move(nm);
      return id;
    }
    if (end()) fail(at, "'#' without a parameter number");
    const int32_t index = real_value(depth);
    return add(Op::kParam, at, index);
  }

  int32_t function(int depth) {
    const int at = col();
    char nm[8];
    size_t n = 0;
    bool too_long = false;
    std::string written;
    while (is_letter(peek())) {
      if (n + 1 < sizeof nm) nm[n++] = peek();
      else too_long = true;
      written.push_back(upper(peek()));
      advance();
    }
    nm[n] = 0;
    Op op = Op::kNumber;
    bool known = false;
    if (!too_long) {
      for (const FunctionName& f : kFunctions) {
        if (std::string_view(nm) == f.name) {
          op = f.op;
          known = true;
          break;
        }
      }
    }
    if (!known) fail(at, "unknown function '" + written + "'");
    if (peek() != '[') fail(col(), "expected '[' after " + written + ", found " + found_here());
    if (op == Op::kExists) return exists(at, depth);
    const int32_t arg = expression(depth);
    if (op != Op::kAtan) return add(op, at, arg);
    if (peek() != '/') fail(col(), "expected '/' after ATAN[...] (ATAN[y]/[x]), found " + found_here());
    advance();
    if (peek() != '[') fail(col(), "expected '[' after ATAN[...]/, found " + found_here());
    const int32_t arg2 = expression(depth);
    return add(Op::kAtan, at, arg, arg2);
  }

  int32_t exists(int at, int depth) {
    advance();  // '['
    if (peek() != '#') fail(col(), "expected '#' inside EXISTS[...], found " + found_here());
    const int32_t id = add(Op::kExists, at);
    advance();
    if (peek() == '<') {
      std::string nm;
      name(&nm);
      out_.arena.nodes[static_cast<size_t>(id)].name = std::move(nm);
    } else {
      if (end()) fail(col(), "expected a parameter inside EXISTS[...], found the end of the line");
      const int32_t index = real_value(depth);
      out_.arena.nodes[static_cast<size_t>(id)].a = index;
    }
    if (peek() != ']') fail(col(), "expected ']' to close EXISTS[...], found " + found_here());
    advance();
    return id;
  }

  // [a op b op ...]: LinuxCNC's six levels, left to right within a level.
  int32_t expression(int depth) {
    if (depth > kMaxNesting) fail(col(), "expression nested too deeply");
    const int open = col();
    advance();
    const int32_t e = binary(2, depth, open);
    advance();  // binary() stops only at ']'
    return e;
  }

  // Precedence climbing: the operands and operators of levels >= `level`, left to
  // right within a level (the same tree, node for node in the same order, as one
  // recursive reader per level).
  int32_t binary(int level, int depth, int open) {
    int32_t left = real_value(depth);
    for (;;) {
      int at = 0;
      int len = 0;
      const Op op = peek_operator(open, &at, &len);
      const int p = precedence(op);  // 0 at ']'
      if (p < level) return left;
      for (int k = 0; k < len; ++k) advance();
      if (end()) fail(open, "missing ']' to close this '['");
      const int32_t right = binary(p + 1, depth, open);
      left = add(op, at, left, right);
    }
  }

  // The operator ahead, or kNumber at ']'. Anything else is an error here, as in
  // LinuxCNC's read_operation: an expression must continue or close.
  Op peek_operator(int open, int* at, int* len) const {
    *at = col();
    *len = 1;
    const char c = peek();
    switch (c) {
      case ']': return Op::kNumber;
      case '+': return Op::kAdd;
      case '-': return Op::kSub;
      case '/': return Op::kDiv;
      case '*':
        if (peek_at(1) == '*') {
          *len = 2;
          return Op::kPow;
        }
        return Op::kMul;
      case '\0': fail(open, "missing ']' to close this '['");
      default: break;
    }
    const char c1 = peek_at(1);
    *len = 2;
    if (c == 'o' && c1 == 'r') return Op::kOr;
    if (c == 'e' && c1 == 'q') return Op::kEq;
    if (c == 'n' && c1 == 'e') return Op::kNe;
    if (c == 'g' && c1 == 't') return Op::kGt;
    if (c == 'g' && c1 == 'e') return Op::kGe;
    if (c == 'l' && c1 == 't') return Op::kLt;
    if (c == 'l' && c1 == 'e') return Op::kLe;
    *len = 3;
    const char c2 = peek_at(2);
    if (c == 'a' && c1 == 'n' && c2 == 'd') return Op::kAnd;
    if (c == 'm' && c1 == 'o' && c2 == 'd') return Op::kMod;
    if (c == 'x' && c1 == 'o' && c2 == 'r') return Op::kXor;
    if (is_letter(c)) {
      std::string w;
      for (int k = 0; is_letter(peek_at(k)) && k < 12; ++k) w.push_back(upper(peek_at(k)));
      fail(*at, "unknown operator '" + w + "'");
    }
    fail(*at, "expected an operator or ']', found " + quoted(s_[i_]));
  }

  std::string_view s_;
  Line& out_;
  size_t i_ = 0;
};

}  // namespace

void lex_line(std::string_view text, Line& out) {
  out.clear();
  Reader(text, out).line();
}

}  // namespace cnc::rs274
