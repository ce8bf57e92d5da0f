#include "scene_file.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <filesystem>
#include <fstream>
#include <sstream>

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

void add_table(const toml::table& table, const std::string& file, const fs::path& base,
               std::vector<std::string>& out) {
  for (const auto& [k, node] : table) {
    std::string key(k.str());
    std::replace(key.begin(), key.end(), '_', '-');
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
      if (is_path_option(key) && !text.empty() && fs::path(text).is_relative()) text = (base / text).string();
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
