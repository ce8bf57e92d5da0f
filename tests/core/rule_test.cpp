// Rule: parsing, typing and evaluation of the attribute conditions artists write.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "lapflow/core/rule.hpp"

using namespace lapflow;

namespace {

/// Evaluates `text` with the named values (names the rule does not read are ignored).
bool eval(const std::string& text, const std::map<std::string, float>& values) {
  const Rule rule = Rule::parse(text);
  std::vector<float> v;
  for (const std::string& name : rule.names()) {
    const auto it = values.find(name);
    EXPECT_NE(it, values.end()) << "no value for " << name << " in " << text;
    v.push_back(it == values.end() ? 0.0f : it->second);
  }
  return rule.holds(v.data());
}

/// Asserts that parsing `text` fails at `column` with a message containing `part`.
void expect_error(const std::string& text, int column, const std::string& part) {
  SCOPED_TRACE("rule: " + text);
  try {
    Rule::parse(text);
    ADD_FAILURE() << "parsed without error";
  } catch (const RuleError& e) {
    EXPECT_EQ(e.column(), column) << e.what();
    const std::string what = e.what();
    const std::string prefix = "column " + std::to_string(column) + ":";
    EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
    EXPECT_NE(what.find(part), std::string::npos) << what;
  }
}

}  // namespace

TEST(Rule, EmptyRuleHoldsEverywhere) {
  const Rule rule;
  EXPECT_TRUE(rule.empty());
  EXPECT_TRUE(rule.names().empty());
  EXPECT_TRUE(rule.holds(nullptr));
  EXPECT_FALSE(Rule::parse("true").empty());
  EXPECT_TRUE(Rule::parse("true").holds(nullptr));
  EXPECT_FALSE(Rule::parse("false").holds(nullptr));
  EXPECT_EQ(Rule::parse("  speed > 1.5 ").text(), "  speed > 1.5 ");
}

TEST(Rule, AndBindsTighterThanOrAndNotTighterThanAnd) {
  // a > 1 or (b > 1 and c > 1)
  const std::string rule = "a > 1 or b > 1 and c > 1";
  EXPECT_TRUE(eval(rule, {{"a", 2}, {"b", 0}, {"c", 0}}));
  EXPECT_FALSE(eval(rule, {{"a", 0}, {"b", 2}, {"c", 0}}));
  EXPECT_TRUE(eval(rule, {{"a", 0}, {"b", 2}, {"c", 2}}));
  EXPECT_TRUE(eval("a > 1 || b > 1 && c > 1", {{"a", 0}, {"b", 2}, {"c", 2}}));
  // not (a > 1) and b > 1, not not ((a > 1) and (b > 1)).
  EXPECT_TRUE(eval("not a > 1 and b > 1", {{"a", 0}, {"b", 2}}));
  EXPECT_FALSE(eval("not a > 1 and b > 1", {{"a", 2}, {"b", 2}}));
  EXPECT_TRUE(eval("!a > 1", {{"a", 0}}));
  EXPECT_TRUE(eval("not not a > 1", {{"a", 2}}));
  EXPECT_TRUE(eval("foam >= 0.5 or (temperature > 900 and not age < 2)",
                   {{"foam", 0}, {"temperature", 1000}, {"age", 3}}));
  EXPECT_FALSE(eval("foam >= 0.5 or (temperature > 900 and not age < 2)",
                    {{"foam", 0}, {"temperature", 1000}, {"age", 1}}));
}

TEST(Rule, ParenthesesOverridePrecedence) {
  const std::string rule = "(a > 1 or b > 1) and c > 1";
  EXPECT_FALSE(eval(rule, {{"a", 2}, {"b", 0}, {"c", 0}}));
  EXPECT_TRUE(eval(rule, {{"a", 2}, {"b", 0}, {"c", 2}}));
  EXPECT_TRUE(eval("not (a > 1 and b > 1)", {{"a", 2}, {"b", 0}}));
  EXPECT_TRUE(eval("((((a)))) * (2 + 1) == 6", {{"a", 2}}));
}

TEST(Rule, ArithmeticFollowsUsualPrecedence) {
  EXPECT_TRUE(eval("a + b * c == 7", {{"a", 1}, {"b", 2}, {"c", 3}}));
  EXPECT_TRUE(eval("(a + b) * c == 9", {{"a", 1}, {"b", 2}, {"c", 3}}));
  EXPECT_TRUE(eval("a - b - c == -4", {{"a", 1}, {"b", 2}, {"c", 3}}));  // left to right
  EXPECT_TRUE(eval("a / b / c == 1", {{"a", 6}, {"b", 2}, {"c", 3}}));
  EXPECT_TRUE(eval("-a * -b == 6 and - - a == 2 and +a == 2", {{"a", 2}, {"b", 3}}));
  EXPECT_TRUE(eval("2 * speed > 1.5", {{"speed", 1}}));
  EXPECT_FALSE(eval("speed > 1.5 and curvature > 20", {{"speed", 2}, {"curvature", 10}}));
  EXPECT_TRUE(eval("speed > 1.5 and curvature > 20", {{"speed", 2}, {"curvature", 30}}));
  EXPECT_TRUE(eval("1 / a > 1e30", {{"a", 0}})) << "division by zero is +inf, as IEEE says";
}

TEST(Rule, FunctionsAbsMinMax) {
  EXPECT_TRUE(eval("abs(v) == 3", {{"v", -3}}));
  EXPECT_TRUE(eval("abs(-v - 1) == 4", {{"v", 3}}));
  EXPECT_TRUE(eval("min(a, b) == 1 and max(a, b) == 4", {{"a", 4}, {"b", 1}}));
  EXPECT_TRUE(eval("max(abs(a), min(b, 2 * c)) == 6", {{"a", -5}, {"b", 7}, {"c", 3}}));
  EXPECT_TRUE(eval("min ( a , b ) < 0", {{"a", -1}, {"b", 1}}));
  // Uncalled, abs/min/max are ordinary attribute names.
  EXPECT_TRUE(eval("min > 1 and max(min, 0) > 1", {{"min", 2}}));
}

TEST(Rule, NamesAreListedOnceInOrderOfFirstAppearance) {
  const Rule rule = Rule::parse("speed > 1 and (foam < speed or max(age, foam) > 2) and not_a_keyword == 0");
  EXPECT_EQ(rule.names(), (std::vector<std::string>{"speed", "foam", "age", "not_a_keyword"}));
  const float values[] = {2, 0, 3, 0};
  EXPECT_TRUE(rule.holds(values));
  EXPECT_TRUE(Rule::parse("true or 1 > 2").names().empty());
  EXPECT_EQ(Rule::parse("_x1 > X_2").names(), (std::vector<std::string>{"_x1", "X_2"}));
}

TEST(Rule, ComparisonsWithNaNAreFalseExceptNotEqual) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const char* op : {"<", "<=", ">", ">=", "=="}) {
    EXPECT_FALSE(eval(std::string("a ") + op + " 1", {{"a", nan}})) << op;
    EXPECT_FALSE(eval(std::string("1 ") + op + " a", {{"a", nan}})) << op;
  }
  EXPECT_TRUE(eval("a != 1", {{"a", nan}}));
  EXPECT_TRUE(eval("a != a", {{"a", nan}}));
  EXPECT_TRUE(eval("not a > 1", {{"a", nan}}));
  // NaN passes through arithmetic and functions, whichever side it is on.
  EXPECT_FALSE(eval("a + 1 > 0 or abs(a) >= 0", {{"a", nan}}));
  EXPECT_FALSE(eval("min(a, 1) <= 1 or min(1, a) <= 1", {{"a", nan}}));
  EXPECT_FALSE(eval("max(a, 1) >= 1 or max(1, a) >= 1", {{"a", nan}}));
}

TEST(Rule, NumberLiterals) {
  EXPECT_TRUE(eval("a == 1e-3", {{"a", 1e-3f}}));
  EXPECT_TRUE(eval("a == .5 and a == 0.5 and a == 5e-1 and a == 5.E-1 and a == 0.05e+1", {{"a", 0.5f}}));
  EXPECT_TRUE(eval("a == 20 and a == 20. and a == 2e1", {{"a", 20}}));
  // Literals are rounded to float like the attributes they meet.
  EXPECT_TRUE(eval("a == 0.1 and a <= 0.1", {{"a", 0.1f}}));
  EXPECT_TRUE(eval("a > 1e-50", {{"a", 1e-30f}})) << "too small for a float: rounds to 0";
  expect_error("a > 1e39", 5, "'1e39' is too large");
  expect_error("a > 1e999", 5, "'1e999' is too large");
  expect_error("a > 2x", 5, "'2x' is not a number");
  expect_error("a > 1.5.2", 5, "'1.5.2' is not a number");
  expect_error("a > 1e", 5, "'1e' is not a number");
  expect_error("a > 1e+", 5, "'1e+' is not a number");
}

TEST(Rule, TypeErrorsPointAtTheOperand) {
  expect_error("speed", 1, "column 1: 'speed' is a number, not a condition: compare it (e.g. speed > 1)");
  expect_error("speed > 1 + (a > 2)", 13, "'(a > 2)' is a condition, not a number");
  expect_error("speed + 1", 1, "'speed + 1' is a number, not a condition");
  expect_error("a > 1 and b", 11, "'b' is a number, not a condition");
  expect_error("b or a > 1", 1, "'b' is a number, not a condition");
  expect_error("not speed", 5, "'speed' is a number, not a condition");
  expect_error("-(a > 1)", 2, "is a condition, not a number");
  expect_error("(a > 1) > 2", 1, "'(a > 1)' is a condition, not a number");
  expect_error("abs(a > 1) > 2", 5, "'a > 1' is a condition, not a number");
  expect_error("true * 2 > 1", 1, "'true' is a condition, not a number");
}

TEST(Rule, OperatorMistakes) {
  expect_error("speed = 2", 7, "'=' is not a comparison: write '=='");
  expect_error("a > 1 & b > 1", 7, "'&' is not an operator");
  expect_error("a > 1 | b > 1", 7, "'|' is not an operator");
  expect_error("a < b < c", 7, "comparisons do not chain");
  expect_error("a == b != c", 8, "comparisons do not chain");
  expect_error("a > 1 b", 7, "unexpected 'b'");
  expect_error("speed 2 > 1", 7, "unexpected '2'");
  expect_error("a > and", 5, "expected a value, found 'and'");
  expect_error("a > * 2", 5, "expected a value, found '*'");
}

TEST(Rule, UnknownCharactersCountColumnsInCharacters) {
  expect_error("speed > 1 ; foam > 2", 11, "';' is not allowed in a rule");
  expect_error("a\t> 1 @", 7, "'@' is not allowed");  // a tab counts as one column
  expect_error("temp\xc3\xa9 > 1", 5, "'\xc3\xa9' is not allowed");
  // Each of the two-byte characters before the error is one column.
  expect_error("(\xc3\xa9\xc3\xa9) # 1", 2, "is not allowed");
  expect_error("a > 1 and \"b\" > 1", 11, "'\"' is not allowed");
}

TEST(Rule, UnbalancedParentheses) {
  expect_error("a > 1)", 6, "column 6: ')' closes nothing");
  expect_error(")", 1, "')' closes nothing");
  expect_error("(a > 1", 7, "column 7: '(' at column 1 is not closed");
  expect_error("a > 1 and ((b > 1)", 19, "'(' at column 11 is not closed");
  expect_error("abs(a", 6, "'(' at column 4 is not closed");
  expect_error("(a > 1 b)", 8, "unexpected 'b': expected an operator or ')'");
  expect_error("()", 2, "expected a value before ')'");
}

TEST(Rule, RuleEndsTooEarlyOrIsEmpty) {
  expect_error("", 1, "column 1: the rule is empty");
  expect_error("  \t ", 1, "column 1: the rule is empty");
  expect_error("a >", 4, "column 4: the rule ends where a value is expected");
  expect_error("a > 1 and", 10, "the rule ends where a value is expected");
  expect_error("not", 4, "the rule ends where a value is expected");
  expect_error("min(a,", 7, "the rule ends where a value is expected");
}

TEST(Rule, FunctionMistakes) {
  expect_error("sqrt(a) > 1", 1, "column 1: 'sqrt' is not a function: abs, min, max");
  expect_error("a > 1 and Abs(b) > 1", 11, "'Abs' is not a function");
  expect_error("abs(a, b) > 1", 6, "'abs' takes one number: abs(x)");
  expect_error("min(a) > 1", 6, "'min' takes two numbers: min(a, b)");
  expect_error("max(a, b, c) > 1", 9, "'max' takes two numbers");
  expect_error("min(a b) > 1", 7, "unexpected 'b': expected ',' or an operator");
  expect_error("abs() > 1", 5, "expected a value before ')'");
}

TEST(Rule, RejectsRulesNestedDeeperThanTheStack) {
  // "x > (1 + (1 + ... 1))": x, then one pending 1 per level, then the last 1.
  auto nested = [](int levels) {
    std::string s = "x > ";
    for (int i = 0; i < levels; ++i) s += "(1 + ";
    s += "1";
    s += std::string(levels, ')');
    return s;
  };
  const int fits = Rule::kStack - 2;
  const Rule deepest = Rule::parse(nested(fits));
  const float x = fits + 1.5f;  // the sum is fits + 1
  EXPECT_TRUE(deepest.holds(&x));
  const float y = fits + 0.5f;
  EXPECT_FALSE(deepest.holds(&y));
  // One more level: the innermost '1' is the value that does not fit.
  const std::string too_deep = nested(fits + 1);
  expect_error(too_deep, int(too_deep.find(')')), "the rule nests too deeply");
  // Parentheses alone need no stack but still may not nest without bound.
  const std::string parens = std::string(10000, '(') + "a > 1" + std::string(10000, ')');
  EXPECT_THROW(Rule::parse(parens), RuleError);
  expect_error(std::string(10000, '-') + "a > 1", 2 * Rule::kStack + 1, "nests too deeply");
  expect_error(std::string(10000, '!') + "a > 1", 2 * Rule::kStack + 1, "nests too deeply");
  // Long flat chains evaluate in two stack entries.
  std::string flat = "a";
  for (int i = 0; i < 1000; ++i) flat += " + a";
  flat += " > 1000 and a > 0";
  for (int i = 0; i < 1000; ++i) flat += " and a > 0";
  const float one = 1;
  EXPECT_TRUE(Rule::parse(flat).holds(&one));
}
