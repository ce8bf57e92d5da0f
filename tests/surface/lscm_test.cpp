// Patch creation and LSCM flattening (ALGORITHM.md steps 2-3).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <utility>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "patches/internal.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using detail::PatchMesh;

namespace {

// A jittered planar grid (irregular triangles), tilted into 3D.
PatchMesh tilted_plane(int n, double jitter) {
  const TriMesh g = test::plane_grid(n, n, 1.0, 1.0);
  PatchMesh m{g.positions, g.triangles};
  const Vec3 axis = normalized(Vec3{1, 2, 0.5});
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    Vec3& p = m.positions[i];
    p.x += jitter / n * (hash_to_unit(hash64(i, 1)) - 0.5);
    p.y += jitter / n * (hash_to_unit(hash64(i, 2)) - 0.5);
    p = test::rotate(p, axis, 0.7) + Vec3{0.3, -1, 2};
  }
  return m;
}

double signed_area(const std::vector<Vec2>& uv, const Tri& f) {
  return 0.5 * cross(uv[f[1]] - uv[f[0]], uv[f[2]] - uv[f[0]]);
}

// The 3D point that rest uv `q` maps to (-1 triangle when no triangle holds it).
Vec3 point_at_uv(const Patch& p, const Vec2& q, int* triangle = nullptr) {
  for (int t = 0; t < int(p.triangles.size()); ++t) {
    const Tri& f = p.triangles[t];
    const Vec2 a = p.rest_uv[f[0]], b = p.rest_uv[f[1]], c = p.rest_uv[f[2]];
    const double area = cross(b - a, c - a);
    const double l1 = cross(q - a, c - a) / area, l2 = cross(b - a, q - a) / area;
    if (l1 >= -1e-9 && l2 >= -1e-9 && l1 + l2 <= 1 + 1e-9) {
      if (triangle) *triangle = t;
      return p.positions[f[0]] * (1 - l1 - l2) + p.positions[f[1]] * l1 + p.positions[f[2]] * l2;
    }
  }
  if (triangle) *triangle = -1;
  return {NAN, NAN, NAN};
}

// The faces of an icosphere whose centroid passes `keep`, reindexed.
template <class Keep>
PatchMesh sphere_piece(int subdivisions, Keep keep) {
  const TriMesh s = test::icosphere(subdivisions, 1.0);
  PatchMesh m;
  std::vector<int> local(s.positions.size(), -1);
  for (const Tri& f : s.triangles) {
    if (!keep((s.positions[f[0]] + s.positions[f[1]] + s.positions[f[2]]) / 3.0)) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      if (local[f[k]] < 0) local[f[k]] = int(m.positions.size()), m.positions.push_back(s.positions[f[k]]);
      g[k] = local[f[k]];
    }
    m.triangles.push_back(g);
  }
  return m;
}

// The shared LSCM (surface/lscm.hpp) on a PatchMesh.
bool flatten(const PatchMesh& m, std::vector<Vec2>& uv, int pin_a = -1, int pin_b = -1, Vec2 uv_a = {0, 0},
             Vec2 uv_b = {1, 0}) {
  return detail::lscm_flatten(m.positions, m.triangles, uv, pin_a, pin_b, uv_a, uv_b);
}
bool flatten_reference(const PatchMesh& m, std::vector<Vec2>& uv, int pin_a = -1, int pin_b = -1, Vec2 uv_a = {0, 0},
                       Vec2 uv_b = {1, 0}) {
  return detail::lscm_flatten_reference(m.positions, m.triangles, uv, pin_a, pin_b, uv_a, uv_b);
}
double energy(const PatchMesh& m, const std::vector<Vec2>& uv) {
  return detail::lscm_energy(m.positions, m.triangles, uv);
}

// Largest uv difference over the largest uv coordinate.
double relative_uv_difference(const std::vector<Vec2>& a, const std::vector<Vec2>& b) {
  double diff = 0, scale = 0;
  for (std::size_t v = 0; v < a.size(); ++v) diff = std::max(diff, norm(a[v] - b[v])), scale = std::max(scale, norm(b[v]));
  return diff / scale;
}

}  // namespace

TEST(PatchesFlatten, PlanarPatchIsAnIsometryUpToScale) {
  const PatchMesh m = tilted_plane(12, 0.6);
  std::vector<Vec2> uv;
  ASSERT_TRUE(flatten(m, uv));
  double a3 = 0, auv = 0;
  for (const Tri& f : m.triangles) {
    a3 += 0.5 * norm(cross(m.positions[f[1]] - m.positions[f[0]], m.positions[f[2]] - m.positions[f[0]]));
    auv += signed_area(uv, f);
  }
  const double scale = std::sqrt(a3 / auv);
  for (const Tri& f : m.triangles) {
    const double delta = detail::triangle_distortion(uv[f[0]], uv[f[1]], uv[f[2]], m.positions[f[0]],
                                                     m.positions[f[1]], m.positions[f[2]], scale);
    EXPECT_NEAR(delta, 1.0, 1e-3);
  }
}

TEST(PatchesFlatten, PinsAtTheirDistanceGiveAnIsometryOfAPlanarMesh) {
  // The atlas's use (atlas/flatten.cpp): its own pins, at (0,0) and (their 3D
  // distance, 0), so a flat chart keeps every length, on both solver paths
  // (the large mesh has over 1536 unknowns and goes to the Eigen reference;
  // its normal equations, whose condition grows with the mesh, lose more
  // digits).
  for (int n : {12, 48}) {
    SCOPED_TRACE("grid " + std::to_string(n));
    const PatchMesh m = tilted_plane(n, 0.6);
    const int a = 3, b = int(m.positions.size()) - 5;
    std::vector<Vec2> uv;
    ASSERT_TRUE(flatten(m, uv, a, b, {0, 0}, {norm(m.positions[b] - m.positions[a]), 0}));
    for (const Tri& f : m.triangles)
      for (int k = 0; k < 3; ++k) {
        const int p = f[k], q = f[(k + 1) % 3];
        const double l3 = norm(m.positions[q] - m.positions[p]);
        EXPECT_NEAR(norm(uv[q] - uv[p]), l3, 1e-7 * l3);
      }
  }
}

TEST(PatchesFlatten, PatchWithAHoleHasNoFlippedTriangle) {
  // A curved cap (part of a sphere) with a hole off its centre.
  const TriMesh s = test::icosphere(4, 1.0);
  PatchMesh m;
  std::vector<int> local(s.positions.size(), -1);
  for (const Tri& f : s.triangles) {
    const Vec3 c = (s.positions[f[0]] + s.positions[f[1]] + s.positions[f[2]]) / 3.0;
    if (c.z < 0.3 || norm(c - normalized(Vec3{0.3, 0.1, 1})) < 0.2) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      if (local[f[k]] < 0) local[f[k]] = int(m.positions.size()), m.positions.push_back(s.positions[f[k]]);
      g[k] = local[f[k]];
    }
    m.triangles.push_back(g);
  }
  std::vector<Vec2> uv;
  ASSERT_TRUE(flatten(m, uv));
  for (const Tri& f : m.triangles) EXPECT_GT(signed_area(uv, f), 0);
}

TEST(PatchesFlatten, EigenSolverAgreesWithCgal) {
  // Non-developable, so the answer depends on the pins: use CGAL's.
  const TriMesh s = test::icosphere(3, 1.0);
  PatchMesh m;
  std::vector<int> local(s.positions.size(), -1);
  for (const Tri& f : s.triangles) {
    const Vec3 c = (s.positions[f[0]] + s.positions[f[1]] + s.positions[f[2]]) / 3.0;
    if (c.z < 0.6) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      if (local[f[k]] < 0) local[f[k]] = int(m.positions.size()), m.positions.push_back(s.positions[f[k]]);
      g[k] = local[f[k]];
    }
    m.triangles.push_back(g);
  }
  ASSERT_GT(m.triangles.size(), 100u);
  // Two far-apart border vertices.
  int a = 0, b = 0;
  for (int v = 0; v < int(m.positions.size()); ++v) {
    if (m.positions[v].x < m.positions[a].x) a = v;
    if (m.positions[v].x > m.positions[b].x) b = v;
  }
  std::vector<Vec2> mine, cgal;
  ASSERT_TRUE(flatten(m, mine, a, b, {0, 0.5}, {1, 0.5}));
  ASSERT_TRUE(detail::cgal_lscm_flatten(m, a, b, cgal));
  // CGAL stops its conjugate gradient at a 1e-6 relative residual, which
  // leaves uv errors of a few 1e-4 on this unit-length map; the direct
  // solve must agree to that and reach an energy no higher than CGAL's.
  for (std::size_t v = 0; v < mine.size(); ++v) EXPECT_LT(norm(mine[v] - cgal[v]), 2e-3) << v;
  EXPECT_LE(energy(m, mine), energy(m, cgal) * (1 + 1e-12));
  EXPECT_GT(energy(m, mine), 0.99 * energy(m, cgal));
}

TEST(PatchesFlatten, NonManifoldVertexIsSplit) {
  // Two triangles touching at vertex 0 only (a bow tie).
  PatchMesh m{{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}}, {{0, 1, 2}, {0, 3, 4}}};
  detail::split_nonmanifold_vertices(m);
  ASSERT_EQ(m.positions.size(), 6u);
  EXPECT_NE(m.triangles[0][0], m.triangles[1][0]);
  EXPECT_EQ(m.positions[m.triangles[1][0]], (Vec3{0, 0, 0}));
}

class CreatePatch : public ::testing::TestWithParam<bool> {};

TEST_P(CreatePatch, PlanarPatchIsPlacedInTheUnitSquare) {
  const TriMesh plane = test::plane_grid(40, 40, 1.0, 1.0);
  SurfaceQuery q(plane);
  PatchOptions o;
  o.radius = 0.1;
  o.remesh = GetParam();
  const Vec3 p{0.503, 0.497, 0};
  const auto patch = create_patch(q, {p, {0, 0, 1}, -1}, 42, 3, o, {});
  ASSERT_TRUE(patch.has_value());
  EXPECT_EQ(patch->id, 42u);
  EXPECT_EQ(patch->birth_frame, 3);
  // p sits at (0.5, 0.5).
  EXPECT_LT(norm(point_at_uv(*patch, {0.5, 0.5}) - p), 1e-9);
  double a3 = 0, auv = 0;
  for (std::size_t t = 0; t < patch->triangles.size(); ++t) {
    const Tri& f = patch->triangles[t];
    a3 += 0.5 * norm(cross(patch->positions[f[1]] - patch->positions[f[0]], patch->positions[f[2]] - patch->positions[f[0]]));
    auv += signed_area(patch->rest_uv, f);
    EXPECT_NEAR(patch->triangle_delta[t], 1.0, 1e-3);
    EXPECT_NEAR(patch->triangle_quality[t], 1.0, 1e-3);
  }
  EXPECT_NEAR(auv * 4 * o.radius * o.radius, a3, 1e-9);
  // The footprint: a disk of radius about r, so uv within about 0.5 of the centre.
  for (std::size_t v = 0; v < patch->positions.size(); ++v) {
    EXPECT_LE(norm(patch->positions[v] - p), o.radius + 0.04);
    EXPECT_LE(norm(patch->rest_uv[v] - Vec2{0.5, 0.5}), 0.7);
    EXPECT_GE(patch->surface_triangle[v], 0);
    // B_V: boundary vertices far from the centre are 0, the rest 1.
    if (norm(patch->rest_uv[v] - Vec2{0.5, 0.5}) < 0.3) {
      EXPECT_EQ(patch->border[v], 1);
    }
  }
  int zero_border = 0;
  for (uint8_t b : patch->border) zero_border += b == 0;
  EXPECT_GT(zero_border, 8);
  if (o.remesh) {
    // Target edge r/6: a disk of radius r holds on the order of 250 triangles.
    EXPECT_GT(patch->triangles.size(), 100u);
    EXPECT_LT(patch->triangles.size(), 600u);
  }
}

INSTANTIATE_TEST_SUITE_P(RemeshOrNot, CreatePatch, ::testing::Values(false, true));

TEST(PatchesCreate, DropsTrianglesFacingAwayAndOrientationFollowsTheSeed) {
  // A thin slab: the patch at the top face must not take the bottom face 0.02 below.
  TriMesh top = test::plane_grid(20, 20, 1.0, 1.0, 0.02);
  TriMesh bottom = test::plane_grid(20, 20, 1.0, 1.0, 0.0);
  for (Tri& f : bottom.triangles) std::swap(f[1], f[2]);  // facing down
  const int base = int(top.positions.size());
  top.positions.insert(top.positions.end(), bottom.positions.begin(), bottom.positions.end());
  for (Tri f : bottom.triangles) top.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
  SurfaceQuery q(top);
  PatchOptions o;
  o.radius = 0.15;
  o.remesh = false;
  o.seed = 9;
  const auto a = create_patch(q, {{0.5, 0.5, 0.02}, {0, 0, 1}, -1}, 1, 0, o, {});
  ASSERT_TRUE(a);
  for (const Vec3& p : a->positions) EXPECT_EQ(p.z, 0.02);
  // Orientation: random per id unless aligned; aligned puts +x along +u.
  const auto b = create_patch(q, {{0.5, 0.5, 0.02}, {0, 0, 1}, -1}, 2, 0, o, {});
  EXPECT_NE(a->rest_uv, b->rest_uv);
  o.align = true;
  o.align_direction = {1, 0, 0.3};
  const auto c = create_patch(q, {{0.5, 0.5, 0.02}, {0, 0, 1}, -1}, 3, 0, o, {});
  ASSERT_TRUE(c);
  const Vec3 x1 = point_at_uv(*c, {0.6, 0.5});
  EXPECT_NEAR(x1.x - 0.5, 0.1 * 2 * o.radius, 1e-9);
  EXPECT_NEAR(x1.y - 0.5, 0.0, 1e-9);
}

TEST(PatchesCreate, CutNeverTakesADirectedEdgeTwice) {
  // A fin on a plane: a third triangle on the edge (a, b) of the patch's
  // seed triangle, facing up and oriented like the seed's neighbour, so that
  // neighbour and the fin both run b -> a. A cut taking both would be no
  // oriented surface (LSCM needs one): it keeps one of them.
  TriMesh m = test::plane_grid(20, 20, 1.0, 1.0);
  SurfaceQuery flat(m);
  const Vec3 p{0.512, 0.493, 0};
  const int seed = flat.closest(p, 1.0).triangle;
  ASSERT_GE(seed, 0);
  const Tri s = m.triangles[seed];
  const int32_t a = s[0], b = s[1];
  int neighbour = -1;  // the triangle holding b -> a
  for (int t = 0; t < int(m.triangles.size()); ++t)
    for (int k = 0; k < 3; ++k)
      if (m.triangles[t][k] == b && m.triangles[t][(k + 1) % 3] == a) neighbour = t;
  ASSERT_GE(neighbour, 0);
  const Tri& nt = m.triangles[neighbour];
  const int32_t d = nt[0] != a && nt[0] != b ? nt[0] : nt[1] != a && nt[1] != b ? nt[1] : nt[2];
  m.positions.push_back(m.positions[d] + Vec3{0, 0, 0.01});  // the fin's apex, just above d
  m.triangles.push_back({b, a, int32_t(m.positions.size() - 1)});
  SurfaceQuery q(m);
  PatchOptions o;
  o.radius = 0.12;
  o.remesh = false;  // the cut itself
  const auto patch = create_patch(q, {p, {0, 0, 1}, seed}, 1, 0, o, {});
  ASSERT_TRUE(patch);
  // By position (split vertices share one): every directed edge once.
  std::map<std::pair<std::array<double, 3>, std::array<double, 3>>, int> directed;
  auto at = [&](int32_t v) {
    const Vec3& x = patch->positions[v];
    return std::array<double, 3>{x.x, x.y, x.z};
  };
  for (const Tri& f : patch->triangles)
    for (int k = 0; k < 3; ++k) {
      const int uses = ++directed[std::make_pair(at(f[k]), at(f[(k + 1) % 3]))];
      EXPECT_EQ(uses, 1);
    }
  // The seed's plane around p is all there: about pi r^2 / (1/20^2 / 2)
  // grid triangles, whichever of the neighbour and the fin was kept.
  EXPECT_GT(patch->triangles.size(), 30u);
  EXPECT_LT(norm(point_at_uv(*patch, {0.5, 0.5}) - p), 1e-9);
}

TEST(PatchesCreate, RemeshingCostStaysBoundedWhenFluidTrianglesDwarfThePatch) {
  // Two triangles 100 r across: remeshing them at r/6 would make ~10^6 triangles.
  const TriMesh big = test::plane_grid(1, 1, 10.0, 10.0);
  SurfaceQuery q(big);
  PatchOptions o;
  o.radius = 0.1;
  const auto p = create_patch(q, {{5.2, 4.1, 0}, {0, 0, 1}, -1}, 0, 0, o, {});
  ASSERT_TRUE(p);
  EXPECT_LT(p->triangles.size(), 4000u);
  EXPECT_LT(norm(point_at_uv(*p, {0.5, 0.5}) - Vec3{5.2, 4.1, 0}), 1e-9);
  for (float d : p->triangle_delta) EXPECT_NEAR(d, 1.0, 1e-3);
}

TEST(PatchesFlatten, SolverAgreesWithTheEigenReference) {
  // lscm_flatten (minimum degree ordering, own LDL^H) against the previous
  // solver (Eigen SimplicialLDLT, AMD): same pins, same map to rounding.
  struct Case {
    const char* name;
    PatchMesh mesh;
    int pin_a = -1, pin_b = -1;
  };
  std::vector<Case> cases;
  cases.push_back({"jittered plane", tilted_plane(14, 0.6)});
  cases.push_back({"cap", sphere_piece(4, [](const Vec3& c) { return c.z > 0.55; })});
  cases.push_back({"cap with a hole",
                   sphere_piece(4, [](const Vec3& c) { return c.z > 0.3 && norm(c - normalized(Vec3{0.3, 0.1, 1})) > 0.2; })});
  cases.push_back({"pinned cap", sphere_piece(3, [](const Vec3& c) { return c.z > 0.4; }), 0, 7});
  {
    // Degenerate triangles (zero area, a repeated vertex), a vertex no
    // triangle uses and an edge shared by three triangles.
    PatchMesh m = tilted_plane(8, 0.5);
    const int n = int(m.positions.size());
    m.positions.push_back((m.positions[0] + m.positions[1]) * 0.5);  // on the edge 0-1: a zero-area triangle
    m.triangles.push_back({0, 1, n});
    m.triangles.push_back({2, 2, 3});
    m.triangles.push_back({m.triangles[30][0], m.triangles[30][0], m.triangles[30][1]});
    m.triangles.push_back({m.triangles[30][0], m.triangles[30][0], m.triangles[30][2]});
    m.positions.push_back({5, 5, 5});  // unused
    m.positions.push_back(m.positions[10] + Vec3{0, 0, 0.05});
    m.triangles.push_back({m.triangles[20][0], m.triangles[20][1], n + 2});  // a third triangle on an edge
    cases.push_back({"degenerate", m});
  }
  // Over 1536 unknowns lscm_flatten hands the system to the reference.
  cases.push_back({"large", tilted_plane(48, 0.6)});
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<Vec2> mine, reference;
    const Vec2 uv_a{0.1, 0.2}, uv_b{0.9, 0.4};
    ASSERT_TRUE(flatten(c.mesh, mine, c.pin_a, c.pin_b, uv_a, uv_b));
    ASSERT_TRUE(flatten_reference(c.mesh, reference, c.pin_a, c.pin_b, uv_a, uv_b));
    ASSERT_EQ(mine.size(), reference.size());
    EXPECT_LT(relative_uv_difference(mine, reference), 1e-9);
    // The energy agrees to rounding (uv spans about 1, so 1e-15 is noise; a
    // planar patch has energy 0 up to that).
    const double e_mine = energy(c.mesh, mine), e_ref = energy(c.mesh, reference);
    EXPECT_NEAR(e_mine, e_ref, 1e-9 * e_ref + 1e-15);
  }
}

TEST(PatchesFlatten, SolverFailsWhereTheReferenceFails) {
  std::vector<Vec2> uv{{7, 7}};
  // Every triangle degenerate: nothing to solve.
  const PatchMesh flat{{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}}, {{0, 1, 2}, {1, 2, 3}}};
  EXPECT_FALSE(flatten_reference(flat, uv));
  EXPECT_FALSE(flatten(flat, uv));
  // One triangle: both free vertices pinned, no unknown left.
  const PatchMesh one{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}};
  std::vector<Vec2> a, b;
  EXPECT_EQ(flatten(one, a), flatten_reference(one, b));
  EXPECT_EQ(a, b);
  // Too few vertices.
  const PatchMesh tiny{{{0, 0, 0}, {1, 0, 0}}, {{0, 1, 1}}};
  EXPECT_FALSE(flatten(tiny, uv));
  EXPECT_EQ(uv, (std::vector<Vec2>{{7, 7}}));  // untouched on failure
}

// Anticipated shear: under a steady simple shear v = (g (y - 1), 0, 0) a new patch
// is laid with the inverse of the flow's deformation over `anticipate` of its
// predicted life, so the flow itself brings its distortion down to 1 (that
// many frames later) before raising it again; the texture disk still has the
// patch's area; a flow without strain (a translation), or one that changed
// since the previous frame, changes nothing.
TEST(PatchesCreate, AnticipatedShearIsUndoneByTheFlow) {
  const TriMesh plane = test::plane_grid(80, 80, 2.0, 2.0);
  SurfaceQuery q(plane);
  const double g = 1.5, dt = 1.0 / 24;
  const VelocityField shear = [g](const Vec3& x) { return Vec3{g * (x.y - 1), 0, 0}; };
  PatchOptions o;
  o.radius = 0.1;
  o.anticipate = 0.5;
  o.velocity = &shear;
  o.dt = dt;
  WeightOptions w;
  const Vec3 p{1.0, 1.0, 0};
  const auto patch = create_patch(q, {p, {0, 0, 1}, -1}, 7, 0, o, w);
  ASSERT_TRUE(patch.has_value());
  // Frames until a conformal patch reaches delta_max under this shear: the
  // map I + g t e_x e_y^T has delta = k/2 + sqrt(1 + k^2/4) with k = g t.
  int life = 0;
  for (int n = 1; n < 1000 && !life; ++n) {
    const double k = g * n * dt;
    if (0.5 * k + std::sqrt(1 + 0.25 * k * k) >= w.delta_max) life = n;
  }
  const double m = o.anticipate * life;  // frames until the patch is undistorted
  auto median_delta = [&](const Patch& pt) {
    std::vector<double> d(pt.triangle_delta.begin(), pt.triangle_delta.end());
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    return d[d.size() / 2];
  };
  const double k0 = g * m * dt, born = 0.5 * k0 + std::sqrt(1 + 0.25 * k0 * k0);
  EXPECT_NEAR(median_delta(*patch), born, 0.02);
  // The flow over m frames (exact for a steady shear).
  Patch later = *patch;
  for (Vec3& x : later.positions) x.x += g * (x.y - 1) * m * dt;
  patch_weights(plane, o.radius, w, later);
  for (float d : later.triangle_delta) EXPECT_NEAR(d, 1.0, 0.02);
  // Area: uv area times (2r)^2 is the 3D area (the stretch has determinant 1).
  double a3 = 0, auv = 0;
  for (const Tri& f : patch->triangles) {
    a3 += 0.5 * norm(cross(patch->positions[f[1]] - patch->positions[f[0]], patch->positions[f[2]] - patch->positions[f[0]]));
    auv += signed_area(patch->rest_uv, f);
  }
  EXPECT_NEAR(auv * 4 * o.radius * o.radius, a3, 1e-3 * a3);
  // The texture disk is covered: every rest uv direction from the centre reaches 0.5.
  for (int k = 0; k < 16; ++k) {
    const double a = 2 * M_PI * k / 16;
    int t = -1;
    point_at_uv(*patch, {0.5 + 0.45 * std::cos(a), 0.5 + 0.45 * std::sin(a)}, &t);
    EXPECT_GE(t, 0) << "direction " << k;
  }
  // The prediction assumes a steady flow: with the previous frame's field
  // the same, nothing changes; where the flow changed since (here it
  // reversed), the patch is the conformal one, bit for bit.
  const auto plain = create_patch(q, {p, {0, 0, 1}, -1}, 7, 0, PatchOptions{.radius = 0.1}, w);
  o.previous_velocity = &shear;
  const auto steady = create_patch(q, {p, {0, 0, 1}, -1}, 7, 0, o, w);
  ASSERT_TRUE(plain && steady);
  EXPECT_EQ(steady->rest_uv, patch->rest_uv);
  const VelocityField reversed = [g](const Vec3& x) { return Vec3{-g * (x.y - 1), 0, 0}; };
  o.previous_velocity = &reversed;
  const auto unsteady = create_patch(q, {p, {0, 0, 1}, -1}, 7, 0, o, w);
  ASSERT_TRUE(unsteady);
  EXPECT_EQ(unsteady->rest_uv, plain->rest_uv);
  o.previous_velocity = nullptr;
  // A translation has no strain: the conformal patch, bit for bit.
  const VelocityField slide = [](const Vec3&) { return Vec3{0.3, 0.1, 0}; };
  o.velocity = &slide;
  const auto slid = create_patch(q, {p, {0, 0, 1}, -1}, 7, 0, o, w);
  ASSERT_TRUE(slid);
  EXPECT_EQ(plain->rest_uv, slid->rest_uv);
}
