// Feature maps: known answers for luminance, edges and the distance
// transform, the CLI's output read back, bad input, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/addons/feature_map.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

using test::TempDir;

// Left half 0, right half 1 (grey), `w` x `h`, step between x = w/2-1 and w/2.
Image step_image(int w, int h) {
  Image img(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = w / 2; x < w; ++x) img.at(x, y, 0) = 1.f;
  return img;
}

std::string exemplar(const std::string& file) { return std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/" + file; }

TEST(FeatureMap, LuminanceOfKnownColours) {
  Image img(3, 1, 3);
  const float colours[3][3] = {{1, 0, 0}, {0, 1, 0}, {0.2f, 0.4f, 0.8f}};
  for (int x = 0; x < 3; ++x)
    for (int c = 0; c < 3; ++c) img.at(x, 0, c) = colours[x][c];
  const Image y = luminance(img);
  ASSERT_EQ(y.channels, 1);
  EXPECT_NEAR(y.at(0, 0, 0), 0.2126, 1e-6);
  EXPECT_NEAR(y.at(1, 0, 0), 0.7152, 1e-6);
  EXPECT_NEAR(y.at(2, 0, 0), 0.2126 * 0.2 + 0.7152 * 0.4 + 0.0722 * 0.8, 1e-6);

  // The luminance method stretches to [0,1]: black 0, white 1, mid grey 0.5.
  Image grey(3, 1, 4, 1.f);  // RGBA: alpha must be ignored
  for (int c = 0; c < 3; ++c) grey.at(0, 0, c) = 0.f, grey.at(1, 0, c) = 1.f, grey.at(2, 0, c) = 0.5f;
  grey.at(2, 0, 3) = 0.f;
  FeatureMapOptions o;
  o.method = FeatureMethod::Luminance;
  const Image f = make_feature_map(grey, o);
  EXPECT_FLOAT_EQ(f.at(0, 0, 0), 0.f);
  EXPECT_FLOAT_EQ(f.at(1, 0, 0), 1.f);
  EXPECT_NEAR(f.at(2, 0, 0), 0.5f, 1e-6);
  o.invert = true;
  EXPECT_NEAR(make_feature_map(grey, o).at(2, 0, 0), 0.5f, 1e-6);
  EXPECT_FLOAT_EQ(make_feature_map(grey, o).at(1, 0, 0), 0.f);
}

TEST(FeatureMap, EdgesPeakOnTheStep) {
  const Image step = step_image(16, 8);
  // Without blur: Sobel / 8 of a unit step is exactly 0.5 on both sides of it, 0 elsewhere.
  const Image g = gradient_magnitude(step, 0);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) EXPECT_FLOAT_EQ(g.at(x, y, 0), (x == 7 || x == 8) ? 0.5f : 0.f) << x << "," << y;
  // With blur the peak stays on the step and falls off monotonically.
  const Image gb = gradient_magnitude(step, 1.5);
  for (int y = 0; y < 8; ++y) {
    EXPECT_NEAR(gb.at(7, y, 0), gb.at(8, y, 0), 1e-6);
    for (int x = 1; x <= 7; ++x) EXPECT_LE(gb.at(x - 1, y, 0), gb.at(x, y, 0) + 1e-7);
    for (int x = 8; x < 15; ++x) EXPECT_GE(gb.at(x, y, 0), gb.at(x + 1, y, 0) - 1e-7);
  }
  // The edges method is low on the step (erode there first), 1 on the flats.
  FeatureMapOptions o;
  o.method = FeatureMethod::Edges;
  o.edge_sigma = 0;
  const Image f = make_feature_map(step, o);
  for (int x = 0; x < 16; ++x) EXPECT_FLOAT_EQ(f.at(x, 3, 0), (x == 7 || x == 8) ? 0.f : 1.f) << x;
}

TEST(FeatureMap, DistanceTransformIsExactEuclidean) {
  // One seed pixel: the distance is the exact Euclidean distance to it.
  Image seeds(23, 17, 1);
  seeds.at(5, 11, 0) = 1.f;
  Image d = distance_transform(seeds);
  for (int y = 0; y < 17; ++y)
    for (int x = 0; x < 23; ++x) EXPECT_NEAR(d.at(x, y, 0), std::hypot(x - 5.0, y - 11.0), 1e-5) << x << "," << y;

  // A vertical line at x = 9: distance |x - 9|, the same on every row.
  Image line(20, 6, 1);
  for (int y = 0; y < 6; ++y) line.at(9, y, 0) = 1.f;
  d = distance_transform(line);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 20; ++x) EXPECT_FLOAT_EQ(d.at(x, y, 0), float(std::abs(x - 9)));

  // Scattered seeds against brute force.
  Image scattered(31, 29, 1);
  std::vector<std::pair<int, int>> pts;
  for (int i = 0; i < 12; ++i) {
    const int x = int(hash64(7, uint64_t(i), 0) % 31), y = int(hash64(7, uint64_t(i), 1) % 29);
    scattered.at(x, y, 0) = 1.f;
    pts.emplace_back(x, y);
  }
  d = distance_transform(scattered);
  for (int y = 0; y < 29; ++y)
    for (int x = 0; x < 31; ++x) {
      double best = 1e30;
      for (auto [px, py] : pts) best = std::min(best, std::hypot(double(x - px), double(y - py)));
      EXPECT_NEAR(d.at(x, y, 0), best, 1e-5) << x << "," << y;
    }

  // No seed at all: infinitely far.
  d = distance_transform(Image(4, 3, 1));
  for (float v : d.pixels) EXPECT_TRUE(std::isinf(v));
}

TEST(FeatureMap, DistanceIsHighInsideElementsAndZeroOnTheirBorder) {
  // A bright disk (radius 12 px) on black: the feature is 0 on its rim and
  // highest at its centre, rising monotonically inward.
  Image disk(64, 64, 3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      if (std::hypot(x - 31.5, y - 31.5) < 12) disk.at(x, y, 0) = disk.at(x, y, 1) = disk.at(x, y, 2) = 0.8f;
  FeatureMapOptions o;
  o.method = FeatureMethod::Distance;
  o.distance_max = 8;  // pixels
  const Image f = make_feature_map(disk, o);
  EXPECT_FLOAT_EQ(f.at(31, 20, 0), 0.f);                  // on the rim
  EXPECT_FLOAT_EQ(f.at(31, 31, 0), 1.f);                  // the centre is > 8 px from the rim
  for (int y = 21; y < 31; ++y) EXPECT_LE(f.at(31, y, 0), f.at(31, y + 1, 0));
  // distance_max scales distances linearly: halving it doubles every unsaturated value.
  o.distance_max = 16;
  const Image f16 = make_feature_map(disk, o);
  for (std::size_t p = 0; p < f.pixels.size(); ++p) EXPECT_NEAR(f.pixels[p], std::min(1.f, 2 * f16.pixels[p]), 1e-6);
}

TEST(FeatureMap, ShippedExemplarsAgreeWithTheirFeatureMaps) {
  // The distance method is built for textures of distinct elements: pebbles
  // (rounded distance to the cell border) must come out close to the shipped map.
  const Image color = read_image(exemplar("pebbles.color.png"));
  const Image shipped = read_image(exemplar("pebbles.feature.png"), ColorSpace::Linear);
  FeatureMapOptions o;
  o.method = FeatureMethod::Distance;
  EXPECT_GT(image_correlation(make_feature_map(color, o), shipped), 0.6);
  o.method = FeatureMethod::Luminance;
  EXPECT_GT(image_correlation(make_feature_map(color, o), shipped), 0.3);
  o.method = FeatureMethod::Edges;
  EXPECT_GT(image_correlation(make_feature_map(color, o), shipped), 0.3);
}

TEST(FeatureMap, SameResultAtOneAndTwoThreads) {
  const Image color = resize_image(read_image(exemplar("scales.color.png")), 256, 256);
  for (FeatureMethod m : {FeatureMethod::Luminance, FeatureMethod::Edges, FeatureMethod::Distance}) {
    FeatureMapOptions o;
    o.method = m;
    o.blur_sigma = 1.5;
    set_thread_count(1);
    const Image a = make_feature_map(color, o);
    set_thread_count(2);
    const Image b = make_feature_map(color, o);
    set_thread_count(0);
    EXPECT_EQ(a.pixels, b.pixels) << feature_method_name(m);
  }
}

TEST(FeatureMapCli, WritesPngExrTiffThatReadBack) {
  TempDir dir("featuremap");
  const std::string in = exemplar("squares.color.png");
  FeatureMapOptions o;
  o.method = FeatureMethod::Edges;
  const Image expected = make_feature_map(read_image(in), o);
  for (const std::string ext : {"png", "exr", "tif"}) {
    const std::string out = dir / ("f." + ext);
    std::string err;
    ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " feature-map '" + in + "' -o '" + out +
                                    "' --method edges -q",
                                nullptr, &err, dir),
              0)
        << err;
    const Image back = read_image(out, ColorSpace::Linear);
    ASSERT_EQ(back.width, expected.width);
    ASSERT_EQ(back.height, expected.height);
    ASSERT_EQ(back.channels, 1) << ext;
    // 16-bit integer files quantise to 1/65535; EXR stores float.
    const double tol = ext == "exr" ? 1e-6 : 1.0 / 65535;
    double worst = 0;
    for (std::size_t p = 0; p < back.pixels.size(); ++p)
      worst = std::max(worst, double(std::abs(back.pixels[p] - expected.pixels[p])));
    EXPECT_LE(worst, tol) << ext;
  }
  // --compare prints the correlation with a reference map on stdout.
  std::string out;
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " feature-map '" + in + "' -o '" + (dir / "d.png") +
                                  "' -q --compare '" + exemplar("squares.feature.png") + "'",
                              &out, nullptr, dir),
            0);
  EXPECT_NE(out.find("correlation with"), std::string::npos) << out;
}

TEST(FeatureMapCli, BadInputNamesTheFile) {
  TempDir dir("featuremap_bad");
  std::string err;
  const std::string missing = dir / "no_such_exemplar.png";
  EXPECT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " feature-map '" + missing + "' -o '" + (dir / "o.png") + "'",
                              nullptr, &err, dir),
            2);
  EXPECT_NE(err.find("no_such_exemplar.png"), std::string::npos) << err;

  const std::string garbage = dir / "garbage.png";
  test::write_bytes(garbage, "this is not a PNG file at all");
  EXPECT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " feature-map '" + garbage + "' -o '" + (dir / "o.png") + "'",
                              nullptr, &err, dir),
            2);
  EXPECT_NE(err.find("garbage.png"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(dir / "o.png"));

  EXPECT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " feature-map '" + exemplar("pebbles.color.png") +
                                  "' -o '" + (dir / "o.jpg") + "'",
                              nullptr, &err, dir),
            2);
  EXPECT_NE(err.find("o.jpg"), std::string::npos) << err;

  // The library names the file too.
  try {
    read_image(missing);
    FAIL() << "read_image accepted a missing file";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_exemplar.png"), std::string::npos);
  }
}

}  // namespace
}  // namespace lapflow
