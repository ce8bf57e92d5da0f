// The option table (lapflow/bake/options.hpp): each option once, and every
// recorded option round-trips through NAME.bake.json.
#include <gtest/gtest.h>

#include <set>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace {

TEST(OptionTable, EachOptionOnceWithAnExampleThatParsesAndDiffersFromTheDefault) {
  std::set<std::string> names, keys;
  for (const BakeOption& o : bake_option_table()) {
    SCOPED_TRACE(o.name);
    EXPECT_TRUE(names.insert(o.name).second) << "declared twice";
    if (!o.manifest_key.empty()) {
      EXPECT_TRUE(keys.insert(o.manifest_key).second) << "manifest key used twice";
    }
    EXPECT_EQ(find_bake_option(o.name), &o);
    EXPECT_FALSE(o.help.empty() && o.on_command_line) << "a flag without help";
    ASSERT_FALSE(o.example.empty());
    BakeOptions b = default_bake_options();
    set_bake_option(b, o, o.example);
    if (o.name != "paper") {
      EXPECT_NE(o.get(b), o.default_text()) << "the example is the default";
    }
    // The default reads back as itself.
    BakeOptions d = default_bake_options();
    if (!o.default_text().empty() && o.name != "paper") {
      set_bake_option(d, o, o.default_text());
      EXPECT_EQ(o.get(d), o.default_text());
    }
  }
  EXPECT_EQ(find_bake_option("min_speed"), find_bake_option("min-speed"));
  EXPECT_EQ(find_bake_option("no-such-option"), nullptr);
}

TEST(OptionTable, BadValuesAreUsageErrorsNamingTheFlagAndWhatItTakes) {
  const auto message = [](const char* name, const std::string& text) {
    BakeOptions o = default_bake_options();
    try {
      set_bake_option(o, *find_bake_option(name), text);
    } catch (const UsageError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message("min-speed", "fast"), "--min-speed: 'fast' is not a number");
  EXPECT_EQ(message("min-speed", "nan"), "--min-speed: 'nan' is not a number");
  EXPECT_EQ(message("track-texel", "2"), "--track-texel: '2' is not in [0.0009765625, 1]");
  EXPECT_EQ(message("velocity-band", "2.5"), "--velocity-band: '2.5' is not a whole number");
  EXPECT_EQ(message("mode", "fade"), "--mode: 'fade' is not one of erosion, blend, advect");
  EXPECT_EQ(message("remesher", "x"), "--remesher: 'x' is not one of lattice, isotropic, cgal");
  EXPECT_EQ(message("keep-states", "-3"), "--keep-states: '-3' is not all, last, none or a count of frames");
  EXPECT_EQ(message("orientation", "up"), "--orientation: 'up' is not 'random' or 'world:x,y,z'");
  EXPECT_EQ(message("orientation", "world:0,0,0"),
            "--orientation: 'world:0,0,0' is not a direction (a zero or infinite one is not)");
  EXPECT_EQ(message("frames", "ten"), "--frames: 'ten' is not a frame range A-B");
  EXPECT_EQ(message("name", "../shot"), "--name: '../shot' is not a file name (no folder: the files go in --out)");
  EXPECT_EQ(message("remesher", "grid"), "accepted");  // the old name
}

/// Options with every recorded option set to its example, the paths absolute.
BakeOptions every_option_changed() {
  BakeOptions o = default_bake_options();
  for (const BakeOption& option : bake_option_table())
    if (!option.manifest_key.empty()) set_bake_option(o, option, option.example);
  o.name = "shot";
  o.out_dir = "/tmp/lapflow_options_test";
  return o;
}

TEST(OptionTable, EveryRecordedOptionRoundTripsThroughTheManifest) {
  const BakeOptions o = every_option_changed();
  const BakeManifest m = make_bake_manifest(o, {3, 4});
  test::TempDir dir("options_manifest");
  const std::string path = bake_manifest_path(dir.str(), "shot");
  write_bake_manifest(m, path);
  const BakeManifest r = read_bake_manifest(path);
  const BakeOptions back = bake_options_from_manifest(r);
  for (const BakeOption& option : bake_option_table()) {
    if (option.manifest_key.empty()) continue;
    SCOPED_TRACE(option.name);
    if (option.kind == OptionKind::Path)
      EXPECT_EQ(option.get(back), option.get(m.options)) << "absolute";
    else
      EXPECT_EQ(option.get(back), option.get(o));
  }
  EXPECT_TRUE(bake_manifest_differences(path, m).empty());
}

TEST(OptionTable, OnlyThePictureOptionsLeaveTheTrackingChecksum) {
  const BakeOptions base = every_option_changed();
  const BakeManifest a = make_bake_manifest(base, {1});
  for (const BakeOption& option : bake_option_table()) {
    if (option.manifest_key.empty()) continue;
    SCOPED_TRACE(option.name);
    BakeOptions o = base;
    // An empty text clears a repeatable option (its default: none given).
    set_bake_option(o, option, option.default_text().empty() && !option.repeatable ? "x" : option.default_text());
    const BakeManifest b = make_bake_manifest(o, {1});
    ASSERT_NE(bake_manifest_checksum(a), bake_manifest_checksum(b)) << "the manifest does not record it";
    EXPECT_EQ(bake_tracking_checksum(a) != bake_tracking_checksum(b), option.effect == OptionEffect::Animation);
  }
}

TEST(OptionTable, TheMarkdownListsEveryFlagOnce) {
  const std::string md = bake_options_markdown();
  for (const BakeOption& o : bake_option_table()) {
    if (!o.on_command_line) continue;
    const std::string cell = "| `" + o.flag() + "`";
    const std::size_t at = md.find(cell);
    EXPECT_NE(at, std::string::npos) << o.name;
    EXPECT_EQ(md.find(cell, at + 1), std::string::npos) << o.name << " listed twice";
  }
}

}  // namespace
}  // namespace lapflow
