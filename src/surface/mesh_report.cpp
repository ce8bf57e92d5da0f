// What a user checks before a long bake: topology problems and velocity range.
#include <algorithm>
#include <numeric>

#include "lapflow/surface/mesh.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

bool has_repeated_index(const Tri& f) { return f[0] == f[1] || f[1] == f[2] || f[0] == f[2]; }

/// True when the triangles around vertex v form one disk or one half-disk.
/// The link of v (the edge opposite v in each incident triangle) must be a
/// single path or a single cycle: every link vertex of degree <= 2, connected.
bool is_manifold_vertex(const TriMesh& m, int v, const int32_t* tris, std::size_t n, std::vector<int32_t>& ids,
                        std::vector<int>& degree, std::vector<int>& parent) {
  ids.clear();
  for (std::size_t i = 0; i < n; ++i)
    for (int32_t x : m.triangles[tris[i]])
      if (x != v) ids.push_back(x);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  degree.assign(ids.size(), 0);
  parent.resize(ids.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  int components = int(ids.size());
  for (std::size_t i = 0; i < n; ++i) {
    const Tri& f = m.triangles[tris[i]];
    const int k = f[0] == v ? 0 : (f[1] == v ? 1 : 2);
    const int a = int(std::lower_bound(ids.begin(), ids.end(), f[(k + 1) % 3]) - ids.begin());
    const int b = int(std::lower_bound(ids.begin(), ids.end(), f[(k + 2) % 3]) - ids.begin());
    if (++degree[a] > 2 || ++degree[b] > 2) return false;
    const int ra = find(a), rb = find(b);
    if (ra != rb) parent[rb] = ra, --components;
  }
  return components == 1;
}

}  // namespace

MeshReport analyze_mesh(const TriMesh& m) {
  MeshReport r;
  r.vertices = m.vertex_count();
  r.triangles = m.triangle_count();
  r.bounds = bounding_box(m);
  std::vector<int> comp;
  r.components = triangle_components(m, comp);

  const std::size_t nt = m.triangles.size(), nv = m.positions.size();
  const Vec3 diag = r.bounds.size();
  const double area_floor = 1e-12 * norm2(diag);
  std::vector<double> area(nt);
  std::vector<uint8_t> degenerate(nt);
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      area[t] = triangle_area(m, int(t));
      degenerate[t] = has_repeated_index(m.triangles[t]) || area[t] <= area_floor;
    }
  });
  for (std::size_t t = 0; t < nt; ++t) {  // serial sum: same bits for any thread count
    r.area += area[t];
    r.degenerate_triangles += degenerate[t];
  }

  // Edges as sorted (lo, hi) keys: a run of length 1 is a boundary edge, more
  // than 2 a non-manifold one. Triangles with a repeated index have no proper
  // edges and are left out (they are already counted as degenerate).
  std::vector<uint64_t> edges;
  edges.reserve(3 * nt);
  for (const Tri& f : m.triangles) {
    if (has_repeated_index(f)) continue;
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = uint32_t(f[k]), b = uint32_t(f[(k + 1) % 3]);
      edges.push_back(uint64_t(std::min(a, b)) << 32 | std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) ++r.boundary_edges;
    if (j - i > 2) ++r.non_manifold_edges;
    i = j;
  }

  // Vertex -> incident proper triangles (CSR).
  std::vector<int32_t> offset(nv + 1, 0), incident;
  for (const Tri& f : m.triangles)
    if (!has_repeated_index(f))
      for (int32_t x : f) ++offset[x + 1];
  std::partial_sum(offset.begin(), offset.end(), offset.begin());
  incident.resize(offset[nv]);
  {
    std::vector<int32_t> fill(offset.begin(), offset.end() - 1);
    for (std::size_t t = 0; t < nt; ++t)
      if (!has_repeated_index(m.triangles[t]))
        for (int32_t x : m.triangles[t]) incident[fill[x]++] = int32_t(t);
  }
  std::vector<uint8_t> referenced(nv, 0);
  for (const Tri& f : m.triangles)
    for (int32_t x : f) referenced[x] = 1;

  std::vector<uint8_t> bad_vertex(nv, 0);
  parallel_for(nv, [&](std::size_t b, std::size_t e) {
    std::vector<int32_t> ids;
    std::vector<int> degree, parent;
    for (std::size_t v = b; v < e; ++v) {
      const std::size_t n = std::size_t(offset[v + 1] - offset[v]);
      if (n == 0) continue;
      bad_vertex[v] = !is_manifold_vertex(m, int(v), incident.data() + offset[v], n, ids, degree, parent);
    }
  }, 1024);

  r.has_velocity = m.has_velocities();
  double speed_sum = 0;
  std::size_t speed_n = 0;
  r.speed_min = INFINITY;
  for (std::size_t v = 0; v < nv; ++v) {
    r.non_manifold_vertices += bad_vertex[v];
    if (!referenced[v]) {
      ++r.isolated_vertices;
      continue;
    }
    if (r.has_velocity) {
      const double s = norm(m.velocities[v]);
      r.speed_min = std::min(r.speed_min, s);
      r.speed_max = std::max(r.speed_max, s);
      speed_sum += s;
      ++speed_n;
    }
  }
  if (speed_n == 0) r.speed_min = 0;
  r.speed_mean = speed_n ? speed_sum / double(speed_n) : 0;
  return r;
}

}  // namespace lapflow
