// Poisson-disk seeding (ALGORITHM.md step 1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "test_helpers.hpp"

using namespace lapflow;

namespace {

double min_pair_distance(const std::vector<SurfacePoint>& s) {
  double best = INFINITY;
  for (std::size_t i = 0; i < s.size(); ++i)
    for (std::size_t j = i + 1; j < s.size(); ++j) best = std::min(best, norm(s[i].position - s[j].position));
  return best;
}

// Largest distance from a dense set of surface points (vertices and
// centroids) to the nearest sample.
double coverage_radius(const TriMesh& m, const std::vector<SurfacePoint>& s) {
  std::vector<Vec3> probes = m.positions;
  for (const Tri& f : m.triangles) probes.push_back((m.positions[f[0]] + m.positions[f[1]] + m.positions[f[2]]) / 3.0);
  double worst = 0;
  for (const Vec3& p : probes) {
    double best = INFINITY;
    for (const SurfacePoint& q : s) best = std::min(best, norm2(q.position - p));
    worst = std::max(worst, std::sqrt(best));
  }
  return worst;
}

}  // namespace

TEST(PatchesSeed, RespectsMinimumDistanceAndCoversTheSurface) {
  const TriMesh sphere = test::icosphere(4, 1.0);
  const double d = 0.15;
  const auto samples = seed_points(sphere, d, 7);
  // 4 pi / d^2 = 558: random sequential packing holds about 0.7 of that.
  EXPECT_GT(samples.size(), 300u);
  EXPECT_LT(samples.size(), 600u);
  EXPECT_GE(min_pair_distance(samples), d);
  EXPECT_LE(coverage_radius(sphere, samples), 2 * d);
  // A maximal sampling leaves no point farther than d (up to the probes' spacing).
  EXPECT_LE(coverage_radius(sphere, samples), 1.05 * d);
  for (const SurfacePoint& s : samples) {
    ASSERT_GE(s.triangle, 0);
    EXPECT_NEAR(norm(s.normal), 1.0, 1e-12);
    EXPECT_GT(dot(s.normal, s.position), 0.9);  // outward face normal of a unit sphere
  }
}

TEST(PatchesSeed, IsScaleInvariant) {
  TriMesh a = test::plane_grid(30, 20, 3.0, 2.0);
  TriMesh b = a;
  const double k = 7.3;
  for (Vec3& p : b.positions) p = p * k;
  const auto sa = seed_points(a, 0.2, 3), sb = seed_points(b, 0.2 * k, 3);
  ASSERT_EQ(sa.size(), sb.size());
  for (std::size_t i = 0; i < sa.size(); ++i) {
    EXPECT_EQ(sa[i].triangle, sb[i].triangle);
    EXPECT_LT(norm(sa[i].position * k - sb[i].position), 1e-9 * k);
  }
}

TEST(PatchesSeed, EveryComponentGetsASampleAndDistanceIsPerComponent) {
  TriMesh m = test::icosphere(3, 1.0);
  // A droplet much smaller than the spacing, 0.05 from the body.
  const TriMesh drop = test::icosphere(1, 0.02, {1.07, 0, 0});
  const int base = int(m.positions.size());
  m.positions.insert(m.positions.end(), drop.positions.begin(), drop.positions.end());
  for (Tri f : drop.triangles) m.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
  const int body_triangles = 20 * 64;
  const auto s = seed_points(m, 0.3, 11);
  int on_drop = 0;
  for (const SurfacePoint& p : s) on_drop += p.triangle >= body_triangles;
  EXPECT_EQ(on_drop, 1);
  std::vector<SurfacePoint> body;
  for (const SurfacePoint& p : s)
    if (p.triangle < body_triangles) body.push_back(p);
  EXPECT_GE(min_pair_distance(body), 0.3);
}

// The accepted samples are bucketed in a dense array over the mesh's box, or
// in a hash map when that box holds too many cells: both must give the same
// samples. Two spheres 3 apart (dense) and the same two spheres 2e5 apart
// (the box is then 1e6 cells long: the hash map).
TEST(PatchesSeed, FarApartComponentsSeedAsCloseOnes) {
  auto pair = [](double gap) {
    TriMesh m = test::icosphere(3, 1.0);
    const TriMesh b = test::icosphere(3, 1.0, {gap, 0, 0});
    const int base = int(m.positions.size());
    m.positions.insert(m.positions.end(), b.positions.begin(), b.positions.end());
    for (Tri f : b.triangles) m.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
    return m;
  };
  const double d = 0.2, gap = 2e5;
  const auto near = seed_points(pair(3.0), d, 9), far = seed_points(pair(gap), d, 9);
  ASSERT_EQ(near.size(), far.size());
  ASSERT_GT(near.size(), 100u);
  const int per_sphere = 20 * 64;
  std::vector<SurfacePoint> far_b;
  for (std::size_t i = 0; i < near.size(); ++i) {
    ASSERT_EQ(near[i].triangle, far[i].triangle) << i;
    const double shift = near[i].triangle >= per_sphere ? gap - 3.0 : 0.0;
    EXPECT_LT(norm(near[i].position + Vec3{shift, 0, 0} - far[i].position), 1e-9) << i;
    if (far[i].triangle >= per_sphere) far_b.push_back(far[i]);
  }
  EXPECT_GE(min_pair_distance(far_b), d * (1 - 1e-9));
}

TEST(PatchesSeed, SameSamplesForAnyThreadCountAndDifferentForAnotherSeed) {
  const TriMesh sphere = test::icosphere(4, 1.0);
  set_thread_count(1);
  const auto one = seed_points(sphere, 0.1, 5);
  set_thread_count(2);
  const auto two = seed_points(sphere, 0.1, 5);
  set_thread_count(0);
  ASSERT_EQ(one.size(), two.size());
  for (std::size_t i = 0; i < one.size(); ++i) EXPECT_EQ(one[i].position, two[i].position);
  const auto other = seed_points(sphere, 0.1, 6);
  EXPECT_NE(other.front().position, one.front().position);
}

TEST(PatchesSeed, FreshSeedingCountIsWhatSeedingCreates) {
  const TriMesh sphere = test::icosphere(4);
  const SurfaceQuery surface(sphere);
  PatchOptions po;
  po.radius = 0.2;
  po.seed = 3;
  SeedOptions so;
  for (int frame : {1, 7}) {
    PatchSet set;
    seed_patches(surface, frame, po, so, {}, set);
    // On a smooth sphere every sample becomes a patch.
    EXPECT_EQ(fresh_seeding_count(sphere, frame, po, so), set.patches.size()) << "frame " << frame;
  }
  so.spacing = 2;  // twice the distance: about a quarter of the samples
  PatchSet sparse;
  seed_patches(surface, 1, po, so, {}, sparse);
  EXPECT_EQ(fresh_seeding_count(sphere, 1, po, so), sparse.patches.size());
  EXPECT_LT(sparse.patches.size(), fresh_seeding_count(sphere, 1, po, SeedOptions{}) / 2);
}
