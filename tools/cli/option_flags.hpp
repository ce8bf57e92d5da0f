#pragma once
// The command-line flags of the bake's option table (lapflow/bake/options.hpp).
#include <CLI/CLI.hpp>

#include "lapflow/bake/options.hpp"

namespace lapflow::cli {

/// Adds a flag for every option of the table that is on the command line
/// and not global (--seed is declared with the global options), grouped by
/// stage, with its unit, range and default in `--help`. A flag given sets
/// its option of `o` (set_bake_option: a value that does not parse or is out
/// of range is a CLI::ValidationError naming the flag and what it takes).
/// `o` starts as default_bake_options().
void add_bake_table_flags(CLI::App& cmd, BakeOptions& o);

/// A flag of another command (`lapflow render`) that stands for the table's
/// option `name`: its help (with `note` after it), unit and stage come from
/// the table, and its value is checked as the table checks it before
/// `apply` gets the text ("true" / "false" for a flag).
CLI::Option* add_table_flag(CLI::App& cmd, const std::string& name, std::function<void(const std::string&)> apply,
                            const std::string& note);

}  // namespace lapflow::cli
