#pragma once
// `lapflow bake scene.toml`: a TOML scene file whose keys mirror the long
// options. It is expanded into option arguments placed before the user's own,
// so that options given on the command line override the file.
#include <string>
#include <vector>

namespace lapflow::cli {

/// Keys whose values are paths: resolved relative to the scene file's folder.
bool is_path_option(const std::string& key);

/// Reads `path` and returns `--key=value` arguments (arrays give one argument
/// per element; `true` booleans give `--key`, `false` gives `--key=false`).
/// Accepts keys with `-` or `_`, at the top level or in a `[bake]` table.
/// Throws InputError naming the file and the key for a malformed file or a
/// value that is not a string, number or boolean.
std::vector<std::string> scene_file_arguments(const std::string& path);
/// The same for a scene file's text already in memory (`path` names it in
/// errors and gives the folder relative paths start from): the fuzzers' entry.
std::vector<std::string> scene_text_arguments(const std::string& text, const std::string& path);

/// Replaces, in `args` (argv without the program name), every positional
/// argument ending in `.toml` that follows the command by the file's options,
/// inserted right after the command name.
void expand_scene_files(std::vector<std::string>& args);

}  // namespace lapflow::cli
