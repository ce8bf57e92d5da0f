#pragma once
/// \file options.hpp The bake's options, each declared once. The table below
/// is what the command line's flags (`lapflow bake`, `lapflow track`), their
/// checks and error messages, `--help`, NAME.bake.json (written and read), the
/// scene file's keys and docs/options.md are made from. Adding an option adds
/// one entry here and the code that uses the field.
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "lapflow/bake/bake.hpp"

namespace lapflow {

/// How an option's value is spelled.
enum class OptionKind {
  Number,   ///< a real number
  Integer,  ///< a whole number
  Flag,     ///< on or off: --name (and --no-name when negatable)
  Choice,   ///< one of `choices`
  Text,     ///< free text with its own syntax (a frame range, a direction)
  Path,     ///< a file, folder or file pattern: relative to the scene file in one
  Size,     ///< bytes, as 16G or 500M
};

/// The stage an option belongs to: `--help` and docs/options.md group by it.
enum class OptionStage { Input, Exemplar, Patches, Erosion, Atlas, Output, Limits };

/// What an option changes.
enum class OptionEffect {
  Animation,  ///< the patches: tracking decides with it (`lapflow render` cannot change it)
  Picture,    ///< only the images and the UV mesh (`lapflow render` may set it anew)
  Neither,    ///< how the bake runs or where it writes, not what it makes
};

struct BakeOption {
  std::string name;   ///< "min-speed": --min-speed, and min_speed (or min-speed) in a scene file
  OptionKind kind = OptionKind::Number;
  OptionStage stage = OptionStage::Input;
  OptionEffect effect = OptionEffect::Animation;
  std::string unit;   ///< "m/s", "r" (patch radii), "texels", ...; empty: none
  std::optional<std::pair<double, double>> range;  ///< accepted values, both ends included
  std::vector<std::string> choices;                ///< Choice: the accepted words (the first ones shown)
  std::string help;
  /// Where NAME.bake.json records it: "min_speed" at the top, "exemplar/color"
  /// nested, "settings/spacing" as text in "settings". Empty: not recorded.
  std::string manifest_key;
  /// The value a manifest that has no such key stands for (a manifest written
  /// before the option existed); none: the default.
  std::optional<std::string> absent;
  bool negatable = false;        ///< Flag: also --no-NAME
  /// Given more than once, each occurrence applies in turn (--layer,
  /// --where): `set` adds to what is there instead of replacing it.
  bool repeatable = false;
  bool on_command_line = true;   ///< false: set by the library or a preset, recorded in the manifest
  bool global = false;           ///< a flag every command has (--seed): declared with the global options
  std::vector<std::string> excludes;  ///< flags that cannot be given with this one
  std::string example;           ///< a valid value other than the default (the round-trip test's)
  /// The value as the command line spells it.
  std::function<std::string(const BakeOptions&)> get;
  /// Parses `text` into the options; throws std::invalid_argument whose
  /// what() completes "'TEXT' is not ..." (e.g. "a number", "in [0, 1]").
  std::function<void(BakeOptions&, const std::string&)> set;
  /// The manifest's text when it differs from the command line's (an enum
  /// recorded as its number); empty functions: get and set.
  std::function<std::string(const BakeOptions&)> manifest_get;
  std::function<void(BakeOptions&, const std::string&)> manifest_set;

  /// "--min-speed".
  std::string flag() const { return "--" + name; }
  /// The default as the command line shows it.
  std::string default_text() const;
};

/// Every option of `lapflow bake` and `lapflow track`, in the order `--help`
/// shows them within a stage.
const std::vector<BakeOption>& bake_option_table();

/// The entry named `name` ("min-speed" or "min_speed"), or null.
const BakeOption* find_bake_option(std::string_view name);

/// The options a bake starts from before its flags apply: BakeOptions' own
/// defaults, with radius and resolution automatic (0) and no name.
BakeOptions default_bake_options();

/// Sets option `option` of `o` from its command-line text; throws
/// UsageError "--name: 'TEXT' is not ..." when the text does not parse or
/// is out of range.
void set_bake_option(BakeOptions& o, const BakeOption& option, const std::string& text);

/// The stage's title as `--help` and docs/options.md show it: "Input", ...
std::string_view option_stage_name(OptionStage stage);
std::string_view option_effect_name(OptionEffect effect);

/// docs/options.md: one Markdown table per stage, every option once.
std::string bake_options_markdown();

}  // namespace lapflow
