// Rasterizer with the real stages: an icosphere, its surface atlas, seeded
// patches (create_patch for hole filling). Checks coverage, one patch per
// texel with the exemplar colour at its own (u, v), the oldest-first rule
// against a brute-force 3D search, stillness across frames and determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>

#include "io_test_helpers.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/raster/raster.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "raster/raster_fixture.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

// One frame as a bake runs it with the tracking at the output's resolution
// (track_pass with births by create_patch on `q`, then output_pass): the
// output pass's images with the tracking pass's counts (stats).
FrameTextures run_frame(const SurfaceQuery& q, const SurfaceAtlas& atlas, const RasterExemplar& rex,
                        const RasterOptions& ro, const PatchOptions& popt, const WeightOptions& wopt, int frame,
                        PatchSet& patches) {
  const SurfaceAdjacency adjacency = build_surface_adjacency(q.mesh());
  const TriangleLocator locate = surface_triangle_locator(q, ro.radius);
  RasterStats tracked = track_pass(q.mesh(), atlas, rex, ro, wopt, locate, frame,
                                   surface_patch_maker(q, adjacency, popt, wopt, frame), patches);
  FrameTextures out = output_pass(q.mesh(), atlas, rex, ro, wopt, locate, patches);
  out.stats = std::move(tracked);
  return out;
}

struct SphereScene {
  TriMesh mesh = test::icosphere(4, 1.0);
  SurfaceAtlas atlas;
  Exemplar ex = test::ramp_exemplar(64, 0.f);
  RasterExemplar rex;
  PatchOptions popt;
  WeightOptions wopt;
  RasterOptions ropt;

  explicit SphereScene(int resolution = 384) {
    AtlasOptions ao;
    ao.resolution = resolution;
    atlas = build_surface_atlas(mesh, ao);
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) ex.feature.at(x, y, 0) = float(0.5 + 0.5 * std::sin(x * 0.4) * std::cos(y * 0.3));
    ex.displacement = ex.feature;
    rex = prepare_raster_exemplar(ex, 0.1);
    popt.radius = 0.35;
    popt.seed = 3;
    ropt.radius = popt.radius;
    ropt.mipmap = false;
    ropt.use_paper_hole_filling();  // the reference tests check the paper's test; hold tests turn it on
  }
  PatchSet seeded(const SurfaceQuery& q) const {
    PatchSet ps;
    seed_patches(q, 0, popt, SeedOptions{}, wopt, ps);
    return ps;
  }
};

// Point of chart texel k on the sphere mesh.
Vec3 texel_point(const TriMesh& m, const SurfaceAtlas& atlas, std::size_t k) {
  const TexelMap& tm = atlas.texels;
  const Tri& t = m.triangles[tm.triangle[k]];
  float fb1, fb2;
  texel_barycentrics(atlas.corner_uv, atlas.resolution, tm.texel[k], tm.triangle[k], fb1, fb2);
  const double b1 = fb1, b2 = fb2;
  return m.positions[t[0]] * (1 - b1 - b2) + m.positions[t[1]] * b1 + m.positions[t[2]] * b2;
}

// Does patch p clearly keep point x (by a margin), by the paper's definition
// done in 3D: the patch triangle under x (projection inside by `tol`), its
// interpolated (u, v, w), the erosion formula?
bool clearly_keeps(const Patch& p, const ErosionMap& e, const Vec3& x, double tol) {
  for (std::size_t ti = 0; ti < p.triangles.size(); ++ti) {
    const Tri& t = p.triangles[ti];
    if (p.triangle_delta.size() == p.triangles.size() && !(p.triangle_delta[ti] <= 3.0)) continue;
    const Vec3 &a = p.positions[t[0]], &b = p.positions[t[1]], &c = p.positions[t[2]];
    const Vec3 n = cross(b - a, c - a);
    const double n2 = norm2(n);
    if (n2 == 0) continue;
    if (std::abs(dot(x - a, n)) / std::sqrt(n2) > 0.05) continue;  // far off the triangle's plane
    const double l1 = dot(cross(x - a, c - a), n) / n2, l2 = dot(cross(b - a, x - a), n) / n2, l0 = 1 - l1 - l2;
    if (l0 < tol || l1 < tol || l2 < tol) continue;
    const Vec2 uv = p.rest_uv[t[0]] * l0 + p.rest_uv[t[1]] * l1 + p.rest_uv[t[2]] * l2;
    const double w = l0 * p.weight[t[0]] + l1 * p.weight[t[1]] + l2 * p.weight[t[2]];
    // Kept with a margin: still kept with w lowered by 0.02.
    if (erosion_keeps(e, uv.x, uv.y, w - 0.02) && std::min({uv.x, uv.y, 1 - uv.x, 1 - uv.y}) > 0.01) return true;
  }
  return false;
}

TEST(RasterPipeline, SphereFullCoverageOnePatchPerTexelOldestFirst) {
  SphereScene sc;
  SurfaceQuery q(sc.mesh);
  PatchSet patches = sc.seeded(q);
  ASSERT_GT(patches.patches.size(), 20u);
  const std::size_t seeded = patches.patches.size();
  const FrameTextures out = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 0, patches);
  const RasterStats& st = out.stats;
  ASSERT_EQ(st.chart_texels, sc.atlas.texels.size());
  EXPECT_EQ(st.covered_texels, st.chart_texels);
  EXPECT_EQ(st.forced_texels, 0u);
  EXPECT_EQ(patches.patches.size(), seeded + st.patches_born - st.patches_retired);
  std::map<uint32_t, std::size_t> index_of;
  for (std::size_t i = 0; i < patches.patches.size(); ++i) index_of[patches.patches[i].id] = i;

  const auto& tm = sc.atlas.texels;
  const int N = sc.atlas.resolution;
  std::size_t older_keeps = 0, checked = 0;
  double worst_colour = 0;
  for (std::size_t k = 0; k < tm.size(); ++k) {
    const int x = int(tm.texel[k] % N), y = int(tm.texel[k] / N);
    const float id = out.aov.at(x, y, 0);
    ASSERT_GE(id, 0.f);
    ASSERT_TRUE(index_of.count(uint32_t(id))) << "texel from a retired patch";
    const double u = out.aov.at(x, y, 1), v = out.aov.at(x, y, 2), w = out.aov.at(x, y, 3);
    // The winner passes the erosion test at its own (u, v, w) (float AOV: tiny slack).
    EXPECT_TRUE(erosion_keeps(sc.rex.erosion, u, v, w + 1e-5)) << x << "," << y;
    float e[3];
    sample_bilinear(sc.ex.color, u, v, e);
    for (int c = 0; c < 3; ++c) worst_colour = std::max(worst_colour, double(std::abs(e[c] - out.color.at(x, y, c))));
    // Brute force over the older patches on a subset of texels.
    if (k % 5 != 0) continue;
    ++checked;
    const Vec3 p = texel_point(sc.mesh, sc.atlas, k);
    for (std::size_t i = 0; i < index_of[uint32_t(id)]; ++i)
      if (clearly_keeps(patches.patches[i], sc.rex.erosion, p, 0.02)) {
        ++older_keeps;
        break;
      }
  }
  EXPECT_LT(worst_colour, 1e-5);
  EXPECT_GT(checked, 1000u);
  EXPECT_EQ(older_keeps, 0u) << "texels where an older patch clearly keeps the point but a younger one won";
}

TEST(RasterPipeline, StillSurfaceGivesIdenticalFramesAndOneAndTwoThreadsAgree) {
  SphereScene sc(256);
  SurfaceQuery q(sc.mesh);
  auto bake = [&](int threads) {
    set_thread_count(threads);
    PatchSet patches = sc.seeded(q);
    FrameTextures f0 = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 0, patches);
    // Zero velocity, same mesh: frame 1 rasterizes the same patches again.
    FrameTextures f1 = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 1, patches);
    set_thread_count(0);
    return std::make_pair(std::move(f0), std::move(f1));
  };
  const auto [a0, a1] = bake(1);
  const auto [b0, b1] = bake(2);
  EXPECT_EQ(a1.stats.patches_born, 0u);
  EXPECT_EQ(a1.stats.patches_retired, 0u);
  EXPECT_TRUE(a0.color.pixels == a1.color.pixels);
  EXPECT_TRUE(a0.aov.pixels == a1.aov.pixels);
  EXPECT_TRUE(a0.color.pixels == b0.color.pixels);
  EXPECT_TRUE(a0.displacement.pixels == b0.displacement.pixels);
  EXPECT_TRUE(a0.aov.pixels == b0.aov.pixels);
  EXPECT_TRUE(a1.color.pixels == b1.color.pixels);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// One frame of the shared Mantaflow dam break: a real, non-trivial mesh and
// atlas; every chart texel gets exactly one live patch. A few newborns on
// sharp creases do not keep their own centre (their centre triangle marked
// folded); their texels are forced to a neighbour's or the nearest patch,
// which must stay rare.
TEST(RasterPipeline, DamBreakFrameFullCoverage) {
  const std::string path = LAPFLOW_SOURCE_DIR "/../shared/data/dam_break/dam_break.0040.ply";
  LAPFLOW_NEED_SHARED(path);
  const TriMesh mesh = read_mesh(path);
  AtlasOptions ao;
  ao.resolution = 512;
  const SurfaceAtlas atlas = build_surface_atlas(mesh, ao);
  SurfaceQuery q(mesh);
  PatchOptions popt;
  const Box3 box = bounding_box(mesh);
  popt.radius = 0.06 * norm(box.size());
  WeightOptions wopt;
  const Exemplar ex = test::ramp_exemplar(64, 0.5f);
  const RasterExemplar rex = prepare_raster_exemplar(ex, 0.1);
  for (RasterMode mode : {RasterMode::Erosion, RasterMode::Blend}) {
    SCOPED_TRACE(mode == RasterMode::Blend ? "blend" : "erosion");
    PatchSet patches;
    seed_patches(q, 40, popt, SeedOptions{}, wopt, patches);
    RasterOptions ro;
    ro.radius = popt.radius;
    ro.mode = mode;
    const FrameTextures out = run_frame(q, atlas, rex, ro, popt, wopt, 40, patches);
    EXPECT_EQ(out.stats.covered_texels, out.stats.chart_texels);
    EXPECT_LE(out.stats.forced_texels, out.stats.chart_texels / 1000);
    EXPECT_LT(out.stats.patches_born, patches.patches.size());
    std::set<float> live;
    for (const Patch& p : patches.patches) live.insert(float(p.id));
    const int N = atlas.resolution;
    for (uint32_t t : atlas.texels.texel) {
      ASSERT_EQ(out.color.pixels[std::size_t(t) * 4 + 3], 1.f);
      ASSERT_TRUE(live.count(out.aov.at(int(t % N), int(t / N), 0)));
    }
  }
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// With the erosion hold (RasterOptions::hold) an unchanged mesh still gives
// bit-identical frames: a texel marks only cells wholly inside its own
// footprint, so no texel that lost on frame 0 finds its cell held on frame 1.
// Frame 1 is also the first frame that reads Patch::held.
TEST(RasterPipeline, HoldKeepsAStillSurfaceIdentical) {
  SphereScene sc(256);
  sc.ropt.hold = true;
  SurfaceQuery q(sc.mesh);
  PatchSet patches = sc.seeded(q);
  FrameTextures f0 = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 0, patches);
  std::size_t held_patches = 0;
  for (const Patch& p : patches.patches) held_patches += !p.held.empty();
  EXPECT_GT(held_patches, patches.patches.size() / 2);
  FrameTextures f1 = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 1, patches);
  FrameTextures f2 = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 2, patches);
  EXPECT_EQ(f1.stats.patches_born + f2.stats.patches_born, 0u);
  EXPECT_EQ(f1.stats.patches_retired + f2.stats.patches_retired, 0u);
  EXPECT_TRUE(f0.color.pixels == f1.color.pixels);
  EXPECT_TRUE(f0.aov.pixels == f1.aov.pixels);
  EXPECT_TRUE(f1.aov.pixels == f2.aov.pixels);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

// RasterOptions::rest_bound: a patch at rest wins no texel beyond the cells
// it held (grown by rest_reach_cells). Frame 0 marks the held cells; then
// every patch is at rest and one patch keeps only the cells of a disc
// around its centre: on frame 1 other patches take most of the surface
// beyond the disc, while without the rule it keeps winning its whole eroded
// shape. What it still shows beyond the disc is next to a chart's border
// (exempt) or closed from its own texels by the hole filling. Coverage
// stays full either way.
TEST(RasterPipeline, RestBoundKeepsAPatchAtRestToTheCellsItHeld) {
  auto frame1 = [](bool rest_bound, uint32_t& id, std::size_t& beyond, std::size_t& uncovered) {
    SphereScene sc(256);
    sc.ropt.hold = true;
    sc.ropt.rest_bound = rest_bound;
    SurfaceQuery q(sc.mesh);
    PatchSet patches = sc.seeded(q);
    run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 0, patches);
    // The patch that won the most cells.
    std::size_t best = 0, most = 0;
    for (std::size_t p = 0; p < patches.patches.size(); ++p) {
      std::size_t n = 0;
      for (uint64_t w : patches.patches[p].held) n += std::size_t(__builtin_popcountll(w));
      if (n > most) most = n, best = p;
    }
    constexpr double kDisc = 0.15;  // in uv, around (0.5, 0.5)
    Patch& a = patches.patches[best];
    id = a.id;
    for (int cv = 0; cv < kHeldCells; ++cv)
      for (int cu = 0; cu < kHeldCells; ++cu)
        if (std::hypot((cu + 0.5) / kHeldCells - 0.5, (cv + 0.5) / kHeldCells - 0.5) > kDisc) {
          const std::size_t bit = std::size_t(cv) * kHeldCells + std::size_t(cu);
          a.held[bit >> 6] &= ~(uint64_t(1) << (bit & 63));
        }
    // `a` is not used past here: the frame may append newborns and move the patches.
    for (Patch& p : patches.patches) p.at_rest = true;
    const FrameTextures f = run_frame(q, sc.atlas, sc.rex, sc.ropt, sc.popt, sc.wopt, 1, patches);
    beyond = uncovered = 0;
    // The disc grown by the reach twice (the tracking pass marks the cells
    // the patch won within one reach; the output pass draws within one reach
    // of those) and the diagonal of a cell.
    const double texel_uv = f.stats.texel_world_size / (2 * sc.ropt.radius);
    const double reach = kDisc + (2 * rest_reach_cells(texel_uv) + 1.5) / kHeldCells;
    for (std::size_t k = 0; k < sc.atlas.texels.size(); ++k) {
      const float* t = &f.aov.pixels[std::size_t(sc.atlas.texels.texel[k]) * 4];
      uncovered += t[0] < 0;
      if (t[0] == float(id) && std::hypot(t[1] - 0.5, t[2] - 0.5) > reach) ++beyond;
    }
  };
  uint32_t id_on = 0, id_off = 0;
  std::size_t beyond_on = 0, beyond_off = 0, uncovered_on = 0, uncovered_off = 0;
  frame1(true, id_on, beyond_on, uncovered_on);
  frame1(false, id_off, beyond_off, uncovered_off);
  ASSERT_EQ(id_on, id_off);
  EXPECT_EQ(uncovered_on, 0u);
  EXPECT_EQ(uncovered_off, 0u);
  EXPECT_GT(beyond_off, 100u) << "without the rule the patch must win beyond its disc, or this test shows nothing";
  // The rule leaves under a quarter of the texels beyond the disc.
  EXPECT_LT(4 * beyond_on, beyond_off);
}

}  // namespace
}  // namespace lapflow
