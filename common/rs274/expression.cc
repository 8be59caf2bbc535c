#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "common/rs274/lexer.h"
#include "common/rs274/parameters.h"

namespace cnc::rs274 {

namespace {

// LinuxCNC's TOLERANCE_EQUAL: EQ, NE, LE and GE treat closer values as equal
// (LE/GE since 2.9.0; LT and GT stay exact).
constexpr double kToleranceEqual = 1e-6;

// LinuxCNC converts degrees with M_PIl, so the product is a long double; doing the
// same keeps results identical to the last bit.
constexpr long double kPiL = 3.141592653589793238462643383279502884L;

double to_radians(double deg) { return static_cast<double>(static_cast<long double>(deg) * kPiL / 180.0L); }
// ((x * 180.0) / M_PIl): the product is a double (rounded), the division long double.
double to_degrees(double rad) { return static_cast<double>(static_cast<long double>(rad * 180.0) / kPiL); }

class Evaluator {
 public:
  Evaluator(const ExprArena& arena, const ParamReader& params) : arena_(arena), params_(params) {}

  double eval(int32_t id) const {
    const Node& n = node(id);
    const double v = compute(n);
    if (std::isnan(v)) throw Error(n.column, "calculation resulted in 'not a number'");
    if (std::isinf(v)) throw Error(n.column, "calculation resulted in 'infinity'");
    return v;
  }

 private:
  const Node& node(int32_t id) const {
    if (id < 0 || static_cast<size_t>(id) >= arena_.nodes.size()) throw Error(0, "expression refers to a missing node");
    return arena_.nodes[static_cast<size_t>(id)];
  }

  double compute(const Node& n) const {
    switch (n.op) {
      case Op::kNumber: return n.value;
      case Op::kParam: return params_.numbered(eval(n.a), n.column);
      case Op::kNamedParam: return params_.named(n.name, n.column);
      case Op::kExists:
        if (!n.name.empty()) return params_.exists(n.name) ? 1.0 : 0.0;
        return exists_numbered(eval(n.a));
      case Op::kNeg: return -eval(n.a);
      case Op::kAtan: {
        const double y = eval(n.a);
        const double x = eval(n.b);
        return to_degrees(std::atan2(y, x));
      }
      default: break;
    }
    if (n.b < 0) return unary(n, eval(n.a));
    const double l = eval(n.a);
    const double r = eval(n.b);
    return binary(n, l, r);
  }

  // LinuxCNC's EXISTS[#n]: whether n (an integer within 1e-4) names a parameter.
  static double exists_numbered(double index) {
    double f = std::floor(index);
    if (index - f > 0.9999) f = std::ceil(index);
    else if (index - f > 0.0001) return 0.0;
    return (f >= 1 && f <= 5601) ? 1.0 : 0.0;
  }

  static double unary(const Node& n, double x) {
    switch (n.op) {
      case Op::kAbs: return std::fabs(x);
      case Op::kAcos:
        if (x < -1.0 || x > 1.0) throw Error(n.column, "argument to ACOS out of range [-1, 1]: " + std::to_string(x));
        return to_degrees(std::acos(x));
      case Op::kAsin:
        if (x < -1.0 || x > 1.0) throw Error(n.column, "argument to ASIN out of range [-1, 1]: " + std::to_string(x));
        return to_degrees(std::asin(x));
      case Op::kCos: return std::cos(to_radians(x));
      case Op::kSin: return std::sin(to_radians(x));
      case Op::kTan: return std::tan(to_radians(x));
      case Op::kExp: return std::exp(x);
      case Op::kFix: return std::floor(x);
      case Op::kFup: return std::ceil(x);
      case Op::kLn:
        if (x <= 0.0) throw Error(n.column, "zero or negative argument to LN: " + std::to_string(x));
        return std::log(x);
      case Op::kSqrt:
        if (x < 0.0) throw Error(n.column, "negative argument to SQRT: " + std::to_string(x));
        return std::sqrt(x);
      // LinuxCNC truncates x +/- 0.5 toward zero (so 0.49999999999999994 rounds
      // to 1); it does so through an int, which this keeps exact beyond 2^31.
      case Op::kRound: return std::trunc(x + (x < 0.0 ? -0.5 : 0.5));
      default: throw Error(n.column, "unknown operation in expression");
    }
  }

  static double binary(const Node& n, double l, double r) {
    switch (n.op) {
      case Op::kPow:
        if (l < 0.0 && std::floor(r) != r)
          throw Error(n.column, "attempt to raise a negative number to a non-integer power");
        return std::pow(l, r);
      case Op::kMul: return l * r;
      case Op::kDiv:
        if (r == 0.0) throw Error(n.column, "division by zero");
        return l / r;
      case Op::kMod: {
        if (r == 0.0) throw Error(n.column, "MOD by zero");
        // LinuxCNC: fmod, then a negative result moves up by |r|.
        double m = std::fmod(l, r);
        if (m < 0.0) m += std::fabs(r);
        return m;
      }
      case Op::kAdd: return l + r;
      case Op::kSub: return l - r;
      case Op::kEq: return std::fabs(l - r) < kToleranceEqual ? 1.0 : 0.0;
      case Op::kNe: return std::fabs(l - r) >= kToleranceEqual ? 1.0 : 0.0;
      case Op::kGt: return l > r ? 1.0 : 0.0;
      case Op::kGe: return (std::fabs(l - r) < kToleranceEqual || l >= r) ? 1.0 : 0.0;
      case Op::kLt: return l < r ? 1.0 : 0.0;
      case Op::kLe: return (std::fabs(l - r) < kToleranceEqual || l <= r) ? 1.0 : 0.0;
      case Op::kAnd: return (l == 0.0 || r == 0.0) ? 0.0 : 1.0;
      case Op::kOr: return (l != 0.0 || r != 0.0) ? 1.0 : 0.0;
      case Op::kXor: return ((l == 0.0) != (r == 0.0)) ? 1.0 : 0.0;
      default: throw Error(n.column, "unknown operation in expression");
    }
  }

  const ExprArena& arena_;
  const ParamReader& params_;
};

int text_precedence(const Node& n) {
  switch (n.op) {
    case Op::kPow: return 6;
    case Op::kMul: case Op::kDiv: case Op::kMod: return 5;
    case Op::kAdd: case Op::kSub: return 4;
    case Op::kEq: case Op::kNe: case Op::kGt: case Op::kGe: case Op::kLt: case Op::kLe: return 3;
    case Op::kAnd: case Op::kOr: case Op::kXor: return 2;
    default: return 0;  // not binary
  }
}

const char* op_text(Op op) {
  switch (op) {
    case Op::kPow: return "**";
    case Op::kMul: return "*";
    case Op::kDiv: return "/";
    case Op::kMod: return " MOD ";
    case Op::kAdd: return "+";
    case Op::kSub: return "-";
    case Op::kEq: return " EQ ";
    case Op::kNe: return " NE ";
    case Op::kGt: return " GT ";
    case Op::kGe: return " GE ";
    case Op::kLt: return " LT ";
    case Op::kLe: return " LE ";
    case Op::kAnd: return " AND ";
    case Op::kOr: return " OR ";
    case Op::kXor: return " XOR ";
    case Op::kAbs: return "ABS";
    case Op::kAcos: return "ACOS";
    case Op::kAsin: return "ASIN";
    case Op::kAtan: return "ATAN";
    case Op::kCos: return "COS";
    case Op::kExp: return "EXP";
    case Op::kFix: return "FIX";
    case Op::kFup: return "FUP";
    case Op::kLn: return "LN";
    case Op::kRound: return "ROUND";
    case Op::kSin: return "SIN";
    case Op::kSqrt: return "SQRT";
    case Op::kTan: return "TAN";
    default: return "?";
  }
}

class Printer {
 public:
  explicit Printer(const ExprArena& arena) : arena_(arena) {}

  // A binary expression standing alone is shown in the brackets it needs anyway.
  void value(int32_t id) {
    const Node* n = get(id);
    if (n && text_precedence(*n) > 0) {
      out += '[';
      inner(id);
      out += ']';
    } else {
      inner(id);
    }
  }

  // Inside brackets: only sub-expressions that bind looser than their parent (or
  // as loosely, on the right, since evaluation runs left to right) get brackets.
  void inner(int32_t id) {
    const Node* n = get(id);
    if (!n) {
      out += '?';
      return;
    }
    const int p = text_precedence(*n);
    if (p > 0) {
      operand(n->a, p, false);
      out += op_text(n->op);
      operand(n->b, p, true);
      return;
    }
    switch (n->op) {
      case Op::kNumber: number(n->value); return;
      case Op::kParam: out += '#'; value(n->a); return;
      case Op::kNamedParam: out += "#<" + n->name + ">"; return;
      case Op::kExists:
        out += "EXISTS[#";
        if (n->name.empty()) value(n->a);
        else out += "<" + n->name + ">";
        out += ']';
        return;
      case Op::kNeg: out += '-'; value(n->a); return;
      case Op::kAtan:
        out += "ATAN[";
        inner(n->a);
        out += "]/[";
        inner(n->b);
        out += ']';
        return;
      default:
        out += op_text(n->op);
        out += '[';
        inner(n->a);
        out += ']';
        return;
    }
  }

  std::string out;

 private:
  const Node* get(int32_t id) const {
    if (id < 0 || static_cast<size_t>(id) >= arena_.nodes.size()) return nullptr;
    return &arena_.nodes[static_cast<size_t>(id)];
  }

  void operand(int32_t id, int parent, bool right) {
    const Node* n = get(id);
    const int p = n ? text_precedence(*n) : 0;
    if (p > 0 && (p < parent || (right && p == parent))) {
      out += '[';
      inner(id);
      out += ']';
    } else {
      inner(id);
    }
  }

  void number(double v) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
  }

  const ExprArena& arena_;
};

}  // namespace

double evaluate(const ExprArena& arena, int32_t root, const ParamReader& params) {
  return Evaluator(arena, params).eval(root);
}

std::string to_text(const ExprArena& arena, int32_t root) {
  Printer p(arena);
  p.value(root);
  return p.out;
}

// #n and #<name> in the text are replaced by their values, as LinuxCNC's
// convert_param_comment: "%lf" until a %d (%.0f), %f (%.4f) or %.Nf changes the
// format for the rest of the text; a value within TOLERANCE_EQUAL of 0 prints as 0
// (no "-0.000000"); a parameter that does not exist prints "######".
std::string expand_parameters(const std::string& t, int column, const ParamReader& params) {
  std::string out;
  std::string format = "%lf";
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
    if (j >= t.size()) throw Error(column, "named parameter not terminated in a DEBUG/PRINT comment");
    if (t[j] == '<') {
      const size_t e = t.find('>', j);
      if (e == std::string::npos) throw Error(column, "named parameter not terminated in a DEBUG/PRINT comment");
      std::string name;
      for (size_t k = j + 1; k < e; ++k)
        if (!std::isspace(static_cast<unsigned char>(t[k])))
          name += static_cast<char>(std::tolower(static_cast<unsigned char>(t[k])));
      const bool found = params.exists(name);
      put_value(found, found ? params.named(name, column) : 0.0);
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
    put_value(found, n >= 1 && found ? params.numbered(static_cast<double>(n), column) : 0.0);
    i = k - 1;
  }
  return out;
}

}  // namespace cnc::rs274
