// Chart segmentation of the surface atlas: region growing from seeds under a
// normal-cone criterion (a chart whose normals stay within a cone is close to a
// height field, which LSCM flattens with little area distortion). Closed
// components are cut because their normals cannot fit in one cone; tiny
// droplets get charts of their own because growth never crosses components.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "atlas/internal.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow::atlas_detail {

TriangleInfo analyze_triangles(const TriMesh& mesh) {
  const std::size_t nt = mesh.triangle_count(), nv = mesh.vertex_count();
  TriangleInfo info;
  info.normal.assign(nt, Vec3{});
  info.area.assign(nt, 0.0);
  info.degenerate.assign(nt, 0);
  info.across.assign(3 * nt, -1);
  const Vec3 diag = bounding_box(mesh).size();
  const double min_area = 1e-12 * norm2(diag);

  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      const Tri& f = mesh.triangles[t];
      const Vec3 n = triangle_normal_area2(mesh, int(t));
      const double a2 = norm(n);
      double longest2 = 0;
      for (int k = 0; k < 3; ++k)
        longest2 = std::max(longest2, norm2(mesh.positions[f[(k + 1) % 3]] - mesh.positions[f[k]]));
      // A needle (height below 1e-8 of its longest edge) has a meaningless
      // normal and would dominate the LSCM system through its 1/area weight.
      const bool deg = f[0] == f[1] || f[1] == f[2] || f[0] == f[2] || 0.5 * a2 <= min_area ||
                       a2 <= 1e-8 * longest2 || !std::isfinite(a2);
      info.degenerate[t] = deg;
      info.area[t] = std::isfinite(a2) ? 0.5 * a2 : 0.0;
      if (!deg) info.normal[t] = n / a2;
    }
  });

  // Outgoing half-edges per vertex (counting sort): an edge is crossed only
  // when exactly one triangle uses a->b and exactly one uses b->a.
  std::vector<int32_t> offs(nv + 1, 0), half(3 * nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) ++offs[mesh.triangles[t][k] + 1];
  for (std::size_t v = 0; v < nv; ++v) offs[v + 1] += offs[v];
  {
    std::vector<int32_t> fill(offs.begin(), offs.end() - 1);
    for (std::size_t t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k) half[fill[mesh.triangles[t][k]]++] = int32_t(3 * t + k);
  }
  auto target = [&](int32_t h) { return mesh.triangles[h / 3][(h % 3 + 1) % 3]; };
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      if (info.degenerate[t]) continue;
      for (int k = 0; k < 3; ++k) {
        const int32_t va = mesh.triangles[t][k], vb = mesh.triangles[t][(k + 1) % 3];
        int same = 0, opposite = 0, other = -1;
        for (int32_t i = offs[va]; i < offs[va + 1]; ++i) same += target(half[i]) == vb;
        for (int32_t i = offs[vb]; i < offs[vb + 1]; ++i)
          if (target(half[i]) == va) {
            ++opposite;
            other = half[i] / 3;
          }
        if (same == 1 && opposite == 1 && other != int(t) && !info.degenerate[other]) info.across[3 * t + k] = other;
      }
    }
  });
  return info;
}

void Charts::rebuild_csr(std::size_t triangle_count) {
  offsets.assign(std::size_t(count) + 1, 0);
  for (std::size_t t = 0; t < triangle_count; ++t) ++offsets[chart_of_triangle[t] + 1];
  for (int c = 0; c < count; ++c) offsets[c + 1] += offsets[c];
  triangles.resize(triangle_count);
  std::vector<int32_t> fill(offsets.begin(), offsets.end() - 1);
  for (std::size_t t = 0; t < triangle_count; ++t) triangles[fill[chart_of_triangle[t]]++] = int32_t(t);
}

namespace {

/// Growth under a cone leaves saw-tooth boundaries (a triangle just outside
/// the cone between two inside). A triangle with two or more neighbours in one
/// other chart moves there when that chart's cone admits it: straighter
/// boundaries pack tighter and flatten better. Jacobi sweeps (labels read from
/// the previous sweep) keep it independent of the thread count.
void smooth_boundaries(const TriangleInfo& info, double cos_cone, Charts& charts) {
  const std::size_t nt = info.area.size();
  for (int sweep = 0; sweep < 4; ++sweep) {
    std::vector<Vec3> axis(charts.count);
    for (std::size_t t = 0; t < nt; ++t)
      if (charts.chart_of_triangle[t] >= 0) axis[charts.chart_of_triangle[t]] += info.normal[t] * info.area[t];
    for (Vec3& a : axis) a = normalized(a);
    std::vector<int32_t> next(charts.chart_of_triangle);
    parallel_for(nt, [&](std::size_t b, std::size_t e) {
      for (std::size_t t = b; t < e; ++t) {
        const int32_t c = charts.chart_of_triangle[t];
        if (c < 0) continue;
        int32_t n[3];
        for (int k = 0; k < 3; ++k) {
          const int32_t u = info.across[3 * t + k];
          n[k] = u < 0 ? -1 : charts.chart_of_triangle[u];
        }
        for (int k = 0; k < 3; ++k) {
          const int32_t o = n[k];
          if (o < 0 || o == c || (o != n[(k + 1) % 3] && o != n[(k + 2) % 3])) continue;
          if (dot(info.normal[t], axis[o]) >= cos_cone) next[t] = o;
          break;
        }
      }
    }, 4096);
    if (next == charts.chart_of_triangle) break;
    charts.chart_of_triangle.swap(next);
  }
}

/// Makes every chart edge-connected (smoothing may cut a chart in two) and
/// numbers charts by their lowest triangle; drops emptied charts.
void split_components(const TriangleInfo& info, Charts& charts) {
  const std::size_t nt = info.area.size();
  std::vector<int32_t> label(nt, -1), stack;
  int count = 0;
  for (std::size_t s = 0; s < nt; ++s) {
    if (charts.chart_of_triangle[s] < 0 || label[s] >= 0) continue;
    const int32_t c = charts.chart_of_triangle[s];
    label[s] = count;
    stack.assign(1, int32_t(s));
    while (!stack.empty()) {
      const int32_t t = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        const int32_t u = info.across[3 * std::size_t(t) + k];
        if (u < 0 || label[u] >= 0 || charts.chart_of_triangle[u] != c) continue;
        label[u] = count;
        stack.push_back(u);
      }
    }
    ++count;
  }
  charts.chart_of_triangle.swap(label);
  charts.count = count;
}

}  // namespace

Charts segment_charts(const TriMesh& mesh, const TriangleInfo& info, const ChartOptions& options) {
  const std::size_t nt = mesh.triangle_count();
  const double cos_cone = std::cos(options.cone_degrees * std::numbers::pi / 180.0);
  Charts charts;
  charts.chart_of_triangle.assign(nt, -1);
  std::vector<int32_t> queue;
  queue.reserve(nt);
  for (std::size_t seed = 0; seed < nt; ++seed) {
    if (info.degenerate[seed] || charts.chart_of_triangle[seed] >= 0) continue;
    const int c = charts.count++;
    charts.chart_of_triangle[seed] = c;
    Vec3 sum = info.normal[seed] * info.area[seed];
    Vec3 axis = info.normal[seed];
    queue.clear();
    queue.push_back(int32_t(seed));
    // FIFO growth keeps charts compact (roughly geodesic discs around the
    // seed); the running area-weighted mean normal centres the cone.
    for (std::size_t head = 0; head < queue.size(); ++head) {
      const int32_t t = queue[head];
      for (int k = 0; k < 3; ++k) {
        const int32_t u = info.across[3 * t + k];
        if (u < 0 || charts.chart_of_triangle[u] >= 0) continue;
        if (dot(info.normal[u], axis) < cos_cone) continue;
        charts.chart_of_triangle[u] = c;
        sum += info.normal[u] * info.area[u];
        const Vec3 n = normalized(sum);
        if (norm2(n) > 0) axis = n;
        queue.push_back(u);
      }
    }
  }

  smooth_boundaries(info, cos_cone, charts);
  split_components(info, charts);

  // Degenerate triangles: the chart of the lowest-index proper triangle that
  // shares a vertex, so one of their vertices has a uv in that chart and the
  // triangle can collapse onto it. Isolated ones form charts of their own.
  std::vector<int32_t> vertex_chart(mesh.vertex_count(), -1);
  for (std::size_t t = 0; t < nt; ++t) {
    if (info.degenerate[t]) continue;
    for (int k = 0; k < 3; ++k) {
      int32_t& vc = vertex_chart[mesh.triangles[t][k]];
      if (vc < 0) vc = charts.chart_of_triangle[t];
    }
  }
  for (std::size_t t = 0; t < nt; ++t) {
    if (!info.degenerate[t]) continue;
    int c = -1;
    for (int k = 0; k < 3 && c < 0; ++k) c = vertex_chart[mesh.triangles[t][k]];
    if (c < 0) {
      c = charts.count++;
      for (int k = 0; k < 3; ++k) vertex_chart[mesh.triangles[t][k]] = c;
    }
    charts.chart_of_triangle[t] = c;
  }
  charts.rebuild_csr(nt);
  return charts;
}

}  // namespace lapflow::atlas_detail
