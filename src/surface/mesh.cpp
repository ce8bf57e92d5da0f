#include "lapflow/surface/mesh.hpp"

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
