// ALGORITHM.md step 4: advect every patch vertex and centre from frame f-1 to
// frame f, project onto frame f's surface, drop what left it.
//
// Integrator: explicit trapezoidal RK2 (Heun), second order like the midpoint
// rule. With velocities known only at the two frame times, the midpoint rule
// needs v(x, t + h/2) = average of both fields at the midpoint (two closest-
// point queries for vertex velocities) while Heun needs v_prev at x and v_next
// at the Euler end point (one each).
//
// Sub-steps (velocity linear in time between the frames): the first full step
// gives k1 and k2 for free, and from them how far the step reaches (|v| dt
// against r) and how much the velocity turns along it. Heun is exact for a
// velocity linear in time along the path (translation, constant acceleration,
// linear shear); its error is in the turn, about turn^3 / 6 of the radius of
// the path per step. Sub-stepping on the turn instead of the speed keeps fast
// but straight flows (most of a splash) at one step per frame.
#include <algorithm>
#include <cmath>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "patches/internal.hpp"

namespace lapflow {
namespace {

constexpr int kMaxSubsteps = 64;
constexpr double kNearFraction = 1.0 / 16;  // first projection radius, as a fraction of max_projection * r
// Run-off (AdvectOptions::run_off): how far from the surface a vertex past its
// edge is kept, as a fraction of r (docs/temporal.md, "Run-off edges": 0.25
// is the projection's reach and keeps nothing; 1 pops a little less on
// channel but lets p99 distortion over 3 on three frames).
constexpr double kRunOffReach = 0.5;

struct Moved {
  Vec3 position;
  int32_t triangle = -1;
  bool kept = false;
  bool still = false;  ///< the velocity did not move it (before projection)
};

}  // namespace

AdvectStats advect_patches(const SurfaceQuery& next, const VelocityField& v_prev, const VelocityField& v_next,
                           const PatchOptions& patch_options, const AdvectOptions& options, PatchSet& patches) {
  AdvectStats stats;
  const double r = patch_options.radius, dt = options.dt;
  const double max_proj = options.max_projection * r;
  const double run_off_reach = options.run_off ? kRunOffReach * r : 0.0;
  const std::size_t np = patches.patches.size();
  // Vertices of all patches, then one centre per patch, in one index space.
  std::vector<std::size_t> offset(np + 1, 0);
  for (std::size_t i = 0; i < np; ++i) offset[i + 1] = offset[i] + patches.patches[i].positions.size();
  const std::size_t nverts = offset[np];
  std::vector<Moved> moved(nverts + np);

  auto velocity = [&](const Vec3& x, double s) {  // s in [0, dt]
    if (s <= 0) return v_prev(x);
    if (s >= dt) return v_next(x);
    const double a = s / dt;
    return v_prev(x) * (1 - a) + v_next(x) * a;
  };
  // Per-vertex velocities: a patch vertex lies on the triangle of frame f-1
  // it was projected onto (surface_triangle), so its velocity there needs
  // no closest-point search (one search of three per vertex). The tolerance
  // only accepts points on that triangle up to rounding.
  const VertexVelocity* prev_vertex = v_prev.target<VertexVelocity>();
  const double on_surface = 1e-9 * r;
  const double cos_max_turn = std::cos(options.max_turn);
  auto advect = [&](const Vec3& x0, int32_t prev_triangle) {
    Vec3 k1;
    if (!(prev_vertex && prev_vertex->on_triangle(x0, prev_triangle, on_surface, k1))) k1 = v_prev(x0);
    const Vec3 k2 = v_next(x0 + k1 * dt);
    const double s1 = norm(k1), s2 = norm(k2);
    const double reach = std::max(s1, s2) * dt / (options.max_step_fraction * r);
    const double cos_turn = s1 > 0 && s2 > 0 ? std::clamp(dot(k1, k2) / (s1 * s2), -1.0, 1.0) : 1.0;
    // acos only when the turn may exceed max_turn (the margin keeps the
    // decision the same as comparing acos itself); a smooth flow skips it.
    const double turn = cos_turn > cos_max_turn + 1e-12 ? 0.0 : std::acos(cos_turn);
    // Heun's error over a step of length L that turns by `turn` is about
    // turn^2 L / 6 (turn^3 / 6 of the path's radius L / turn), and n
    // sub-steps divide it by n^2: a step shorter than r / 4 needs fewer of
    // them for the same error, max_turn^2 r / 24 (r / 9600) a frame; longer
    // steps keep the plain turn rule (a vortex adds its error up frame after
    // frame). So a vertex that creeps a fraction of a millimetre in a noisy
    // direction (most of a splash's slow surface) does not take up to
    // kMaxSubsteps sub-steps for it.
    const double length = std::max(s1, s2) * dt;
    const double turn_need = turn / options.max_turn * std::min(1.0, std::sqrt(4 * length / r));
    const double need = std::max(reach, turn_need);
    if (!(need > 1)) return x0 + (k1 + k2) * (0.5 * dt);  // also NaN: the vertex is dropped later
    const int n = std::min(int(std::ceil(need)), kMaxSubsteps);
    const double h = dt / n;
    Vec3 x = x0;
    for (int i = 0; i < n; ++i) {
      const Vec3 a = i == 0 ? k1 : velocity(x, i * h);
      const Vec3 b = velocity(x + a * h, (i + 1) * h);
      x += (a + b) * (0.5 * h);
    }
    return x;
  };
  // The point a vertex at `from` lands on: a point already on the surface
  // stays bit for bit (stillness: zero velocity on an unchanged mesh must
  // not let rounding creep).
  auto settle = [&](ClosestHit h, const Vec3& from) {
    if (h.distance <= on_surface) h.point = from;
    return h;
  };
  // A vertex whose step leaves the surface (farther than max_proj) while the
  // surface is still where the vertex was. Along the surface's normal, the
  // liquid crosses its surface there (an outflow or inflow face, or a
  // velocity the mesh does not follow): that part of the step cannot be
  // followed, so with `through_flow` the vertex takes its tangential part, or
  // stays where it was when that slides off the surface too. Along the
  // surface, the step ran off its edge with the liquid (an open end of the
  // domain): with `run_off` the vertex keeps its advected position, off the
  // surface, if that is within run_off_reach of it (`off_edge`). Otherwise, or
  // when the surface moved away, found = false: the vertex is removed.
  const TriMesh& next_mesh = next.mesh();
  // run_off: a vertex off the surface goes on while the surface is within
  // run_off_reach of it.
  auto near_edge = [&](const Vec3& x) { return run_off_reach > 0 && next.closest(x, run_off_reach).found; };
  auto leave = [&](const Vec3& x0, const Vec3& x, bool& off_edge) {
    off_edge = false;
    const ClosestHit here = settle(next.closest(x0, max_proj), x0);
    if (!(here.found && here.distance <= max_proj)) return ClosestHit{};
    const Vec3 n2 = triangle_normal_area2(next_mesh, here.triangle);
    const double l = norm(n2);
    if (!(l > 0)) return ClosestHit{};
    const Vec3 n = n2 / l, step = x - x0;
    const double along_normal = dot(step, n);
    if (!(std::abs(along_normal) > max_proj)) {
      off_edge = near_edge(x);
      return ClosestHit{};
    }
    if (!options.through_flow) return ClosestHit{};
    const Vec3 to = here.point + (step - n * along_normal);
    const ClosestHit slid = settle(next.closest(to, max_proj), to);
    return slid.found && slid.distance <= max_proj ? slid : here;
  };
  parallel_for(nverts + np, [&](std::size_t b, std::size_t e) {
    std::size_t p = std::upper_bound(offset.begin(), offset.end(), std::min(b, nverts)) - offset.begin() - 1;
    for (std::size_t i = b; i < e; ++i) {
      Vec3 x;
      int32_t prev_triangle = -1;
      if (i < nverts) {
        while (offset[p + 1] <= i) ++p;
        const Patch& patch = patches.patches[p];
        x = patch.positions[i - offset[p]];
        if (patch.surface_triangle.size() == patch.positions.size()) prev_triangle = patch.surface_triangle[i - offset[p]];
      } else {
        x = patches.patches[i - nverts].center;
      }
      const Vec3 x0 = x;
      // Past the surface's edge since an earlier frame (run_off).
      const bool was_off = i < nverts && prev_triangle < 0 &&
                           patches.patches[p].surface_triangle.size() == patches.patches[p].positions.size();
      x = advect(x, prev_triangle);
      Moved& m = moved[i];
      m.position = x;
      m.still = x.x == x0.x && x.y == x0.y && x.z == x0.z;
      if (!is_finite(x)) continue;
      // Most advected points are within a small fraction of r of the new
      // surface: a small query radius lets Embree prune far more of its tree.
      // The closest point within the small radius, when there is one, is the
      // closest point within max_proj too, so the answer is the same.
      ClosestHit hit = next.closest(x, kNearFraction * max_proj);
      if (!hit.found) hit = next.closest(x, max_proj);
      hit = settle(hit, x);
      bool off_edge = false;
      if (!(hit.found && hit.distance <= max_proj) && i < nverts) {
        if (was_off)  // past the edge since an earlier frame
          off_edge = near_edge(x);
        else if (options.through_flow || run_off_reach > 0)
          hit = leave(x0, x, off_edge);
      }
      if (off_edge) {
        m.kept = true;  // at its advected position, off the surface (triangle -1)
      } else if (hit.found && hit.distance <= max_proj) {
        m.position = hit.point;
        m.triangle = hit.triangle;
        m.kept = true;
      }
    }
  }, 512);

  struct PatchStats {
    std::size_t removed_v = 0, removed_t = 0;
    double residual = 0;
  };
  std::vector<PatchStats> per_patch(np);
  const TriMesh& mesh = next.mesh();
  parallel_for(np, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      Patch& patch = patches.patches[i];
      const Moved* mv = moved.data() + offset[i];
      const std::size_t n = patch.positions.size();
      patch.at_rest = std::all_of(mv, mv + n, [](const Moved& m) { return m.still; });
      // A centre that left the surface keeps its advected position: it only
      // marks where the patch was born.
      const Moved& c = moved[nverts + i];
      if (is_finite(c.position)) patch.center = c.position;

      auto residual = [&](std::size_t v) {
        if (mv[v].triangle < 0) return 0.0;  // off the surface's edge
        const Tri& f = mesh.triangles[mv[v].triangle];
        const Vec3& a = mesh.positions[f[0]];
        return norm(closest_point_on_triangle(mv[v].position, a, mesh.positions[f[1]], mesh.positions[f[2]]).point -
                    mv[v].position);
      };
      std::vector<uint8_t> used(n, 0);
      std::size_t kept_triangles = 0;
      for (const Tri& f : patch.triangles)
        if (mv[f[0]].kept && mv[f[1]].kept && mv[f[2]].kept) {
          ++kept_triangles;
          used[f[0]] = used[f[1]] = used[f[2]] = 1;
        }
      per_patch[i].removed_t = patch.triangles.size() - kept_triangles;
      if (kept_triangles == patch.triangles.size() && std::find(used.begin(), used.end(), 0) == used.end()) {
        // Nothing removed (the common case): move the vertices in place.
        patch.surface_triangle.resize(n);
        for (std::size_t v = 0; v < n; ++v) {
          patch.positions[v] = mv[v].position;
          patch.surface_triangle[v] = mv[v].triangle;
          per_patch[i].residual = std::max(per_patch[i].residual, residual(v));
        }
      } else {
        std::vector<Tri> tris;
        tris.reserve(kept_triangles);
        for (const Tri& f : patch.triangles)
          if (mv[f[0]].kept && mv[f[1]].kept && mv[f[2]].kept) tris.push_back(f);
        std::vector<int32_t> remap(n, -1);
        std::vector<Vec3> pos;
        std::vector<Vec2> uv;
        std::vector<int32_t> st;
        std::vector<float> w;  // the weights follow their vertices (WeightOptions::keep_at_rest)
        const bool has_weights = patch.weight.size() == n;
        pos.reserve(n), uv.reserve(n), st.reserve(n);
        for (std::size_t v = 0; v < n; ++v) {
          if (!used[v]) continue;
          remap[v] = int32_t(pos.size());
          pos.push_back(mv[v].position);
          uv.push_back(patch.rest_uv[v]);
          if (has_weights) w.push_back(patch.weight[v]);
          st.push_back(mv[v].triangle);
          per_patch[i].residual = std::max(per_patch[i].residual, residual(v));
        }
        per_patch[i].removed_v = n - pos.size();
        for (Tri& f : tris)
          for (int k = 0; k < 3; ++k) f[k] = remap[f[k]];
        patch.positions = std::move(pos);
        patch.rest_uv = std::move(uv);
        patch.surface_triangle = std::move(st);
        patch.triangles = std::move(tris);
        if (has_weights) patch.weight = std::move(w);
      }
    }
  }, 8);

  stats.vertices_moved = nverts;
  for (const PatchStats& s : per_patch) {
    stats.vertices_removed += s.removed_v;
    stats.triangles_removed += s.removed_t;
    stats.max_residual = std::max(stats.max_residual, s.residual);
  }
  auto& list = patches.patches;
  const std::size_t before = list.size();
  list.erase(std::remove_if(list.begin(), list.end(), [](const Patch& p) { return !p.alive(); }), list.end());
  stats.patches_removed = before - list.size();
  return stats;
}

}  // namespace lapflow
