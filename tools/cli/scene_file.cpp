#include "scene_file.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lapflow/bake/layers.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow::cli {
namespace fs = std::filesystem;

bool is_path_option(const std::string& key) {
  const BakeOption* option = find_bake_option(key);
  return option && option->kind == OptionKind::Path;
}

namespace {

std::string scalar_text(const toml::node& node, const std::string& file, const std::string& key) {
  if (auto s = node.value<std::string>()) return *s;
  if (node.is_integer()) return std::to_string(*node.value<int64_t>());
  if (node.is_floating_point()) {
    // Shortest text that reads back as the same double (std::to_string
    // would print 1e-7 as 0.000000).
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, *node.value<double>());
    return std::string(buf, r.ptr);
  }
  if (node.is_boolean()) return *node.value<bool>() ? "true" : "false";
  throw InputError(file, "key '" + key + "': expected a string, number or boolean");
}

std::string line_of(const toml::node& node) { return "line " + std::to_string(node.source().begin.line); }

/// A shipped exemplar's name (`pebbles`: no folder, no extension), which
/// is not a path to take from the scene file's folder.
bool shipped_name(const std::string& text) {
  return text.find('/') == std::string::npos && text.find('.') == std::string::npos;
}

/// A layer's files relative to the scene file's folder.
void rebase(ExemplarLayer& layer, const fs::path& base) {
  for (std::string* path : {&layer.color, &layer.feature, &layer.displacement})
    if (!path->empty() && fs::path(*path).is_relative() && !(path == &layer.color && shipped_name(*path)))
      *path = (base / *path).string();
}

/// `layer = "NAME=COLOR,..."` (';' between several), or `[[layer]]` tables
/// with name, color (or exemplar), feature, displacement and where: one
/// --layer each, and a --where for a table's rule.
void add_layers(const toml::node& node, const std::string& file, const fs::path& base,
                std::vector<std::string>& out) {
  auto from_text = [&](const toml::node& value) {
    const std::optional<std::string> text = value.value<std::string>();
    if (!text) throw InputError(file, line_of(value) + ": 'layer' expects NAME=COLOR[,FEATURE[,DISP]] or [[layer]] tables");
    for (std::size_t at = 0; at < text->size();) {
      const std::size_t end = std::min(text->find(';', at), text->size());
      const std::string one = text->substr(at, end - at);
      ExemplarLayer layer;
      try {
        layer = parse_layer(one);
      } catch (const std::invalid_argument& e) {
        throw InputError(file, line_of(value) + ": layer " + quote_token(one) + " is not " + e.what());
      }
      rebase(layer, base);
      out.push_back("--layer=" + layer_text(layer));
      at = end + 1;
    }
  };
  auto from_table = [&](const toml::table& t) {
    ExemplarLayer layer;
    std::string where;
    for (const auto& [k, value] : t) {
      const std::string key(k.str());
      const std::optional<std::string> text = value.value<std::string>();
      if (!text)
        throw InputError(file, line_of(value) + ": [[layer]] key " + quote_token(key) + " expects a string");
      if (key == "name") layer.name = *text;
      else if (key == "color" || key == "exemplar") layer.color = *text;
      else if (key == "feature") layer.feature = *text;
      else if (key == "displacement") layer.displacement = *text;
      else if (key == "where") where = *text;
      else
        throw InputError(file, line_of(value) + ": [[layer]] has no key " + quote_token(key) +
                                   " (name, color, feature, displacement, where)");
    }
    if (!is_layer_name(layer.name))
      throw InputError(file, line_of(t) + ": a [[layer]] needs a name of letters, digits, '_' and '-'");
    if (layer.color.empty()) throw InputError(file, line_of(t) + ": [[layer]] '" + layer.name + "' has no color");
    rebase(layer, base);
    out.push_back("--layer=" + layer_text(layer));
    if (!where.empty()) out.push_back("--where=" + layer.name + ":" + where);
  };
  if (const toml::array* arr = node.as_array()) {
    for (const toml::node& v : *arr) {
      if (const toml::table* t = v.as_table()) from_table(*t);
      else from_text(v);
    }
  } else {
    from_text(node);
  }
}

void add_table(const toml::table& table, const std::string& file, const fs::path& base,
               std::vector<std::string>& out) {
  for (const auto& [k, node] : table) {
    std::string key(k.str());
    std::replace(key.begin(), key.end(), '_', '-');
    if (key == "layer") {
      add_layers(node, file, base, out);
      continue;
    }
    if (node.is_table()) continue;  // sections are handled by the caller
    // A key becomes `--key`: anything but an option name (an empty key, a
    // space, an '=') would reach the command line as something else.
    const bool option_name =
        !key.empty() && std::isalnum(static_cast<unsigned char>(key[0])) &&
        std::all_of(key.begin(), key.end(),
                    [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '-'; });
    if (!option_name)
      throw InputError(file, "line " + std::to_string(node.source().begin.line) + ": key " +
                                 quote_token(key) + " is not an option name (letters, digits, '-' and '_')");
    auto emit = [&](const toml::node& value) {
      std::string text = scalar_text(value, file, key);
      if (value.is_boolean()) {
        out.push_back(text == "true" ? "--" + key : "--" + key + "=false");
        return;
      }
      if (is_path_option(key) && !text.empty() && fs::path(text).is_relative() &&
          !(key == "exemplar" && shipped_name(text)))
        text = (base / text).string();
      out.push_back("--" + key + "=" + text);
    };
    if (const toml::array* arr = node.as_array()) {
      for (const toml::node& v : *arr) emit(v);
    } else {
      emit(node);
    }
  }
}

}  // namespace

std::vector<std::string> scene_file_arguments(const std::string& path) {
  if (!fs::exists(path)) throw InputError(path, "scene file not found");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in) throw InputError(path, "cannot read the scene file");
  return scene_text_arguments(text.str(), path);
}

std::vector<std::string> scene_text_arguments(const std::string& text, const std::string& path) {
  toml::table table;
  try {
    table = toml::parse(text, path);
  } catch (const toml::parse_error& e) {
    throw InputError(path, "line " + std::to_string(e.source().begin.line) + ": " + std::string(e.description()));
  }
  const fs::path base = fs::path(path).parent_path();
  std::vector<std::string> out;
  add_table(table, path, base, out);
  if (const toml::table* bake = table["bake"].as_table()) add_table(*bake, path, base, out);
  return out;
}

void expand_scene_files(std::vector<std::string>& args) {
  if (args.empty()) return;
  std::vector<std::string> scene_args, rest;
  for (std::size_t i = 1; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a.size() > 5 && a.rfind(".toml") == a.size() - 5 && a[0] != '-') {
      auto expanded = scene_file_arguments(a);
      scene_args.insert(scene_args.end(), expanded.begin(), expanded.end());
    } else {
      rest.push_back(a);
    }
  }
  if (scene_args.empty()) return;
  std::vector<std::string> result{args[0]};
  result.insert(result.end(), scene_args.begin(), scene_args.end());
  result.insert(result.end(), rest.begin(), rest.end());
  args = std::move(result);
}

}  // namespace lapflow::cli
