#include "option_flags.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <map>

#include "lapflow/core/errors.hpp"

namespace lapflow::cli {

namespace {

/// What --help shows after the flag: the unit where there is one, else the kind.
std::string type_name(const BakeOption& o) {
  if (!o.choices.empty()) return fmt::format("{}", fmt::join(o.choices, "|"));
  if (!o.unit.empty()) return o.unit;
  switch (o.kind) {
    case OptionKind::Number: return "NUMBER";
    case OptionKind::Integer: return "INT";
    case OptionKind::Path: return "PATH";
    case OptionKind::Size: return "SIZE";
    default: return "TEXT";
  }
}

/// Sets `option` of `o` from `text`; a bad value is a CLI11 parse error, so
/// that the error line ends with the hint to --help like every other.
void apply(BakeOptions& o, const BakeOption& option, const std::string& text) {
  try {
    set_bake_option(o, option, text);
  } catch (const UsageError& e) {
    throw CLI::ValidationError(e.what());
  }
}

std::string help_text(const BakeOption& o) {
  std::string help = o.help;
  if (o.range && o.kind != OptionKind::Flag) help += fmt::format(" (range {} to {})", o.range->first, o.range->second);
  if (!o.unit.empty()) help += fmt::format(" [unit: {}]", o.unit);
  return help;
}

}  // namespace

void add_bake_table_flags(CLI::App& cmd, BakeOptions& o) {
  o = default_bake_options();
  std::map<std::string, CLI::Option*> added;
  for (const BakeOption& option : bake_option_table()) {
    if (!option.on_command_line || option.global) continue;
    const BakeOption* entry = &option;
    CLI::Option* flag = nullptr;
    if (option.kind == OptionKind::Flag) {
      const std::string names = option.negatable ? option.flag() + ",!--no-" + option.name : option.flag();
      flag = cmd.add_flag_function(
          names, [&o, entry](std::int64_t count) { apply(o, *entry, count > 0 ? "true" : "false"); },
          help_text(option));
      if (option.negatable) flag->description(help_text(option) + fmt::format(" (default: {})", option.default_text() == "true" ? "on" : "off"));
    } else if (option.repeatable) {
      flag = cmd.add_option_function<std::vector<std::string>>(
                    option.flag(),
                    [&o, entry](const std::vector<std::string>& texts) {
                      for (const std::string& text : texts) apply(o, *entry, text);
                    },
                    help_text(option))
                 ->type_name(type_name(option))
                 ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
                 ->allow_extra_args(false);
    } else {
      flag = cmd.add_option_function<std::string>(
                    option.flag(), [&o, entry](const std::string& text) { apply(o, *entry, text); },
                    help_text(option))
                 ->type_name(type_name(option));
      const std::string d = option.default_text();
      if (!d.empty()) flag->default_str(d);
    }
    flag->group(std::string(option_stage_name(option.stage)));
    added[option.name] = flag;
  }
  for (const BakeOption& option : bake_option_table())
    for (const std::string& other : option.excludes)
      if (added.count(option.name) && added.count(other)) added[option.name]->excludes(added[other]);
}

CLI::Option* add_table_flag(CLI::App& cmd, const std::string& name, std::function<void(const std::string&)> apply,
                            const std::string& note) {
  const BakeOption* option = find_bake_option(name);
  if (!option) throw std::logic_error("no option " + name + " in the option table");
  auto checked = [option, apply = std::move(apply)](const std::string& text) {
    BakeOptions scratch = default_bake_options();
    try {
      set_bake_option(scratch, *option, text);
    } catch (const UsageError& e) {
      throw CLI::ValidationError(e.what());
    }
    apply(text);
  };
  CLI::Option* flag = nullptr;
  if (option->kind == OptionKind::Flag)
    flag = cmd.add_flag_function(option->flag(), [checked](std::int64_t n) { checked(n > 0 ? "true" : "false"); },
                                 help_text(*option) + " " + note);
  else
    flag = cmd.add_option_function<std::string>(option->flag(), checked, help_text(*option) + " " + note)
               ->type_name(type_name(*option));
  return flag->group(std::string(option_stage_name(option->stage)));
}

}  // namespace lapflow::cli
