// tools/blender/blender_lookdev.py in Debian's Blender: a tiny bake rendered headless
// must show the atlas's colours. Skipped when `blender` is not on PATH (CI).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "addons/albedo_helpers.hpp"
#include "io_test_helpers.hpp"
#include "lapflow/io/image.hpp"

namespace lapflow {
namespace {

using test::TempDir;

bool have_blender(const TempDir& dir) { return test::have_command("blender", dir); }

std::string lookdev(const std::string& args) {
  return "blender -b --factory-startup -P '" LAPFLOW_SOURCE_DIR "/tools/blender/blender_lookdev.py' -- " + args;
}

using test::Rgb;
using test::chroma_distance;
using test::luma;

TEST(BlenderLookdev, RendersTheAtlasColoursOfABake) {
  TempDir dir("blender");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender lookdev script is not tested here";
  // lava: dark red-brown plates and orange cracks, far from grey.
  ASSERT_NO_FATAL_FAILURE(test::bake_lava_demo(dir, 2, "--resolution 256"));
  std::string err;

  // Matte, no bump, no ground, linear view: the render is albedo x lighting,
  // so textured / grey (albedo 0.18) is the albedo the camera saw.
  const std::string common = "--bake '" + (dir / "bake") +
                             "' --frames 2 --samples 16 --resolution 160x120 --displacement none --no-ground "
                             "--transparent --view-transform Standard --exposure -1 ";
  ASSERT_EQ(test::run_command(lookdev(common + "--material matte --out '" + (dir / "tex") + "'"), nullptr, &err, dir), 0)
      << err;
  ASSERT_EQ(test::run_command(lookdev(common + "--material grey --out '" + (dir / "grey") + "'"), nullptr, &err, dir), 0)
      << err;
  const Image tex = read_image(dir / "tex/demo.0002.png"), grey = read_image(dir / "grey/demo.0002.png");
  ASSERT_EQ(tex.width, 160);
  ASSERT_EQ(tex.height, 120);
  ASSERT_EQ(tex.channels, 4);
  ASSERT_EQ(grey.width, 160);
  ASSERT_EQ(grey.channels, 4);

  // The atlas's mean colour over chart texels (A = 1).
  const Image atlas = read_image(dir / "bake/demo.color.0002.exr");
  Rgb atlas_mean{};
  double atlas_n = 0;
  for (std::size_t p = 0; p < std::size_t(atlas.width) * atlas.height; ++p)
    if (atlas.pixels[p * 4 + 3] > 0.5f) {
      for (int c = 0; c < 3; ++c) atlas_mean[std::size_t(c)] += atlas.pixels[p * 4 + std::size_t(c)];
      ++atlas_n;
    }
  for (double& v : atlas_mean) v /= atlas_n;

  // Over lit object pixels: mean render colour, mean seen albedo, its spread.
  Rgb tex_mean{}, grey_mean{}, albedo_mean{};
  std::vector<double> albedo_luma;
  double object = 0;
  for (std::size_t p = 0; p < std::size_t(tex.width) * tex.height; ++p) {
    const float* t = &tex.pixels[p * 4];
    const float* g = &grey.pixels[p * 4];
    if (t[3] > 0.5f) ++object;
    if (t[3] < 0.99f || g[3] < 0.99f || g[1] < 0.02f) continue;
    Rgb albedo;
    for (std::size_t c = 0; c < 3; ++c) {
      tex_mean[c] += t[c];
      grey_mean[c] += g[c];
      albedo[c] = 0.18 * t[c] / g[c];
      albedo_mean[c] += albedo[c];
    }
    albedo_luma.push_back(luma(albedo));
  }
  const double n = double(albedo_luma.size());
  const double pixels = double(tex.width) * tex.height;
  ASSERT_GT(n, 0.05 * pixels) << "the object covers too little of the frame: camera framing is off";
  EXPECT_LT(object, 0.95 * pixels) << "the object fills the whole frame: camera framing is off";
  for (std::size_t c = 0; c < 3; ++c) tex_mean[c] /= n, grey_mean[c] /= n, albedo_mean[c] /= n;

  double var = 0;
  for (double l : albedo_luma) var += (l - luma(albedo_mean)) * (l - luma(albedo_mean));
  const double variation = std::sqrt(var / n) / luma(albedo_mean);
  std::printf("atlas mean %.3f %.3f %.3f | seen albedo %.3f %.3f %.3f (variation %.2f) | chroma distance textured "
              "%.3f, grey %.3f\n",
              atlas_mean[0], atlas_mean[1], atlas_mean[2], albedo_mean[0], albedo_mean[1], albedo_mean[2], variation,
              chroma_distance(tex_mean, atlas_mean), chroma_distance(grey_mean, atlas_mean));

  // The seen albedo has the atlas's colour and brightness.
  EXPECT_LT(chroma_distance(albedo_mean, atlas_mean), 0.05)
      << "albedo " << albedo_mean[0] << " " << albedo_mean[1] << " " << albedo_mean[2] << " vs atlas " << atlas_mean[0]
      << " " << atlas_mean[1] << " " << atlas_mean[2];
  EXPECT_NEAR(luma(albedo_mean) / luma(atlas_mean), 1.0, 0.3);
  // The textured render is coloured like the atlas, unlike the grey one.
  EXPECT_LT(chroma_distance(tex_mean, atlas_mean), 0.5 * chroma_distance(grey_mean, atlas_mean));
  // The texture shows as variation (lava: dark plates, bright cracks), far
  // above the render noise of the ratio.
  EXPECT_GT(variation, 0.2);
}

TEST(BlenderPatches, ColoursEachPatchCoreByItsId) {
  TempDir dir("blender_patches");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender patch script is not tested here";
  const std::string lapflow = LAPFLOW_BINARY;
  std::string err;
  ASSERT_EQ(test::run_command(lapflow + " demo --out '" + (dir / "mesh") + "' --frames 2 --triangles 3000 --no-bake -q",
                              nullptr, &err, dir),
            0)
      << err;
  ASSERT_EQ(test::run_command(lapflow + " patches --mesh '" + (dir / "mesh") + "/demo.%04d.ply' --radius 0.06 -q --out '" +
                                  (dir / "p") + "'",
                              nullptr, &err, dir),
            0)
      << err;
  ASSERT_EQ(test::run_command("blender -b --factory-startup -P '" LAPFLOW_SOURCE_DIR "/tools/blender/blender_patches.py' -- "
                              "--patches '" + (dir / "p") + "/demo.patches.%04d.ply' --frames 2 --samples 4 "
                              "--resolution 160x120 --no-ground --out '" + (dir / "r") + "'",
                              nullptr, &err, dir),
            0)
      << err;
  const Image img = read_image(dir / "r/demo.patches.0002.png");
  ASSERT_EQ(img.width, 160);
  ASSERT_EQ(img.height, 120);
  // The cores are coloured by a hash of patch_id: saturated pixels of many
  // different hues (the sky and the fluid-free background are not saturated).
  std::array<int, 12> hue_bins{};
  int saturated = 0;
  for (std::size_t p = 0; p < std::size_t(img.width) * img.height; ++p) {
    const float* c = &img.pixels[p * std::size_t(img.channels)];
    const float hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
    if (hi < 0.02f || (hi - lo) / hi < 0.5f) continue;
    ++saturated;
    double h;  // hue in [0, 6)
    if (hi == c[0]) h = std::fmod((c[1] - c[2]) / (hi - lo) + 6.0, 6.0);
    else if (hi == c[1]) h = (c[2] - c[0]) / (hi - lo) + 2.0;
    else h = (c[0] - c[1]) / (hi - lo) + 4.0;
    ++hue_bins[std::min<std::size_t>(11, std::size_t(h * 2))];
  }
  int hues = 0;
  for (int n : hue_bins) hues += n >= 10;
  std::printf("saturated pixels %d of %d, hue bins used %d of 12\n", saturated, img.width * img.height, hues);
  EXPECT_GT(saturated, img.width * img.height / 50);
  EXPECT_GE(hues, 5);

  // A missing dump is a clear error.
  EXPECT_EQ(test::run_command("blender -b --factory-startup -P '" LAPFLOW_SOURCE_DIR "/tools/blender/blender_patches.py' -- "
                              "--patches '" + (dir / "p") + "/demo.patches.%04d.ply' --frames 7",
                              nullptr, &err, dir),
            2);
  EXPECT_NE(err.find("demo.patches.0007.ply"), std::string::npos) << err;
}

TEST(BlenderLookdev, MissingBakeFailsWithAClearMessage) {
  TempDir dir("blender_missing");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender lookdev script is not tested here";
  std::string err;
  EXPECT_EQ(test::run_command(lookdev("--bake '" + (dir / "no_such_bake") + "'"), nullptr, &err, dir), 2);
  EXPECT_NE(err.find("no_such_bake"), std::string::npos) << err;
  EXPECT_NE(err.find("blender_lookdev: error"), std::string::npos) << err;
}

}  // namespace
}  // namespace lapflow
