// The array remesher (patch_remesh.cpp) against CGAL's isotropic_remeshing on
// sliver-heavy patches: edge lengths, triangle shape, topology, and the patch
// it makes through create_patch (on the surface, same for any thread count).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <filesystem>
#include <functional>
#include <numeric>
#include <string>

#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "patches/internal.hpp"
#include "io_test_helpers.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

using detail::PatchMesh;

// A gently bent n x n grid over [0,1]^2 where a third of the vertices slide
// 0.47 cell toward a neighbour along x or y: edges of 0.06 cell and
// triangles with angles under a degree, as marching cubes makes.
TriMesh sliver_grid(int n) {
  TriMesh m = test::plane_grid(n, n, 1.0, 1.0);  // vertex (i, j) is j * (n + 1) + i
  const double h = 1.0 / n;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      double x = i * h, y = j * h;
      const uint64_t k = hash64(uint64_t(i), uint64_t(j), 77) % 3;
      if (i < n && j > 0 && j < n && k == 1) x += 0.47 * h;
      if (j < n && i > 0 && i < n && k == 2) y += 0.47 * h;
      m.positions[std::size_t(j) * (n + 1) + i] = {x, y, 0.15 * std::sin(3 * x) * std::cos(2 * y)};
    }
  return m;
}

double min_angle_deg(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 p[3] = {a, b, c};
  double best = 180;
  for (int k = 0; k < 3; ++k) {
    const Vec3 u = p[(k + 1) % 3] - p[k], v = p[(k + 2) % 3] - p[k];
    const double nu = norm(u), nv = norm(v);
    if (!(nu > 0) || !(nv > 0)) return 0;
    best = std::min(best, std::acos(std::clamp(dot(u, v) / (nu * nv), -1.0, 1.0)) * 180 / M_PI);
  }
  return best;
}

struct Quality {
  double min_edge = INFINITY, max_edge = 0;  // in units of the target edge
  double min_angle = 180, mean_min_angle = 0, below_20 = 0;  // degrees; fraction of triangles
  int flipped = 0;        // normal against the surface's (+z side for the grid)
  int euler = 0, border_loops = 0, components = 0;
  bool manifold = true;
};

Quality measure(const PatchMesh& m, double target, const std::function<Vec3(const Vec3&)>& surface_normal) {
  Quality q;
  std::vector<std::pair<uint64_t, int>> edges;  // undirected key -> +1 / -1 orientation
  for (const Tri& t : m.triangles) {
    const Vec3 &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    const double ang = min_angle_deg(a, b, c);
    q.min_angle = std::min(q.min_angle, ang);
    q.mean_min_angle += ang;
    q.below_20 += ang < 20;
    if (!(dot(cross(b - a, c - a), surface_normal((a + b + c) / 3.0)) > 0)) ++q.flipped;
    for (int k = 0; k < 3; ++k) {
      const uint32_t u = t[k], v = t[(k + 1) % 3];
      edges.push_back({(uint64_t(std::min(u, v)) << 32) | std::max(u, v), u < v ? 1 : -1});
    }
  }
  q.mean_min_angle /= double(m.triangles.size());
  q.below_20 /= double(m.triangles.size());
  std::sort(edges.begin(), edges.end());
  std::vector<int> parent(m.positions.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  int n_edges = 0;
  std::vector<uint8_t> used(m.positions.size(), 0), on_border(m.positions.size(), 0);
  for (const Tri& t : m.triangles)
    for (int v : t) used[v] = 1;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    ++n_edges;
    const int a = int(edges[i].first >> 32), b = int(edges[i].first & 0xffffffffu);
    const double len = norm(m.positions[a] - m.positions[b]) / target;
    q.min_edge = std::min(q.min_edge, len);
    q.max_edge = std::max(q.max_edge, len);
    if (j - i > 2 || (j - i == 2 && edges[i].second == edges[i + 1].second)) q.manifold = false;
    if (j - i == 1) {
      on_border[a] = on_border[b] = 1;
      parent[find(a)] = find(b);
    }
    i = j;
  }
  // Vertex manifoldness: splitting non-manifold vertices must add none.
  PatchMesh copy = m;
  detail::split_nonmanifold_vertices(copy);
  if (copy.positions.size() != m.positions.size()) q.manifold = false;
  const int nv = int(std::count(used.begin(), used.end(), 1));
  q.euler = nv - n_edges + int(m.triangles.size());
  for (int v = 0; v < int(m.positions.size()); ++v) q.border_loops += on_border[v] && find(v) == v;
  // Edge-connected pieces.
  std::vector<int> tp(m.triangles.size());
  std::iota(tp.begin(), tp.end(), 0);
  auto tfind = [&](int x) {
    while (tp[x] != x) x = tp[x] = tp[tp[x]];
    return x;
  };
  std::vector<std::pair<uint64_t, int>> te;
  for (int t = 0; t < int(m.triangles.size()); ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t u = m.triangles[t][k], v = m.triangles[t][(k + 1) % 3];
      te.push_back({(uint64_t(std::min(u, v)) << 32) | std::max(u, v), t});
    }
  std::sort(te.begin(), te.end());
  for (std::size_t i = 1; i < te.size(); ++i)
    if (te[i].first == te[i - 1].first) tp[tfind(te[i].second)] = tfind(te[i - 1].second);
  for (int t = 0; t < int(m.triangles.size()); ++t) q.components += tfind(t) == t;
  return q;
}

std::string describe(const Quality& q) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "edges [%.3f, %.3f] L, min angle %.2f, mean min angle %.2f, <20deg %.3f, flipped %d",
                q.min_edge, q.max_edge, q.min_angle, q.mean_min_angle, q.below_20, q.flipped);
  return buf;
}

// Both remeshers on the same input; the fast one must be at least about as
// good as CGAL's on every statistic, with the topology of the input.
void compare_remeshers(const PatchMesh& input, double target, const std::function<Vec3(const Vec3&)>& normal) {
  const Quality in = measure(input, target, normal);
  ASSERT_TRUE(in.manifold);
  ASSERT_EQ(in.flipped, 0);
  PatchMesh fast = input, cgal = input;
  ASSERT_TRUE(detail::isotropic_remesh(fast, target));
  ASSERT_TRUE(detail::cgal_remesh(cgal, target));
  const Quality qf = measure(fast, target, normal), qc = measure(cgal, target, normal);
  if (std::getenv("LAPFLOW_REMESH_STATS"))
    std::printf("input %zu tris: %s\ncgal  %zu tris: %s\nfast  %zu tris: %s\n", input.triangles.size(),
                describe(in).c_str(), cgal.triangles.size(), describe(qc).c_str(), fast.triangles.size(),
                describe(qf).c_str());
  SCOPED_TRACE("input: " + describe(in));
  SCOPED_TRACE("cgal:  " + describe(qc));
  SCOPED_TRACE("fast:  " + describe(qf));
  EXPECT_TRUE(qf.manifold);
  EXPECT_EQ(qf.flipped, 0);
  EXPECT_EQ(qf.euler, in.euler);
  EXPECT_EQ(qf.border_loops, in.border_loops);
  EXPECT_EQ(qf.components, 1);
  // Bounds chosen after measuring both remeshers on these inputs (see the trace).
  EXPECT_GE(qf.min_edge, 0.2);
  EXPECT_LE(qf.max_edge, 2.0);
  EXPECT_GE(qf.min_angle, 0.7 * qc.min_angle);
  EXPECT_GE(qf.mean_min_angle, qc.mean_min_angle - 1.5);
  EXPECT_LE(qf.below_20, qc.below_20 + 0.02);
  // The triangle count is CGAL's within 10%.
  EXPECT_NEAR(double(fast.triangles.size()), double(cgal.triangles.size()), 0.1 * double(cgal.triangles.size()));
}

TEST(PatchesRemesh, SliverGridMatchesCgalQuality) {
  const TriMesh grid = sliver_grid(24);
  PatchMesh m{grid.positions, grid.triangles};
  auto normal = [](const Vec3&) { return Vec3{0, 0, 1}; };
  {
    SCOPED_TRACE("slivers at the fluid's scale (L = 0.8 cell)");
    compare_remeshers(m, 0.8 / 24, normal);
  }
  {
    SCOPED_TRACE("coarse target (L = 2.5 cells): mostly collapses");
    compare_remeshers(m, 2.5 / 24, normal);
  }
  {
    SCOPED_TRACE("fine target (L = 0.3 cell): mostly splits");
    compare_remeshers(m, 0.3 / 24, normal);
  }
}

TEST(PatchesRemesh, HoleKeepsItsBorderLoop) {
  TriMesh grid = sliver_grid(24);
  // Cut a hole: drop the triangles whose centroid is near the middle.
  std::vector<Tri> kept;
  for (const Tri& t : grid.triangles) {
    const Vec3 c = (grid.positions[t[0]] + grid.positions[t[1]] + grid.positions[t[2]]) / 3.0;
    if (std::hypot(c.x - 0.5, c.y - 0.5) > 0.2) kept.push_back(t);
  }
  PatchMesh m{grid.positions, kept};
  // Isolated vertices (in the hole) are dropped by both remeshers.
  compare_remeshers(m, 0.8 / 24, [](const Vec3&) { return Vec3{0, 0, 1}; });
}

TEST(PatchesRemesh, RejectsNonManifoldInput) {
  // Three triangles on one edge.
  PatchMesh m{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}}, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}}};
  const PatchMesh before = m;
  EXPECT_FALSE(detail::isotropic_remesh(m, 0.3));
  EXPECT_EQ(m.triangles, before.triangles);
}

using test::dam_break_frame;

TEST(PatchesRemesh, DamBreakCutsMatchCgalQuality) {
  LAPFLOW_NEED_SHARED(dam_break_frame(9));
  const TriMesh fluid = read_mesh(dam_break_frame(9));
  const SurfaceQuery surface(fluid);
  const SurfaceAdjacency adj = build_surface_adjacency(fluid);
  const double r = 0.05;
  // The cut (no remeshing keeps it as is, snapped on the fluid where it already is).
  PatchOptions cut_only;
  cut_only.radius = r;
  cut_only.remesh = false;
  const auto points = seed_points(fluid, 6 * r, 11);
  ASSERT_GE(points.size(), 8u);
  auto normal_at = [&](const Vec3& x) {
    const ClosestHit hit = surface.closest(x, INFINITY);
    return normalized(triangle_normal_area2(fluid, hit.triangle));
  };
  for (std::size_t i = 0; i < 8; ++i) {
    const auto cut = create_patch(surface, adj, points[i], uint32_t(i), 9, cut_only, {});
    ASSERT_TRUE(cut);
    SCOPED_TRACE("dam_break frame 9, patch " + std::to_string(i));
    compare_remeshers(PatchMesh{cut->positions, cut->triangles}, r / 6, normal_at);
  }
}

TEST(PatchesRemesh, CreatedPatchLiesOnTheSurfaceForAnyThreadCount) {
  const TriMesh grid = sliver_grid(40);
  const SurfaceQuery surface(grid);
  PatchOptions o;
  o.radius = 0.12;
  o.remesher = Remesher::Isotropic;
  const PatchSet one = test::seed_on_threads(surface, o, 1), two = test::seed_on_threads(surface, o, 2);
  ASSERT_GT(one.patches.size(), 20u);
  test::expect_same_patches(one, two);
  for (const Patch& p : one.patches) {
    for (std::size_t v = 0; v < p.positions.size(); ++v) {
      // Snapped onto the fluid, with the triangle under it known.
      const ClosestHit hit = surface.closest(p.positions[v], o.radius);
      ASSERT_TRUE(hit.found);
      EXPECT_LT(hit.distance, 1e-9 * o.radius);
      EXPECT_GE(p.surface_triangle[v], 0);
    }
    // Remeshed: no edge longer than twice the target (r/6) after the snap.
    for (const Tri& t : p.triangles)
      for (int k = 0; k < 3; ++k)
        EXPECT_LT(norm(p.positions[t[k]] - p.positions[t[(k + 1) % 3]]), 2.0 * o.radius / 6);
  }
}

}  // namespace
}  // namespace lapflow
