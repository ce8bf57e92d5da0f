// vertex_mean_curvature: known answers on spheres, planes and cylinders.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <utility>
#include <vector>

#include "lapflow/surface/mesh.hpp"
#include "test_helpers.hpp"

using namespace lapflow;

namespace {

/// Open cylinder of radius `r` around the z axis, `rings` + 1 rings of
/// `segments` vertices over z in [0, height], CCW seen from outside. With
/// `staggered`, every other ring turns by half a segment, so that short rings
/// make obtuse triangles.
TriMesh cylinder(double r, double height, int segments, int rings, bool staggered) {
  TriMesh m;
  for (int j = 0; j <= rings; ++j)
    for (int i = 0; i < segments; ++i) {
      const double a = 2 * std::numbers::pi * (i + (staggered && j % 2 ? 0.5 : 0.0)) / segments;
      m.positions.push_back({r * std::cos(a), r * std::sin(a), height * j / rings});
    }
  auto at = [&](int i, int j) { return j * segments + (i % segments); };
  for (int j = 0; j < rings; ++j)
    for (int i = 0; i < segments; ++i) {
      const int a = at(i, j), b = at(i + 1, j), c = at(i, j + 1), d = at(i + 1, j + 1);
      if (staggered && j % 2) {  // ring j is turned: its vertex i sits between c and d
        m.triangles.push_back({a, d, c});
        m.triangles.push_back({a, b, d});
      } else {
        m.triangles.push_back({a, b, c});
        m.triangles.push_back({b, d, c});
      }
    }
  return m;
}

bool on_cylinder_rim(const TriMesh& m, int v, double height) {
  return m.positions[v].z == 0 || m.positions[v].z == height;
}

}  // namespace

TEST(MeanCurvature, IcosphereIsOneOverRadiusEverywhere) {
  const double radius = 0.5;
  const TriMesh sphere = test::icosphere(4, radius, {1, -2, 3});  // 5120 triangles
  const std::vector<float> h = vertex_mean_curvature(sphere);
  ASSERT_EQ(h.size(), sphere.vertex_count());
  // The cotangent formula is near exact on an icosphere: 0.1% (3% would do for texture choice).
  for (std::size_t v = 0; v < h.size(); ++v) ASSERT_NEAR(h[v], 1 / radius, 0.001 / radius) << "vertex " << v;
}

TEST(MeanCurvature, IrregularSphereWithObtuseTrianglesStaysNearOneOverRadius) {
  const double radius = 0.5, edge = 1.1 * radius / 16;  // level 4: 1/16 of the icosahedron's edge
  TriMesh sphere = test::icosphere(4, radius);
  for (std::size_t v = 0; v < sphere.vertex_count(); ++v) {  // move each vertex along the sphere
    const double x = double(v);
    const Vec3 shift{std::sin(12.9898 * x), std::sin(78.233 * x + 1), std::sin(37.719 * x + 2)};
    sphere.positions[v] = normalized(sphere.positions[v] + shift * (0.2 * edge)) * radius;
  }
  int obtuse = 0;
  for (int t = 0; t < int(sphere.triangle_count()); ++t) {
    const Tri& f = sphere.triangles[t];
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = sphere.positions[f[k]];
      if (dot(sphere.positions[f[(k + 1) % 3]] - p, sphere.positions[f[(k + 2) % 3]] - p) < 0) ++obtuse;
    }
  }
  ASSERT_GT(obtuse, 200) << "the jitter should make obtuse triangles";
  // Pointwise the cotangent formula only approximates an irregular mesh; the
  // mixed areas keep every value positive and the mean on the mark.
  const std::vector<float> h = vertex_mean_curvature(sphere);
  double sum = 0;
  for (std::size_t v = 0; v < h.size(); ++v) {
    EXPECT_NEAR(h[v], 1 / radius, 0.2 / radius) << "vertex " << v;
    sum += h[v];
  }
  EXPECT_NEAR(sum / double(h.size()), 1 / radius, 0.0005 / radius);
}

TEST(MeanCurvature, ScalesAsOneOverLength) {
  const TriMesh unit = test::icosphere(2);
  TriMesh big = unit;
  for (Vec3& p : big.positions) p *= 8;  // a power of two: exact
  const std::vector<float> h1 = vertex_mean_curvature(unit), h8 = vertex_mean_curvature(big);
  for (std::size_t v = 0; v < h1.size(); ++v) EXPECT_FLOAT_EQ(h8[v], h1[v] / 8) << "vertex " << v;
}

TEST(MeanCurvature, FlatGridIsZeroInsideAndOnItsBorder) {
  TriMesh grid = test::plane_grid(12, 9, 3.0, 2.0, 0.25);
  // Jitter the interior in the plane: obtuse triangles must not bend a plane.
  for (int j = 1; j < 9; ++j)
    for (int i = 1; i < 12; ++i) {
      Vec3& p = grid.positions[j * 13 + i];
      p.x += 0.09 * std::sin(7.0 * i + 3.0 * j);
      p.y += 0.07 * std::cos(5.0 * i - 2.0 * j);
    }
  const std::vector<float> h = vertex_mean_curvature(grid);
  ASSERT_EQ(h.size(), grid.vertex_count());
  for (std::size_t v = 0; v < h.size(); ++v) {
    const int i = int(v % 13), j = int(v / 13);
    if (i == 0 || i == 12 || j == 0 || j == 9)
      EXPECT_EQ(h[v], 0.0f) << "border vertex " << v;
    else
      EXPECT_LT(std::abs(h[v]), 1e-6) << "interior vertex " << v;
  }
}

TEST(MeanCurvature, CylinderIsHalfOfOneOverRadius) {
  const double r = 0.3, height = 1.0;
  for (const bool staggered : {false, true}) {
    SCOPED_TRACE(staggered ? "staggered rings, obtuse triangles" : "aligned rings, right triangles");
    // Staggered: rings 0.005 apart under 0.026-long chords make triangles with a 138-degree apex.
    const int rings = staggered ? 200 : 20;
    const TriMesh m = cylinder(r, height, 72, rings, staggered);
    const std::vector<float> h = vertex_mean_curvature(m);
    int interior = 0;
    for (int v = 0; v < int(m.vertex_count()); ++v) {
      if (on_cylinder_rim(m, v, height)) {
        EXPECT_EQ(h[v], 0.0f) << "rim vertex " << v;
        continue;
      }
      ++interior;
      EXPECT_NEAR(h[v], 1 / (2 * r), 0.01 / (2 * r)) << "vertex " << v;
    }
    EXPECT_EQ(interior, 72 * (rings - 1));
  }
}

TEST(MeanCurvature, FlippingTheTrianglesFlipsTheSign) {
  const TriMesh sphere = test::icosphere(2, 0.7);
  TriMesh inside_out = sphere;
  for (Tri& f : inside_out.triangles) std::swap(f[1], f[2]);
  const std::vector<float> h = vertex_mean_curvature(sphere), flipped = vertex_mean_curvature(inside_out);
  for (std::size_t v = 0; v < h.size(); ++v) {
    EXPECT_GT(h[v], 0) << "vertex " << v;
    EXPECT_EQ(flipped[v], -h[v]) << "vertex " << v;
  }
}

TEST(MeanCurvature, IsolatedVerticesAndDegenerateTrianglesGiveZeroNotNaN) {
  TriMesh m = test::icosphere(1);
  const std::vector<float> clean = vertex_mean_curvature(m);
  const int lone = int(m.vertex_count());
  m.positions.push_back({5, 5, 5});  // isolated
  for (int k = 0; k < 3; ++k) m.positions.push_back({6, 6, 6});
  m.triangles.push_back({lone + 1, lone + 2, lone + 3});  // zero area
  m.triangles.push_back({lone + 1, lone + 2, lone + 1});  // repeated index
  m.triangles.push_back({0, 0, lone + 3});                // repeated index touching the sphere
  const std::vector<float> h = vertex_mean_curvature(m);
  ASSERT_EQ(h.size(), m.vertex_count());
  for (int v = 0; v < lone; ++v) EXPECT_EQ(h[v], clean[v]) << "vertex " << v;
  for (int v = lone; v < lone + 4; ++v) EXPECT_EQ(h[v], 0.0f) << "vertex " << v;
  EXPECT_TRUE(vertex_mean_curvature(TriMesh{}).empty());
}
