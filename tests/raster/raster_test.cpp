// Rasterizer tests on hand-built planes with analytic answers: the erosion is
// the paper's formula texel by texel, the oldest non-eroded patch wins, one
// patch per texel (no blending), holes get filled, hidden patches retire, the
// seam fallback agrees with the in-chart path, and any thread count gives the
// same images.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/raster_fixture.hpp"
#include "raster/internal.hpp"
#include "raster/tiles.hpp"
#include "raster/sampling.hpp"

namespace lapflow {
namespace {

/// The paper's raster (every hole a patch, no hysteresis, no merge): what the
/// brute-force reference (expect_matches_reference) computes. Tests of
/// RasterOptions::hold, small_hole and merge turn them on themselves.
RasterOptions paper_options() {
  RasterOptions o;
  o.use_paper_hole_filling();
  return o;
}

using test::PatchSpec;
using test::PlaneFixture;

// The paper's erosion formula written out independently of the rasterizer:
// returns the signed margin (>= 0 kept) of a patch at (u, v) with weight w.
struct Formula {
  const Image& feature;
  double M = 0, eps = 0.1;
  Formula(const Image& f, double e) : feature(f), eps(e) {
    for (int y = 0; y < f.height; ++y)
      for (int x = 0; x < f.width; ++x) {
        const double u = (x + 0.5) / f.width, v = 1 - (y + 0.5) / f.height;
        M = std::max(M, std::sqrt(f.at(x, y, 0) + D(u, v)));
      }
  }
  static double D(double u, double v) { return std::max(0.0, 1 - std::hypot(u - 0.5, v - 0.5) / 0.5); }
  double margin(double u, double v, double w) const {
    const double inside = std::min({u, 1 - u, v, 1 - v});
    if (inside < 0) return inside;
    float F;
    sample_bilinear(feature, u, v, &F);
    const double m = std::sqrt(F + D(u, v)) / M - eps - (1 - w);
    return std::min(m, inside);
  }
};

// Reference winner by the paper's definition: walk the patches oldest first,
// the first that covers the texel's point and keeps it. `ambiguous` when a
// decision on the way was within round-off.
struct RefWinner {
  int id = -1;
  bool ambiguous = false;
};
RefWinner reference(const PlaneFixture& f, const std::vector<std::pair<uint32_t, PatchSpec>>& stack,
                    const Formula& formula, const Vec3& p) {
  RefWinner r;
  for (const auto& [id, s] : stack) {
    if (!s.covers(p, f.L)) continue;
    const double x0 = std::max(0.0, s.centre.x - s.half), x1 = std::min(f.L, s.centre.x + s.half);
    const double y0 = std::max(0.0, s.centre.y - s.half), y1 = std::min(f.L, s.centre.y + s.half);
    const double edge = std::min({p.x - x0, x1 - p.x, p.y - y0, y1 - p.y});
    const Vec2 uv = s.uv_at(p);
    const double m = formula.margin(uv.x, uv.y, s.w_at(p));
    if (std::abs(m) < 1e-6 || edge < 1e-9) r.ambiguous = true;
    if (m >= 0) {
      r.id = int(id);
      return r;
    }
  }
  return r;
}

RasterExemplar prepared(const Exemplar& ex, double eps = 0.1) { return prepare_raster_exemplar(ex, eps); }

struct Scene {
  PlaneFixture f;
  Exemplar ex;
  RasterExemplar rex;
  PatchSet patches;
  std::vector<std::pair<uint32_t, PatchSpec>> specs;  // id -> spec, in creation order
  /// (id, spec) in the final stack order (retired patches won nothing, so
  /// leaving them out does not change any winner).
  std::vector<std::pair<uint32_t, PatchSpec>> stack() const {
    std::vector<std::pair<uint32_t, PatchSpec>> out;
    for (const Patch& p : patches.patches) out.push_back({p.id, spec(p.id)});
    return out;
  }
  double r = 0.1;

  void add(const PatchSpec& s) {
    const uint32_t id = patches.next_id++;
    patches.patches.push_back(test::make_grid_patch(f, s, id));
    specs.push_back({id, s});
  }
  // Hole-filling patches: full-size, w = 1, angle from the id.
  PatchMaker maker() {
    return [this](const SurfacePoint& at, uint32_t id) -> std::optional<Patch> {
      PatchSpec s;
      s.centre = at.position;
      s.r = r, s.half = r, s.m = 8;
      s.angle = 6.283185307179586 * hash_to_unit(hash64(7, id));
      static std::mutex mu;  // hole filling creates patches in parallel
      std::lock_guard<std::mutex> lock(mu);
      specs.push_back({id, s});
      return test::make_grid_patch(f, s, id);
    };
  }
  /// One frame as a bake runs it with the tracking at the output's
  /// resolution: the tracking pass (births from `make`, retirement), then
  /// the output pass of the patches it leaves. The images are the output
  /// pass's, the counts (stats) the tracking pass's.
  FrameTextures run_with(const RasterOptions& o, const PatchMaker& make) {
    RasterStats tracked = track_pass(f.mesh, f.atlas, rex, o, WeightOptions{}, TriangleLocator{}, 0, make, patches);
    FrameTextures out = output_pass(f.mesh, f.atlas, rex, o, WeightOptions{}, TriangleLocator{}, patches);
    out.stats = std::move(tracked);
    return out;
  }
  FrameTextures run(RasterOptions o, bool holes = true) {
    o.radius = r;
    return run_with(o, holes ? maker() : PatchMaker{});
  }
  const PatchSpec& spec(uint32_t id) const {
    for (const auto& [i, s] : specs)
      if (i == id) return s;
    throw std::runtime_error("no spec");
  }
};

/// A 1 m plane of 8x8 quads with an N^2 atlas (split: two charts), the ramp
/// exemplar of M^2 pixels (colour = (u, v, 0.5), flat feature map) and
/// patch radius r: the set-up of most single-patch tests.
Scene ramp_plane(int N, int M, double r, bool split = false) {
  Scene sc;
  sc.f = test::make_plane(8, 1.0, N, split);
  sc.ex = test::ramp_exemplar(M, 0.f);
  sc.rex = prepared(sc.ex);
  sc.r = r;
  return sc;
}

Scene random_scene(bool split, int count, uint64_t seed, int N = 256) {
  Scene sc;
  sc.f = test::make_plane(16, 1.0, N, split);
  sc.ex = test::ramp_exemplar(64, 0.f);
  // A feature map with structure so that erosion shapes are not just disks.
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      sc.ex.feature.at(x, y, 0) = float(0.5 + 0.5 * std::sin(x * 0.4) * std::cos(y * 0.3));
  sc.ex.displacement = sc.ex.feature;
  sc.rex = prepared(sc.ex);
  for (int k = 0; k < count; ++k) {
    PatchSpec s;
    s.r = sc.r, s.half = sc.r;
    s.centre = {0.1 + 0.8 * hash_to_unit(hash64(seed, k, 1)), 0.1 + 0.8 * hash_to_unit(hash64(seed, k, 2)), 0};
    s.angle = 6.283185307179586 * hash_to_unit(hash64(seed, k, 3));
    s.w0 = 0.6 + 0.4 * hash_to_unit(hash64(seed, k, 4));
    s.wx = k % 3 == 0 ? 1.5 : 0;  // some patches with a weight gradient (affine: interpolated exactly)
    sc.add(s);
  }
  return sc;
}

// The rasterized winner of every chart texel equals the paper's definition.
void expect_matches_reference(const Scene& sc, const FrameTextures& out, std::size_t* checked_out = nullptr) {
  const Formula formula(sc.ex.feature, 0.1);
  const auto& tm = sc.f.atlas.texels;
  const auto stack = sc.stack();
  std::size_t checked = 0, mismatches = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const Vec3 p = sc.f.texel_point(k);
    const RefWinner ref = reference(sc.f, stack, formula, p);
    if (ref.ambiguous) continue;
    const int x = int(tm.texel[k] % sc.f.atlas.resolution), y = int(tm.texel[k] / sc.f.atlas.resolution);
    const int got = int(out.aov.at(x, y, 0));
    ++checked;
    if (got != ref.id) {
      if (++mismatches <= 5) ADD_FAILURE() << "texel (" << x << "," << y << ") point (" << p.x << "," << p.y
                                           << "): patch " << got << ", paper says " << ref.id;
    }
  }
  EXPECT_EQ(mismatches, 0u) << "of " << checked << " texels";
  EXPECT_GT(checked, tm.size() * 9 / 10);
  if (checked_out) *checked_out = checked;
}

TEST(Raster, ErosionMatchesThePaperFormulaTexelByTexel) {
  // One undistorted patch covering the plane, constant weight, a striped
  // feature map: the kept region is the paper's Fig. 8 shape for each w.
  std::vector<double> kept_fraction;
  for (double w : {1.0, 0.8, 0.6, 0.45}) {
    Scene sc;
    sc.f = test::make_plane(8, 1.0, 192, false);
    sc.ex = test::ramp_exemplar(48, 0.f);
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) sc.ex.feature.at(x, y, 0) = float(0.5 + 0.5 * std::sin(x * 0.5 + y * 0.2));
    sc.rex = prepared(sc.ex);
    sc.r = 0.5;
    PatchSpec s;
    s.centre = {0.5, 0.5, 0};
    s.r = 0.5, s.half = 0.5, s.m = 10, s.w0 = w;
    sc.add(s);
    RasterOptions o = paper_options();
    o.fill_holes = false;
    o.retire = false;
    const FrameTextures out = sc.run(o, false);
    std::size_t checked = 0;
    expect_matches_reference(sc, out, &checked);
    kept_fraction.push_back(double(out.stats.covered_texels) / out.stats.chart_texels);
    EXPECT_EQ(out.stats.forced_texels, 0u);
  }
  // Lower weight, more erosion (strictly: the stripes make each step visible).
  for (std::size_t i = 1; i < kept_fraction.size(); ++i) EXPECT_LT(kept_fraction[i], kept_fraction[i - 1]);
  // w = 1: only the border erodes (inscribed disk of D plus the feature map's help).
  EXPECT_GT(kept_fraction[0], 0.7);
}

TEST(Raster, FlatFeatureMapKeepsTheInscribedDisk) {
  // F = 0: kept iff sqrt(D)/M - eps >= 1 - w. With w = 1, M = max sqrt(D) ~ 1:
  // D >= eps^2 M^2, i.e. |uv - c| <= 0.5 (1 - eps^2 M^2): a disk of area ~ pi 0.495^2.
  Scene sc = ramp_plane(256, 64, 0.5);
  PatchSpec s;
  s.centre = {0.5, 0.5, 0};
  s.r = 0.5, s.half = 0.5, s.m = 8;
  sc.add(s);
  RasterOptions o = paper_options();
  o.fill_holes = false;
  const FrameTextures out = sc.run(o, false);
  const double M = sc.rex.erosion.inv_max > 0 ? 1 / sc.rex.erosion.inv_max : 0;
  const double radius = 0.5 * (1 - 0.01 * M * M);
  const double expected = M_PI * radius * radius;
  EXPECT_NEAR(double(out.stats.covered_texels) / out.stats.chart_texels, expected, 0.01);
  expect_matches_reference(sc, out);
}

TEST(Raster, OldestNonErodedPatchWinsOnePatchPerTexel) {
  Scene sc = random_scene(false, 40, 11);
  RasterOptions o = paper_options();
  o.mipmap = false;
  const FrameTextures out = sc.run(o);
  EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
  EXPECT_EQ(out.stats.forced_texels, 0u);
  EXPECT_GT(out.stats.skipped_triangles, 0u);  // the draw's skip was on
  expect_matches_reference(sc, out);
  // No blending: each texel's colour is the exemplar at its own patch (u, v),
  // and that (u, v) is the analytic map of the winning patch.
  const auto& tm = sc.f.atlas.texels;
  const int N = sc.f.atlas.resolution;
  double max_colour = 0, max_uv = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % N), y = int(tm.texel[k] / N);
    const int id = int(out.aov.at(x, y, 0));
    ASSERT_GE(id, 0);
    const Vec2 uv = sc.spec(uint32_t(id)).uv_at(sc.f.texel_point(k));
    max_uv = std::max({max_uv, std::abs(uv.x - out.aov.at(x, y, 1)), std::abs(uv.y - out.aov.at(x, y, 2))});
    float e[3];
    sample_bilinear(sc.ex.color, out.aov.at(x, y, 1), out.aov.at(x, y, 2), e);
    for (int c = 0; c < 3; ++c) max_colour = std::max(max_colour, double(std::abs(e[c] - out.color.at(x, y, c))));
    EXPECT_EQ(out.color.at(x, y, 3), 1.f);
  }
  EXPECT_LT(max_uv, 1e-5);      // float AOV of an exact affine map
  EXPECT_LT(max_colour, 1e-5);  // one patch's colour, not a mix
}

TEST(Raster, SeamFallbackAgreesWithThePaperAcrossCharts) {
  Scene sc = random_scene(true, 40, 23);
  RasterOptions o = paper_options();
  o.mipmap = false;
  const FrameTextures out = sc.run(o);
  EXPECT_GT(out.stats.seam_triangles, 0u);
  // Triangles under older patches were left out (OwnedTiles), and every
  // texel still has the paper's winner.
  EXPECT_GT(out.stats.skipped_triangles, 0u);
  EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
  expect_matches_reference(sc, out);
}

TEST(Raster, OlderPatchHidesYoungerOneWhichRetires) {
  Scene sc = ramp_plane(128, 32, 0.3);
  PatchSpec a;
  a.centre = {0.5, 0.5, 0}, a.r = 0.3, a.half = 0.3, a.w0 = 1.0;
  PatchSpec hidden = a;  // same place, lower weight: its kept region is inside a's
  hidden.w0 = 0.7, hidden.angle = 0.3;
  PatchSpec side = a;
  side.centre = {0.7, 0.5, 0}, side.half = 0.25;
  sc.add(a);
  sc.add(hidden);
  sc.add(side);
  RasterOptions o = paper_options();
  o.fill_holes = false;
  const FrameTextures out = sc.run(o, false);
  ASSERT_EQ(sc.patches.patches.size(), 2u);
  EXPECT_EQ(sc.patches.patches[0].id, 0u);
  EXPECT_EQ(sc.patches.patches[1].id, 2u);
  EXPECT_EQ(out.stats.patches_retired, 1u);
  ASSERT_EQ(out.stats.texels_per_patch.size(), 2u);
  EXPECT_GT(out.stats.texels_per_patch[1], 0u);
  // Where both a and side keep a texel, a (older) gives it.
  const Formula formula(sc.ex.feature, 0.1);
  const auto& tm = sc.f.atlas.texels;
  std::size_t both = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const Vec3 p = sc.f.texel_point(k);
    if (!a.covers(p, 1) || !side.covers(p, 1)) continue;
    const Vec2 ua = a.uv_at(p), us = side.uv_at(p);
    if (formula.margin(ua.x, ua.y, 1) > 1e-6 && formula.margin(us.x, us.y, 1) > 1e-6) {
      ++both;
      EXPECT_EQ(out.aov.at(int(tm.texel[k] % 128), int(tm.texel[k] / 128), 0), 0.f);
    }
  }
  EXPECT_GT(both, 100u);
  // And the retired patch is removed even without hole filling.
  EXPECT_EQ(out.stats.texels_per_patch[0] + out.stats.texels_per_patch[1], out.stats.covered_texels);
}

TEST(Raster, HoleFillingCoversEveryTexelFromNothing) {
  Scene sc = random_scene(true, 0, 5);
  RasterOptions o = paper_options();
  const FrameTextures out = sc.run(o);
  EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
  EXPECT_EQ(out.stats.forced_texels, 0u);
  EXPECT_GT(out.stats.patches_born, 0u);
  // Each newborn patch keeps at least a disk of radius ~ r/4 around its centre,
  // so far fewer patches than area / (pi (r/4)^2) are needed.
  EXPECT_LT(out.stats.patches_born, std::size_t(1.0 / (M_PI * 0.025 * 0.025)));
  EXPECT_EQ(sc.patches.patches.size(), out.stats.patches_born);  // none retired: each was born to cover
  for (const Patch& p : sc.patches.patches) EXPECT_EQ(p.birth_frame, 0);
  expect_matches_reference(sc, out);
}

/// The 60-patch two-chart random scene rasterized on `threads` threads:
/// the images and the number of patches left.
std::pair<FrameTextures, std::size_t> bake_random_scene(int threads, RasterMode mode) {
  set_thread_count(threads);
  Scene sc = random_scene(true, 60, 99);
  RasterOptions o = paper_options();
  o.mode = mode;
  FrameTextures out = sc.run(o);
  set_thread_count(0);
  return {std::move(out), sc.patches.patches.size()};
}

TEST(Raster, SameImagesForOneAndTwoThreads) {
  const auto [a, na] = bake_random_scene(1, RasterMode::Erosion);
  const auto [b, nb] = bake_random_scene(2, RasterMode::Erosion);
  EXPECT_EQ(na, nb);
  EXPECT_EQ(a.stats.patches_born, b.stats.patches_born);
  EXPECT_TRUE(a.color.pixels == b.color.pixels);
  EXPECT_TRUE(a.displacement.pixels == b.displacement.pixels);
  EXPECT_TRUE(a.aov.pixels == b.aov.pixels);
}

// RasterOptions::half_images (what a bake writes) gives, pixel for pixel,
// the floats' half bits: chart texels, the dilated gutter and the
// background, in each mode; only the kind of image differs.
TEST(Raster, HalfImagesAreTheFloatImagesInHalf) {
  for (RasterMode mode : {RasterMode::Erosion, RasterMode::Blend}) {
    RasterOptions o = paper_options();
    o.mode = mode;
    o.gutter = 3;
    Scene floats = random_scene(true, 60, 99, 128);
    const FrameTextures a = floats.run(o);
    o.half_images = true;
    Scene halves = random_scene(true, 60, 99, 128);
    const FrameTextures b = halves.run(o);
    ASSERT_FALSE(a.color.empty());
    EXPECT_TRUE(b.color.empty() && b.displacement.empty());
    const HalfImage color = to_half_image(a.color), displacement = to_half_image(a.displacement);
    ASSERT_EQ(b.color_half.bits.size(), color.bits.size());
    EXPECT_EQ(b.color_half.channels, 4);
    EXPECT_TRUE(b.color_half.bits == color.bits);
    EXPECT_TRUE(b.displacement_half.bits == displacement.bits);
    EXPECT_TRUE(a.aov.pixels == b.aov.pixels);
    // The scene has texels of every kind: covered, and gutter (alpha 0).
    std::size_t covered = 0;
    for (std::size_t i = 3; i < a.color.pixels.size(); i += 4) covered += a.color.pixels[i] == 1.f;
    EXPECT_GT(covered, 0u);
    EXPECT_LT(covered, a.color.pixels.size() / 4);
  }
}

TEST(Raster, GutterAndBackgroundTakeTheNearestChartTexel) {
  Scene sc = random_scene(true, 30, 3, 128);
  RasterOptions o = paper_options();
  o.gutter = 3;
  const FrameTextures out = sc.run(o);
  const int N = 128;
  std::vector<int> chart(N * N, 0);
  for (uint32_t t : sc.f.atlas.texels.texel) chart[t] = 1;
  for (int y = 0; y < N; ++y)
    for (int x = 0; x < N; ++x) {
      if (chart[y * N + x]) continue;
      EXPECT_EQ(out.color.at(x, y, 3), 0.f);
      // A pixel next to a chart copies one of its chart neighbours.
      bool next_to_chart = false, equals_a_neighbour = false;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= N || yy >= N || !chart[yy * N + xx]) continue;
          next_to_chart = true;
          equals_a_neighbour |= out.color.at(xx, yy, 0) == out.color.at(x, y, 0) &&
                                out.aov.at(xx, yy, 0) == out.aov.at(x, y, 0);
        }
      if (next_to_chart) {
        EXPECT_TRUE(equals_a_neighbour) << x << "," << y;
      }
      EXPECT_GE(out.aov.at(x, y, 0), 0.f);  // every pixel got some chart texel's values
    }
}

TEST(Raster, MipLevelMatchesTheTexelFootprint) {
  // 1 m plane, 0.9 of a 256 atlas: 1/230.4 m per texel; r = 0.1 puts 0.2 m on
  // a 64-pixel exemplar: 320 px/m, so 1.39 exemplar pixels per atlas texel.
  Scene sc = random_scene(false, 20, 8);
  RasterOptions o = paper_options();
  const FrameTextures out = sc.run(o);
  EXPECT_NEAR(out.stats.texel_world_size, 1.0 / (0.9 * 256), 1e-9);
  EXPECT_NEAR(out.stats.lod, std::log2(64 / (0.9 * 256 * 0.2)), 1e-9);
  // The ramp survives box filtering: the colour still reads the patch's (u, v)
  // wherever the lookup stays clear of the exemplar border.
  const auto& tm = sc.f.atlas.texels;
  double worst = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % 256), y = int(tm.texel[k] / 256);
    const double u = out.aov.at(x, y, 1), v = out.aov.at(x, y, 2);
    if (std::min({u, v, 1 - u, 1 - v}) < 0.05) continue;
    worst = std::max({worst, std::abs(out.color.at(x, y, 0) - u), std::abs(out.color.at(x, y, 1) - v)});
  }
  EXPECT_LT(worst, 1e-5);
}

TEST(Raster, DistortedTrianglesAreNeverDrawn) {
  Scene sc = random_scene(false, 10, 4);
  for (Patch& p : sc.patches.patches) {
    p.triangle_delta.assign(p.triangles.size(), 1.0f);
    for (std::size_t t = 0; t < p.triangles.size(); t += 2) p.triangle_delta[t] = 3.5f;  // > delta_max = 3
  }
  RasterOptions o = paper_options();
  o.fill_holes = false;
  const FrameTextures out = sc.run(o, false);
  EXPECT_EQ(out.stats.distorted_triangles, 10u * 64);
  // The kept texels all come from even triangles... i.e. none of the odd ones:
  // check via the AOV that no texel lies in an "a, b, c" (lower-right) half cell.
  const auto& tm = sc.f.atlas.texels;
  std::size_t kept = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % 256), y = int(tm.texel[k] / 256);
    const int id = int(out.aov.at(x, y, 0));
    if (id < 0) continue;
    const PatchSpec& s = sc.spec(uint32_t(id));
    const Vec3 p = sc.f.texel_point(k);
    const double cell = 2 * s.half / s.m;
    const double fx = std::fmod(p.x - (s.centre.x - s.half), cell) / cell;
    const double fy = std::fmod(p.y - (s.centre.y - s.half), cell) / cell;
    if (std::abs(fx - fy) < 1e-3) continue;  // on the diagonal both halves touch
    EXPECT_LT(fx, fy) << "texel from a triangle with delta > delta_max";
    ++kept;
  }
  EXPECT_GT(kept, 1000u);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(Raster, AdvectModeNeitherErodesNorRetires) {
  // Weight 0 everywhere: Erosion mode keeps nothing, Advect mode keeps the
  // whole uv square, and the hidden duplicate patch is not retired.
  auto scene = [] {
    Scene sc = ramp_plane(128, 32, 0.25);
    PatchSpec a;
    a.centre = {0.5, 0.5, 0}, a.r = 0.25, a.half = 0.25, a.w0 = 0;
    sc.add(a);
    sc.add(a);
    return sc;
  };
  Scene er = scene();
  RasterOptions o = paper_options();
  o.fill_holes = false;
  const FrameTextures eroded = er.run(o, false);
  EXPECT_EQ(eroded.stats.covered_texels, 0u);
  EXPECT_EQ(er.patches.patches.size(), 0u);  // both retired

  Scene ad = scene();
  o.mode = RasterMode::NoErosion;
  const FrameTextures kept = ad.run(o, false);
  EXPECT_EQ(ad.patches.patches.size(), 2u);
  EXPECT_EQ(kept.stats.patches_retired, 0u);
  // The patch's square [0.25, 0.75]^2 of the 1 m plane, 0.9 of a 128 atlas.
  const double expected = 0.25 * double(kept.stats.chart_texels);
  EXPECT_NEAR(double(kept.stats.covered_texels), expected, 0.03 * expected);
  EXPECT_EQ(kept.stats.texels_per_patch[1], 0u);  // the younger copy is hidden everywhere
}

TEST(Raster, RejectsAnAtlasOfAnotherMesh) {
  Scene sc = random_scene(false, 3, 1, 64);
  SurfaceAtlas wrong = sc.f.atlas;
  wrong.corner_uv.pop_back();
  RasterOptions o = paper_options();
  o.radius = sc.r;
  for (RasterMode mode : {RasterMode::Erosion, RasterMode::Blend}) {
    o.mode = mode;
    EXPECT_THROW(track_pass(sc.f.mesh, wrong, sc.rex, o, WeightOptions{}, {}, 0, {}, sc.patches),
                 std::invalid_argument);
    EXPECT_THROW(output_pass(sc.f.mesh, wrong, sc.rex, o, WeightOptions{}, {}, sc.patches), std::invalid_argument);
  }
}

// Every texel's AOV names a patch and reads that patch's affine map at the
// texel's point (exact for the planar grid patches, extrapolated or not).
void expect_named_with_own_map(const Scene& sc, const FrameTextures& out) {
  const auto& tm = sc.f.atlas.texels;
  const int N = sc.f.atlas.resolution;
  double worst = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % N), y = int(tm.texel[k] / N);
    ASSERT_EQ(out.color.at(x, y, 3), 1.f);
    const int id = int(out.aov.at(x, y, 0));
    ASSERT_GE(id, 0);
    const Vec2 uv = sc.spec(uint32_t(id)).uv_at(sc.f.texel_point(k));
    worst = std::max({worst, std::abs(uv.x - out.aov.at(x, y, 1)), std::abs(uv.y - out.aov.at(x, y, 2))});
  }
  EXPECT_LT(worst, 1e-4);
}

TEST(Raster, ChartNoPatchReachesTakesTheNearestPatch) {
  // Two charts; one patch on the left one; create_patch fails everywhere.
  // The rest of the left chart takes neighbours' patches, the right chart
  // (no covered texel to spread from) the nearest patch triangle in 3D.
  for (RasterMode mode : {RasterMode::Erosion, RasterMode::Blend}) {
    Scene sc = ramp_plane(96, 32, 0.1, true);
    PatchSpec a;
    a.centre = {0.3, 0.5, 0}, a.r = 0.15, a.half = 0.15, a.w0 = 1;
    sc.add(a);
    RasterOptions o = paper_options();
    o.mode = mode;
    o.radius = 0.15;
    const FrameTextures out =
        sc.run_with(o, [](const SurfacePoint&, uint32_t) { return std::optional<Patch>{}; });
    const RasterStats& st = out.stats;
    EXPECT_EQ(st.covered_texels, st.chart_texels);
    EXPECT_EQ(st.patches_born, 0u);
    EXPECT_EQ(sc.patches.patches.size(), 1u);
    EXPECT_EQ(st.texels_per_patch[0], st.chart_texels);
    EXPECT_GT(st.forced_texels, st.chart_texels / 2);  // the whole right chart at least
    EXPECT_LT(st.forced_texels, st.chart_texels);
    expect_named_with_own_map(sc, out);
  }
}

TEST(Raster, NewbornsThatKeepNothingStillCoverTheirHoles) {
  // Every newborn is folded (delta = inf on all its triangles, as on a droplet
  // smaller than a patch): none is drawn, yet every texel gets one of them.
  Scene sc = ramp_plane(96, 32, 0.2);
  const PatchMaker base = sc.maker();
  const PatchMaker folded = [&](const SurfacePoint& at, uint32_t id) {
    std::optional<Patch> p = base(at, id);
    p->triangle_delta.assign(p->triangles.size(), INFINITY);
    return p;
  };
  RasterOptions o = paper_options();
  o.radius = sc.r;
  const FrameTextures out = sc.run_with(o, folded);
  EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
  EXPECT_EQ(out.stats.forced_texels, out.stats.chart_texels);
  EXPECT_GT(out.stats.patches_born, 0u);
  EXPECT_EQ(out.stats.distorted_triangles, 0u);  // counted for the first pass only (no patch then)
  expect_named_with_own_map(sc, out);
}

// Blend mode (the 2019 baseline): colour = sum w_i c_i / sum w_i over the
// covering patches, checked against the analytic (u, v, w) of two patches on
// the ramp exemplar (colour = (u, v, 0.5)).
TEST(RasterBlend, OverlapIsTheExactWeightedAverage) {
  Scene sc = ramp_plane(192, 64, 0.3);
  PatchSpec a;
  a.centre = {0.4, 0.45, 0}, a.r = 0.3, a.half = 0.3, a.w0 = 0.8, a.wx = 0.5;  // affine weight: exact
  PatchSpec b = a;
  b.centre = {0.6, 0.55, 0}, b.w0 = 0.3, b.wx = 0, b.wy = -0.4, b.angle = 0.7;
  sc.add(a);
  sc.add(b);
  RasterOptions o = paper_options();
  o.mode = RasterMode::Blend;
  o.mipmap = false;
  o.fill_holes = false;
  const FrameTextures out = sc.run(o, false);
  const auto& tm = sc.f.atlas.texels;
  const int N = 192;
  auto inner = [](const Vec2& uv) { return std::min({uv.x, uv.y, 1 - uv.x, 1 - uv.y}) > 0.02; };
  std::size_t both = 0, only_a = 0, covered = 0;
  double worst = 0, worst_aov = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % N), y = int(tm.texel[k] / N);
    covered += out.color.at(x, y, 3) == 1.f;
    const Vec3 p = sc.f.texel_point(k);
    const Vec2 ua = a.uv_at(p), ub = b.uv_at(p);
    const double wa = a.w_at(p), wb = b.w_at(p);
    const bool in_a = a.covers(p, 1) && inner(ua) && wa > 0.01, in_b = b.covers(p, 1) && inner(ub) && wb > 0.01;
    const bool out_b = !b.covers(p, 1) || std::min({ub.x, ub.y, 1 - ub.x, 1 - ub.y}) < -0.02 || wb < -0.01;
    if (in_a && in_b) {
      ++both;
      const double r = (wa * ua.x + wb * ub.x) / (wa + wb), g = (wa * ua.y + wb * ub.y) / (wa + wb);
      worst = std::max({worst, std::abs(out.color.at(x, y, 0) - r), std::abs(out.color.at(x, y, 1) - g),
                        std::abs(out.color.at(x, y, 2) - 0.5)});
      // AOV: the larger weight, at its own (u, v).
      const bool a_wins = wa > wb + 1e-6, b_wins = wb > wa + 1e-6;
      if (a_wins || b_wins) {
        const PatchSpec& s = a_wins ? a : b;
        EXPECT_EQ(out.aov.at(x, y, 0), a_wins ? 0.f : 1.f);
        worst_aov = std::max({worst_aov, std::abs(out.aov.at(x, y, 1) - s.uv_at(p).x),
                              std::abs(out.aov.at(x, y, 3) - s.w_at(p))});
      }
    } else if (in_a && out_b) {
      ++only_a;
      worst = std::max({worst, std::abs(out.color.at(x, y, 0) - ua.x), std::abs(out.color.at(x, y, 1) - ua.y)});
      EXPECT_EQ(out.aov.at(x, y, 0), 0.f);
    }
  }
  EXPECT_GT(both, 2000u);
  EXPECT_GT(only_a, 1000u);
  EXPECT_LT(worst, 2e-6);  // float colour of an exact weighted average
  EXPECT_LT(worst_aov, 1e-5);
  EXPECT_EQ(covered, out.stats.covered_texels);
  // Without erosion the union of the two squares (where w > 0) is covered.
  EXPECT_GT(out.stats.covered_texels, std::size_t(0.4 * double(out.stats.chart_texels)));
  EXPECT_EQ(out.stats.patches_retired, 0u);
}

TEST(RasterBlend, HiddenPatchesContributeAndOnlyWeightlessOnesRetire) {
  Scene sc = ramp_plane(128, 32, 0.3);
  PatchSpec a;
  a.centre = {0.5, 0.5, 0}, a.r = 0.3, a.half = 0.3, a.w0 = 1.0;
  PatchSpec hidden = a;  // erosion would retire it (see OlderPatchHidesYoungerOneWhichRetires)
  hidden.w0 = 0.7, hidden.angle = 0.3;
  PatchSpec weightless = a;
  weightless.w0 = 0;
  sc.add(a);
  sc.add(hidden);
  sc.add(weightless);
  RasterOptions o = paper_options();
  o.mode = RasterMode::Blend;
  o.fill_holes = false;
  const FrameTextures out = sc.run(o, false);
  ASSERT_EQ(sc.patches.patches.size(), 2u);
  EXPECT_EQ(sc.patches.patches[0].id, 0u);
  EXPECT_EQ(sc.patches.patches[1].id, 1u);
  EXPECT_EQ(out.stats.patches_retired, 1u);
  // The AOV names the heavier patch everywhere both cover.
  EXPECT_EQ(out.stats.texels_per_patch[0], out.stats.covered_texels);
  EXPECT_EQ(out.stats.texels_per_patch[1], 0u);
}

// Luminance standard deviation over covered chart texels.
double contrast(const FrameTextures& out, const SurfaceAtlas& atlas) {
  double s = 0, s2 = 0;
  std::size_t n = 0;
  for (uint32_t t : atlas.texels.texel) {
    const float* c = &out.color.pixels[std::size_t(t) * 4];
    if (c[3] != 1.f) continue;
    const double y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    s += y, s2 += y * y, ++n;
  }
  const double m = s / double(n);
  return std::sqrt(std::max(0.0, s2 / double(n) - m * m));
}

TEST(RasterBlend, GhostingLowersContrastAgainstErosion) {
  auto bake = [](RasterMode mode) {
    Scene sc = random_scene(true, 60, 17);
    for (int y = 0; y < 64; ++y)  // a black-and-white checker: blending misaligned copies greys it
      for (int x = 0; x < 64; ++x)
        for (int c = 0; c < 3; ++c) sc.ex.color.at(x, y, c) = float(((x / 8) + (y / 8)) % 2);
    sc.rex = prepared(sc.ex);
    RasterOptions o = paper_options();
    o.mode = mode;
    FrameTextures out = sc.run(o);
    EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
    return std::make_pair(contrast(out, sc.f.atlas), std::move(out));
  };
  const auto [erosion, e] = bake(RasterMode::Erosion);
  const auto [blend, b] = bake(RasterMode::Blend);
  EXPECT_GT(erosion, 0.3);  // mostly pure black and white texels (mip filtering softens the edges)
  EXPECT_LT(blend, 0.85 * erosion);
}

TEST(RasterBlend, SameImagesForOneAndTwoThreads) {
  const auto [a, na] = bake_random_scene(1, RasterMode::Blend);
  const auto [b, nb] = bake_random_scene(2, RasterMode::Blend);
  EXPECT_EQ(na, nb);
  EXPECT_EQ(a.stats.covered_texels, a.stats.chart_texels);
  EXPECT_EQ(a.stats.patches_born, b.stats.patches_born);
  EXPECT_TRUE(a.color.pixels == b.color.pixels);
  EXPECT_TRUE(a.displacement.pixels == b.displacement.pixels);
  EXPECT_TRUE(a.aov.pixels == b.aov.pixels);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// The gutter passes by their definition: every empty pixel of the whole
// image, each pass, takes the filled 8-neighbour whose source is nearest
// (ties to the lowest source), neighbours filled this pass not counting.
std::vector<int32_t> reference_gutter_passes(std::vector<int32_t> s, int N, int gutter) {
  auto d2 = [N](int64_t a, int64_t b) {
    const int64_t dx = a % N - b % N, dy = a / N - b / N;
    return dx * dx + dy * dy;
  };
  for (int pass = 0; pass < gutter; ++pass) {
    std::vector<int32_t> next = s;
    for (int y = 0; y < N; ++y)
      for (int x = 0; x < N; ++x) {
        const int64_t i = int64_t(y) * N + x;
        if (s[i] >= 0) continue;
        int32_t best = -1;
        int64_t best_d = INT64_MAX;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= N || yy >= N) continue;
            const int32_t c = s[std::size_t(yy) * N + xx];
            if (c < 0) continue;
            const int64_t d = d2(i, c);
            if (d < best_d || (d == best_d && c < best)) best = c, best_d = d;
          }
        next[i] = best;
      }
    s = next;
  }
  return s;
}

TEST(Raster, GutterPassesMatchTheirDefinition) {
  // dilate_sources visits only the pixels next to filled ones, 64 at a time:
  // it must give every pixel within the gutter the source the plain
  // whole-image passes give. Sizes around the 64-pixel word boundaries.
  for (int N : {5, 63, 64, 65, 130}) {
    for (int gutter : {1, 3, 6}) {
      std::vector<int32_t> source(std::size_t(N) * N, -1);
      // Blobs and single pixels, deterministic.
      for (std::size_t i = 0; i < source.size(); ++i) {
        const uint64_t h = hash64(uint64_t(N), uint64_t(gutter), i);
        const int x = int(i % N), y = int(i / N);
        const bool blob = (x / 9 + y / 7) % 4 == 0 && (x % 9) < 5;
        if (blob || h % 97 == 0) source[i] = int32_t(i);
      }
      const std::vector<int32_t> expect = reference_gutter_passes(source, N, gutter);
      std::vector<int32_t> got = source;
      detail::dilate_sources(got, N, gutter);
      std::size_t compared = 0;
      for (std::size_t i = 0; i < got.size(); ++i) {
        if (expect[i] < 0) continue;  // beyond the gutter: the row/column fill, not compared here
        ASSERT_EQ(got[i], expect[i]) << "N " << N << " gutter " << gutter << " pixel " << i;
        ++compared;
      }
      EXPECT_GT(compared, std::size_t(N));
    }
  }
}

}  // namespace
}  // namespace lapflow


namespace lapflow {
namespace {

// RasterOptions::small_hole: holes no wider than small_hole x r are closed by
// the patches around them, wider ones still get a patch, and coverage stays
// complete either way.
TEST(Raster, NarrowHolesAreClosedByTheirNeighboursWideOnesGetAPatch) {
  RasterOptions o = paper_options();
  o.mipmap = false;
  Scene paper = random_scene(false, 40, 11);
  const FrameTextures a = paper.run(o);
  ASSERT_GT(a.stats.patches_born, 0u);  // the scene has holes
  EXPECT_EQ(a.stats.closed_texels, 0u);

  o.small_hole = 0.5;
  Scene closing = random_scene(false, 40, 11);
  const FrameTextures b = closing.run(o);
  EXPECT_EQ(b.stats.covered_texels, b.stats.chart_texels);
  EXPECT_GT(b.stats.closed_texels, 0u);
  EXPECT_LT(b.stats.patches_born, a.stats.patches_born);
  EXPECT_EQ(b.stats.forced_texels, 0u);  // closed texels are counted apart from failures
  EXPECT_LT(closing.patches.patches.size(), paper.patches.patches.size());

  // A hole that is its whole chart has no neighbour to close it: it gets
  // patches whatever small_hole says.
  o.small_hole = 100;
  Scene empty = random_scene(true, 0, 5);
  const FrameTextures c = empty.run(o);
  EXPECT_GT(c.stats.patches_born, 0u);
  EXPECT_EQ(c.stats.covered_texels, c.stats.chart_texels);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// The held test's feature map (RasterOptions::hold): the maximum over a
// (2 kx + 1) x (2 ky + 1) window, clamped at the borders, against a direct
// loop on a random image whose sizes are not multiples of the window.
TEST(Raster, MaxFilterIsTheWindowMaximum) {
  Image img(37, 23, 1);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = float(hash_to_unit(hash64(7, i)));
  for (const auto& [kx, ky] : {std::pair{0, 0}, std::pair{1, 2}, std::pair{3, 1}, std::pair{5, 5}, std::pair{40, 30}}) {
    const Image m = detail::max_filter(img, kx, ky);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        float want = -1;
        for (int yy = std::max(0, y - ky); yy <= std::min(img.height - 1, y + ky); ++yy)
          for (int xx = std::max(0, x - kx); xx <= std::min(img.width - 1, x + kx); ++xx)
            want = std::max(want, img.at(xx, yy, 0));
        ASSERT_EQ(m.at(x, y, 0), want) << "kx " << kx << " ky " << ky << " at " << x << "," << y;
      }
  }
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// The feature map's minima over rectangles (MinPyramid) bound every pixel
// of the rectangle from below and are exact for one pixel and for the whole
// image, on a random image whose sizes are not powers of two.
TEST(Raster, MinPyramidBoundsEveryRectangleFromBelow) {
  Image img(37, 23, 1);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = float(hash_to_unit(hash64(11, i)));
  detail::MinPyramid m;
  m.build(img);
  float all = 1;
  for (float f : img.pixels) all = std::min(all, f);
  EXPECT_EQ(m.min_over(0, 0, img.width - 1, img.height - 1), all);
  for (int k = 0; k < 3000; ++k) {
    int x0 = int(hash_to_unit(hash64(12, k, 0)) * img.width), x1 = int(hash_to_unit(hash64(12, k, 1)) * img.width);
    int y0 = int(hash_to_unit(hash64(12, k, 2)) * img.height), y1 = int(hash_to_unit(hash64(12, k, 3)) * img.height);
    if (k % 4 == 0) x1 = x0, y1 = y0;  // single pixels: exact
    if (x0 > x1) std::swap(x0, x1);
    if (y0 > y1) std::swap(y0, y1);
    float want = 1;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) want = std::min(want, img.at(x, y, 0));
    const float got = m.min_over(x0, y0, x1, y1);
    ASSERT_LE(got, want) << x0 << "," << y0 << " - " << x1 << "," << y1;
    if (x0 == x1 && y0 == y1) {
      ASSERT_EQ(got, want) << x0 << "," << y0;
    }
  }
}

// sure_passes decides for a whole patch triangle only where every point of
// it passes: random triangles in uv with random weights and weight slopes,
// on a random feature map, each sampled at points inside, on its edges and
// just outside them (the draw's barycentric tolerance), with the texels' own
// tests (keeps, keeps_held). Both bounds must also say yes somewhere.
TEST(Raster, SureErosionTestsHoldAtEveryPointOfTheirTriangle) {
  Scene sc = ramp_plane(128, 48, 0.1);
  for (std::size_t i = 0; i < sc.ex.feature.pixels.size(); ++i)
    sc.ex.feature.pixels[i] = float(hash_to_unit(hash64(21, i)) * hash_to_unit(hash64(22, i)));
  sc.rex = prepared(sc.ex);
  RasterOptions o;
  o.radius = sc.r;
  ASSERT_TRUE(o.hold);
  ASSERT_EQ(o.mode, RasterMode::Erosion);
  RasterBuffers r = begin_raster(sc.f.mesh, sc.f.atlas, sc.rex, o, WeightOptions{});
  const detail::RasterContext& ctx = *r.context;
  ASSERT_TRUE(ctx.hold);
  std::size_t sure_keeps = 0, sure_held = 0, neither = 0;
  for (int k = 0; k < 4000; ++k) {
    auto h = [&](int j) { return hash_to_unit(hash64(23, k, j)); };
    const double size = 0.005 + 0.3 * h(0) * h(1);
    const Vec2 c{size + (1 - 2 * size) * h(2), size + (1 - 2 * size) * h(3)};
    Vec2 uv[3];
    float w[3];
    for (int i = 0; i < 3; ++i) {
      uv[i] = c + Vec2{(2 * h(4 + i) - 1) * size, (2 * h(7 + i) - 1) * size};
      w[i] = float(k % 5 == 0 ? 1.0 : h(10 + i));
    }
    const double slope = 2 * h(13);
    const uint8_t sure = detail::sure_passes(ctx, ctx.layers[0], uv, w, slope);
    sure_keeps += (sure & detail::kSureKeeps) != 0;
    sure_held += (sure & detail::kSureHeld) != 0;
    neither += sure == 0;
    if (sure == 0) continue;
    for (int s = 0; s < 200; ++s) {
      // Barycentrics: inside, on an edge, at a vertex, or 1e-9 outside.
      double l1 = hash_to_unit(hash64(24, k, s, 0)), l2 = hash_to_unit(hash64(24, k, s, 1));
      if (l1 + l2 > 1) l1 = 1 - l1, l2 = 1 - l2;
      if (s % 4 == 1) l2 = 1 - l1;
      if (s % 4 == 2) l1 = -1e-9, l2 = s % 8 == 2 ? -1e-9 : l2;
      if (s == 3) l1 = 1, l2 = 0;
      const double l0 = 1.0 - l1 - l2;
      const double u = l0 * uv[0].x + l1 * uv[1].x + l2 * uv[2].x;
      const double v = l0 * uv[0].y + l1 * uv[1].y + l2 * uv[2].y;
      const double wt = l0 * w[0] + l1 * w[1] + l2 * w[2];
      if (sure & detail::kSureKeeps) {
        ASSERT_TRUE(detail::keeps(ctx.layers[0].erosion(), u, v, wt, ctx.mode)) << "triangle " << k << " point " << s;
      }
      if (sure & detail::kSureHeld) {
        ASSERT_TRUE(detail::keeps_held(ctx.layers[0].held_erosion(), ctx.held_reach, o.hold_margin, u, v,
                                       std::min(1.0, wt + slope * ctx.held_reach)))
            << "triangle " << k << " point " << s;
      }
    }
  }
  EXPECT_GT(sure_keeps, 100u);
  EXPECT_GT(sure_held, 100u);
  EXPECT_GT(neither, 100u);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// RasterOptions::merge: a small patch (b) shows as a crescent beside an older
// one (a); a younger one (c) also keeps every texel of that crescent and wins
// plenty elsewhere. b is retired as merged, and on the next frame c takes the
// crescent: no hole, full coverage. Without merge b stays.
TEST(Raster, MergeRetiresASmallPatchWhoseTexelsAnotherKeeps) {
  auto scene = [] {
    Scene sc = ramp_plane(128, 32, 0.2);
    PatchSpec a;
    a.centre = {0.4, 0.5, 0}, a.r = 0.2, a.half = 0.2;
    PatchSpec b;
    b.centre = {0.62, 0.5, 0}, b.r = 0.05, b.half = 0.05;
    PatchSpec c = a;
    c.centre = {0.7, 0.5, 0};
    sc.add(a);
    sc.add(b);
    sc.add(c);
    return sc;
  };
  RasterOptions o = paper_options();
  o.fill_holes = false;
  Scene paper = scene();
  const FrameTextures p0 = paper.run(o, false);
  ASSERT_EQ(paper.patches.patches.size(), 3u);
  const uint64_t crescent = p0.stats.texels_per_patch[1];
  EXPECT_GT(crescent, 20u);

  o.merge = 0.1;  // 0.1 pi (r / texel)^2 = 206 texels
  Scene sc = scene();
  const FrameTextures f0 = sc.run(o, false);
  EXPECT_EQ(f0.stats.retired_merged, 1u);
  ASSERT_EQ(sc.patches.patches.size(), 2u);
  EXPECT_EQ(sc.patches.patches[0].id, 0u);
  EXPECT_EQ(sc.patches.patches[1].id, 2u);
  // The output pass draws the patches the tracking pass leaves: the frame
  // that retires the small patch already shows the others in its place,
  // as the next frame does, and differs from the paper's only there.
  EXPECT_FALSE(f0.aov.pixels == p0.aov.pixels);
  const FrameTextures f1 = sc.run(o, false);
  EXPECT_TRUE(f0.aov.pixels == f1.aov.pixels);
  EXPECT_EQ(f1.stats.covered_texels, p0.stats.covered_texels);
  EXPECT_EQ(f1.stats.texels_per_patch[0], p0.stats.texels_per_patch[0]);
  EXPECT_EQ(f1.stats.texels_per_patch[1], p0.stats.texels_per_patch[2] + crescent);
  EXPECT_EQ(f1.stats.retired_merged, 0u);
}

TEST(Raster, MergeWalkSkipIsExactlyTheWalksDistanceTest) {
  // The merge test's second draw skips a seam walk when no fluid triangle
  // owning a writable texel can pass the walk's distance test: it must say
  // "may write" exactly when a brute-force search over those triangles
  // finds one (or a start triangle is one), or a merge would change.
  Scene sc = ramp_plane(256, 48, 0.1);
  sc.f = test::make_plane(32, 1.0, 256, true);
  RasterOptions o;
  o.radius = sc.r;
  RasterBuffers r = begin_raster(sc.f.mesh, sc.f.atlas, sc.rex, o, WeightOptions{});
  const detail::RasterContext& ctx = *r.context;
  const std::size_t nt = sc.f.mesh.triangles.size();
  ASSERT_GE(nt, 2048u);
  std::size_t yes = 0, no = 0;
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<uint8_t> writable(nt, 0);
    const double share = 0.002 + 0.05 * hash_to_unit(hash64(31, trial));
    for (std::size_t F = 0; F < nt; ++F) writable[F] = hash_to_unit(hash64(32, trial, F)) < share;
    detail::TileMask mask(ctx.N);
    mask.set_writable(ctx, writable);
    for (int k = 0; k < 300; ++k) {
      auto h = [&](int j) { return hash_to_unit(hash64(33, trial, k, j)); };
      const Vec3 c{1.2 * h(0) - 0.1, 1.2 * h(1) - 0.1, 0.05 * (h(2) - 0.5)};
      const double radius = 0.5 * sc.r * h(3) * h(4), margin = 0.05 * sc.r * h(5);
      const int start[3] = {int(h(6) * double(nt)), h(7) < 0.2 ? -1 : int(h(8) * double(nt)), -1};
      bool expected = false;
      for (int s : start) expected = expected || (s >= 0 && writable[std::size_t(s)]);
      for (std::size_t F = 0; F < nt && !expected; ++F)
        expected = writable[F] && !(norm(ctx.tri_sphere[F].centre - c) > radius + ctx.tri_sphere[F].radius + margin);
      ASSERT_EQ(mask.walk_may_write(ctx, start, c, radius, margin), expected) << "trial " << trial << " sphere " << k;
      ++(expected ? yes : no);
    }
  }
  EXPECT_GT(yes, 500u);
  EXPECT_GT(no, 500u);
}

}  // namespace
}  // namespace lapflow
