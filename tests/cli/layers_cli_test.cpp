// `lapflow bake --layer ... --where ...` and `[[layer]]` scene tables
// (docs/layers.md): a layered bake from the command line and from a scene
// file, and its mistakes as exit-2 errors naming the file, the line or the
// rule's column.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "io_test_helpers.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "scene_file.hpp"
#include "lapflow/io/image.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

const std::string kLapflow = LAPFLOW_BINARY;

class LayersCli : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::create_directories(dir_ / "in");
    test::write_heat_plane(dir_ / "in", 2, [](double x, int) { return x; });
  }
  /// Runs `lapflow bake` on the heat plane with `args`; returns the exit code.
  int bake(const std::string& args, std::string* err) {
    return test::run_command(kLapflow + " bake --mesh '" + (dir_ / "in") + "/m.%04d.ply' --radius 0.05 " +
                                 "--resolution 256 --no-usd -q " + args,
                             nullptr, err, dir_);
  }
  TempDir dir_{"layers_cli"};
};

TEST_F(LayersCli, LayersAndRulesFromTheCommandLine) {
  std::string err;
  ASSERT_EQ(bake("--layer hot=lava --layer calm=ripples --where 'hot:heat > 0.5' --aov --out '" + (dir_ / "out") + "'",
                 &err),
            0)
      << err;
  EXPECT_EQ(read_image(dir_ / "out/m.aov.0002.exr").channels, 5) << "patch_id u v w layer";
  const BakeManifest m = read_bake_manifest(dir_ / "out");
  ASSERT_EQ(m.options.layers.size(), 2u);
  EXPECT_EQ(m.options.layers[0].name, "hot");
  EXPECT_TRUE(fs::path(m.options.layers[0].color).is_absolute());
  EXPECT_EQ(m.options.layer_rules, (std::vector<std::pair<std::string, std::string>>{{"hot", "heat > 0.5"}}));
}

TEST_F(LayersCli, LayerTablesInASceneFile) {
  test::write_bytes(dir_ / "shot.toml", "out = \"out\"\n"
                                        "[[layer]]\nname = \"hot\"\ncolor = \"lava\"\nwhere = \"heat > 0.5\"\n"
                                        "[[layer]]\nname = \"calm\"\ncolor = \"ripples\"\n");
  std::string err;
  ASSERT_EQ(bake("'" + (dir_ / "shot.toml") + "'", &err), 0) << err;
  const BakeManifest m = read_bake_manifest(dir_ / "out");
  ASSERT_EQ(m.options.layers.size(), 2u);
  EXPECT_EQ(m.options.layers[1].name, "calm");
  EXPECT_EQ(m.options.layer_rules.size(), 1u);
  // A key a layer table does not take names the file and the line.
  test::write_bytes(dir_ / "bad.toml", "[[layer]]\nname = \"hot\"\ncolor = \"lava\"\nradius = \"0.1\"\n");
  EXPECT_EQ(bake("'" + (dir_ / "bad.toml") + "' --out '" + (dir_ / "bad") + "'", &err), 2);
  EXPECT_NE(err.find("bad.toml"), std::string::npos) << err;
  EXPECT_NE(err.find("line 4: [[layer]] has no key 'radius'"), std::string::npos) << err;
}

TEST_F(LayersCli, MistakesAreExitTwoNamingWhatIsWrong) {
  std::string err;
  const std::string out = " --out '" + (dir_ / "out") + "'";
  // A rule that does not parse: its column.
  EXPECT_EQ(bake("--layer hot=lava --layer calm=ripples --where 'hot:heat >'" + out, &err), 2);
  EXPECT_NE(err.find("column 7: the rule ends where a value is expected"), std::string::npos) << err;
  // An attribute the frames lack: the file and what it has.
  EXPECT_EQ(bake("--layer hot=lava --layer calm=ripples --where 'hot:temperature > 900'" + out, &err), 2);
  EXPECT_NE(err.find("m.0001.ply"), std::string::npos) << err;
  EXPECT_NE(err.find("no property 'temperature' (it has: x y z vx vy vz heat)"), std::string::npos) << err;
  // A layer but the last without a rule.
  EXPECT_EQ(bake("--layer hot=lava --layer calm=ripples" + out, &err), 2);
  EXPECT_NE(err.find("--layer hot: no --where hot:RULE"), std::string::npos) << err;
  // Layers and --exemplar together.
  EXPECT_EQ(bake("--exemplar pebbles --layer hot=lava --layer calm=ripples --where 'hot:heat > 1'" + out, &err), 2);
  EXPECT_NE(err.find("--exemplar and --layer"), std::string::npos) << err;
  // Nothing was written for any of them.
  EXPECT_FALSE(fs::exists(dir_ / "out/m.0001.obj"));
}

TEST(LayersScenes, TheShippedLayeredSceneFilesHoldValidLayersAndRules) {
  int files = 0;
  for (const auto& e : fs::directory_iterator(LAPFLOW_SOURCE_DIR "/exemplars/scenes")) {
    if (e.path().extension() != ".toml") continue;
    SCOPED_TRACE(e.path().string());
    ++files;
    BakeOptions o = default_bake_options();
    for (const std::string& arg : cli::scene_file_arguments(e.path().string())) {
      const std::size_t eq = arg.find('=');  // none: a flag (`aov = true` is --aov)
      const BakeOption* option = find_bake_option(arg.substr(2, eq == std::string::npos ? std::string::npos : eq - 2));
      ASSERT_NE(option, nullptr) << arg;
      set_bake_option(o, *option, eq == std::string::npos ? "true" : arg.substr(eq + 1));
    }
    const LayerRules rules = layer_rules(o);
    EXPECT_GE(rules.size(), 2u);
    EXPECT_EQ(rules.names.back(), "calm");
  }
  EXPECT_GE(files, 2);
}

}  // namespace

TEST_F(LayersCli, TheShippedAnimatedExemplarByNameAFolderOrAPatternAndItsPlayback) {
  std::string err;
  ASSERT_EQ(bake("--exemplar boil --exemplar-fps 12 --exemplar-loop ping-pong --out '" + (dir_ / "out") + "'", &err), 0)
      << err;
  const BakeManifest m = read_bake_manifest(dir_ / "out");
  EXPECT_EQ(fs::path(m.options.exemplar_color).filename(), "boil.color.%04d.png");
  EXPECT_EQ(fs::path(m.options.exemplar_feature).filename(), "boil.feature.%04d.png") << "beside the colour frames";
  EXPECT_EQ(fs::path(m.options.exemplar_displacement).filename(), "boil.disp.%04d.png");
  EXPECT_EQ(m.options.exemplar_fps, 12);
  EXPECT_EQ(m.options.exemplar_loop, ExemplarLoop::PingPong);
  EXPECT_NE(m.feature_digest.find("/12"), std::string::npos) << "12 frames: " << m.feature_digest;

  // A folder, and a layer of it beside a still one.
  const std::string folder = std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/boil";
  ASSERT_EQ(bake("--layer hot=" + folder + " --layer calm=ripples --where 'hot:heat > 0.5' --out '" +
                     (dir_ / "layered") + "'",
                 &err),
            0)
      << err;
  EXPECT_EQ(fs::path(read_bake_manifest(dir_ / "layered").options.layers[0].color).filename(), "boil.color.%04d.png");
}

TEST_F(LayersCli, AnimatedExemplarMistakesAreExit2NamingTheFile) {
  std::string err;
  fs::create_directories(dir_ / "empty");
  EXPECT_EQ(bake("--exemplar '" + (dir_ / "empty") + "' --out '" + (dir_ / "o1") + "'", &err), 2);
  EXPECT_NE(err.find(dir_ / "empty"), std::string::npos) << err;
  EXPECT_NE(err.find("NAME.color.0001.png"), std::string::npos) << err;
  EXPECT_EQ(bake("--exemplar '" + (dir_ / "none.color.%04d.png") + "' --out '" + (dir_ / "o2") + "'", &err), 2);
  EXPECT_NE(err.find("none.color.%04d.png"), std::string::npos) << err;
  EXPECT_EQ(bake("--exemplar boil --exemplar-loop bounce --out '" + (dir_ / "o3") + "'", &err), 2);
  EXPECT_NE(err.find("--exemplar-loop"), std::string::npos) << err;
  EXPECT_NE(err.find("ping-pong"), std::string::npos) << err;
}
