#include "lapflow/core/rule.hpp"

#include <charconv>
#include <cmath>
#include <limits>

#include "lapflow/core/errors.hpp"

namespace lapflow {

RuleError::RuleError(int column, const std::string& message)
    : std::runtime_error("column " + std::to_string(column) + ": " + message), column_(column) {}

namespace {

/// Byte length of the UTF-8 character starting at `pos`; 1 for a byte that
/// does not start a well-formed sequence (it then counts as one character).
std::size_t char_length(std::string_view s, std::size_t pos) {
  const auto c = static_cast<unsigned char>(s[pos]);
  const std::size_t n = c >= 0xc2 && c <= 0xdf ? 2 : c >= 0xe0 && c <= 0xef ? 3 : c >= 0xf0 && c <= 0xf4 ? 4 : 1;
  if (pos + n > s.size()) return 1;
  for (std::size_t k = 1; k < n; ++k)
    if ((static_cast<unsigned char>(s[pos + k]) & 0xc0) != 0x80) return 1;
  return n;
}

bool is_rule_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f'; }
bool is_digit(char c) { return c >= '0' && c <= '9'; }
bool is_name_start(char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_'; }
bool is_name_char(char c) { return is_name_start(c) || is_digit(c); }

/// Deepest nesting of parentheses, `not`, unary signs and calls: bounds the
/// parser's recursion on hostile input such as ten thousand '('.
constexpr int kMaxNesting = 2 * Rule::kStack;

}  // namespace

/// Recursive descent over the text, one token of look-ahead, emitting the
/// postfix program as it goes. Each level returns the type and the byte range
/// of what it parsed, so a type error can quote the offending operand.
struct Rule::Parser {
  enum class Tok {
    kEnd, kNumber, kName, kAnd, kOr, kNot, kTrue, kFalse, kOpen, kClose, kComma,
    kPlus, kMinus, kStar, kSlash, kLt, kLe, kGt, kGe, kEq, kNe
  };
  struct Token {
    Tok kind = Tok::kEnd;
    std::size_t begin = 0, end = 0;  ///< bytes in the text
    double number = 0;
  };
  enum class Type { kNumber, kCondition };
  struct Expr {
    Type type;
    std::size_t begin, end;
  };

  std::string_view text;
  Rule& rule;
  Token tok;
  int stack_depth = 0;  ///< values on the evaluation stack after the program so far
  int nesting = 0;
  int open_parens = 0;

  /// 1-based column of byte `pos`, in characters.
  int column(std::size_t pos) const {
    int col = 1;
    for (std::size_t i = 0; i < pos && i < text.size(); i += char_length(text, i)) ++col;
    return col;
  }
  [[noreturn]] void fail(std::size_t pos, const std::string& message) const { throw RuleError(column(pos), message); }
  std::string_view spelling(const Token& t) const { return text.substr(t.begin, t.end - t.begin); }
  std::string quoted(std::size_t begin, std::size_t end) const {
    return quote_token(text.substr(begin, end - begin));
  }

  // ---- tokens -------------------------------------------------------------
  void advance() {
    std::size_t p = tok.end;
    while (p < text.size() && is_rule_space(text[p])) ++p;
    tok = Token{Tok::kEnd, p, p, 0};
    if (p == text.size()) return;
    const char c = text[p];
    const char next = p + 1 < text.size() ? text[p + 1] : '\0';
    if (is_digit(c) || (c == '.' && is_digit(next))) return lex_number(p);
    if (is_name_start(c)) {
      std::size_t e = p;
      while (e < text.size() && is_name_char(text[e])) ++e;
      const std::string_view word = text.substr(p, e - p);
      const Tok kind = word == "and" ? Tok::kAnd : word == "or" ? Tok::kOr : word == "not" ? Tok::kNot
                     : word == "true" ? Tok::kTrue : word == "false" ? Tok::kFalse : Tok::kName;
      tok = Token{kind, p, e, 0};
      return;
    }
    auto one = [&](Tok kind) { tok = Token{kind, p, p + 1, 0}; };
    auto two = [&](Tok kind) { tok = Token{kind, p, p + 2, 0}; };
    switch (c) {
      case '(': return one(Tok::kOpen);
      case ')': return one(Tok::kClose);
      case ',': return one(Tok::kComma);
      case '+': return one(Tok::kPlus);
      case '-': return one(Tok::kMinus);
      case '*': return one(Tok::kStar);
      case '/': return one(Tok::kSlash);
      case '<': return next == '=' ? two(Tok::kLe) : one(Tok::kLt);
      case '>': return next == '=' ? two(Tok::kGe) : one(Tok::kGt);
      case '!': return next == '=' ? two(Tok::kNe) : one(Tok::kNot);
      case '=':
        if (next == '=') return two(Tok::kEq);
        fail(p, "'=' is not a comparison: write '=='");
      case '&':
        if (next == '&') return two(Tok::kAnd);
        fail(p, "'&' is not an operator: write 'and' or '&&'");
      case '|':
        if (next == '|') return two(Tok::kOr);
        fail(p, "'|' is not an operator: write 'or' or '||'");
      default: break;
    }
    const std::size_t n = char_length(text, p);
    // A well-formed non-ASCII character is shown as itself; the CLI keeps valid UTF-8.
    const std::string shown = n > 1 ? "'" + std::string(text.substr(p, n)) + "'" : quote_token(text.substr(p, 1));
    fail(p, shown + " is not allowed in a rule");
  }

  void lex_number(std::size_t p) {
    std::size_t e = p;
    while (e < text.size() && is_digit(text[e])) ++e;
    if (e < text.size() && text[e] == '.') {
      ++e;
      while (e < text.size() && is_digit(text[e])) ++e;
    }
    bool bad = false;
    if (e < text.size() && (text[e] == 'e' || text[e] == 'E')) {
      std::size_t d = e + 1;
      if (d < text.size() && (text[d] == '+' || text[d] == '-')) ++d;
      if (d < text.size() && is_digit(text[d])) {
        e = d;
        while (e < text.size() && is_digit(text[e])) ++e;
      } else {
        e = d;
        bad = true;
      }
    }
    // "2x", "1.5.2", "1e": quote the whole run so the message shows what was written.
    std::size_t run = e;
    while (run < text.size() && (is_name_char(text[run]) || text[run] == '.')) ++run;
    if (bad || run != e) fail(p, quoted(p, run) + " is not a number");
    double value = 0;
    const auto [ptr, ec] = std::from_chars(text.data() + p, text.data() + e, value);
    // Rounded to float like the attributes it is compared with.
    const float rounded = static_cast<float>(value);
    if (ec != std::errc() || ptr != text.data() + e || !std::isfinite(rounded))
      fail(p, quoted(p, e) + " is too large: numbers go up to 3.4e38");
    tok = Token{Tok::kNumber, p, e, rounded};
  }

  // ---- program --------------------------------------------------------------
  /// Appends one instruction; `at` is the byte the user sees as its cause.
  void emit(Op op, std::size_t at, int name = 0, double constant = 0) {
    switch (op) {
      case Op::kConst:
      case Op::kName: ++stack_depth; break;
      case Op::kNeg:
      case Op::kAbs:
      case Op::kNot: break;
      default: --stack_depth; break;  // binary: two values in, one out
    }
    if (stack_depth > kStack)
      fail(at, "the rule nests too deeply (more than " + std::to_string(kStack) + " values pending)");
    rule.program_.push_back(Instr{op, name, constant});
  }

  int name_index(std::string_view name) {
    for (std::size_t k = 0; k < rule.names_.size(); ++k)
      if (rule.names_[k] == name) return int(k);
    rule.names_.emplace_back(name);
    return int(rule.names_.size()) - 1;
  }

  void need(const Expr& e, Type type) const {
    if (e.type == type) return;
    const std::string q = quoted(e.begin, e.end);
    if (type == Type::kNumber) fail(e.begin, q + " is a condition, not a number");
    const std::string_view raw = text.substr(e.begin, e.end - e.begin);
    const std::string example = raw.size() <= 24 && raw.find_first_of("\t\n\r\v\f") == std::string_view::npos
                                    ? " (e.g. " + std::string(raw) + " > 1)"
                                    : " with '>', '<', '==' ...";
    fail(e.begin, q + " is a number, not a condition: compare it" + example);
  }

  /// Guards one level of recursion against hostile nesting.
  struct Nest {
    Parser& p;
    Nest(Parser& parser, std::size_t at) : p(parser) {
      if (++p.nesting > kMaxNesting) p.fail(at, "the rule nests too deeply");
    }
    ~Nest() { --p.nesting; }
    Nest(const Nest&) = delete;
    Nest& operator=(const Nest&) = delete;
  };

  /// Fails on `tok`, which should have continued the parentheses opened at byte `open`.
  [[noreturn]] void fail_inside(std::size_t open, const char* expected) const {
    if (tok.kind == Tok::kEnd)
      fail(tok.begin, "'(' at column " + std::to_string(column(open)) + " is not closed");
    fail(tok.begin, "unexpected " + quote_token(spelling(tok)) + ": expected " + expected);
  }

  /// Consumes the ')' closing the '(' at byte `open`; returns the byte after it.
  std::size_t close(std::size_t open, const char* expected) {
    if (tok.kind != Tok::kClose) fail_inside(open, expected);
    const std::size_t end = tok.end;
    --open_parens;
    advance();
    return end;
  }

  // ---- grammar, loosest first ----------------------------------------------
  Expr parse_or() {
    Expr lhs = parse_and();
    while (tok.kind == Tok::kOr) {
      const std::size_t at = tok.begin;
      need(lhs, Type::kCondition);
      advance();
      const Expr rhs = parse_and();
      need(rhs, Type::kCondition);
      emit(Op::kOr, at);
      lhs = {Type::kCondition, lhs.begin, rhs.end};
    }
    return lhs;
  }

  Expr parse_and() {
    Expr lhs = parse_not();
    while (tok.kind == Tok::kAnd) {
      const std::size_t at = tok.begin;
      need(lhs, Type::kCondition);
      advance();
      const Expr rhs = parse_not();
      need(rhs, Type::kCondition);
      emit(Op::kAnd, at);
      lhs = {Type::kCondition, lhs.begin, rhs.end};
    }
    return lhs;
  }

  Expr parse_not() {
    if (tok.kind != Tok::kNot) return parse_comparison();
    const std::size_t at = tok.begin;
    const Nest nest(*this, at);
    advance();
    const Expr e = parse_not();
    need(e, Type::kCondition);
    emit(Op::kNot, at);
    return {Type::kCondition, at, e.end};
  }

  static bool is_comparison(Tok t) {
    return t == Tok::kLt || t == Tok::kLe || t == Tok::kGt || t == Tok::kGe || t == Tok::kEq || t == Tok::kNe;
  }

  Expr parse_comparison() {
    const Expr lhs = parse_sum();
    if (!is_comparison(tok.kind)) return lhs;
    const Token op = tok;
    need(lhs, Type::kNumber);
    advance();
    const Expr rhs = parse_sum();
    need(rhs, Type::kNumber);
    const Op code = op.kind == Tok::kLt ? Op::kLt : op.kind == Tok::kLe ? Op::kLe : op.kind == Tok::kGt ? Op::kGt
                  : op.kind == Tok::kGe ? Op::kGe : op.kind == Tok::kEq ? Op::kEq : Op::kNe;
    emit(code, op.begin);
    if (is_comparison(tok.kind))
      fail(tok.begin, "comparisons do not chain: write 'a < b and b < c'");
    return {Type::kCondition, lhs.begin, rhs.end};
  }

  Expr parse_sum() {
    Expr lhs = parse_product();
    while (tok.kind == Tok::kPlus || tok.kind == Tok::kMinus) {
      const Token op = tok;
      need(lhs, Type::kNumber);
      advance();
      const Expr rhs = parse_product();
      need(rhs, Type::kNumber);
      emit(op.kind == Tok::kPlus ? Op::kAdd : Op::kSub, op.begin);
      lhs = {Type::kNumber, lhs.begin, rhs.end};
    }
    return lhs;
  }

  Expr parse_product() {
    Expr lhs = parse_unary();
    while (tok.kind == Tok::kStar || tok.kind == Tok::kSlash) {
      const Token op = tok;
      need(lhs, Type::kNumber);
      advance();
      const Expr rhs = parse_unary();
      need(rhs, Type::kNumber);
      emit(op.kind == Tok::kStar ? Op::kMul : Op::kDiv, op.begin);
      lhs = {Type::kNumber, lhs.begin, rhs.end};
    }
    return lhs;
  }

  Expr parse_unary() {
    if (tok.kind != Tok::kPlus && tok.kind != Tok::kMinus) return parse_primary();
    const Token op = tok;
    const Nest nest(*this, op.begin);
    advance();
    const Expr e = parse_unary();
    need(e, Type::kNumber);
    if (op.kind == Tok::kMinus) emit(Op::kNeg, op.begin);
    return {Type::kNumber, op.begin, e.end};
  }

  Expr parse_primary() {
    const Token t = tok;
    switch (t.kind) {
      case Tok::kNumber:
        emit(Op::kConst, t.begin, 0, t.number);
        advance();
        return {Type::kNumber, t.begin, t.end};
      case Tok::kTrue:
      case Tok::kFalse:
        emit(Op::kConst, t.begin, 0, t.kind == Tok::kTrue ? 1 : 0);
        advance();
        return {Type::kCondition, t.begin, t.end};
      case Tok::kName:
        advance();
        if (tok.kind == Tok::kOpen) return parse_call(t);
        emit(Op::kName, t.begin, name_index(spelling(t)));
        return {Type::kNumber, t.begin, t.end};
      case Tok::kOpen: {
        const Nest nest(*this, t.begin);
        ++open_parens;
        advance();
        const Expr inner = parse_or();
        return {inner.type, t.begin, close(t.begin, "an operator or ')'")};
      }
      case Tok::kEnd: fail(t.begin, "the rule ends where a value is expected");
      case Tok::kClose:
        if (open_parens == 0) fail(t.begin, "')' closes nothing");
        fail(t.begin, "expected a value before ')'");
      default: fail(t.begin, "expected a value, found " + quote_token(spelling(t)));
    }
  }

  /// `name(` ... with `tok` at the '('.
  Expr parse_call(const Token& name) {
    const std::string_view f = spelling(name);
    const int arity = f == "abs" ? 1 : (f == "min" || f == "max") ? 2 : 0;
    if (arity == 0) fail(name.begin, quote_token(f) + " is not a function: abs, min, max");
    const std::string usage = std::string(f) + (arity == 1 ? "(x)" : "(a, b)");
    const std::string takes = "'" + std::string(f) + "' takes " + (arity == 1 ? "one number" : "two numbers") +
                              ": " + usage;
    const std::size_t open = tok.begin;
    const Nest nest(*this, open);
    ++open_parens;
    advance();
    for (int k = 0; k < arity; ++k) {
      if (k > 0) {
        if (tok.kind == Tok::kClose) fail(tok.begin, takes);
        if (tok.kind != Tok::kComma) fail_inside(open, "',' or an operator");
        advance();
      }
      need(parse_or(), Type::kNumber);
    }
    if (tok.kind == Tok::kComma) fail(tok.begin, takes);
    const std::size_t end = close(open, "an operator or ')'");
    emit(arity == 1 ? Op::kAbs : f == "min" ? Op::kMin : Op::kMax, name.begin);
    return {Type::kNumber, name.begin, end};
  }
};

Rule Rule::parse(std::string_view text) {
  Rule rule;
  rule.text_ = std::string(text);
  Parser p{text, rule, {}};
  p.advance();
  if (p.tok.kind == Parser::Tok::kEnd) throw RuleError(1, "the rule is empty");
  const Parser::Expr e = p.parse_or();
  if (p.tok.kind == Parser::Tok::kClose) p.fail(p.tok.begin, "')' closes nothing");
  if (p.tok.kind != Parser::Tok::kEnd)
    p.fail(p.tok.begin, "unexpected " + quote_token(p.spelling(p.tok)) + ": expected an operator or the end of the rule");
  p.need(e, Parser::Type::kCondition);
  return rule;
}

bool Rule::holds(const float* values) const {
  if (program_.empty()) return true;
  double stack[kStack];
  int top = 0;  // values on the stack; parse() proved it stays within kStack
  for (const Instr& in : program_) {
    switch (in.op) {
      case Op::kConst: stack[top++] = in.constant; continue;
      case Op::kName: stack[top++] = values[in.name]; continue;
      case Op::kNeg: stack[top - 1] = -stack[top - 1]; continue;
      case Op::kAbs: stack[top - 1] = std::fabs(stack[top - 1]); continue;
      case Op::kNot: stack[top - 1] = stack[top - 1] == 0 ? 1 : 0; continue;
      default: break;
    }
    const double b = stack[--top];
    double& a = stack[top - 1];
    switch (in.op) {
      case Op::kAdd: a = a + b; break;
      case Op::kSub: a = a - b; break;
      case Op::kMul: a = a * b; break;
      case Op::kDiv: a = a / b; break;
      // NaN in, NaN out (std::fmin would drop it), so a comparison on it fails.
      case Op::kMin: a = std::isnan(b) ? b : (b < a ? b : a); break;
      case Op::kMax: a = std::isnan(b) ? b : (b > a ? b : a); break;
      case Op::kLt: a = a < b; break;
      case Op::kLe: a = a <= b; break;
      case Op::kGt: a = a > b; break;
      case Op::kGe: a = a >= b; break;
      case Op::kEq: a = a == b; break;
      case Op::kNe: a = a != b; break;
      case Op::kAnd: a = a != 0 && b != 0; break;
      case Op::kOr: a = a != 0 || b != 0; break;
      default: break;
    }
  }
  return stack[0] != 0;
}

}  // namespace lapflow
