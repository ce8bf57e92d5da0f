#include "test_helpers.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "lapflow/core/parallel.hpp"

namespace lapflow::test {

TriMesh icosphere(int subdivisions, double radius, Vec3 center) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  TriMesh m;
  m.positions = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  m.triangles = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (Vec3& p : m.positions) p = normalized(p);
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const std::pair<int, int> key{std::min(a, b), std::max(a, b)};
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.positions.push_back(normalized(m.positions[a] + m.positions[b]));
      return mid[key] = int(m.positions.size()) - 1;
    };
    std::vector<Tri> next;
    for (const Tri& f : m.triangles) {
      const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      next.push_back({f[0], a, c});
      next.push_back({f[1], b, a});
      next.push_back({f[2], c, b});
      next.push_back({a, b, c});
    }
    m.triangles = std::move(next);
  }
  for (Vec3& p : m.positions) p = center + p * radius;
  return m;
}

TriMesh plane_grid(int nx, int ny, double size_x, double size_y, double z) {
  TriMesh m;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) m.positions.push_back({size_x * i / nx, size_y * j / ny, z});
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
      m.triangles.push_back({a, b, d});
      m.triangles.push_back({a, d, c});
    }
  return m;
}

Vec3 rotate(const Vec3& v, const Vec3& axis, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return v * c + cross(axis, v) * s + axis * (dot(axis, v) * (1 - c));
}

PatchSet seed_on_threads(const SurfaceQuery& surface, const PatchOptions& options, int threads) {
  PatchSet set;
  set_thread_count(threads);
  seed_patches(surface, 0, options, {}, {}, set);
  set_thread_count(0);
  return set;
}

void expect_same_patches(const PatchSet& a, const PatchSet& b) {
  ASSERT_EQ(a.patches.size(), b.patches.size());
  for (std::size_t i = 0; i < a.patches.size(); ++i) {
    const Patch &p = a.patches[i], &q = b.patches[i];
    SCOPED_TRACE("patch " + std::to_string(i));
    EXPECT_EQ(p.id, q.id);
    EXPECT_EQ(p.positions, q.positions);
    EXPECT_EQ(p.rest_uv, q.rest_uv);
    EXPECT_EQ(p.triangles, q.triangles);
    EXPECT_EQ(p.weight, q.weight);
    EXPECT_EQ(p.surface_triangle, q.surface_triangle);
  }
}

}  // namespace lapflow::test
