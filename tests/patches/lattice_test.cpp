// Tangent-plane resampling of new patches (patch_resample.cpp,
// Remesher::Lattice): on the fluid, not flipped, equilateral away from the
// border, the expected size, holes kept, the remesher where the cut is not a
// height field, and the same patches for any thread count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "patches/internal.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

using detail::LatticeResult;
using detail::PatchPath;
using detail::PatchTrace;

constexpr double kLatticeEdge = 0.8 / 6;  // lattice edge / r with the default remesh_edge (create_patch.cpp)

double min_angle_deg(const Vec3& a, const Vec3& b, const Vec3& c) {
  auto angle = [](const Vec3& u, const Vec3& v) {
    return std::acos(std::clamp(dot(u, v) / (norm(u) * norm(v)), -1.0, 1.0)) * 180 / M_PI;
  };
  return std::min({angle(b - a, c - a), angle(a - b, c - b), angle(a - c, b - c)});
}

struct Made {
  Patch patch;
  PatchTrace trace;
};

Made make(const SurfaceQuery& surface, const Vec3& at, double r) {
  const ClosestHit hit = surface.closest(at, INFINITY);
  EXPECT_TRUE(hit.found);
  SurfacePoint sp{hit.point, normalized(triangle_normal_area2(surface.mesh(), hit.triangle)), hit.triangle};
  PatchOptions o;
  o.radius = r;
  o.remesher = Remesher::Lattice;
  Made m;
  auto p = detail::create_patch_traced(surface, build_surface_adjacency(surface.mesh()), sp, 7, 0, o, {}, m.trace);
  EXPECT_TRUE(p);
  if (p) m.patch = std::move(*p);
  return m;
}

// The properties every resampled patch must have: each vertex on the fluid
// with its fluid triangle known, no triangle facing away from n_p, every
// vertex within r + one lattice edge of p, and (away from the border, where
// the lattice is whole) triangles close to equilateral.
void expect_good_patch(const SurfaceQuery& surface, const Patch& p, double r, double min_angle_inside) {
  const Vec3& c = p.center;
  const Vec3& n = p.center_normal;
  ASSERT_FALSE(p.triangles.empty());
  for (std::size_t v = 0; v < p.positions.size(); ++v) {
    const ClosestHit hit = surface.closest(p.positions[v], r);
    ASSERT_TRUE(hit.found);
    EXPECT_LT(hit.distance, 1e-9 * r);
    // The triangle recorded under the vertex holds it.
    ASSERT_GE(p.surface_triangle[v], 0);
    const Tri& f = surface.mesh().triangles[p.surface_triangle[v]];
    const TrianglePoint q = closest_point_on_triangle(p.positions[v], surface.mesh().positions[f[0]],
                                                      surface.mesh().positions[f[1]], surface.mesh().positions[f[2]]);
    EXPECT_LT(norm(q.point - p.positions[v]), 1e-9 * r);
    // Still: projecting it again (what advection does next frame) lands on
    // the same point, bit for bit, on the same triangle.
    const ClosestHit again = surface.closest(p.positions[v], 1e-6 * r);
    ASSERT_TRUE(again.found);
    EXPECT_EQ(again.point, p.positions[v]);
    EXPECT_EQ(again.triangle, p.surface_triangle[v]);
    EXPECT_LE(norm(p.positions[v] - c), r + 1.2 * kLatticeEdge * r);
  }
  double worst_inside = 180;
  for (const Tri& t : p.triangles) {
    const Vec3 &a = p.positions[t[0]], &b = p.positions[t[1]], &d = p.positions[t[2]];
    EXPECT_GT(dot(cross(b - a, d - a), n), 0);
    if (std::max({norm(a - c), norm(b - c), norm(d - c)}) < r - 2 * kLatticeEdge * r)
      worst_inside = std::min(worst_inside, min_angle_deg(a, b, d));
  }
  EXPECT_GT(worst_inside, min_angle_inside);
}

// Border loops of a triangle mesh (edges with one triangle, chained).
int border_loops(const std::vector<Tri>& triangles) {
  std::map<std::pair<int, int>, int> directed;
  for (const Tri& t : triangles)
    for (int k = 0; k < 3; ++k) directed[{t[k], t[(k + 1) % 3]}]++;
  std::map<int, int> next;  // border edge a -> b (the one triangle's direction)
  for (const auto& [e, count] : directed)
    if (!directed.count({e.second, e.first})) next[e.first] = e.second;
  int loops = 0;
  while (!next.empty()) {
    int v = next.begin()->first;
    ++loops;
    while (next.count(v)) {
      const int w = next[v];
      next.erase(v);
      v = w;
    }
  }
  return loops;
}

// A plane tilted out of the axes, finely meshed, with the disks `holes`
// (centre in the plane's 2D coordinates, radius) cut out of it.
struct Hole {
  double x, y, radius;
};
TriMesh tilted_plane(int n, double size, const std::vector<Hole>& holes) {
  TriMesh m = test::plane_grid(n, n, size, size);
  const Vec3 axis = normalized(Vec3{1, 2, 0.5});
  std::vector<Tri> kept;
  for (const Tri& t : m.triangles) {
    const Vec3 g = (m.positions[t[0]] + m.positions[t[1]] + m.positions[t[2]]) / 3;
    bool in_hole = false;
    for (const Hole& h : holes) in_hole = in_hole || std::hypot(g.x - h.x, g.y - h.y) < h.radius;
    if (!in_hole) kept.push_back(t);
  }
  m.triangles = kept;
  for (Vec3& v : m.positions) v = test::rotate(v, axis, 0.6);
  return m;
}

TEST(PatchesResample, PlaneGivesAnEquilateralDiskOnTheFluid) {
  const double r = 0.1;
  const TriMesh plane = tilted_plane(40, 1.0, {});
  const SurfaceQuery surface(plane);
  const Vec3 axis = normalized(Vec3{1, 2, 0.5});
  const Made m = make(surface, test::rotate({0.503, 0.497, 0}, axis, 0.6), r);
  EXPECT_EQ(m.trace.path, PatchPath::Lattice);
  expect_good_patch(surface, m.patch, r, 59.99);  // a flat lattice: 60 degrees exactly
  // Triangles within r of p, on a lattice of edge l: about the disk of radius
  // r + l/2 over the area of one triangle.
  const double l = kLatticeEdge * r, tri = std::sqrt(3.0) / 4 * l * l;
  const double expected = M_PI * (r + 0.5 * l) * (r + 0.5 * l) / tri;
  EXPECT_NEAR(double(m.patch.triangles.size()), expected, 0.06 * expected);
  EXPECT_EQ(border_loops(m.patch.triangles), 1);
}

TEST(PatchesResample, SphereCapIsResampledOnTheSphere) {
  const double r = 0.25;
  const TriMesh sphere = test::icosphere(4);  // 5120 triangles, edge ~0.06
  const SurfaceQuery surface(sphere);
  for (const Vec3 at : {Vec3{0.3, 0.5, 0.8}, Vec3{-0.9, 0.1, -0.2}, Vec3{0, 0, -1}}) {
    SCOPED_TRACE(at.x);
    const Made m = make(surface, at, r);
    EXPECT_EQ(m.trace.path, PatchPath::Lattice);
    // On the unit sphere the cap at r tilts by about 15 degrees: the lifted
    // lattice stretches radially by at most 1/cos(15 deg) ~ 1.04.
    expect_good_patch(surface, m.patch, r, 50);
    const double l = kLatticeEdge * r, tri = std::sqrt(3.0) / 4 * l * l;
    const double flat = M_PI * (r + 0.5 * l) * (r + 0.5 * l) / tri;
    EXPECT_GT(double(m.patch.triangles.size()), 0.85 * flat);
    EXPECT_LT(double(m.patch.triangles.size()), 1.10 * flat);
    EXPECT_EQ(border_loops(m.patch.triangles), 1);
  }
}

// Every point of every patch triangle (corners, edge midpoints, centroid and
// points in between) lies on the fluid: no triangle spans a hole.
void expect_no_triangle_over_a_hole(const SurfaceQuery& surface, const Patch& p, double r) {
  for (const Tri& t : p.triangles)
    for (double a = 0; a <= 1.0001; a += 0.125)
      for (double b = 0; a + b <= 1.0001; b += 0.125) {
        const Vec3 q = p.positions[t[0]] * (1 - a - b) + p.positions[t[1]] * a + p.positions[t[2]] * b;
        const ClosestHit hit = surface.closest(q, r);
        ASSERT_TRUE(hit.found);
        ASSERT_LT(hit.distance, 1e-9 * r) << "a patch triangle spans a hole";
      }
}

TEST(PatchesResample, HolesStayHolesAndThePatchStaysOne) {
  const double r = 0.1;
  // A hole wider than the lattice edge (0.013) at 0.5 r from p, and one
  // narrower than a lattice triangle (one grid cell, 0.0125 wide) at 0.6 r
  // on the other side, which crosses no lattice edge.
  const std::vector<Hole> holes = {{0.55, 0.5, 0.025}, {0.44, 0.5, 0.006}};
  const TriMesh plane = tilted_plane(80, 1.0, holes);
  ASSERT_EQ(2 * 80 * 80 - plane.triangles.size(), std::size_t(27));  // 25 + 2 triangles
  const SurfaceQuery surface(plane);
  const Vec3 axis = normalized(Vec3{1, 2, 0.5});
  const Made m = make(surface, test::rotate({0.5, 0.5, 0}, axis, 0.6), r);
  EXPECT_EQ(m.trace.path, PatchPath::Lattice);
  expect_good_patch(surface, m.patch, r, 59.99);
  expect_no_triangle_over_a_hole(surface, m.patch, r);
  // One piece (LSCM flattened it) with the outer border and both holes.
  EXPECT_EQ(border_loops(m.patch.triangles), 3);
  // The hole removes about its own area and no more than a lattice ring around it.
  const double l = kLatticeEdge * r, tri = std::sqrt(3.0) / 4 * l * l;
  const double disk = M_PI * (r + 0.5 * l) * (r + 0.5 * l) / tri;
  EXPECT_LT(double(m.patch.triangles.size()), disk - M_PI * 0.025 * 0.025 / tri);
  EXPECT_GT(double(m.patch.triangles.size()), disk - M_PI * (0.025 + 2 * l) * (0.025 + 2 * l) / tri);
}

TEST(PatchesResample, HolesInsideALatticeTriangleStayHoles) {
  // Six one-triangle holes (legs 0.0025) of a fine plane, around p: smaller
  // than a lattice triangle (edge 0.0133), so most cross no lattice edge; the
  // lattice triangles holding their border are left out.
  const double r = 0.1, cell = 1.0 / 400;
  std::vector<Hole> holes;
  for (int k = 0; k < 6; ++k) {
    const double rho = 0.035 + 0.009 * k, angle = k * (M_PI / 3 + 0.37);  // not on one lattice line
    const int i = int(std::floor((0.5 + rho * std::cos(angle)) / cell));
    const int j = int(std::floor((0.5 + rho * std::sin(angle)) / cell));
    // The centroid of the cell's triangle (i,j) (i+1,j) (i+1,j+1).
    holes.push_back({(i + 2.0 / 3) * cell, (j + 1.0 / 3) * cell, 0.3 * cell});
  }
  const TriMesh plane = tilted_plane(400, 1.0, holes);
  ASSERT_EQ(2 * 400 * 400 - plane.triangles.size(), 6u);
  const SurfaceQuery surface(plane);
  const Vec3 axis = normalized(Vec3{1, 2, 0.5});
  const Made m = make(surface, test::rotate({0.5, 0.5, 0}, axis, 0.6), r);
  EXPECT_EQ(m.trace.path, PatchPath::Lattice);
  expect_good_patch(surface, m.patch, r, 59.99);
  expect_no_triangle_over_a_hole(surface, m.patch, r);
  EXPECT_EQ(border_loops(m.patch.triangles), 7);
}

TEST(PatchesResample, NotAHeightFieldFallsBackToTheRemesher) {
  // A droplet smaller than the patch: the cut wraps around it.
  {
    const double r = 0.1;
    const TriMesh drop = test::icosphere(3, 0.06, {1, 2, 3});
    const SurfaceQuery surface(drop);
    const Made m = make(surface, {1, 2, 3.1}, r);
    EXPECT_EQ(m.trace.lattice, LatticeResult::Steep);
    EXPECT_EQ(m.trace.path, PatchPath::Remeshed);
  }
  // A spiral ramp (helicoid, z = c theta, 1.5 turns) around p: every
  // triangle faces up (tilt below 30 degrees) but the turns lie over each
  // other within r of p, so the projection overlaps itself.
  {
    const double r = 0.1, c = 0.02 / (2 * M_PI);  // turns 0.02 apart
    TriMesh ramp;
    const int nr = 8, nt = 120;
    for (int j = 0; j <= nt; ++j)
      for (int i = 0; i <= nr; ++i) {
        const double rho = 0.04 + 0.05 * i / nr, th = 3 * M_PI * j / nt;
        ramp.positions.push_back({rho * std::cos(th), rho * std::sin(th), c * th});
      }
    for (int j = 0; j < nt; ++j)
      for (int i = 0; i < nr; ++i) {
        const int a = j * (nr + 1) + i, b = a + 1, d = a + nr + 1, e = d + 1;
        ramp.triangles.push_back({a, b, e});
        ramp.triangles.push_back({a, e, d});
      }
    const SurfaceQuery surface(ramp);
    const Made m = make(surface, {0.06, 0.001, 0}, r);
    EXPECT_EQ(m.trace.lattice, LatticeResult::Overlap);
    EXPECT_NE(m.trace.path, PatchPath::Lattice);
    ASSERT_FALSE(m.patch.triangles.empty());
  }
}

TEST(PatchesResample, SamePatchesForOneAndTwoThreads) {
  const TriMesh sphere = test::icosphere(4);
  const SurfaceQuery surface(sphere);
  PatchOptions o;
  o.radius = 0.2;
  o.remesher = Remesher::Lattice;
  const PatchSet one = test::seed_on_threads(surface, o, 1), two = test::seed_on_threads(surface, o, 2);
  ASSERT_GT(one.patches.size(), 50u);
  test::expect_same_patches(one, two);
}

}  // namespace
}  // namespace lapflow
