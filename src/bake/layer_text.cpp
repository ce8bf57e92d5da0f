// Exemplar layers' option texts: NAME=COLOR[,FEATURE[,DISP]] and NAME:RULE.
// Apart from layers.cpp so that the readers (options, scene files, the
// fuzzers' library) parse them without the engine.
#include <algorithm>
#include <cctype>
#include <stdexcept>

#include "lapflow/bake/layers.hpp"
#include "lapflow/core/rule.hpp"

namespace lapflow {

bool is_layer_name(const std::string& name) {
  return !name.empty() && std::isalpha(static_cast<unsigned char>(name[0])) &&
         std::all_of(name.begin(), name.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-'; });
}

ExemplarLayer parse_layer(const std::string& text) {
  const std::size_t eq = text.find('=');
  if (eq == std::string::npos)
    throw std::invalid_argument("a layer NAME=COLOR[,FEATURE[,DISP]] (no '=')");
  ExemplarLayer layer;
  layer.name = text.substr(0, eq);
  if (!is_layer_name(layer.name))
    throw std::invalid_argument("a layer NAME=COLOR[,FEATURE[,DISP]] (a name is letters, digits, '_' and '-')");
  std::vector<std::string> files;
  for (std::size_t at = eq + 1;;) {
    const std::size_t comma = text.find(',', at);
    files.push_back(text.substr(at, comma == std::string::npos ? std::string::npos : comma - at));
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  if (files.size() > 3 || files[0].empty())
    throw std::invalid_argument("a layer NAME=COLOR[,FEATURE[,DISP]] (" +
                                std::string(files[0].empty() ? "no colour image" : "more than three files") + ")");
  layer.color = files[0];
  if (files.size() > 1) layer.feature = files[1];
  if (files.size() > 2) layer.displacement = files[2];
  return layer;
}

std::string layer_text(const ExemplarLayer& layer) {
  std::string text = layer.name + "=" + layer.color;
  if (!layer.feature.empty() || !layer.displacement.empty()) text += "," + layer.feature;
  if (!layer.displacement.empty()) text += "," + layer.displacement;
  return text;
}

std::pair<std::string, std::string> parse_layer_rule(const std::string& text) {
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos) throw std::invalid_argument("a layer's rule NAME:RULE (no ':')");
  std::string name = text.substr(0, colon), rule = text.substr(colon + 1);
  if (!is_layer_name(name))
    throw std::invalid_argument("a layer's rule NAME:RULE (a name is letters, digits, '_' and '-')");
  try {
    Rule::parse(rule);
  } catch (const RuleError& e) {
    throw std::invalid_argument("a rule: " + std::string(e.what()));
  }
  return {std::move(name), std::move(rule)};
}

}  // namespace lapflow
