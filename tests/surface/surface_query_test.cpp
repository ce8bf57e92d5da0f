#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "lapflow/surface/surface_query.hpp"

using namespace lapflow;

namespace {
// n x n grid of quads on z = 0 over [0,1]^2, two triangles each.
TriMesh plane_grid(int n) {
  TriMesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.positions.push_back({double(i) / n, double(j) / n, 0});
  auto id = [n](int i, int j) { return int32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}
}  // namespace

TEST(SurfaceQuery, ClosestPointOnPlaneIsTheOrthogonalProjection) {
  const TriMesh m = plane_grid(16);
  SurfaceQuery q(m);
  for (int k = 0; k < 200; ++k) {
    const Vec3 p{0.05 + 0.9 * std::fmod(k * 0.6180339887, 1.0), 0.05 + 0.9 * std::fmod(k * 0.41421356, 1.0),
                 0.01 * std::sin(k)};
    const ClosestHit h = q.closest(p, INFINITY);
    ASSERT_TRUE(h.found);
    EXPECT_NEAR(h.point.x, p.x, 1e-12);
    EXPECT_NEAR(h.point.y, p.y, 1e-12);
    EXPECT_NEAR(h.point.z, 0.0, 1e-12);
    EXPECT_NEAR(h.distance, std::abs(p.z), 1e-12);
    // The barycentrics reproduce the point on the reported triangle.
    const Tri& f = m.triangles[h.triangle];
    const Vec3 x = m.positions[f[0]] * (1 - h.b1 - h.b2) + m.positions[f[1]] * h.b1 + m.positions[f[2]] * h.b2;
    EXPECT_LT(norm(x - h.point), 1e-12);
  }
}

TEST(SurfaceQuery, RadiusBoundsTheSearchAndOutsidePointsClampToTheBorder) {
  const TriMesh m = plane_grid(4);
  SurfaceQuery q(m);
  EXPECT_FALSE(q.closest({0.5, 0.5, 0.3}, 0.2).found);
  EXPECT_TRUE(q.closest({0.5, 0.5, 0.3}, 0.31).found);
  const ClosestHit h = q.closest({1.5, 0.5, 0.0}, INFINITY);
  ASSERT_TRUE(h.found);
  EXPECT_NEAR(h.point.x, 1.0, 1e-12);
  EXPECT_NEAR(h.distance, 0.5, 1e-12);
}

TEST(SurfaceQuery, EmptyMeshFindsNothing) {
  TriMesh m;
  SurfaceQuery q(m);
  EXPECT_FALSE(q.closest({0, 0, 0}, INFINITY).found);
  EXPECT_FALSE(q.intersect({0, 0, 1}, {0, 0, -1}, 0, INFINITY).found);
}

TEST(SurfaceQuery, RayHitsThePlaneAtTheRightDistance) {
  const TriMesh m = plane_grid(8);
  SurfaceQuery q(m);
  const RayHit h = q.intersect({0.3, 0.7, 2.0}, {0, 0, -1}, 0, INFINITY);
  ASSERT_TRUE(h.found);
  EXPECT_NEAR(h.t, 2.0, 1e-6);
}

TEST(SurfaceQuery, ClosestPointOnTriangleMatchesADenseSearchInEveryRegion) {
  // Random triangles (one degenerate: collinear corners) and points all
  // around them, so every Voronoi region (corners, edges, face) is hit.
  auto unit = [](uint64_t k) {  // deterministic pseudo-random in [-1, 1)
    k = (k ^ (k >> 33)) * 0xff51afd7ed558ccdull;
    k = (k ^ (k >> 33)) * 0xc4ceb9fe1a85ec53ull;
    return double((k ^ (k >> 33)) >> 11) * 0x1.0p-52 - 1.0;
  };
  for (int t = 0; t < 8; ++t) {
    const Vec3 a{unit(9 * t + 1), unit(9 * t + 2), unit(9 * t + 3)};
    const Vec3 b{unit(9 * t + 4), unit(9 * t + 5), unit(9 * t + 6)};
    const Vec3 c = t == 7 ? a + (b - a) * 2.5 : Vec3{unit(9 * t + 7), unit(9 * t + 8), unit(9 * t + 9)};
    for (int k = 0; k < 40; ++k) {
      const Vec3 p{2 * unit(1000 * t + 3 * k), 2 * unit(1000 * t + 3 * k + 1), 2 * unit(1000 * t + 3 * k + 2)};
      const TrianglePoint q = closest_point_on_triangle(p, a, b, c);
      // The barycentrics are in the triangle and reproduce the point.
      EXPECT_GE(q.b1, -1e-12);
      EXPECT_GE(q.b2, -1e-12);
      EXPECT_LE(q.b1 + q.b2, 1 + 1e-12);
      EXPECT_LT(norm(a * (1 - q.b1 - q.b2) + b * q.b1 + c * q.b2 - q.point), 1e-12);
      // No point of a dense barycentric grid is closer.
      double best = INFINITY;
      const int n = 200;
      for (int i = 0; i <= n; ++i)
        for (int j = 0; i + j <= n; ++j)
          best = std::min(best, norm(a * (1 - double(i + j) / n) + b * (double(i) / n) + c * (double(j) / n) - p));
      EXPECT_LE(norm(q.point - p), best + 1e-12) << "triangle " << t << " point " << k;
      // ... and q is no closer than the grid's spacing allows.
      const double h = std::max({norm(b - a), norm(c - a), norm(c - b)}) / n;
      EXPECT_GT(norm(q.point - p), best - h);
    }
  }
}
