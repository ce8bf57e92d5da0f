// `lapflow preview --show layers` (docs/preview.md): each texel tinted by its
// exemplar layer over the texture's luminance, the legend, a layered bake's
// halves in their layers' colours as the rule chose them, and the bakes
// that have no layer channel.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "io_test_helpers.hpp"
#include "lapflow/addons/preview.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/io/image.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

namespace fs = std::filesystem;

using test::shipped;

TEST(PreviewLayers, EachTexelIsItsLayersColourShadedByItsLuminance) {
  Image color(4, 1, 4, 0.f), layers(4, 1, 1, 0.f);
  // White, black, white, dark red (luminance 0.2126 * 0.25).
  for (int c = 0; c < 3; ++c) color.at(0, 0, c) = color.at(2, 0, c) = 1.f;
  color.at(3, 0, 0) = 0.25f;
  for (int x = 0; x < 4; ++x) color.at(x, 0, 3) = 0.25f * float(x);
  layers.pixels = {0.f, 1.f, -1.f, 9.f};
  const Image t = tint_by_layer(color, layers);
  ASSERT_EQ(t.channels, 4);
  const double dark = 0.3 + 0.7 * std::sqrt(0.2126 * 0.25);
  const struct {
    int x;
    Vec3 want;
  } cases[] = {{0, preview_layer_color(0)},                // white: the full tint
               {1, preview_layer_color(1) * 0.3},          // black: 0.3 of it
               {2, Vec3{0.5, 0.5, 0.5}},                   // no layer: grey (white: unshaded)
               {3, preview_layer_color(1) * dark}};        // the palette repeats after 8
  for (const auto& c : cases) {
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(t.at(c.x, 0, k), c.want[k], 1e-6) << "texel " << c.x << " channel " << k;
    EXPECT_EQ(t.at(c.x, 0, 3), color.at(c.x, 0, 3)) << "alpha of texel " << c.x;
  }
  // Eight distinct colours.
  for (int a = 0; a < 8; ++a)
    for (int b = a + 1; b < 8; ++b) EXPECT_GT(norm(preview_layer_color(a) - preview_layer_color(b)), 0.2) << a << " " << b;
  EXPECT_THROW(tint_by_layer(color, Image(3, 1, 1)), std::invalid_argument);
}

TEST(PreviewLayers, TheLegendHasASwatchOfEachLayersColourAndItsName) {
  Image img(200, 100, 3, 0.5f);
  EXPECT_FALSE(draw_layer_legend(img, {"hot", "calm"}, 16, "/nonexistent/font.ttf"));
  for (float v : img.pixels) ASSERT_EQ(v, 0.5f);
  if (!fs::exists(default_label_font())) GTEST_SKIP() << "no " << default_label_font();
  ASSERT_TRUE(draw_layer_legend(img, {"hot", "calm"}, 16, default_label_font()));
  // Lines of 16 + 2 * 4 pixels, 4 apart, 8 from the bottom-left corner:
  // swatches [8, 32) x [40, 64) and [8, 32) x [68, 92).
  for (int l = 0; l < 2; ++l) {
    const int cx = 20, cy = l == 0 ? 52 : 80;
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(img.at(cx, cy, k), float(preview_layer_color(l)[k])) << "layer " << l;
    int glyph = 0;  // the name right of the swatch, white
    for (int y = cy - 8; y < cy + 8; ++y)
      for (int x = 36; x < 120; ++x) glyph += img.at(x, y, 0) > 0.9f;
    EXPECT_GT(glyph, 10) << "layer " << l;
  }
  EXPECT_EQ(img.at(150, 10, 0), 0.5f);  // nothing elsewhere
}

/// Frame 1 of the heat plane (heat = x on the unit square at z = 0), baked
/// with AOVs: `hot` (lava) where heat > 0.5, else `calm` (pebbles).
std::string bake_layered_plane(const test::TempDir& dir) {
  fs::create_directories(dir / "in");
  test::write_heat_plane(dir / "in", 1, [](double x, int) { return x; });
  BakeOptions o = default_bake_options();
  o.mesh_pattern = dir / "in/m.%04d.ply";
  o.out_dir = dir / "bake";
  o.name = "t";
  o.patch.radius = 0.05;
  o.atlas.resolution = 256;
  o.aov = true;
  o.usd = false;
  o.layers = {{"hot", shipped("lava", "color"), shipped("lava", "feature"), shipped("lava", "disp")},
              {"calm", shipped("pebbles", "color"), shipped("pebbles", "feature"), shipped("pebbles", "disp")}};
  o.layer_rules = {{"hot", "heat > 0.5"}};
  resolve_bake_options(o);
  bake(o);
  return o.out_dir;
}

TEST(PreviewLayers, TheHotHalfShowsHotsColourAndTheCalmHalfCalms) {
  test::TempDir dir("preview_layers");
  const std::string baked = bake_layered_plane(dir);
  // Straight down on the plane with +y up the picture: +x to the right.
  const std::string args = " --frames 1 --camera 0.5,0.5,2.2,0.5,0.5,0,30 --up y --no-ground --no-labels --width 96 "
                           "--height 96 --samples 1 --no-video --out ";
  std::string out, err;
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " preview " + baked + " --show layers" + args + (dir / "layers"),
                              &out, &err, dir),
            0)
      << err;
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " preview " + baked + args + (dir / "color"), &out, &err, dir),
            0)
      << err;
  const Image layers = read_image(dir / "layers/t.preview.0001.png", ColorSpace::Linear);
  const Image color = read_image(dir / "color/t.preview.0001.png", ColorSpace::Linear);
  ASSERT_EQ(layers.width, 96);
  // Mean colour of the plane's left (x < 0.5: calm) and right (hot) halves,
  // a band of 16 pixels off the boundary and inside the plane's edges.
  auto mean = [](const Image& img, int x0, int x1) {
    Vec3 sum;
    for (int y = 24; y < 72; ++y)
      for (int x = x0; x < x1; ++x) sum += Vec3{img.at(x, y, 0), img.at(x, y, 1), img.at(x, y, 2)};
    return sum * (1.0 / (48.0 * (x1 - x0)));
  };
  const Vec3 calm = mean(layers, 16, 40), hot = mean(layers, 56, 80);
  const Vec3 hot_tint = preview_layer_color(0), calm_tint = preview_layer_color(1);
  EXPECT_GT(hot.x, 2 * hot.z) << "hot is orange";
  EXPECT_GT(calm.z, 2 * calm.x) << "calm is blue";
  // Each half's colour points the way of its layer's tint.
  auto cosine = [](const Vec3& a, const Vec3& b) { return dot(a, b) / (norm(a) * norm(b)); };
  EXPECT_GT(cosine(hot, hot_tint), 0.95);
  EXPECT_GT(cosine(calm, calm_tint), 0.95);
  // Without --show layers the same picture shows the textures' own colours.
  const Vec3 calm_color = mean(color, 16, 40);
  EXPECT_LT(cosine(calm_color, calm_tint), 0.9);
}

/// A one-quad bake of frame 1 with one exemplar: its colour atlas and, when
/// `aov`, a 4-channel AOV (no layer channel).
void write_one_exemplar_bake(const std::string& dir, bool aov) {
  fs::create_directories(dir);
  BakeManifest m;
  m.name = "shot";
  m.dir = dir;
  m.frames = {1};
  m.options.patch.radius = 0.1;
  m.options.aov = aov;
  write_bake_manifest(m, bake_manifest_path(dir, "shot"));
  test::write_bytes(m.frame_file("obj", 1), "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                             "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
  write_exr(m.frame_file("color", 1), Image(8, 8, 4, 1.f), {"R", "G", "B", "A"});
  if (aov) write_exr(m.frame_file("aov", 1), Image(8, 8, 4, 0.f), {"patch_id", "u", "v", "w"});
}

TEST(PreviewLayers, ABakeWithoutALayerChannelIsAnErrorNamingItsAov) {
  test::TempDir dir("preview_layers_bad");
  const std::string bin = LAPFLOW_BINARY, args = " --show layers --width 32 --height 24 --no-video";
  std::string out, err;
  write_one_exemplar_bake(dir / "no_aov", false);
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "no_aov") + args, &out, &err, dir), 2);
  EXPECT_NE(err.find(dir / "no_aov/shot.aov.0001.exr"), std::string::npos) << err;
  EXPECT_NE(err.find("--aov"), std::string::npos) << err;
  write_one_exemplar_bake(dir / "one", true);
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "one") + args, &out, &err, dir), 2);
  EXPECT_NE(err.find(dir / "one/shot.aov.0001.exr"), std::string::npos) << err;
  EXPECT_NE(err.find("no channel 'layer'"), std::string::npos) << err;
  // Any other view is a usage error.
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "one") + " --show heat", &out, &err, dir), 2);
  // The colour view of the same bake is fine.
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "one") + " --width 32 --height 24 --no-video", &out, &err, dir),
            0)
      << err;
}

}  // namespace
}  // namespace lapflow
