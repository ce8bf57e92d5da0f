#pragma once
/// \file rule.hpp Conditions over per-vertex attributes that artists write to
/// choose an exemplar layer, e.g. `speed > 1.5 and curvature > 20`.
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace lapflow {

/// A rule's syntax or type error. what() is "column N: ...", N the 1-based
/// column in the rule's text, counted in characters (a tab counts as one).
class RuleError : public std::runtime_error {
 public:
  RuleError(int column, const std::string& message);
  int column() const { return column_; }

 private:
  int column_;
};

/// A boolean expression over named per-vertex attributes.
///
/// Grammar, loosest binding first: `or` (`||`); `and` (`&&`); `not` (`!`);
/// one comparison `< <= > >= == !=` between two numbers (no chains); `+ -`;
/// `* /`; unary `- +`; then numbers (`20`, `1.5`, `.5`, `1e-3`), attribute
/// names `[A-Za-z_][A-Za-z0-9_]*`, `true`, `false`, parentheses, `abs(x)`,
/// `min(a, b)` and `max(a, b)`. Keywords (and, or, not, true, false) are not
/// names; abs, min and max are names when not called.
///
/// Evaluation is in double precision. Number literals are first rounded to
/// float, like the attributes, so `foam == 0.1` holds for a stored 0.1f.
/// Arithmetic and functions pass NaN through; every comparison with NaN is
/// false except `!=`, which is true (IEEE 754).
class Rule {
 public:
  /// The empty rule: empty() is true and it holds everywhere.
  Rule() = default;
  /// Parses and checks `text`; throws RuleError naming the column of the
  /// first mistake.
  static Rule parse(std::string_view text);

  const std::string& text() const { return text_; }
  /// The attribute names the rule reads, each once, in order of first appearance.
  const std::vector<std::string>& names() const { return names_; }
  /// Evaluates the rule with values[k] the value of names()[k]. No allocation.
  bool holds(const float* values) const;
  bool empty() const { return program_.empty(); }

  /// Deepest evaluation stack a rule may need; parse() rejects deeper rules.
  static constexpr int kStack = 64;

 private:
  /// One postfix instruction; booleans are 0 and 1 on the stack.
  enum class Op : std::uint8_t {
    kConst, kName, kNeg, kAbs, kAdd, kSub, kMul, kDiv, kMin, kMax,
    kLt, kLe, kGt, kGe, kEq, kNe, kNot, kAnd, kOr
  };
  struct Instr {
    Op op = Op::kConst;
    int name = 0;         ///< index into names_ for kName
    double constant = 0;  ///< value for kConst
  };
  struct Parser;  // rule.cpp: recursive descent straight to the postfix program

  std::string text_;
  std::vector<std::string> names_;
  std::vector<Instr> program_;
};

}  // namespace lapflow
