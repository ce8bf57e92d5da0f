#include "lapflow/surface/mesh.hpp"

#include <algorithm>
#include <cstdint>
#include <numeric>

namespace lapflow {

Vec3 triangle_normal_area2(const TriMesh& m, int t) {
  const Tri& f = m.triangles[t];
  const Vec3& a = m.positions[f[0]];
  return cross(m.positions[f[1]] - a, m.positions[f[2]] - a);
}

double triangle_area(const TriMesh& m, int t) { return 0.5 * norm(triangle_normal_area2(m, t)); }

double surface_area(const TriMesh& m) {
  double a = 0;
  for (int t = 0; t < int(m.triangles.size()); ++t) a += triangle_area(m, t);
  return a;
}

std::vector<Vec3> vertex_normals(const TriMesh& m) {
  std::vector<Vec3> n(m.positions.size());
  for (int t = 0; t < int(m.triangles.size()); ++t) {
    const Vec3 fn = triangle_normal_area2(m, t);
    for (int k = 0; k < 3; ++k) n[m.triangles[t][k]] += fn;
  }
  for (Vec3& v : n) v = normalized(v);
  return n;
}

namespace {

bool repeats_a_corner(const Tri& f) { return f[0] == f[1] || f[1] == f[2] || f[0] == f[2]; }

/// 1 for each vertex on an edge that only one triangle uses. Each edge is
/// bucketed under its lower vertex (a counting sort), so the work is linear in
/// the triangles. Triangles with a repeated index have no proper edges.
std::vector<uint8_t> boundary_vertices(const TriMesh& m) {
  const std::size_t nv = m.positions.size();
  std::vector<std::size_t> offset(nv + 1, 0);
  for (const Tri& f : m.triangles)
    if (!repeats_a_corner(f))
      for (int k = 0; k < 3; ++k) ++offset[std::min(f[k], f[(k + 1) % 3]) + 1];
  std::partial_sum(offset.begin(), offset.end(), offset.begin());
  std::vector<int32_t> upper(offset[nv]);
  {
    std::vector<std::size_t> fill(offset.begin(), offset.end() - 1);
    for (const Tri& f : m.triangles)
      if (!repeats_a_corner(f))
        for (int k = 0; k < 3; ++k) {
          const int32_t a = f[k], b = f[(k + 1) % 3];
          upper[fill[std::min(a, b)]++] = std::max(a, b);
        }
  }
  std::vector<int32_t> uses(nv, 0);
  std::vector<uint8_t> boundary(nv, 0);
  for (std::size_t v = 0; v < nv; ++v) {
    const auto begin = upper.begin() + std::ptrdiff_t(offset[v]), end = upper.begin() + std::ptrdiff_t(offset[v + 1]);
    for (auto it = begin; it != end; ++it) ++uses[*it];
    for (auto it = begin; it != end; ++it)
      if (uses[*it] == 1) boundary[v] = boundary[*it] = 1;
    for (auto it = begin; it != end; ++it) uses[*it] = 0;
  }
  return boundary;
}

}  // namespace

std::vector<float> vertex_mean_curvature(const TriMesh& m) {
  const std::size_t nv = m.positions.size();
  std::vector<Vec3> laplacian(nv), normal(nv);  // sum of (cot a + cot b)(x_j - x_i); sum of 2 * area * face normal
  std::vector<double> area(nv, 0.0);            // mixed Voronoi area
  // One serial pass in triangle order: the sums, hence the result, do not
  // depend on the thread count.
  for (const Tri& f : m.triangles) {
    if (repeats_a_corner(f)) continue;
    const Vec3 p[3] = {m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]};
    const Vec3 n2 = cross(p[1] - p[0], p[2] - p[0]);
    const double area2 = norm(n2);  // twice the triangle's area
    if (!(area2 > 0)) continue;     // no angles to take cotangents of
    double cot[3], dots[3];
    for (int k = 0; k < 3; ++k) {
      dots[k] = dot(p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
      cot[k] = dots[k] / area2;  // |u x v| is twice the area at every corner
    }
    const bool obtuse = dots[0] < 0 || dots[1] < 0 || dots[2] < 0;
    for (int k = 0; k < 3; ++k) {
      const int a = (k + 1) % 3, b = (k + 2) % 3;
      // The edge opposite corner k gets cot k, at both of its ends.
      const Vec3 ab = p[b] - p[a];
      laplacian[f[a]] += cot[k] * ab;
      laplacian[f[b]] -= cot[k] * ab;
      normal[f[k]] += n2;
      // Mixed area: the Voronoi region when no angle is obtuse, else a share of
      // the triangle that keeps the regions inside it.
      if (!obtuse)
        area[f[k]] += (norm2(p[k] - p[a]) * cot[b] + norm2(p[k] - p[b]) * cot[a]) / 8;
      else
        area[f[k]] += area2 * (dots[k] < 0 ? 0.25 : 0.125);
    }
  }
  const std::vector<uint8_t> boundary = boundary_vertices(m);
  std::vector<float> h(nv, 0.0f);
  for (std::size_t v = 0; v < nv; ++v) {
    if (boundary[v] || !(area[v] > 0)) continue;
    const Vec3 k = laplacian[v] / (2 * area[v]);  // -2 H n
    h[v] = float(-0.5 * dot(k, normalized(normal[v])));
  }
  return h;
}

Box3 bounding_box(const TriMesh& m) {
  Box3 b;
  if (m.triangles.empty()) {
    for (const Vec3& p : m.positions) b.extend(p);
  } else {
    for (const Tri& f : m.triangles)
      for (int k = 0; k < 3; ++k) b.extend(m.positions[f[k]]);
  }
  return b;
}

int triangle_components(const TriMesh& m, std::vector<int>& component_of_triangle) {
  // Union-find over vertices, then label triangles in order of first appearance.
  std::vector<int> parent(m.positions.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const Tri& f : m.triangles) {
    const int a = find(f[0]);
    for (int k = 1; k < 3; ++k) {
      const int b = find(f[k]);
      if (a != b) parent[b] = a;
    }
  }
  std::vector<int> label(m.positions.size(), -1);
  component_of_triangle.assign(m.triangles.size(), -1);
  int count = 0;
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const int root = find(m.triangles[t][0]);
    if (label[root] < 0) label[root] = count++;
    component_of_triangle[t] = label[root];
  }
  return count;
}

}  // namespace lapflow
