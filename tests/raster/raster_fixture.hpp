#pragma once
// Hand-built fixtures for the rasterizer tests: a flat square fluid mesh in
// the z = 0 plane with an analytic atlas (one chart, or two charts split at
// x = L/2 and placed apart so patch triangles straddle a seam), grid patches
// whose rest uv is an affine map of xy, and a smooth exemplar. Every answer
// is analytic: a texel's surface point, each patch's (u, v) and w there.
#include <cmath>
#include <optional>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/raster/raster.hpp"

namespace lapflow::test {

struct PlaneFixture {
  TriMesh mesh;
  SurfaceAtlas atlas;
  double L = 1;     // side of the square (metres)
  int g = 1;        // grid cells per side
  bool split = false;
  double scale = 0;  // atlas uv per metre
  Vec2 offset[2];    // atlas uv of each chart's origin

  double h() const { return L / g; }
  int chart_of_x(double x) const { return split && x >= 0.5 * L ? 1 : 0; }
  /// Fluid triangle under (x, y), or -1 off the square.
  int locate(double x, double y) const {
    if (x < 0 || y < 0 || x > L || y > L) return -1;
    const int i = std::min(g - 1, int(x / h())), j = std::min(g - 1, int(y / h()));
    const double fx = x / h() - i, fy = y / h() - j;
    return 2 * (j * g + i) + (fx >= fy ? 0 : 1);
  }
  /// Surface point of chart texel k of the texel map.
  Vec3 texel_point(std::size_t k) const {
    const Tri& t = mesh.triangles[atlas.texels.triangle[k]];
    float fb1, fb2;
    texel_barycentrics(atlas.corner_uv, atlas.resolution, atlas.texels.texel[k], atlas.texels.triangle[k], fb1, fb2);
    const double b1 = fb1, b2 = fb2;
    return mesh.positions[t[0]] * (1 - b1 - b2) + mesh.positions[t[1]] * b1 + mesh.positions[t[2]] * b2;
  }
};

/// g x g cells over [0,L]^2; atlas resolution N. Charts occupy [0.05, 0.95]
/// (one chart) or two halves separated by a gap of several texels.
inline PlaneFixture make_plane(int g, double L, int N, bool split) {
  PlaneFixture f;
  f.L = L, f.g = g, f.split = split;
  for (int j = 0; j <= g; ++j)
    for (int i = 0; i <= g; ++i) f.mesh.positions.push_back({i * L / g, j * L / g, 0});
  auto vid = [&](int i, int j) { return int32_t(j * (g + 1) + i); };
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i) {
      f.mesh.triangles.push_back({vid(i, j), vid(i + 1, j), vid(i + 1, j + 1)});
      f.mesh.triangles.push_back({vid(i, j), vid(i + 1, j + 1), vid(i, j + 1)});
    }
  if (!split) {
    f.scale = 0.9 / L;
    f.offset[0] = f.offset[1] = {0.05, 0.05};
  } else {
    f.scale = 0.85 / L;  // two halves of 0.425 each, 0.05 apart
    f.offset[0] = {0.05, 0.075};
    f.offset[1] = {0.525 - 0.5 * L * f.scale, 0.075};
  }
  auto& A = f.atlas;
  A.resolution = N;
  A.chart_count = split ? 2 : 1;
  for (std::size_t t = 0; t < f.mesh.triangles.size(); ++t) {
    const Tri& T = f.mesh.triangles[t];
    const Vec3 c = (f.mesh.positions[T[0]] + f.mesh.positions[T[1]] + f.mesh.positions[T[2]]) / 3.0;
    const int chart = f.chart_of_x(c.x);
    A.chart_of_triangle.push_back(chart);
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = f.mesh.positions[T[k]];
      A.corner_uv.push_back(f.offset[chart] + Vec2{p.x, p.y} * f.scale);
    }
  }
  // Texels whose centre lies inside a chart, in texel order.
  for (int y = 0; y < N; ++y)
    for (int x = 0; x < N; ++x) {
      const Vec2 uv{(x + 0.5) / N, 1.0 - (y + 0.5) / N};
      for (int chart = 0; chart < A.chart_count; ++chart) {
        const Vec2 q = (uv - f.offset[chart]) / f.scale;
        const double x0 = chart == 1 ? 0.5 * L : 0, x1 = split && chart == 0 ? 0.5 * L : L;
        if (!(q.x >= x0 && q.x < x1 && q.y >= 0 && q.y < L)) continue;
        const int t = f.locate(q.x, q.y);
        A.texels.texel.push_back(uint32_t(y * N + x));
        A.texels.triangle.push_back(t);
      }
    }
  return f;
}

/// A planar patch: m x m grid over the square of half-side `half` around
/// `centre`, rest uv = (0.5, 0.5) + Rot(angle) (p - centre) / (2r), weight an
/// affine function of the position (so linear interpolation is exact).
struct PatchSpec {
  Vec3 centre;
  double r = 0.1, angle = 0, half = 0.1;
  int m = 8;
  double w0 = 1, wx = 0, wy = 0;  // w = w0 + wx (x - cx) + wy (y - cy)

  Vec2 uv_at(const Vec3& p) const {
    const double dx = p.x - centre.x, dy = p.y - centre.y, c = std::cos(angle), s = std::sin(angle);
    return {0.5 + (c * dx - s * dy) / (2 * r), 0.5 + (s * dx + c * dy) / (2 * r)};
  }
  double w_at(const Vec3& p) const { return w0 + wx * (p.x - centre.x) + wy * (p.y - centre.y); }
  /// Inside the patch's mesh (which is clipped to the square [0,L]^2).
  bool covers(const Vec3& p, double L) const {
    const double x0 = std::max(0.0, centre.x - half), x1 = std::min(L, centre.x + half);
    const double y0 = std::max(0.0, centre.y - half), y1 = std::min(L, centre.y + half);
    return p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1;
  }
};

inline Patch make_grid_patch(const PlaneFixture& f, const PatchSpec& s, uint32_t id, int frame = 0) {
  Patch p;
  p.id = id;
  p.birth_frame = frame;
  p.center = s.centre;
  p.center_normal = {0, 0, 1};
  const double x0 = std::max(0.0, s.centre.x - s.half), x1 = std::min(f.L, s.centre.x + s.half);
  const double y0 = std::max(0.0, s.centre.y - s.half), y1 = std::min(f.L, s.centre.y + s.half);
  for (int j = 0; j <= s.m; ++j)
    for (int i = 0; i <= s.m; ++i) {
      const Vec3 q{x0 + (x1 - x0) * i / s.m, y0 + (y1 - y0) * j / s.m, 0};
      p.positions.push_back(q);
      p.rest_uv.push_back(s.uv_at(q));
      p.weight.push_back(float(s.w_at(q)));
      p.surface_triangle.push_back(f.locate(q.x, q.y));
    }
  for (int j = 0; j < s.m; ++j)
    for (int i = 0; i < s.m; ++i) {
      const int32_t a = j * (s.m + 1) + i, b = a + 1, c = a + s.m + 2, d = a + s.m + 1;
      p.triangles.push_back({a, b, c});
      p.triangles.push_back({a, c, d});
    }
  return p;
}

/// Exemplar whose colour is a linear ramp (R = u, G = v, B = 0.5): bilinear
/// and box-filtered mip lookups reproduce (u, v) exactly away from the border.
inline Exemplar ramp_exemplar(int size, float feature_value) {
  Exemplar ex;
  ex.color = Image(size, size, 3);
  ex.feature = Image(size, size, 1, feature_value);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      ex.color.at(x, y, 0) = (x + 0.5f) / size;
      ex.color.at(x, y, 1) = 1.f - (y + 0.5f) / size;
      ex.color.at(x, y, 2) = 0.5f;
    }
  ex.displacement = ex.feature;
  return ex;
}

}  // namespace lapflow::test
