// Exemplar layers (docs/layers.md): the layer a patch shows follows the
// rules over the simulation's attributes, a region whose rule changes shows
// the new layer within --layer-switch frames, the state and a render keep
// each patch's layer, and a bake of one layer is a bake of one exemplar.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>

#include "io_test_helpers.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
using lapflow::test::shipped;
using lapflow::test::shipped_layer;
namespace fs = std::filesystem;

namespace {


/// Two layers: `hot` (lava) where heat > 0.5, else `calm` (pebbles).
BakeOptions heat_bake(const std::string& meshes, const std::string& out) {
  BakeOptions o = default_bake_options();
  o.mesh_pattern = meshes + "/m.%04d.ply";
  o.out_dir = out;
  o.name = "t";
  o.patch.radius = 0.05;
  o.atlas.resolution = 256;
  o.aov = true;
  o.keep_states = -1;
  o.usd = false;
  o.layers = {shipped_layer("hot", "lava"), shipped_layer("calm", "pebbles")};
  o.layer_rules = {{"hot", "heat > 0.5"}};
  return o;
}

/// Per frame: of the chart texels whose surface point has x in `keep`, the
/// fraction whose AOV layer is the one `want(x)` names. Bakes with the
/// library's frame loop so that the atlas's texels give their points.
std::vector<double> layer_agreement(BakeOptions o, const std::function<bool(double)>& keep,
                                    const std::function<int(double, int)>& want, int frames) {
  resolve_bake_options(o);
  const BakeExemplars exemplars = load_bake_exemplars(o);
  const FrameSource source = frame_source(o);
  PatchSet patches;
  std::shared_ptr<Frame> prev;
  std::vector<double> out;
  for (int f = 1; f <= frames; ++f) {
    std::shared_ptr<Frame> cur = load_frame(source, f);
    build_frame_atlases(*cur, o);
    track_frame(*cur, prev.get(), patches, exemplars.layers(), o);
    render_frame(*cur, patches, exemplars.layers(), o);
    const Image& aov = cur->textures.aov;
    EXPECT_EQ(aov.channels, 5) << "patch_id u v w layer";
    const TexelMap& tm = cur->atlas.texels;
    std::size_t counted = 0, agree = 0;
    for (std::size_t i = 0; i < tm.size(); ++i) {
      float b1, b2;
      texel_barycentrics(cur->atlas.corner_uv, cur->atlas.resolution, tm.texel[i], tm.triangle[i], b1, b2);
      const Tri& t = cur->mesh.triangles[tm.triangle[i]];
      const double x = cur->mesh.positions[t[0]].x * (1 - b1 - b2) + cur->mesh.positions[t[1]].x * b1 +
                       cur->mesh.positions[t[2]].x * b2;
      if (!keep(x)) continue;
      ++counted;
      agree += int(aov.pixels[std::size_t(tm.texel[i]) * 5 + 4]) == want(x, f);
    }
    out.push_back(counted ? double(agree) / double(counted) : 0.0);
    prev = cur;
  }
  return out;
}

TEST(Layers, TheShownLayerFollowsTheRuleAwayFromTheBoundary) {
  TempDir dir("layers_half");
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 12, [](double x, int) { return x; });
  const BakeOptions o = heat_bake(dir / "in", dir / "out");
  // Half the surface is hot (x > 0.5). A patch keeps the layer of the point
  // it was born at and reaches r = 0.05 from it: beyond that band the
  // shown layer is the rule's.
  const std::vector<double> agreement = layer_agreement(
      o, [](double x) { return std::abs(x - 0.5) > 0.05; }, [](double x, int) { return x > 0.5 ? 0 : 1; }, 12);
  for (std::size_t f = 0; f < agreement.size(); ++f) {
    SCOPED_TRACE(fmt::format("frame {}", f + 1));
    EXPECT_GE(agreement[f], 0.95);
  }
}

TEST(Layers, ARegionWhoseRuleChangesShowsTheNewLayerWithinTheSwitchFrames) {
  TempDir dir("layers_switch");
  fs::create_directories(dir / "in");
  // Cold everywhere on frames 1-6, hot from frame 7.
  constexpr int kChange = 7, kFrames = 16;
  test::write_heat_plane(dir / "in", kFrames, [](double, int f) { return f >= kChange ? 1.0 : 0.0; });
  BakeOptions o = heat_bake(dir / "in", dir / "out");
  o.layer_switch = 4;
  const std::vector<double> hot = layer_agreement(
      o, [](double) { return true; }, [](double, int) { return 0; }, kFrames);
  int first = 0;
  for (int f = 1; f <= kFrames && !first; ++f)
    if (hot[f - 1] >= 0.95) first = f;
  for (int f = 1; f < kChange; ++f) EXPECT_EQ(hot[f - 1], 0.0) << "frame " << f << ": nothing is hot yet";
  ASSERT_GT(first, 0) << "the surface never came to show the hot layer";
  // A patch goes after layer_switch frames of the other rule at its centre;
  // the hole filling of that frame brings the new layer.
  EXPECT_LE(first - kChange + 1, o.layer_switch) << "frames from the change to 95% shown";
  for (int f = first; f <= kFrames; ++f) EXPECT_GE(hot[f - 1], 0.95) << "frame " << f;
}

TEST(Layers, OneLayerIsTheSameBakeAsOneExemplar) {
  TempDir dir("layers_one");
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 3, [](double x, int) { return x; });
  BakeOptions a = heat_bake(dir / "in", dir / "a");
  a.layers.clear();
  a.layer_rules.clear();
  a.exemplar_color = shipped("pebbles", "color");
  a.exemplar_feature = shipped("pebbles", "feature");
  a.exemplar_displacement = shipped("pebbles", "disp");
  BakeOptions b = heat_bake(dir / "in", dir / "b");
  b.layers = {shipped_layer("only", "pebbles")};
  b.layer_rules.clear();
  resolve_bake_options(a);
  resolve_bake_options(b);
  bake(a);
  bake(b);
  for (int f = 1; f <= 3; ++f)
    for (const std::string kind : {"color", "disp", "aov"}) {
      const std::string file = fmt::format("t.{}.{:04d}.exr", kind, f);
      EXPECT_TRUE(test::read_bytes(dir / ("a/" + file)) == test::read_bytes(dir / ("b/" + file))) << file;
    }
  EXPECT_TRUE(test::read_bytes(dir / "a/t.0003.obj") == test::read_bytes(dir / "b/t.0003.obj"));
  EXPECT_EQ(bake_state_file_patches_crc(dir / "a/t.state.0003.bin"), bake_state_file_patches_crc(dir / "b/t.state.0003.bin"))
      << "the patch data";
  EXPECT_EQ(read_image(dir / "b/t.aov.0003.exr").channels, 4) << "no layer channel with one layer";
}

TEST(Layers, TheStateKeepsEachPatchsLayerAndARenderDrawsIt) {
  TempDir dir("layers_render");
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 3, [](double x, int) { return x; });
  BakeOptions o = heat_bake(dir / "in", dir / "bake");
  resolve_bake_options(o);
  bake(o);
  const BakeState state = read_bake_state(dir / "bake/t.state.0003.bin");
  EXPECT_EQ(state.header.layers, 2);
  std::size_t hot = 0;
  for (const Patch& p : state.patches.patches) hot += p.layer == 0;
  EXPECT_GT(hot, 0u);
  EXPECT_LT(hot, state.patches.patches.size());
  // The render of the states draws the same atlases, each patch in its layer.
  RenderOptions r;
  r.dir = dir / "bake";
  r.out_dir = dir / "render";
  render(r);
  for (const std::string kind : {"color", "aov"})
    EXPECT_TRUE(test::read_bytes(dir / fmt::format("bake/t.{}.0003.exr", kind)) ==
                test::read_bytes(dir / fmt::format("render/t.{}.0003.exr", kind)))
        << kind;
  // A layer swapped for an exemplar of another feature map is refused: its
  // patches' erosion would differ.
  RenderOptions swap = r;
  swap.out_dir = dir / "swapped";
  swap.layers = {shipped_layer("hot", "scales")};
  EXPECT_NE(test::input_error_of([&] { render(swap); }).find("feature maps"), std::string::npos);
  // One of the same feature map draws the same patches with other colours.
  swap.layers = {{"hot", shipped("pebbles", "color"), shipped("lava", "feature"), shipped("lava", "disp")}};
  render(swap);
  EXPECT_FALSE(test::read_bytes(dir / "bake/t.color.0003.exr") == test::read_bytes(dir / "swapped/t.color.0003.exr"));
  EXPECT_TRUE(test::read_bytes(dir / "bake/t.aov.0003.exr") == test::read_bytes(dir / "swapped/t.aov.0003.exr"));
  swap.layers = {shipped_layer("spray", "lava")};
  try {
    render(swap);
    ADD_FAILURE() << "a layer the tracking has not";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("no layer 'spray' (its layers: hot, calm)"), std::string::npos) << e.what();
  }
}

TEST(Layers, ALayeredBakeIsTheSameAtAnyThreadCount) {
  TempDir dir("layers_threads");
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 3, [](double x, int f) { return x + 0.1 * f; });
  for (const int threads : {1, 2}) {
    BakeOptions o = heat_bake(dir / "in", dir / fmt::format("t{}", threads));
    o.layer_switch = 1;  // retire on the first frame of another rule: the switch runs
    resolve_bake_options(o);
    set_thread_count(threads);
    bake(o);
  }
  set_thread_count(0);
  for (const std::string file : {"t.color.0003.exr", "t.aov.0003.exr", "t.0003.obj"})
    EXPECT_TRUE(test::read_bytes(dir / ("t1/" + file)) == test::read_bytes(dir / ("t2/" + file))) << file;
  EXPECT_EQ(bake_state_file_patches_crc(dir / "t1/t.state.0003.bin"), bake_state_file_patches_crc(dir / "t2/t.state.0003.bin"));
}

TEST(Layers, RulesAreCheckedBeforeTheBake) {
  BakeOptions o = default_bake_options();
  o.layers = {shipped_layer("foam", "foam"), shipped_layer("calm", "pebbles")};
  const auto usage = [&] {
    try {
      layer_rules(o);
    } catch (const UsageError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(usage(), "--layer foam: no --where foam:RULE; every layer but the last (the default) needs a rule");
  o.layer_rules = {{"foam", "speed > 1.5 and curvature > 20 or foam > 0.5"}};
  EXPECT_EQ(usage(), "accepted");
  const LayerRules rules = layer_rules(o);
  EXPECT_EQ(rules.attributes, (std::vector<std::string>{"speed", "curvature", "foam"}));
  EXPECT_EQ(rules.file_attributes(), (std::vector<std::string>{"foam"}));
  const float fast_flat[] = {2.f, 0.f, 0.f}, fast_curved[] = {2.f, 30.f, 0.f}, foamy[] = {0.f, 0.f, 1.f};
  EXPECT_EQ(rules.choose(fast_flat), 1);
  EXPECT_EQ(rules.choose(fast_curved), 0);
  EXPECT_EQ(rules.choose(foamy), 0);
  o.layer_rules.push_back({"calm", "speed < 1"});
  EXPECT_EQ(usage(), "--where calm:speed < 1: layer 'calm' is the last, the default where no other rule holds: it "
                     "takes no rule");
  o.layer_rules = {{"foam", "speed >"}};
  EXPECT_EQ(usage(), "--where foam:speed >: column 8: the rule ends where a value is expected");
  o.layer_rules = {{"spray", "speed > 1"}, {"foam", "speed > 2"}};
  EXPECT_EQ(usage(), "--where spray:speed > 1: no --layer is named 'spray'");
  // The option's text: a rule that does not parse names its column.
  BakeOptions b = default_bake_options();
  try {
    set_bake_option(b, *find_bake_option("where"), "foam:speed = 2");
    ADD_FAILURE() << "accepted";
  } catch (const UsageError& e) {
    EXPECT_EQ(std::string(e.what()),
              "--where: 'foam:speed = 2' is not a rule: column 7: '=' is not a comparison: write '=='");
  }
}

TEST(Layers, AnAttributeTheFramesLackIsAnInputErrorNamingTheFile) {
  TempDir dir("layers_attr");
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 2, [](double x, int) { return x; });
  BakeOptions o = heat_bake(dir / "in", dir / "out");
  o.layer_rules = {{"hot", "temperature > 900"}};
  const std::string message = test::input_error_of([&] { resolve_bake_options(o); });
  EXPECT_NE(message.find(dir / "in/m.0001.ply"), std::string::npos) << message;
  EXPECT_NE(message.find("no property 'temperature' (it has: x y z vx vy vz heat)"), std::string::npos) << message;
}

}  // namespace
