// LSCM of every atlas chart (Levy et al. 2002) with the shared solver of
// surface/lscm.hpp: two pinned vertices at the ends of the chart's longest
// side. Charts that flip a triangle or stretch too much are split and redone,
// never dropped.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "atlas/internal.hpp"
#include "lapflow/core/parallel.hpp"
#include "surface/lscm.hpp"

namespace lapflow::atlas_detail {
namespace {

/// Largest share of a chart's area allowed outside the density band: the
/// atlas must keep 95% of the surface in the band, so charts keep 98%.
constexpr double kMaxOutsideShare = 0.02;
/// Largest share of a chart's uv area allowed outside the density band.
constexpr double kMaxOutsideUvShare = 0.05;

/// LSCM of one chart; writes 3 uv per triangle of `tris` (chart-local,
/// density-normalised) into corner_uv. Returns false when the chart must be
/// split; `force` writes the best result anyway (a chart that cannot split).
bool flatten_one(const TriMesh& mesh, const TriangleInfo& info, const std::vector<int32_t>& tris,
                 double max_stretch, bool force, std::vector<Vec2>& corner_uv) {
  std::vector<int32_t> verts;
  verts.reserve(tris.size() * 3);
  for (int32_t t : tris)
    if (!info.degenerate[t])
      for (int k = 0; k < 3; ++k) verts.push_back(mesh.triangles[t][k]);
  std::sort(verts.begin(), verts.end());
  verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
  const int nv = int(verts.size());
  auto local = [&](int32_t v) { return int(std::lower_bound(verts.begin(), verts.end(), v) - verts.begin()); };

  std::vector<Vec2> uv(nv);
  if (nv >= 3) {
    // Pins: the extreme vertices along the longest side of the chart's box.
    Box3 box;
    for (int32_t v : verts) box.extend(mesh.positions[v]);
    const Vec3 size = box.size();
    const int axis = size.x >= size.y && size.x >= size.z ? 0 : (size.y >= size.z ? 1 : 2);
    int pa = 0, pb = 0;
    for (int i = 1; i < nv; ++i) {
      if (mesh.positions[verts[i]][axis] < mesh.positions[verts[pa]][axis]) pa = i;
      if (mesh.positions[verts[i]][axis] > mesh.positions[verts[pb]][axis]) pb = i;
    }
    if (pa == pb) return true;  // cannot happen with a proper triangle; keep the point
    // The chart on its own: its vertices renumbered, its proper triangles
    // (degenerate ones ask nothing of the map).
    std::vector<Vec3> positions(nv);
    for (int i = 0; i < nv; ++i) positions[i] = mesh.positions[verts[i]];
    std::vector<Tri> local_tris;
    local_tris.reserve(tris.size());
    for (int32_t t : tris)
      if (!info.degenerate[t]) {
        const Tri& f = mesh.triangles[t];
        local_tris.push_back({local(f[0]), local(f[1]), local(f[2])});
      }
    const Vec2 uv_a{0, 0}, uv_b{norm(positions[pb] - positions[pa]), 0};
    if (!detail::lscm_flatten(positions, local_tris, uv, pa, pb, uv_a, uv_b)) {
      if (!force) return false;
      // Singular: only the pins have a place; the checks below see the
      // collapsed triangles.
      uv.assign(nv, Vec2{});
      uv[pa] = uv_a, uv[pb] = uv_b;
    }
  }

  // Check flips and the spread of sqrt(area3D / areaUV), then normalise so the
  // chart's area-weighted mean density is 1 (uv in metres).
  double sum_a = 0, sum_as = 0;
  std::vector<double> dens(tris.size(), 0);
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const int32_t t = tris[i];
    if (info.degenerate[t]) continue;
    const Tri& f = mesh.triangles[t];
    const Vec2 a = uv[local(f[0])], b = uv[local(f[1])], c = uv[local(f[2])];
    const double auv = 0.5 * cross(b - a, c - a);
    if (!(auv > 1e-14 * info.area[t])) {
      if (!force) return false;  // flipped or collapsed
      continue;
    }
    dens[i] = std::sqrt(info.area[t] / auv);
    sum_a += info.area[t];
    sum_as += info.area[t] * dens[i];
  }
  const double mean = sum_a > 0 ? sum_as / sum_a : 1.0;
  // Shares outside the band, by surface area and by atlas (uv) area: a
  // sliver blown up in uv is tiny on the surface but wastes the atlas.
  double outside = 0, outside_uv = 0, sum_uv = 0;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    if (info.degenerate[tris[i]] || dens[i] <= 0) continue;
    const double d = dens[i] / mean;
    const double auv = info.area[tris[i]] / (dens[i] * dens[i]);
    sum_uv += auv;
    if (d < 1.0 / max_stretch || d > max_stretch) outside += info.area[tris[i]], outside_uv += auv;
  }
  if ((outside > kMaxOutsideShare * sum_a || outside_uv > kMaxOutsideUvShare * sum_uv) && !force) return false;

  Vec2 centre{};
  for (const Vec2& p : uv) centre += p;
  if (nv > 0) centre = centre / double(nv);
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const int32_t t = tris[i];
    const Tri& f = mesh.triangles[t];
    for (int k = 0; k < 3; ++k) {
      Vec2 p = centre;
      if (info.degenerate[t]) {
        // Collapse onto the first vertex that has a uv in this chart.
        for (int j = 0; j < 3; ++j)
          if (std::binary_search(verts.begin(), verts.end(), f[j])) {
            p = uv[local(f[j])];
            break;
          }
      } else {
        p = uv[local(f[k])];
      }
      corner_uv[3 * std::size_t(t) + k] = (p - centre) * mean;
    }
  }
  return true;
}

/// Unit direction of the long side of the minimum-area rectangle around `pts`.
Vec2 long_side(const std::vector<Vec2>& pts) {
  const std::vector<Vec2> hull = convex_hull(pts);
  if (hull.size() < 3) return hull.size() == 2 && norm(hull[1] - hull[0]) > 0 ? (hull[1] - hull[0]) / norm(hull[1] - hull[0]) : Vec2{1, 0};
  double best = INFINITY;
  Vec2 dir{1, 0};
  for (std::size_t i = 0; i < hull.size(); ++i) {
    const Vec2 e = hull[(i + 1) % hull.size()] - hull[i];
    const double l = norm(e);
    if (!(l > 0)) continue;
    const Vec2 u = e / l, v{-u.y, u.x};
    double ulo = INFINITY, uhi = -INFINITY, vlo = INFINITY, vhi = -INFINITY;
    for (const Vec2& p : hull) {
      ulo = std::min(ulo, dot(p, u)), uhi = std::max(uhi, dot(p, u));
      vlo = std::min(vlo, dot(p, v)), vhi = std::max(vhi, dot(p, v));
    }
    const double area = (uhi - ulo) * (vhi - vlo);
    if (area < best * (1 - 1e-12)) best = area, dir = (uhi - ulo) >= (vhi - vlo) ? u : v;
  }
  return dir;
}

/// Length of the long side of the minimum-area rectangle around a chart's uv.
double uv_length(const std::vector<int32_t>& tris, const std::vector<Vec2>& corner_uv) {
  std::vector<Vec2> pts;
  pts.reserve(3 * tris.size());
  for (int32_t t : tris)
    for (int k = 0; k < 3; ++k) pts.push_back(corner_uv[3 * std::size_t(t) + k]);
  const Vec2 u = long_side(pts), v{-u.y, u.x};
  double lo = INFINITY, hi = -INFINITY, vlo = INFINITY, vhi = -INFINITY;
  for (const Vec2& p : pts) lo = std::min(lo, dot(p, u)), hi = std::max(hi, dot(p, u)), vlo = std::min(vlo, dot(p, v)), vhi = std::max(vhi, dot(p, v));
  return pts.empty() ? 0 : std::max(hi - lo, vhi - vlo);
}

/// Splits a chart at the median of its triangles along the long side of
/// their minimum-area rectangle in the chart's best-fit plane, then into
/// edge-connected parts. Degenerate triangles follow a proper
/// triangle sharing a vertex. Parts are ordered by their lowest triangle.
std::vector<std::vector<int32_t>> split_chart(const TriMesh& mesh, const TriangleInfo& info,
                                              const std::vector<int32_t>& tris) {
  std::vector<int32_t> proper;
  for (int32_t t : tris)
    if (!info.degenerate[t]) proper.push_back(t);
  if (proper.size() < 2) return {tris};
  auto centroid = [&](int32_t t) {
    const Tri& f = mesh.triangles[t];
    return (mesh.positions[f[0]] + mesh.positions[f[1]] + mesh.positions[f[2]]) / 3.0;
  };
  Vec3 mean{};
  for (int32_t t : proper) mean += centroid(t);
  mean = mean / double(proper.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int32_t t : proper) {
    const Vec3 d = centroid(t) - mean;
    const Eigen::Vector3d v(d.x, d.y, d.z);
    cov += v * v.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const Eigen::Vector3d ax = eig.eigenvectors().col(2), ay = eig.eigenvectors().col(1);
  // The cut runs across the long side of the centroids' minimum-area
  // rectangle in the chart's plane, not across the principal axis: a near
  // square face's principal axis can be its diagonal, and a diagonal cut
  // through the grid of a fluid mesh leaves two saw-toothed triangles that
  // pack badly (docs/atlas.md).
  const Vec3 e1{ax.x(), ax.y(), ax.z()}, e2{ay.x(), ay.y(), ay.z()};
  std::vector<Vec2> plane;
  plane.reserve(proper.size());
  for (int32_t t : proper) plane.push_back({dot(centroid(t) - mean, e1), dot(centroid(t) - mean, e2)});
  const Vec2 d = long_side(plane);
  const Vec3 axis = e1 * d.x + e2 * d.y;
  std::vector<std::pair<double, int32_t>> proj;
  proj.reserve(proper.size());
  for (int32_t t : proper) proj.emplace_back(dot(centroid(t) - mean, axis), t);
  std::sort(proj.begin(), proj.end());
  // side: 0/1 by the median; label holds part ids after the flood fill.
  std::vector<std::pair<int32_t, int>> side;  // (triangle, side) sorted by triangle
  side.reserve(proper.size());
  for (std::size_t i = 0; i < proj.size(); ++i) side.emplace_back(proj[i].second, i < proj.size() / 2 ? 0 : 1);
  std::sort(side.begin(), side.end());
  // Triangle -> position in `side`, in a per-thread array reset on exit
  // (charts are small next to the mesh; a search per lookup was the cost).
  thread_local std::vector<int32_t> slot;
  if (slot.size() < info.area.size()) slot.assign(info.area.size(), -1);
  for (std::size_t i = 0; i < side.size(); ++i) slot[side[i].first] = int32_t(i);
  struct Reset {
    const std::vector<std::pair<int32_t, int>>& side;
    ~Reset() {
      for (const auto& s : side) slot[s.first] = -1;
    }
  } reset{side};
  auto find = [&](int32_t t) { return int(slot[t]); };
  // A cut through the triangle strips of a fluid mesh is saw-toothed; a few
  // sequential sweeps (in triangle order, so deterministic and free of the
  // oscillation of simultaneous flips) move a triangle with two neighbours
  // on the other side across.
  for (int sweep = 0; sweep < 3; ++sweep) {
    bool changed = false;
    for (std::size_t i = 0; i < side.size(); ++i) {
      int other = 0;
      for (int k = 0; k < 3; ++k) {
        const int32_t u = info.across[3 * std::size_t(side[i].first) + k];
        const int j = u < 0 ? -1 : find(u);
        other += j >= 0 && side[j].second != side[i].second;
      }
      if (other >= 2) side[i].second = 1 - side[i].second, changed = true;
    }
    if (!changed) break;
  }
  std::vector<int> part(side.size(), -1);
  int parts = 0;
  std::vector<int> stack;
  for (std::size_t s = 0; s < side.size(); ++s) {
    if (part[s] >= 0) continue;
    part[s] = parts;
    stack.assign(1, int(s));
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        const int32_t u = info.across[3 * std::size_t(side[i].first) + k];
        if (u < 0) continue;
        const int j = find(u);
        if (j < 0 || part[j] >= 0 || side[j].second != side[i].second) continue;
        part[j] = parts;
        stack.push_back(j);
      }
    }
    ++parts;
  }
  std::vector<std::vector<int32_t>> out(parts);
  for (std::size_t s = 0; s < side.size(); ++s) out[part[s]].push_back(side[s].first);
  // Degenerate triangles follow the lowest proper triangle sharing a vertex.
  std::vector<std::pair<int32_t, int>> vertex_part;  // (vertex, part), first proper triangle wins
  for (std::size_t s = 0; s < side.size(); ++s)
    for (int32_t v : mesh.triangles[side[s].first]) vertex_part.emplace_back(v, part[s]);
  std::stable_sort(vertex_part.begin(), vertex_part.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (int32_t t : tris) {
    if (!info.degenerate[t]) continue;
    int target = 0;
    for (int32_t v : mesh.triangles[t]) {
      auto it = std::lower_bound(vertex_part.begin(), vertex_part.end(), std::make_pair(v, INT32_MIN),
                                 [](const auto& a, const auto& b) { return a.first < b.first; });
      if (it != vertex_part.end() && it->first == v) {
        target = it->second;
        break;
      }
    }
    out[target].push_back(t);
  }
  for (auto& p : out) std::sort(p.begin(), p.end());
  return out;
}

}  // namespace

std::vector<Vec2> flatten_charts(const TriMesh& mesh, const TriangleInfo& info, Charts& charts,
                                 double max_stretch, double max_chart_area, double max_chart_length) {
  std::vector<Vec2> corner_uv(3 * mesh.triangle_count());
  std::vector<std::vector<int32_t>> lists(charts.count);
  for (int c = 0; c < charts.count; ++c)
    lists[c].assign(charts.triangles.begin() + charts.offsets[c], charts.triangles.begin() + charts.offsets[c + 1]);
  std::vector<int32_t> pending(charts.count);
  std::iota(pending.begin(), pending.end(), 0);
  // Rounds: flatten all pending charts in parallel, then split the failures
  // in chart order (new charts appended), so ids do not depend on threads.
  for (int round = 0; !pending.empty(); ++round) {
    std::vector<uint8_t> ok(pending.size(), 1);
    parallel_for(pending.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        double area = 0;
        for (int32_t t : lists[pending[i]]) area += info.area[t];
        ok[i] = area <= max_chart_area && flatten_one(mesh, info, lists[pending[i]], max_stretch, false, corner_uv) &&
                uv_length(lists[pending[i]], corner_uv) <= max_chart_length;
      }
    }, 1);
    // Splits are computed in parallel, ids handed out in chart order.
    std::vector<std::vector<std::vector<int32_t>>> split(pending.size());
    parallel_for(pending.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i)
        if (!ok[i]) split[i] = split_chart(mesh, info, lists[pending[i]]);
    }, 1);
    std::vector<int32_t> next;
    for (std::size_t i = 0; i < pending.size(); ++i) {
      if (ok[i]) continue;
      const int32_t c = pending[i];
      auto& parts = split[i];
      if (parts.size() < 2 || round >= 64) {
        // A single proper triangle always flattens exactly; this keeps the
        // loop finite on pathological input by accepting the best we have.
        flatten_one(mesh, info, lists[c], max_stretch, true, corner_uv);
        continue;
      }
      lists[c] = std::move(parts[0]);
      next.push_back(c);
      for (std::size_t p = 1; p < parts.size(); ++p) {
        next.push_back(int32_t(lists.size()));
        lists.push_back(std::move(parts[p]));
      }
    }
    pending = std::move(next);
  }
  charts.count = int(lists.size());
  for (int c = 0; c < charts.count; ++c)
    for (int32_t t : lists[c]) charts.chart_of_triangle[t] = c;
  charts.rebuild_csr(mesh.triangle_count());
  return corner_uv;
}

}  // namespace lapflow::atlas_detail
