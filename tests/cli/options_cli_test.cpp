// The flags of `lapflow bake` / `lapflow track` come from the option table:
// every option round-trips command line -> options -> manifest -> options ->
// scene file -> options, --help and docs/options.md list each one once.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <fstream>
#include <regex>
#include <sstream>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/bake/render.hpp"
#include "option_flags.hpp"
#include "scene_file.hpp"

namespace lapflow {
namespace {

/// The options `lapflow bake ARGS` parses into (the flags of the table only).
BakeOptions parse_bake_flags(std::vector<std::string> args) {
  CLI::App app("lapflow");
  CLI::App* bake = app.add_subcommand("bake");
  BakeOptions o;
  cli::add_bake_table_flags(*bake, o);
  args.insert(args.begin(), "bake");
  std::reverse(args.begin(), args.end());  // CLI11 takes them last to first
  app.parse(args);
  return o;
}

/// The command line of every option of the table at its example value.
std::vector<std::string> example_arguments() {
  std::vector<std::string> args;
  for (const BakeOption& o : bake_option_table()) {
    if (!o.on_command_line || o.global || o.name == "paper") continue;
    if (o.kind == OptionKind::Flag)
      args.push_back(o.example == "true" ? o.flag() : "--no-" + o.name);
    else
      args.push_back(o.flag() + "=" + o.example);
  }
  return args;
}

/// `o` as a scene file: one key per recorded option on the command line.
std::string scene_text(const BakeOptions& o) {
  std::string text;
  for (const BakeOption& option : bake_option_table()) {
    if (!option.on_command_line || option.global || option.manifest_key.empty()) continue;
    std::string key = option.name;
    std::replace(key.begin(), key.end(), '-', '_');
    const std::string value = option.get(o);
    if (option.kind == OptionKind::Flag || option.kind == OptionKind::Number || option.kind == OptionKind::Integer)
      text += key + " = " + value + "\n";
    else
      text += key + " = \"" + value + "\"\n";
  }
  return text;
}

TEST(OptionFlags, EveryOptionRoundTripsThroughCommandLineManifestAndSceneFile) {
  test::TempDir dir("options_round_trip");
  // Command line -> options: each flag sets its option to the example.
  const BakeOptions cli = parse_bake_flags(example_arguments());
  for (const BakeOption& o : bake_option_table()) {
    if (!o.on_command_line || o.global || o.name == "paper") continue;
    SCOPED_TRACE(o.name);
    BakeOptions expected = default_bake_options();
    set_bake_option(expected, o, o.example);
    EXPECT_EQ(o.get(cli), o.get(expected));
  }
  // -> manifest -> options.
  BakeOptions named = cli;
  named.out_dir = dir.str();
  std::vector<int> frames;
  for (int f = cli.frames->first; f <= cli.frames->last; ++f) frames.push_back(f);
  const BakeManifest written = make_bake_manifest(named, frames);
  write_bake_manifest(written, bake_manifest_path(dir.str(), named.name));
  const BakeOptions from_manifest = bake_options_from_manifest(read_bake_manifest(dir.str()));
  // -> scene file -> options.
  const std::string scene = dir / "shot.toml";
  test::write_bytes(scene, scene_text(from_manifest));
  std::vector<std::string> scene_args = cli::scene_file_arguments(scene);
  const BakeOptions from_scene = parse_bake_flags(scene_args);
  for (const BakeOption& o : bake_option_table()) {
    if (o.manifest_key.empty() || !o.on_command_line || o.global) continue;
    SCOPED_TRACE(o.name);
    // Paths come back absolute (the manifest records them so).
    const std::string want = o.kind == OptionKind::Path ? o.get(written.options) : o.get(cli);
    EXPECT_EQ(o.get(from_manifest), want) << "manifest";
    EXPECT_EQ(o.get(from_scene), want) << "scene file";
  }
  EXPECT_EQ(from_manifest.frames->first, 3);
  EXPECT_EQ(from_manifest.frames->last, 40);
}

TEST(OptionFlags, FlagsCheckTheirValuesAndPaperExcludesWhatItSets) {
  EXPECT_THROW(parse_bake_flags({"--min-speed=fast"}), CLI::ValidationError);
  EXPECT_THROW(parse_bake_flags({"--track-texel", "2"}), CLI::ValidationError);
  EXPECT_THROW(parse_bake_flags({"--paper", "--merge", "0.2"}), CLI::ExcludesError);
  const BakeOptions paper = parse_bake_flags({"--paper"});
  EXPECT_FALSE(paper.raster.hold);
  EXPECT_EQ(paper.patch.anticipate, 0);
  EXPECT_FALSE(paper.advect.through_flow);
  const BakeOptions defaults = parse_bake_flags({});
  for (const BakeOption& o : bake_option_table()) EXPECT_EQ(o.get(defaults), o.default_text()) << o.name;
  // A scene file's `no_remesh = true` and `hold = false` spell the negations.
  EXPECT_FALSE(parse_bake_flags({"--no-remesh"}).patch.remesh);
  EXPECT_FALSE(parse_bake_flags({"--hold=false"}).raster.hold);
  EXPECT_TRUE(parse_bake_flags({"--no-hold=false"}).raster.hold);
}

/// Lines of `text` that start (after spaces) with `flag` as a whole word.
int lines_starting_with(const std::string& text, const std::string& flag) {
  const std::regex line("(^|\n) *" + flag + "($|[^-a-z])");
  return int(std::distance(std::sregex_iterator(text.begin(), text.end(), line), std::sregex_iterator()));
}

TEST(OptionFlags, HelpListsEveryOptionOnceUnderItsStage) {
  test::TempDir dir("options_help");
  for (const char* command : {"bake", "track"}) {
    std::string out, err;
    ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " " + command + " --help", &out, &err, dir), 0) << err;
    ASSERT_NE(out.find("\nOptions:"), std::string::npos);
    out = out.substr(out.find("\nOptions:"));  // the list, not the description above it
    for (const BakeOption& o : bake_option_table()) {
      if (!o.on_command_line) continue;
      EXPECT_EQ(lines_starting_with(out, o.flag()), 1) << command << " " << o.flag();
    }
    for (const char* stage : {"Input:", "Exemplar:", "Patches:", "Erosion:", "Atlas:", "Output:", "Limits:"})
      EXPECT_NE(out.find(stage), std::string::npos) << command << " " << stage;
    EXPECT_NE(out.find("--min-speed m/s=0 "), std::string::npos) << "unit and default";
  }
}

TEST(OptionFlags, DocsOptionsIsTheTable) {
  std::ifstream in(LAPFLOW_SOURCE_DIR "/docs/options.md");
  std::stringstream text;
  text << in.rdbuf();
  const std::string md = bake_options_markdown();
  EXPECT_NE(text.str().find(md), std::string::npos)
      << "docs/options.md is out of date: regenerate its table with `lapflow options`";
  test::TempDir dir("options_cmd");
  std::string out, err;
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " options", &out, &err, dir), 0) << err;
  EXPECT_EQ(out, md);
}

}  // namespace
}  // namespace lapflow
