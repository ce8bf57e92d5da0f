// ALGORITHM.md step 5: per-triangle distortion and quality, per-vertex border
// factor and weight of one patch.
#include <algorithm>
#include <cmath>
#include <limits>

#include "lapflow/core/parallel.hpp"
#include "lapflow/patches/patches.hpp"
#include "patches/internal.hpp"

namespace lapflow {
namespace detail {

double triangle_distortion(const Vec2& u0, const Vec2& u1, const Vec2& u2, const Vec3& p0, const Vec3& p1,
                           const Vec3& p2, double scale, double* s1_out, double* s2_out) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const Vec2 d1 = (u1 - u0) * scale, d2 = (u2 - u0) * scale;
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const double det = cross(d1, d2);
  // A uv triangle that is flat or reversed has no meaningful distortion.
  if (!(det > 1e-30 * (dot(d1, d1) + dot(d2, d2)))) {
    if (s1_out) *s1_out = kInf;
    if (s2_out) *s2_out = 0;
    return kInf;
  }
  // J = [e1 e2] [d1 d2]^-1, a 3x2 matrix; its singular values are the square
  // roots of the eigenvalues of the 2x2 Gram matrix J^T J.
  const Vec3 jx = (e1 * d2.y - e2 * d1.y) / det;
  const Vec3 jy = (e2 * d1.x - e1 * d2.x) / det;
  return delta_from_gram(dot(jx, jx), dot(jx, jy), dot(jy, jy), s1_out, s2_out);
}

double delta_from_gram(double a, double b, double c, double* s1_out, double* s2_out) {
  const double mean = 0.5 * (a + c), dev = std::sqrt(0.25 * (a - c) * (a - c) + b * b);
  const double s1 = std::sqrt(mean + dev), s2 = std::sqrt(std::max(mean - dev, 0.0));
  if (s1_out) *s1_out = s1;
  if (s2_out) *s2_out = s2;
  if (!(s2 > 0)) return std::numeric_limits<double>::infinity();
  return std::max(s1, 1.0 / s2);
}

}  // namespace detail

void patch_weights(const TriMesh& surface, double radius, const WeightOptions& options, Patch& patch) {
  const std::size_t nv = patch.positions.size(), nt = patch.triangles.size();
  patch.triangle_delta.assign(nt, 0.f);
  patch.triangle_quality.assign(nt, 0.f);
  const double scale = 2 * radius;
  const double denom = options.delta_max - 1;
  // Unit normal of the fluid triangle under each vertex, once per vertex
  // (each vertex is shared by about six patch triangles).
  std::vector<Vec3> fluid_normal;
  if (!patch.surface_triangle.empty()) {
    fluid_normal.resize(nv);
    for (std::size_t v = 0; v < nv; ++v) {
      const int32_t t = patch.surface_triangle[v];
      if (t >= 0 && std::size_t(t) < surface.triangles.size()) fluid_normal[v] = normalized(triangle_normal_area2(surface, t));
    }
  }
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& f = patch.triangles[t];
    double delta = detail::triangle_distortion(patch.rest_uv[f[0]], patch.rest_uv[f[1]], patch.rest_uv[f[2]],
                                               patch.positions[f[0]], patch.positions[f[1]],
                                               patch.positions[f[2]], scale);
    // Folded: the patch triangle faces against the fluid it lies on.
    if (!patch.surface_triangle.empty()) {
      Vec3 under;
      for (int k = 0; k < 3; ++k) under += fluid_normal[f[k]];
      const Vec3 n = cross(patch.positions[f[1]] - patch.positions[f[0]], patch.positions[f[2]] - patch.positions[f[0]]);
      if (norm2(under) > 0 && dot(n, under) <= 0) delta = std::numeric_limits<double>::infinity();
    }
    patch.triangle_delta[t] = float(delta);
    const double q = std::isfinite(delta) ? std::max((options.delta_max - delta) / denom, 0.0) : 0.0;
    patch.triangle_quality[t] = float(std::min(q, 1.0));
  }

  // Q_V: mean of incident Q_T (accumulated in triangle order: deterministic).
  std::vector<double> sum(nv, 0.0);
  std::vector<int> count(nv, 0);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      sum[patch.triangles[t][k]] += patch.triangle_quality[t];
      ++count[patch.triangles[t][k]];
    }

  // Boundary vertices: ends of edges used by one triangle. Edges are grouped
  // by their lower vertex (a counting sort: a patch vertex has a handful of
  // edges) and counted within each group; sorting all 3 * nt edge keys cost
  // about as much as the rest of the weights.
  std::vector<int32_t> first(nv + 1, 0);
  for (const Tri& f : patch.triangles)
    for (int k = 0; k < 3; ++k) ++first[std::min(f[k], f[(k + 1) % 3]) + 1];
  for (std::size_t v = 0; v < nv; ++v) first[v + 1] += first[v];
  std::vector<int32_t> upper(3 * nt), fill(first.begin(), first.end() - 1);
  for (const Tri& f : patch.triangles)
    for (int k = 0; k < 3; ++k) upper[fill[std::min(f[k], f[(k + 1) % 3])]++] = std::max(f[k], f[(k + 1) % 3]);
  std::vector<uint8_t> on_boundary(nv, 0);
  for (std::size_t a = 0; a < nv; ++a)
    for (int32_t i = first[a]; i < first[a + 1]; ++i) {
      int uses = 0;
      for (int32_t j = first[a]; j < first[a + 1]; ++j) uses += upper[j] == upper[i];
      if (uses == 1) on_boundary[a] = on_boundary[upper[i]] = 1;
    }

  const bool keep = options.keep_at_rest && patch.at_rest && patch.weight.size() == nv;
  patch.quality.assign(nv, 0.f);
  patch.border.assign(nv, 0);
  if (!keep) patch.weight.assign(nv, 0.f);
  const Vec2 centre{0.5, 0.5};
  for (std::size_t v = 0; v < nv; ++v) {
    patch.quality[v] = count[v] ? float(sum[v] / count[v]) : 0.f;
    const bool near_centre = norm(patch.rest_uv[v] - centre) <= options.center_radius;
    patch.border[v] = (!on_boundary[v] || near_centre) ? 1 : 0;
    // At rest a vertex keeps its weight, but a border it gained (a triangle
    // lost to projection) still zeroes it.
    if (!keep) patch.weight[v] = patch.quality[v] * float(patch.border[v]);
    else if (!patch.border[v]) patch.weight[v] = 0.f;
  }
}

void update_weights(const TriMesh& surface, double radius, const WeightOptions& options, PatchSet& patches) {
  parallel_for(patches.patches.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) patch_weights(surface, radius, options, patches.patches[i]);
  }, 8);
}

}  // namespace lapflow
