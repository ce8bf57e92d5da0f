// analyze_mesh: known answers on tiny meshes built in code.
#include <gtest/gtest.h>

#include "lapflow/surface/mesh.hpp"
#include "lapflow/core/parallel.hpp"
#include "test_helpers.hpp"

using namespace lapflow;

namespace {
TriMesh tetrahedron(Vec3 offset = {}, int base = 0) {
  TriMesh m;
  m.positions = {offset + Vec3{0, 0, 0}, offset + Vec3{1, 0, 0}, offset + Vec3{0, 1, 0}, offset + Vec3{0, 0, 1}};
  m.triangles = {{base + 0, base + 2, base + 1}, {base + 0, base + 1, base + 3}, {base + 0, base + 3, base + 2},
                 {base + 1, base + 2, base + 3}};
  return m;
}
}  // namespace

TEST(AnalyzeMesh, ClosedTetrahedron) {
  TriMesh m = tetrahedron();
  m.velocities = {{0, 0, 0}, {3, 4, 0}, {0, 0, 1}, {0, 0, 2}};
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.vertices, 4u);
  EXPECT_EQ(r.triangles, 4u);
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.boundary_edges, 0u);
  EXPECT_EQ(r.non_manifold_edges, 0u);
  EXPECT_EQ(r.non_manifold_vertices, 0u);
  EXPECT_EQ(r.degenerate_triangles, 0u);
  EXPECT_EQ(r.isolated_vertices, 0u);
  EXPECT_NEAR(r.area, 1.5 + std::sqrt(3.0) / 2, 1e-12);
  EXPECT_EQ(r.bounds.lo, Vec3(0, 0, 0));
  EXPECT_EQ(r.bounds.hi, Vec3(1, 1, 1));
  EXPECT_TRUE(r.has_velocity);
  EXPECT_DOUBLE_EQ(r.speed_min, 0);
  EXPECT_DOUBLE_EQ(r.speed_max, 5);
  EXPECT_DOUBLE_EQ(r.speed_mean, 2);
}

TEST(AnalyzeMesh, TwoTetrahedraSharingAVertex) {
  // The second tetrahedron's vertex 0 is the first one's vertex 3: two fans
  // (two spheres) meet at one point.
  TriMesh m = tetrahedron();
  const TriMesh b = tetrahedron({0, 0, 1}, 3);
  for (int i = 1; i < 4; ++i) m.positions.push_back(b.positions[i]);
  for (Tri f : b.triangles) m.triangles.push_back(f);
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.vertices, 7u);
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.non_manifold_vertices, 1u);
  EXPECT_EQ(r.non_manifold_edges, 0u);
  EXPECT_EQ(r.boundary_edges, 0u);
}

TEST(AnalyzeMesh, ThreeTrianglesOnOneEdge) {
  TriMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0}, {0.5, 0, 1}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.non_manifold_edges, 1u);
  EXPECT_EQ(r.boundary_edges, 6u);
  // The edge's two end points have a fan of three blades: not a half-disk.
  EXPECT_EQ(r.non_manifold_vertices, 2u);
  EXPECT_EQ(r.components, 1);
}

TEST(AnalyzeMesh, OpenSheetIsManifoldWithBoundary) {
  const TriMesh m = test::plane_grid(4, 3, 4.0, 3.0);
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.boundary_edges, 2u * (4 + 3));
  EXPECT_EQ(r.non_manifold_vertices, 0u);
  EXPECT_EQ(r.non_manifold_edges, 0u);
  EXPECT_NEAR(r.area, 12.0, 1e-12);
  EXPECT_FALSE(r.has_velocity);
}

TEST(AnalyzeMesh, DegenerateTrianglesAndIsolatedVertices) {
  TriMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {5, 5, 5}};
  m.triangles = {{0, 1, 3}, {0, 1, 2}, {1, 1, 3}};  // fine, collinear, repeated index
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.degenerate_triangles, 2u);
  EXPECT_EQ(r.isolated_vertices, 1u);
  // The isolated vertex does not stretch the bounds.
  EXPECT_EQ(r.bounds.hi, Vec3(2, 1, 0));
}

TEST(AnalyzeMesh, CountsComponentsAndIsThreadCountIndependent) {
  TriMesh m = test::icosphere(3);
  const TriMesh far = test::icosphere(2, 0.5, {5, 0, 0});
  const int base = int(m.positions.size());
  m.positions.insert(m.positions.end(), far.positions.begin(), far.positions.end());
  for (Tri f : far.triangles) m.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
  set_thread_count(1);
  const MeshReport one = analyze_mesh(m);
  set_thread_count(2);
  const MeshReport two = analyze_mesh(m);
  set_thread_count(0);
  EXPECT_EQ(one.components, 2);
  EXPECT_EQ(one.boundary_edges, 0u);
  EXPECT_EQ(one.non_manifold_vertices, 0u);
  EXPECT_EQ(one.area, two.area);  // bitwise
  EXPECT_EQ(one.non_manifold_vertices, two.non_manifold_vertices);
  EXPECT_EQ(one.degenerate_triangles, two.degenerate_triangles);
}
