// Advection, projection and weights of patches (ALGORITHM.md steps 4-5).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <array>
#include <map>
#include <memory>
#include <set>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "patches/internal.hpp"
#include "test_helpers.hpp"

using namespace lapflow;

namespace {

// The 3D point that rest uv `q` maps to (NaN when no triangle holds it).
Vec3 point_at_uv(const Patch& p, const Vec2& q) {
  for (const Tri& f : p.triangles) {
    const Vec2 a = p.rest_uv[f[0]], b = p.rest_uv[f[1]], c = p.rest_uv[f[2]];
    const double area = cross(b - a, c - a);
    const double l1 = cross(q - a, c - a) / area, l2 = cross(b - a, q - a) / area;
    if (l1 >= -1e-9 && l2 >= -1e-9 && l1 + l2 <= 1 + 1e-9)
      return p.positions[f[0]] * (1 - l1 - l2) + p.positions[f[1]] * l1 + p.positions[f[2]] * l2;
  }
  return {NAN, NAN, NAN};
}

double brute_force_distance(const TriMesh& m, const Vec3& p) {
  double best = INFINITY;
  for (const Tri& f : m.triangles) {
    const Vec3 q = closest_point_on_triangle(p, m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]).point;
    best = std::min(best, norm(q - p));
  }
  return best;
}

// A unit sphere translating with velocity V and spinning at omega about its
// centre, re-meshed every frame (the icosphere under a different random
// rotation, so no vertex lines up with the previous frame's).
struct RigidSphere {
  Vec3 c0{0.2, -0.1, 0.3}, V{0.6, 0.2, -0.3}, axis = normalized(Vec3{0.3, 1, 0.2});
  double omega = 1.5;  // rad/s
  Vec3 centre(double t) const { return c0 + V * t; }
  // Exact flow of a point that was at x0 at time 0.
  Vec3 flow(const Vec3& x0, double t) const { return centre(t) + test::rotate(x0 - c0, axis, omega * t); }
  VelocityField velocity(double t) const {
    return [this, t](const Vec3& x) { return V + cross(axis * omega, x - centre(t)); };
  }
  TriMesh mesh(int frame) const {
    TriMesh m = test::icosphere(5, 1.0);
    const Vec3 a = normalized(Vec3{hash_to_unit(hash64(frame, 1)) - 0.5, hash_to_unit(hash64(frame, 2)) - 0.5,
                                   hash_to_unit(hash64(frame, 3)) - 0.5});
    const double angle = 6.28 * hash_to_unit(hash64(frame, 4));
    const Vec3 c = centre(frame / 24.0);
    for (Vec3& p : m.positions) p = c + test::rotate(p, a, angle);
    return m;
  }
};

struct RigidRun {
  PatchSet patches;
  std::vector<Vec3> start_centres;
  std::size_t removed = 0;
  double max_residual = 0;
  TriMesh last;
};

RigidRun run_rigid(int frames, const PatchOptions& po, double omega = 1.5) {
  RigidSphere s;
  s.omega = omega;
  RigidRun run;
  auto mesh = std::make_unique<TriMesh>(s.mesh(0));
  auto query = std::make_unique<SurfaceQuery>(*mesh);
  seed_patches(*query, 0, po, {}, {}, run.patches);
  for (const Patch& p : run.patches.patches) run.start_centres.push_back(p.center);
  AdvectOptions ao;
  ao.dt = 1.0 / 24;
  for (int f = 1; f <= frames; ++f) {
    auto next_mesh = std::make_unique<TriMesh>(s.mesh(f));
    auto next_query = std::make_unique<SurfaceQuery>(*next_mesh);
    const AdvectStats st =
        advect_patches(*next_query, s.velocity((f - 1) / 24.0), s.velocity(f / 24.0), po, ao, run.patches);
    update_weights(next_query->mesh(), po.radius, {}, run.patches);
    run.removed += st.vertices_removed;
    run.max_residual = std::max(run.max_residual, st.max_residual);
    query = std::move(next_query);
    mesh = std::move(next_mesh);
  }
  run.last = *mesh;
  return run;
}

}  // namespace

TEST(PatchesAdvect, RigidMotionKeepsPatchesUndistorted) {
  PatchOptions po;
  po.radius = 0.3;
  po.seed = 4;
  const int frames = 48;
  const RigidRun run = run_rigid(frames, po);
  ASSERT_GT(run.patches.patches.size(), 50u);
  EXPECT_EQ(run.removed, 0u);
  RigidSphere s;
  double worst_delta = 0, worst_centre = 0;
  for (std::size_t i = 0; i < run.patches.patches.size(); ++i) {
    const Patch& p = run.patches.patches[i];
    for (float d : p.triangle_delta) worst_delta = std::max(worst_delta, double(d));
    const Vec3 exact = s.flow(run.start_centres[i], frames / 24.0);
    // The centre of the texture rides with the surface: exact flow, projected.
    const Vec3 on_surface = s.centre(frames / 24.0) + normalized(exact - s.centre(frames / 24.0));
    worst_centre = std::max(worst_centre, norm(point_at_uv(p, {0.5, 0.5}) - on_surface));
    worst_centre = std::max(worst_centre, norm(p.center - exact));
  }
  EXPECT_LT(worst_delta, 1.05);
  EXPECT_LT(worst_centre, po.radius / 100);
  // Projection residual of every kept vertex (a sample checked by brute force).
  EXPECT_LT(run.max_residual, 1e-5 * po.radius);
  for (std::size_t i = 0; i < run.patches.patches.size(); i += 7)
    for (const Vec3& x : run.patches.patches[i].positions)
      EXPECT_LT(brute_force_distance(run.last, x), 1e-5 * po.radius);
}

TEST(PatchesAdvect, FastSpinIsSubSteppedOnTheTurn) {
  // 4 rad/s at 24 fps: the velocity turns 0.17 rad per frame, so one RK2 step
  // per frame would drift the texture by about 0.17^3/6 of the radius a frame.
  PatchOptions po;
  po.radius = 0.3;
  const int frames = 24;
  const double omega = 4.0;
  const RigidRun run = run_rigid(frames, po, omega);
  RigidSphere s;
  s.omega = omega;
  EXPECT_EQ(run.removed, 0u);
  double worst = 0, worst_delta = 0;
  for (std::size_t i = 0; i < run.patches.patches.size(); ++i) {
    const Patch& p = run.patches.patches[i];
    worst = std::max(worst, norm(p.center - s.flow(run.start_centres[i], frames / 24.0)));
    for (float d : p.triangle_delta) worst_delta = std::max(worst_delta, double(d));
  }
  EXPECT_LT(worst, po.radius / 100);
  EXPECT_LT(worst_delta, 1.05);
}

TEST(PatchesAdvect, SameResultForOneAndTwoThreads) {
  PatchOptions po;
  po.radius = 0.4;
  set_thread_count(1);
  const RigidRun one = run_rigid(3, po);
  set_thread_count(2);
  const RigidRun two = run_rigid(3, po);
  set_thread_count(0);
  test::expect_same_patches(one.patches, two.patches);
}

TEST(PatchesAdvect, SimpleShearMatchesTheAnalyticDistortion) {
  // The vertical plane y = 0, sheared by u = (g z, 0, 0): every material
  // triangle undergoes [[1, g t], [0, 1]] in the (x, z) plane.
  TriMesh plane = test::plane_grid(60, 60, 2.0, 2.0);
  for (Vec3& p : plane.positions) p = {p.x - 1, 0, p.y - 1};
  SurfaceQuery q(plane);
  PatchOptions po;
  po.radius = 0.2;
  po.remesh = true;
  PatchSet set;
  for (int k = 0; k < 3; ++k) {
    auto p = create_patch(q, {{0.1 * k - 0.1, 0, 0.05 * k}, {0, -1, 0}, -1}, uint32_t(k), 0, po, {});
    ASSERT_TRUE(p);
    set.patches.push_back(std::move(*p));
  }
  const double g = 1.0;
  const VelocityField shear = [g](const Vec3& x) { return Vec3{g * x.z, 0, 0}; };
  AdvectOptions ao;
  ao.dt = 1.0 / 24;
  const int frames = 12;
  std::size_t removed = 0;
  for (int f = 1; f <= frames; ++f) {
    removed += advect_patches(q, shear, shear, po, ao, set).vertices_removed;
    update_weights(q.mesh(), po.radius, {}, set);
  }
  EXPECT_EQ(removed, 0u);
  const double k = g * frames * ao.dt;
  const double s1 = std::sqrt((2 + k * k + k * std::sqrt(k * k + 4)) / 2);
  for (const Patch& p : set.patches)
    for (float d : p.triangle_delta) EXPECT_NEAR(d, s1, 0.01 * s1);
  // Quality follows: Q_T = (3 - delta) / 2.
  EXPECT_NEAR(set.patches[0].triangle_quality[0], (3 - s1) / 2, 0.01);
}

TEST(PatchesAdvect, VerticesThatLeaveTheSurfaceAreRemoved) {
  // Frame 0: the plane z = 0 over [0, 2] x [0, 1]. Frame 1: the half x > 1
  // has pinched off and dropped by r (a droplet leaving), with no velocity
  // to follow it. A vertex at x > 1 + r/4 is then farther than r/4 from the
  // new surface and must go; every other vertex stays.
  const double r = 0.18;  // r/4 falls between grid lines: no vertex on the threshold
  const TriMesh before = test::plane_grid(80, 40, 2.0, 1.0);
  TriMesh after = test::plane_grid(40, 40, 1.0, 1.0);
  TriMesh drop = test::plane_grid(40, 40, 1.0, 1.0, -r);
  const int base = int(after.positions.size());
  for (const Vec3& p : drop.positions) after.positions.push_back(p + Vec3{1.0, 0, 0});
  for (Tri f : drop.triangles) after.triangles.push_back({f[0] + base, f[1] + base, f[2] + base});
  SurfaceQuery q0(before), q1(after);
  PatchOptions po;
  po.radius = r;
  po.remesh = true;
  PatchSet set;
  // One patch across the cut, one on the part that stays, one on the droplet.
  for (const Vec3& c : {Vec3{1.0, 0.5, 0}, Vec3{0.4, 0.5, 0}, Vec3{1.6, 0.5, 0}}) {
    auto p = create_patch(q0, {c, {0, 0, 1}, -1}, set.next_id++, 0, po, {});
    ASSERT_TRUE(p);
    set.patches.push_back(std::move(*p));
  }
  const PatchSet start = set;
  const VelocityField still = [](const Vec3&) { return Vec3{}; };
  const AdvectStats st = advect_patches(q1, still, still, po, {}, set);
  ASSERT_EQ(set.patches.size(), 2u);  // the droplet's patch is gone
  EXPECT_EQ(st.patches_removed, 1u);
  EXPECT_EQ(set.patches[0].id, 0u);
  EXPECT_EQ(set.patches[1].id, 1u);
  ASSERT_EQ(set.patches[1].positions.size(), start.patches[1].positions.size());  // untouched
  for (std::size_t v = 0; v < start.patches[1].positions.size(); ++v)
    EXPECT_LT(norm(set.patches[1].positions[v] - start.patches[1].positions[v]), 1e-12);
  // The patch across the cut keeps exactly the triangles whose vertices stay
  // (vertices are identified by their rest uv).
  const Patch& a = start.patches[0];
  std::vector<uint8_t> stays(a.positions.size());
  for (std::size_t v = 0; v < stays.size(); ++v) stays[v] = a.positions[v].x <= 1 + r / 4 + 1e-12;
  std::set<std::pair<double, double>> expected;
  for (const Tri& f : a.triangles)
    if (stays[f[0]] && stays[f[1]] && stays[f[2]])
      for (int k = 0; k < 3; ++k) expected.insert({a.rest_uv[f[k]].x, a.rest_uv[f[k]].y});
  const Patch& b = set.patches[0];
  std::set<std::pair<double, double>> got;
  for (const Vec2& uv : b.rest_uv) got.insert({uv.x, uv.y});
  EXPECT_EQ(got, expected);
  for (std::size_t v = 0; v < a.positions.size(); ++v)
    if (expected.count({a.rest_uv[v].x, a.rest_uv[v].y}) && !got.count({a.rest_uv[v].x, a.rest_uv[v].y}))
      ADD_FAILURE() << "lost vertex at " << a.positions[v].x << " " << a.positions[v].y << " " << a.positions[v].z;
  EXPECT_LT(got.size(), a.positions.size());
  for (const Vec3& x : b.positions) {
    EXPECT_LE(x.x, 1.0 + 1e-12);
    EXPECT_LT(brute_force_distance(after, x), 1e-5 * r);
  }
  // The cut is a new border: those vertices weigh 0 unless near the centre.
  int zero = 0;
  for (std::size_t v = 0; v < b.positions.size(); ++v)
    if (b.positions[v].x > 0.999 && norm(b.rest_uv[v] - Vec2{0.5, 0.5}) > 0.125) zero += b.weight[v] == 0;
  EXPECT_GT(zero, 0);
}

// A face the liquid crosses (an outflow or inflow face of a simulation
// domain): the surface stays where it is while the fluid passes through it.
// The velocity's step along the normal is longer than the projection reach.
TEST(PatchesAdvect, ThroughFlowFaceKeepsItsTextureWithTheTangentialStep) {
  const double r = 0.18, dt = 1.0 / 24;  // reach r/4 = 4.5 cm
  const TriMesh plane = test::plane_grid(80, 40, 2.0, 1.0);
  const TriMesh remeshed = test::plane_grid(70, 30, 2.0, 1.0);  // the same face, other vertices
  SurfaceQuery q0(plane), q1(remeshed);
  PatchOptions po;
  po.radius = r;
  const Vec3 velocity{0.3, 0.1, -2.0};  // 8.3 cm a frame into the face, 1.3 cm along it
  const VelocityField v = [&](const Vec3&) { return velocity; };
  PatchSet start;
  auto p = create_patch(q0, {{1.0, 0.5, 0}, {0, 0, 1}, -1}, start.next_id++, 0, po, {});
  ASSERT_TRUE(p);
  start.patches.push_back(std::move(*p));
  AdvectOptions ao;
  ao.dt = dt;
  ASSERT_TRUE(ao.through_flow) << "the default";

  PatchSet kept = start;
  const AdvectStats st = advect_patches(q1, v, v, po, ao, kept);
  EXPECT_EQ(st.vertices_removed, 0u);
  ASSERT_EQ(kept.patches.size(), 1u);
  ASSERT_EQ(kept.patches[0].positions.size(), start.patches[0].positions.size());
  const Vec3 tangential{velocity.x * dt, velocity.y * dt, 0};
  for (std::size_t k = 0; k < start.patches[0].positions.size(); ++k) {
    const Vec3 want = start.patches[0].positions[k] + tangential;
    EXPECT_LT(norm(kept.patches[0].positions[k] - want), 1e-9) << "vertex " << k;
    EXPECT_EQ(kept.patches[0].rest_uv[k].x, start.patches[0].rest_uv[k].x);
  }

  // The paper's rule: every vertex is farther than r/4 from the face, and
  // the patch goes.
  ao.through_flow = false;
  PatchSet removed = start;
  EXPECT_EQ(advect_patches(q1, v, v, po, ao, removed).patches_removed, 1u);
  EXPECT_TRUE(removed.patches.empty());
}

// Patches created on `q` at the given centres (facing +z), ids 0, 1, ...
static PatchSet patches_at(const SurfaceQuery& q, const PatchOptions& po, std::initializer_list<Vec3> centres) {
  PatchSet set;
  for (const Vec3& c : centres)
    if (auto p = create_patch(q, {c, {0, 0, 1}, -1}, set.next_id++, 0, po, {})) set.patches.push_back(std::move(*p));
  return set;
}

// Only a crossing counts: a step that runs along the surface off its edge, or
// a surface that moved away, is left to the other rules (run-off, removal),
// the same with or without this one.
TEST(PatchesAdvect, ThroughFlowLeavesOtherLossesAlone) {
  const double r = 0.18, dt = 1.0 / 24;
  const TriMesh plane = test::plane_grid(50, 50, 1.0, 1.0);
  SurfaceQuery q(plane);
  PatchOptions po;
  po.radius = r;
  const PatchSet start = patches_at(q, po, {{0.9, 0.5, 0}, {0.4, 0.5, 0}});
  ASSERT_EQ(start.patches.size(), 2u);
  AdvectOptions on, off;
  on.dt = off.dt = dt;
  off.through_flow = false;
  // 12.5 cm a frame along the face: the patch at x = 0.9 runs off its edge.
  const VelocityField along = [](const Vec3&) { return Vec3{3.0, 0, 0}; };
  PatchSet a = start, b = start;
  const AdvectStats sa = advect_patches(q, along, along, po, on, a);
  const AdvectStats sb = advect_patches(q, along, along, po, off, b);
  EXPECT_GT(sa.vertices_removed, 0u) << "the edge must cut the first patch, or this shows nothing";
  EXPECT_EQ(sa.vertices_removed, sb.vertices_removed);
  ASSERT_EQ(a.patches.size(), b.patches.size());
  for (std::size_t i = 0; i < a.patches.size(); ++i) EXPECT_EQ(a.patches[i].positions, b.patches[i].positions);

  // The face moved away by r with the fluid standing still: the same.
  const SurfaceQuery away(test::plane_grid(50, 50, 1.0, 1.0, r));
  const VelocityField still = [](const Vec3&) { return Vec3{}; };
  PatchSet c = start;
  EXPECT_EQ(advect_patches(away, still, still, po, on, c).patches_removed, 2u);
}

// Liquid leaving the domain over an open end: the step runs along the
// surface and past its edge (x = 1). With run_off the texture goes over the
// edge with the liquid: a vertex that lands farther than the projection's
// reach (r/4) past the edge, but within r/2 of the surface, keeps exactly its
// advected position off the surface, and the triangles around it stay; the
// next frame it goes on with the flow while it is within r/2. Without it (the
// paper) those vertices and their triangles are removed.
TEST(PatchesAdvect, RunOffCarriesTheTextureOverTheEdge) {
  const double r = 0.18, dt = 1.0 / 24;
  const TriMesh plane = test::plane_grid(50, 50, 1.0, 1.0);
  SurfaceQuery q(plane);
  PatchOptions po;
  po.radius = r;
  const PatchSet start = patches_at(q, po, {{0.9, 0.5, 0}});
  ASSERT_EQ(start.patches.size(), 1u);
  const Vec3 step{0.125, 0, 0};  // 3 m/s: 12.5 cm a frame along the surface
  const VelocityField along = [&](const Vec3&) { return step / dt; };
  AdvectOptions on, off;
  on.dt = off.dt = dt;
  ASSERT_TRUE(on.run_off) << "the default";
  off.run_off = false;
  const Patch& a = start.patches[0];
  auto index_of = [&](const Patch& b) {  // vertices are identified by their rest uv
    std::map<std::pair<double, double>, std::size_t> at;
    for (std::size_t v = 0; v < a.rest_uv.size(); ++v) at[{a.rest_uv[v].x, a.rest_uv[v].y}] = v;
    std::vector<std::size_t> of(b.rest_uv.size());
    for (std::size_t v = 0; v < b.rest_uv.size(); ++v) of[v] = at.at({b.rest_uv[v].x, b.rest_uv[v].y});
    return of;
  };
  auto tris_of = [&](const Patch& b) {
    const std::vector<std::size_t> of = index_of(b);
    std::set<std::array<std::size_t, 3>> t;
    for (const Tri& f : b.triangles) t.insert({of[f[0]], of[f[1]], of[f[2]]});
    return t;
  };

  PatchSet carried = start;
  advect_patches(q, along, along, po, on, carried);
  ASSERT_EQ(carried.patches.size(), 1u);
  const Patch& b = carried.patches[0];
  const std::vector<std::size_t> of = index_of(b);
  std::size_t past = 0;
  for (std::size_t v = 0; v < of.size(); ++v) {
    const Vec3 want = a.positions[of[v]] + step;
    if (b.surface_triangle[v] < 0) {
      ++past;
      EXPECT_EQ(b.positions[v].x, want.x) << "vertex " << v;
      EXPECT_EQ(b.positions[v].y, want.y);
      EXPECT_GT(want.x, 1.0 + r / 4);
      EXPECT_LE(want.x, 1.0 + r / 2 + 1e-12);
    } else {
      EXPECT_LE(b.positions[v].x, 1.0 + 1e-12);
    }
  }
  EXPECT_GT(past, 10u) << "vertices must run past the edge, or this test shows nothing";
  // Every triangle whose vertices all land within r/2 of the surface stays.
  const auto kept = tris_of(b);
  std::size_t beyond_reach = 0;
  for (const Tri& f : a.triangles) {
    double hi = -1e300;
    for (int k = 0; k < 3; ++k) hi = std::max(hi, a.positions[f[k]].x + step.x);
    const bool within = hi <= 1.0 + r / 2 - 1e-9;
    EXPECT_EQ(kept.count({std::size_t(f[0]), std::size_t(f[1]), std::size_t(f[2])}) == 1, within);
    beyond_reach += hi > 1.0 + r / 2 + 1e-9;
  }
  EXPECT_GT(beyond_reach, 0u);

  // The next frame, slower: the vertices past the edge go on exactly with the
  // flow while they are within r/2 of the surface, and are removed beyond.
  const Vec3 slow{0.02, 0, 0};
  const VelocityField on_ = [&](const Vec3&) { return slow / dt; };
  PatchSet next = carried;
  advect_patches(q, on_, on_, po, on, next);
  ASSERT_EQ(next.patches.size(), 1u);
  const Patch& c = next.patches[0];
  const std::vector<std::size_t> of2 = index_of(c);
  std::size_t went_on = 0;
  for (std::size_t v = 0; v < of2.size(); ++v)
    if (c.surface_triangle[v] < 0) {
      ++went_on;
      EXPECT_EQ(c.positions[v].x, a.positions[of2[v]].x + step.x + slow.x);
      EXPECT_LE(c.positions[v].x, 1.0 + r / 2 + 1e-12);
    }
  EXPECT_GT(went_on, 0u);
  EXPECT_LT(went_on, past) << "some must have gone beyond r/2";

  // The paper's rule: nothing off the surface, and fewer triangles.
  PatchSet cut = start;
  advect_patches(q, along, along, po, off, cut);
  ASSERT_EQ(cut.patches.size(), 1u);
  for (std::size_t v = 0; v < cut.patches[0].positions.size(); ++v) {
    EXPECT_GE(cut.patches[0].surface_triangle[v], 0);
    EXPECT_LE(cut.patches[0].positions[v].x, 1.0 + 1e-12);
  }
  const auto kept_off = tris_of(cut.patches[0]);
  EXPECT_LT(kept_off.size(), kept.size());
  for (const auto& t : kept_off) EXPECT_TRUE(kept.count(t)) << "run-off keeps every triangle the paper keeps";
}

TEST(PatchesWeights, FoldedTriangleHasZeroQuality) {
  const TriMesh plane = test::plane_grid(20, 20, 1.0, 1.0);
  SurfaceQuery q(plane);
  PatchOptions po;
  po.radius = 0.2;
  po.remesh = false;
  auto p = create_patch(q, {{0.5, 0.5, 0}, {0, 0, 1}, -1}, 0, 0, po, {});
  ASSERT_TRUE(p);
  for (float w : p->triangle_quality) EXPECT_NEAR(w, 1.0, 1e-6);
  // Reverse one triangle in 3D: it now faces against the fluid.
  std::swap(p->positions[p->triangles[0][1]], p->positions[p->triangles[0][2]]);
  patch_weights(plane, po.radius, {}, *p);
  EXPECT_EQ(p->triangle_quality[0], 0.f);
  EXPECT_FALSE(std::isfinite(p->triangle_delta[0]));
}

TEST(PatchesAdvect, StillnessIsBitForBit) {
  const TriMesh sphere = test::icosphere(4, 1.0);
  SurfaceQuery q(sphere);
  PatchOptions po;
  po.radius = 0.3;
  PatchSet set;
  seed_patches(q, 0, po, {}, {}, set);
  const VelocityField still = [](const Vec3&) { return Vec3{}; };
  PatchSet moved = set;
  for (int f = 0; f < 3; ++f) {
    advect_patches(q, still, still, po, {}, moved);
    update_weights(q.mesh(), po.radius, {}, moved);
  }
  ASSERT_EQ(moved.patches.size(), set.patches.size());
  for (std::size_t i = 0; i < set.patches.size(); ++i) {
    EXPECT_EQ(moved.patches[i].positions, set.patches[i].positions);
    EXPECT_EQ(moved.patches[i].weight, set.patches[i].weight);
    EXPECT_EQ(moved.patches[i].triangles, set.patches[i].triangles);
  }
}

namespace {

// The rigid sphere with per-vertex velocities (the exact rigid field at the
// vertices), advected with vertex_velocity_field; `wrap` hides the field's
// VertexVelocity behind a lambda so advection must search every sample.
RigidRun run_rigid_vertex_velocity(int frames, const PatchOptions& po, bool wrap) {
  RigidSphere s;
  RigidRun run;
  auto with_velocity = [&](int f) {
    auto m = std::make_unique<TriMesh>(s.mesh(f));
    const VelocityField v = s.velocity(f / 24.0);
    for (const Vec3& p : m->positions) m->velocities.push_back(v(p));
    return m;
  };
  auto mesh = with_velocity(0);
  auto query = std::make_unique<SurfaceQuery>(*mesh);
  seed_patches(*query, 0, po, {}, {}, run.patches);
  AdvectOptions ao;
  ao.dt = 1.0 / 24;
  for (int f = 1; f <= frames; ++f) {
    auto next_mesh = with_velocity(f);
    auto next_query = std::make_unique<SurfaceQuery>(*next_mesh);
    VelocityField prev = vertex_velocity_field(*query), next = vertex_velocity_field(*next_query);
    EXPECT_NE(prev.target<VertexVelocity>(), nullptr);
    if (wrap) {
      prev = [p = prev](const Vec3& x) { return p(x); };
      next = [n = next](const Vec3& x) { return n(x); };
    }
    const AdvectStats st = advect_patches(*next_query, prev, next, po, ao, run.patches);
    update_weights(next_query->mesh(), po.radius, {}, run.patches);
    run.removed += st.vertices_removed;
    run.max_residual = std::max(run.max_residual, st.max_residual);
    query = std::move(next_query);
    mesh = std::move(next_mesh);
  }
  return run;
}

}  // namespace

TEST(PatchesAdvect, VertexVelocityOnTheKnownTriangleMatchesTheSearch) {
  // Advection reads a patch vertex's frame f-1 velocity on the triangle it
  // was projected onto instead of searching for the closest point: the
  // vertex lies on that triangle (up to rounding), so both are the velocity
  // at the same surface point and the patches must agree to rounding.
  PatchOptions po;
  po.radius = 0.4;
  const RigidRun searched = run_rigid_vertex_velocity(3, po, true);
  set_thread_count(1);
  const RigidRun one = run_rigid_vertex_velocity(3, po, false);
  set_thread_count(2);
  const RigidRun two = run_rigid_vertex_velocity(3, po, false);
  set_thread_count(0);
  ASSERT_EQ(searched.patches.patches.size(), one.patches.patches.size());
  ASSERT_EQ(one.patches.patches.size(), two.patches.patches.size());
  double worst = 0;
  for (std::size_t i = 0; i < one.patches.patches.size(); ++i) {
    const Patch &a = searched.patches.patches[i], &b = one.patches.patches[i], &c = two.patches.patches[i];
    ASSERT_EQ(a.positions.size(), b.positions.size());
    EXPECT_EQ(a.triangles, b.triangles);
    for (std::size_t v = 0; v < a.positions.size(); ++v) worst = std::max(worst, norm(a.positions[v] - b.positions[v]));
    EXPECT_EQ(b.positions, c.positions) << "same result for 1 and 2 threads";
    EXPECT_EQ(b.weight, c.weight);
  }
  EXPECT_LT(worst, 1e-9 * po.radius);
  EXPECT_LT(one.max_residual, 1e-5 * po.radius);
}

TEST(VertexVelocity, OnTriangleAnswersOnlyForPointsOfThatTriangle) {
  TriMesh m = test::plane_grid(4, 4, 1.0, 1.0);
  for (const Vec3& p : m.positions) m.velocities.push_back({2 * p.x - p.y, 0.5 + p.y, 3 * p.x});
  const SurfaceQuery q(m);
  const VertexVelocity field(q);
  const Vec3 p{0.3, 0.55, 0.0};
  const ClosestHit hit = q.closest(p, INFINITY);
  ASSERT_TRUE(hit.found);
  Vec3 v;
  ASSERT_TRUE(field.on_triangle(p, hit.triangle, 1e-12, v));
  EXPECT_LT(norm(v - field(p)), 1e-12);
  EXPECT_LT(norm(v - Vec3{2 * 0.3 - 0.55, 0.5 + 0.55, 0.9}), 1e-12);  // affine: exact
  EXPECT_FALSE(field.on_triangle(p + Vec3{0, 0, 1e-6}, hit.triangle, 1e-9, v)) << "off the surface";
  const int other = hit.triangle == 0 ? int(m.triangles.size()) - 1 : 0;
  EXPECT_FALSE(field.on_triangle(p, other, 1e-9, v)) << "a far triangle";
  EXPECT_FALSE(field.on_triangle(p, -1, 1e-9, v));
  EXPECT_FALSE(field.on_triangle(p, int(m.triangles.size()), 1e-9, v));
}
