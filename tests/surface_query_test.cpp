#include <gtest/gtest.h>

#include <cmath>

#include "lapflow/surface_query.hpp"

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
