// Surface atlas (ALGORITHM.md step 6): every triangle in one chart, charts
// apart by the (shared) gutter, no flips, uv in [0,1], texel density within bounds,
// texel map known answers, same atlas at any thread count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "io_test_helpers.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

// ---- meshes ----------------------------------------------------------------

TriMesh torus(int nu, int nv, double big_r, double small_r) {
  TriMesh m;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * std::numbers::pi * i / nu, v = 2 * std::numbers::pi * j / nv;
      m.positions.push_back({(big_r + small_r * std::cos(v)) * std::cos(u), (big_r + small_r * std::cos(v)) * std::sin(u),
                             small_r * std::sin(v)});
    }
  auto id = [&](int i, int j) { return int32_t(((i + nu) % nu) * nv + (j + nv) % nv); };
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

/// Closed axis-aligned box [0,sx]x[0,sy]x[0,sz], each face an n x n grid,
/// vertices welded along the edges, outward CCW.
TriMesh closed_box(int n, Vec3 size) {
  TriMesh m;
  std::vector<std::pair<std::array<long, 3>, int32_t>> index;
  auto vertex = [&](const Vec3& p) {
    const std::array<long, 3> key{std::lround(p.x * 1e6), std::lround(p.y * 1e6), std::lround(p.z * 1e6)};
    for (const auto& [k, i] : index)
      if (k == key) return i;
    index.emplace_back(key, int32_t(m.positions.size()));
    m.positions.push_back(p);
    return int32_t(m.positions.size() - 1);
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int a = (axis + 1) % 3, b = (axis + 2) % 3;
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          int32_t q[4];
          const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
          for (int k = 0; k < 4; ++k) {
            Vec3 p;
            p[axis] = side * size[axis];
            p[a] = size[a] * (i + di[k]) / n;
            p[b] = size[b] * (j + dj[k]) / n;
            q[k] = vertex(p);
          }
          // (a, b, axis) is right-handed, so CCW in (a,b) faces +axis.
          if (side == 1) {
            m.triangles.push_back({q[0], q[1], q[2]});
            m.triangles.push_back({q[0], q[2], q[3]});
          } else {
            m.triangles.push_back({q[0], q[2], q[1]});
            m.triangles.push_back({q[0], q[3], q[2]});
          }
        }
    }
  return m;
}

void append(TriMesh& m, const TriMesh& other, Vec3 offset = {}) {
  const int32_t base = int32_t(m.positions.size());
  for (const Vec3& p : other.positions) m.positions.push_back(p + offset);
  for (const Tri& t : other.triangles) m.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

/// A box with a fin on one edge (three triangles on it), a second box glued
/// at one corner vertex, a pair of inconsistently oriented triangles, and
/// degenerate triangles: repeated index, collinear, and an isolated one.
TriMesh non_manifold_mesh() {
  TriMesh m = closed_box(6, {1, 1, 1});
  const int32_t corner = int32_t(std::find(m.positions.begin(), m.positions.end(), Vec3{1, 1, 1}) - m.positions.begin());
  TriMesh second = closed_box(4, {0.5, 0.5, 0.5});
  const int32_t base = int32_t(m.positions.size());
  append(m, second, {1, 1, 1});
  const int32_t second_corner = base + int32_t(std::find(second.positions.begin(), second.positions.end(), Vec3{0, 0, 0}) -
                                                 second.positions.begin());
  for (std::size_t t = base; t < m.triangles.size(); ++t)
    for (int32_t& v : m.triangles[t])
      if (v == second_corner) v = corner;  // non-manifold vertex
  // Fin on the edge from (0,0,0) along x: a third triangle on a box edge.
  const int32_t o = int32_t(std::find(m.positions.begin(), m.positions.end(), Vec3{0, 0, 0}) - m.positions.begin());
  const int32_t x1 = int32_t(std::find(m.positions.begin(), m.positions.end(), Vec3{1.0 / 6, 0, 0}) - m.positions.begin());
  m.positions.push_back({0.1, -0.3, -0.3});
  m.triangles.push_back({o, x1, int32_t(m.positions.size() - 1)});
  // Two triangles sharing an edge with the same orientation (inconsistent).
  const int32_t p = int32_t(m.positions.size());
  m.positions.insert(m.positions.end(), {{3, 0, 0}, {3.5, 0, 0}, {3, 0.5, 0}, {3.5, 0.5, 0.1}});
  m.triangles.push_back({p, p + 1, p + 2});
  m.triangles.push_back({p + 1, p + 2, p + 3});
  // Degenerate: repeated index on the box, collinear on the box, isolated.
  m.triangles.push_back({o, o, x1});
  const int32_t x2 = int32_t(std::find(m.positions.begin(), m.positions.end(), Vec3{2.0 / 6, 0, 0}) - m.positions.begin());
  m.triangles.push_back({o, x1, x2});
  const int32_t q = int32_t(m.positions.size());
  m.positions.insert(m.positions.end(), {{5, 5, 5}, {5, 5, 5}, {5, 5, 5}});
  m.triangles.push_back({q, q + 1, q + 2});
  return m;
}

TriMesh droplets(int count) {
  TriMesh m;
  for (int i = 0; i < count; ++i) {
    const double r = 0.004 + 0.016 * hash_to_unit(hash64(i, 1));
    const Vec3 c{hash_to_unit(hash64(i, 2)), hash_to_unit(hash64(i, 3)), hash_to_unit(hash64(i, 4))};
    append(m, test::icosphere(i % 3 == 0 ? 2 : 1, r, c));
  }
  return m;
}

// ---- checks ------------------------------------------------------------------

/// Independent density measure: share of the 3D area whose sqrt(area3D/areaUV),
/// normalised by its area-weighted mean, lies in [0.8, 1.25].
double area_in_density_bounds(const TriMesh& m, const SurfaceAtlas& a) {
  double sum = 0, sum_d = 0, inside = 0;
  std::vector<double> d(m.triangle_count(), -1);
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const double a3 = triangle_area(m, int(t));
    const Vec2* uv = &a.corner_uv[3 * t];
    const double auv = 0.5 * cross(uv[1] - uv[0], uv[2] - uv[0]);
    if (a3 <= 1e-14 || auv <= 0) continue;
    d[t] = std::sqrt(a3 / auv);
    sum += a3, sum_d += a3 * d[t];
  }
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    if (d[t] < 0) continue;
    const double n = d[t] / (sum_d / sum);
    if (n >= 0.8 && n <= 1.25) inside += triangle_area(m, int(t));
  }
  return sum > 0 ? inside / sum : 1;
}

/// Does the texel square [x,x+1]x[y,y+1] (texel units, y up), grown by
/// `margin` on every side, overlap the triangle?
bool texel_overlaps(const Vec2 p[3], int x, int y, double margin = 0) {
  const double lo_x = x - margin, hi_x = x + 1 + margin, lo_y = y - margin, hi_y = y + 1 + margin;
  if (std::max({p[0].x, p[1].x, p[2].x}) < lo_x || std::min({p[0].x, p[1].x, p[2].x}) > hi_x) return false;
  if (std::max({p[0].y, p[1].y, p[2].y}) < lo_y || std::min({p[0].y, p[1].y, p[2].y}) > hi_y) return false;
  const double orient = cross(p[1] - p[0], p[2] - p[0]) >= 0 ? 1 : -1;
  for (int k = 0; k < 3; ++k) {
    const Vec2 a = p[k], b = p[(k + 1) % 3];
    bool all_out = true;
    for (const Vec2 c : {Vec2{lo_x, lo_y}, Vec2{hi_x, lo_y}, Vec2{hi_x, hi_y}, Vec2{lo_x, hi_y}})
      all_out = all_out && orient * cross(b - a, c - a) < 0;
    if (all_out) return false;
  }
  return true;
}

/// The atlas claims the texels a triangle comes this close to (texels), so
/// that rounding of the uv never moves a triangle onto an unclaimed texel.
constexpr double kTouch = 1e-6;

/// Every chart's conservative footprint: the texels its triangles touch
/// (x from the left, y from the bottom, in texels).
std::vector<std::vector<std::pair<int, int>>> footprints(const TriMesh& m, const SurfaceAtlas& a) {
  const int n = a.resolution;
  std::vector<std::vector<std::pair<int, int>>> foot(a.chart_count);
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    Vec2 p[3];
    for (int k = 0; k < 3; ++k) p[k] = a.corner_uv[3 * t + k] * n;
    const int bx0 = std::max(0, int(std::floor(std::min({p[0].x, p[1].x, p[2].x}) - kTouch))),
              bx1 = std::min(n - 1, int(std::floor(std::max({p[0].x, p[1].x, p[2].x}) + kTouch))),
              by0 = std::max(0, int(std::floor(std::min({p[0].y, p[1].y, p[2].y}) - kTouch))),
              by1 = std::min(n - 1, int(std::floor(std::max({p[0].y, p[1].y, p[2].y}) + kTouch)));
    for (int y = by0; y <= by1; ++y)
      for (int x = bx0; x <= bx1; ++x)
        if (texel_overlaps(p, x, y, kTouch)) foot[a.chart_of_triangle[t]].emplace_back(x, y);
  }
  for (auto& f : foot) {
    std::sort(f.begin(), f.end());
    f.erase(std::unique(f.begin(), f.end()), f.end());
  }
  return foot;
}

/// The gutter as atlas.hpp states it: texels of a chart's footprint within
/// `gutter` texels (a square: 8-neighbour steps) of another chart's
/// footprint, and footprint texels closer than ceil(gutter / 2) to the
/// atlas's edges. Two charts overlapping count too (distance 0).
std::size_t gutter_violations(const TriMesh& m, const SurfaceAtlas& a, int gutter) {
  const int n = a.resolution;
  const auto foot = footprints(m, a);
  std::vector<int32_t> owner(std::size_t(n) * n, -1);
  std::size_t violations = 0;
  for (int c = 0; c < a.chart_count; ++c)
    for (const auto& [x, y] : foot[c]) {
      int32_t& o = owner[std::size_t(y) * n + x];
      if (o >= 0 && o != c) ++violations;
      o = c;
    }
  const int edge = (gutter + 1) / 2;
  for (int c = 0; c < a.chart_count; ++c) {
    for (const auto& [x, y] : foot[c]) {
      if (x < edge || y < edge || x >= n - edge || y >= n - edge) ++violations;
      // Another chart within G of a footprint texel is within G of a texel
      // on the footprint's rim too (walk from one to the other): only rim
      // texels need the search.
      bool rim = false;
      for (int dy = -1; dy <= 1 && !rim; ++dy)
        for (int dx = -1; dx <= 1 && !rim; ++dx) {
          const int xx = x + dx, yy = y + dy;
          rim = xx < 0 || yy < 0 || xx >= n || yy >= n || owner[std::size_t(yy) * n + xx] != c;
        }
      if (!rim) continue;
      // The square of side 2G+1 around the texel holds no other chart.
      for (int yy = std::max(0, y - gutter); yy <= std::min(n - 1, y + gutter); ++yy)
        for (int xx = std::max(0, x - gutter); xx <= std::min(n - 1, x + gutter); ++xx) {
          const int32_t o = owner[std::size_t(yy) * n + xx];
          if (o >= 0 && o != c) ++violations;
        }
    }
  }
  return violations;
}

/// The smallest distance (8-neighbour steps, max(|dx|, |dy|)) between
/// texel-map texels of two different charts; INT32_MAX for fewer than two charts.
int closest_chart_texels(const SurfaceAtlas& a, int reach) {
  const int n = a.resolution;
  std::vector<int32_t> chart(std::size_t(n) * n, -1);
  for (std::size_t i = 0; i < a.texels.size(); ++i) chart[a.texels.texel[i]] = a.chart_of_triangle[a.texels.triangle[i]];
  int best = INT32_MAX;
  for (std::size_t i = 0; i < a.texels.size(); ++i) {
    const int x = int(a.texels.texel[i] % n), y = int(a.texels.texel[i] / n);
    const int32_t c = chart[a.texels.texel[i]];
    for (int yy = std::max(0, y - reach); yy <= std::min(n - 1, y + reach); ++yy)
      for (int xx = std::max(0, x - reach); xx <= std::min(n - 1, x + reach); ++xx) {
        const int32_t o = chart[std::size_t(yy) * n + xx];
        if (o >= 0 && o != c) best = std::min(best, std::max(std::abs(xx - x), std::abs(yy - y)));
      }
  }
  return best;
}

struct Expect {
  double density_share = 0.95;  ///< area share within [0.8, 1.25]
  double utilization = 0;       ///< lower bound
};

/// The bounds every atlas must hold (issue 4).
void check_atlas(const TriMesh& m, const SurfaceAtlas& a, const AtlasOptions& o, const Expect& e = {}) {
  const std::size_t nt = m.triangle_count();
  ASSERT_EQ(a.resolution, o.resolution);
  ASSERT_EQ(a.corner_uv.size(), 3 * nt);
  ASSERT_EQ(a.chart_of_triangle.size(), nt);
  EXPECT_EQ(a.report.charts, a.chart_count);
  // Every triangle in exactly one chart, and no chart empty.
  std::vector<int> per_chart(a.chart_count, 0);
  for (int32_t c : a.chart_of_triangle) {
    ASSERT_GE(c, 0);
    ASSERT_LT(c, a.chart_count);
    ++per_chart[c];
  }
  for (int c = 0; c < a.chart_count; ++c) EXPECT_GT(per_chart[c], 0) << "chart " << c;
  // uv inside [0,1]; no flipped triangle (3D area above noise must map to positive uv area).
  const Vec3 diag = bounding_box(m).size();
  std::size_t flipped = 0;
  for (std::size_t t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const Vec2 p = a.corner_uv[3 * t + k];
      ASSERT_TRUE(p.x >= 0 && p.x <= 1 && p.y >= 0 && p.y <= 1) << "triangle " << t << " uv " << p.x << "," << p.y;
    }
    const Vec2* uv = &a.corner_uv[3 * t];
    if (triangle_area(m, int(t)) > 1e-9 * norm2(diag) && !(cross(uv[1] - uv[0], uv[2] - uv[0]) > 0)) ++flipped;
  }
  EXPECT_EQ(flipped, 0u);
  EXPECT_EQ(a.report.flipped_triangles, 0u);
  EXPECT_EQ(gutter_violations(m, a, a.report.packing_overflow ? 0 : o.gutter), 0u);
  const double share = area_in_density_bounds(m, a);
  EXPECT_GE(share, e.density_share);
  EXPECT_NEAR(a.report.area_in_density_bounds, share, 1e-6);
  EXPECT_GE(a.report.utilization, e.utilization);
  EXPECT_DOUBLE_EQ(a.report.utilization, double(a.texels.size()) / (double(o.resolution) * o.resolution));
  // Texel map: sorted, valid barycentrics, and the texel centre is where
  // the triangle's uv puts the 3D point of (triangle, b1, b2).
  const int n = o.resolution;
  for (std::size_t i = 0; i < a.texels.size(); ++i) {
    if (i > 0) {
      ASSERT_LT(a.texels.texel[i - 1], a.texels.texel[i]);
    }
    const int32_t t = a.texels.triangle[i];
    ASSERT_GE(t, 0);
    ASSERT_LT(std::size_t(t), nt);
    float fb1, fb2;
    texel_barycentrics(a.corner_uv, a.resolution, a.texels.texel[i], t, fb1, fb2);
    const double b1 = fb1, b2 = fb2, b0 = 1 - b1 - b2;
    ASSERT_TRUE(b1 >= 0 && b2 >= 0 && b0 >= -1e-6);
    const Vec2 uv = a.corner_uv[3 * t] * b0 + a.corner_uv[3 * t + 1] * b1 + a.corner_uv[3 * t + 2] * b2;
    const uint32_t x = a.texels.texel[i] % n, y = a.texels.texel[i] / n;
    ASSERT_NEAR(uv.x * n, x + 0.5, 1e-3);
    ASSERT_NEAR(uv.y * n, n - (y + 0.5), 1e-3);
  }
}

AtlasOptions options(int resolution, int gutter = 4) {
  AtlasOptions o;
  o.resolution = resolution;
  o.gutter = gutter;
  return o;
}

// ---- tests -------------------------------------------------------------------

TEST(SurfaceAtlas, SphereHoldsTheBounds) {
  const TriMesh m = test::icosphere(5, 1.0);  // 20480 triangles
  const AtlasOptions o = options(2048);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 0.95, .utilization = 0.5});
  EXPECT_GE(a.chart_count, 6);  // a closed sphere must be cut
}

TEST(SurfaceAtlas, TorusHoldsTheBounds) {
  const TriMesh m = torus(120, 48, 1.0, 0.35);
  const AtlasOptions o = options(2048);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 0.95, .utilization = 0.5});
}

TEST(SurfaceAtlas, ClosedBoxKeepsFacesFlatAndSeparate) {
  const TriMesh m = closed_box(12, {1.0, 0.6, 0.3});
  const AtlasOptions o = options(1024);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 1.0, .utilization = 0.5});
  // Sharp corners: no chart crosses a 90-degree edge, and a flat face maps
  // isometrically, so every triangle has exactly the mean density.
  std::vector<Vec3> chart_normal(a.chart_count);
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const Vec3 n = normalized(triangle_normal_area2(m, int(t)));
    Vec3& cn = chart_normal[a.chart_of_triangle[t]];
    if (norm2(cn) == 0) cn = n;
    EXPECT_GT(dot(cn, n), 0.999) << "triangle " << t;
  }
  EXPECT_NEAR(a.report.density_p95_low, 1.0, 1e-6);
  EXPECT_NEAR(a.report.density_p95_high, 1.0, 1e-6);
}

TEST(SurfaceAtlas, LongStripIsCutSoThatItDoesNotSetTheScale) {
  // A 6 m x 0.1 m strip (a stream) next to a box: one chart that long
  // would span the atlas alone at a tiny scale. No chart may be longer
  // than half the square root of the surface area.
  TriMesh m = test::plane_grid(240, 4, 6.0, 0.1);
  append(m, closed_box(8, {0.5, 0.5, 0.5}), {0, 1, 0});
  const AtlasOptions o = options(1024);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 1.0, .utilization = 0.6});
  double area = 0;
  for (std::size_t t = 0; t < m.triangle_count(); ++t) area += triangle_area(m, int(t));
  const double limit = 0.5 * std::sqrt(area) * a.report.texels_per_metre / o.resolution;  // atlas uv units
  std::vector<std::vector<Vec2>> uv(a.chart_count);
  for (std::size_t t = 0; t < m.triangle_count(); ++t)
    for (int k = 0; k < 3; ++k) uv[a.chart_of_triangle[t]].push_back(a.corner_uv[3 * t + k]);
  for (int c = 0; c < a.chart_count; ++c) {
    // Diameter bounds the long side of the minimum-area rectangle from
    // below; the long side is at most the diameter: check the diameter
    // against the limit with the square's sqrt(2) of slack.
    double diameter = 0;
    for (const Vec2& p : uv[c])
      for (const Vec2& q : uv[c]) diameter = std::max(diameter, norm(p - q));
    EXPECT_LE(diameter, limit * std::sqrt(2.0) * 1.0001) << "chart " << c;
  }
}

TEST(SurfaceAtlas, PlanarChartIsAnIsometryUpToScale) {
  // LSCM of a flat patch: angles and length ratios kept exactly.
  TriMesh m = test::plane_grid(24, 16, 2.0, 1.0);
  for (Vec3& p : m.positions) p = test::rotate(p, normalized(Vec3{1, 2, 3}), 0.7);
  const AtlasOptions o = options(1024);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 1.0, .utilization = 0.5});
  double scale = 0;
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const Tri& f = m.triangles[t];
    for (int k = 0; k < 3; ++k) {
      const double l3 = norm(m.positions[f[(k + 1) % 3]] - m.positions[f[k]]);
      const double luv = norm(a.corner_uv[3 * t + (k + 1) % 3] - a.corner_uv[3 * t + k]);
      if (scale == 0) scale = luv / l3;
      EXPECT_NEAR(luv / l3, scale, 1e-6 * scale);
    }
  }
}

TEST(SurfaceAtlas, NonManifoldAndDegenerateTrianglesGetAPlace) {
  const TriMesh m = non_manifold_mesh();
  const AtlasOptions o = options(1024);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 0.99});
  // Degenerate triangles collapse to a point (zero uv area) and claim no texel.
  const std::size_t nt = m.triangle_count();
  for (std::size_t t = nt - 3; t < nt; ++t) {
    const Vec2* uv = &a.corner_uv[3 * t];
    EXPECT_EQ(cross(uv[1] - uv[0], uv[2] - uv[0]), 0.0) << "triangle " << t;
  }
  for (int32_t t : a.texels.triangle) EXPECT_LT(std::size_t(t), nt - 3);
  // The repeated-index and collinear triangles join the chart of a box triangle sharing their vertex.
  for (std::size_t t = nt - 3; t < nt - 1; ++t) {
    bool shares = false;
    for (std::size_t u = 0; u < nt - 3; ++u)
      if (a.chart_of_triangle[u] == a.chart_of_triangle[t])
        for (int32_t v : m.triangles[u])
          for (int32_t w : m.triangles[t]) shares = shares || v == w;
    EXPECT_TRUE(shares) << "degenerate triangle " << t << " sits in a chart that does not hold its vertices";
  }
}

TEST(SurfaceAtlas, HundredsOfDropletsGetTheirOwnCharts) {
  const TriMesh m = droplets(300);
  const AtlasOptions o = options(2048);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  check_atlas(m, a, o, {.density_share = 0.95});
  std::vector<int> comp;
  const int components = triangle_components(m, comp);
  ASSERT_EQ(components, 300);
  EXPECT_GE(a.chart_count, 2 * components);  // closed: at least two charts each
  for (std::size_t t = 0; t < m.triangle_count(); ++t)
    for (std::size_t u = t + 1; u < std::min(m.triangle_count(), t + 20); ++u)
      if (a.chart_of_triangle[t] == a.chart_of_triangle[u]) {
        EXPECT_EQ(comp[t], comp[u]);
      }
}

TEST(SurfaceAtlas, OverAThousandChartsReachTheUtilizationFloor) {
  // Issue 15: at least 62% of a 4096^2 atlas in chart texels with over a
  // thousand charts (no shared frame has that many: droplets around a
  // bumpy sphere and a torus stand in for a spray of a large dam break).
  TriMesh m = droplets(160);
  append(m, test::icosphere(4, 0.5), {2, 0, 0});
  append(m, torus(96, 32, 0.6, 0.2), {0, 3, 0});
  const AtlasOptions o = options(4096);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  EXPECT_GT(a.chart_count, 1000);
  check_atlas(m, a, o, {.density_share = 0.95, .utilization = 0.62});
}

// Two atlases are the same, chart for chart and texel for texel.
void expect_same_atlas(const SurfaceAtlas& a, const SurfaceAtlas& b) {
  EXPECT_EQ(a.resolution, b.resolution);
  EXPECT_EQ(a.chart_count, b.chart_count);
  EXPECT_EQ(a.chart_of_triangle, b.chart_of_triangle);
  EXPECT_TRUE(a.corner_uv == b.corner_uv);
  EXPECT_EQ(a.texels.texel, b.texels.texel);
  EXPECT_EQ(a.texels.triangle, b.texels.triangle);
}

TEST(SurfaceAtlas, SameAtlasForOneAndTwoThreads) {
  TriMesh m = droplets(40);
  append(m, test::icosphere(4, 0.5, {2, 0, 0}));
  append(m, torus(60, 24, 1.0, 0.3), {0, 3, 0});
  const AtlasOptions o = options(1024);
  set_thread_count(1);
  const SurfaceAtlas one = build_surface_atlas(m, o);
  set_thread_count(2);
  const SurfaceAtlas two = build_surface_atlas(m, o);
  set_thread_count(0);
  expect_same_atlas(one, two);
}

// The bake builds its tracking and output atlases from one segmentation and
// flattening (build_surface_atlases): each must be exactly the atlas built
// alone for its options, on a synthetic mesh and on a shared frame.
void expect_built_together_as_alone(const TriMesh& m) {
  AtlasOptions tracking = options(512, 2), output = options(1024, 4);
  const std::vector<SurfaceAtlas> both = build_surface_atlases(m, {tracking, output});
  ASSERT_EQ(both.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const SurfaceAtlas alone = build_surface_atlas(m, k == 0 ? tracking : output);
    expect_same_atlas(both[k], alone);
    EXPECT_EQ(both[k].report.utilization, alone.report.utilization);
  }
  EXPECT_NE(both[0].texels.size(), both[1].texels.size());  // two resolutions, really
  output.max_stretch = tracking.max_stretch * 1.5;
  EXPECT_THROW(build_surface_atlases(m, {tracking, output}), UsageError);
}

TEST(SurfaceAtlas, AtlasesBuiltTogetherAreTheAtlasesBuiltAlone) {
  TriMesh m = droplets(30);
  append(m, test::icosphere(4, 0.5, {2, 0, 0}));
  append(m, torus(60, 24, 1.0, 0.3), {0, 3, 0});
  expect_built_together_as_alone(m);
}

TEST(SurfaceAtlas, TexelMapHoldsEveryTexelCentreInsideAChart) {
  // Known answer: brute force over texel centres against every triangle.
  const TriMesh m = test::icosphere(2, 1.0);
  const AtlasOptions o = options(256, 2);
  const SurfaceAtlas a = build_surface_atlas(m, o);
  const int n = o.resolution;
  std::vector<int32_t> expect(std::size_t(n) * n, -1);
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const Vec2 p0 = a.corner_uv[3 * t] * n, p1 = a.corner_uv[3 * t + 1] * n, p2 = a.corner_uv[3 * t + 2] * n;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Vec2 c{x + 0.5, n - (y + 0.5)};
        if (cross(p1 - p0, c - p0) > 1e-7 && cross(p2 - p1, c - p1) > 1e-7 && cross(p0 - p2, c - p2) > 1e-7) {
          int32_t& e = expect[std::size_t(y) * n + x];
          if (e < 0) e = int32_t(t);
        }
      }
  }
  std::size_t strictly_inside = 0;
  for (std::size_t i = 0; i < expect.size(); ++i) {
    if (expect[i] < 0) continue;
    ++strictly_inside;
    const auto it = std::lower_bound(a.texels.texel.begin(), a.texels.texel.end(), uint32_t(i));
    ASSERT_TRUE(it != a.texels.texel.end() && *it == i) << "texel " << i << " missing";
    EXPECT_EQ(a.texels.triangle[it - a.texels.texel.begin()], expect[i]);
  }
  EXPECT_GE(a.texels.size(), strictly_inside);
  EXPECT_LE(a.texels.size(), strictly_inside + strictly_inside / 20);  // only edge-exact centres on top
  // The 3D point of a texel maps back to the texel's uv.
  for (std::size_t i = 0; i < a.texels.size(); i += 7) {
    const int32_t t = a.texels.triangle[i];
    const Tri& f = m.triangles[t];
    float fb1, fb2;
    texel_barycentrics(a.corner_uv, a.resolution, a.texels.texel[i], t, fb1, fb2);
    const double b1 = fb1, b2 = fb2;
    const Vec3 p = m.positions[f[0]] * (1 - b1 - b2) + m.positions[f[1]] * b1 + m.positions[f[2]] * b2;
    // Barycentrics of p recovered in 3D, then through the corner uvs.
    const Vec3 e1 = m.positions[f[1]] - m.positions[f[0]], e2 = m.positions[f[2]] - m.positions[f[0]], d = p - m.positions[f[0]];
    const double d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2), det = d11 * d22 - d12 * d12;
    const double c1 = (d22 * dot(d, e1) - d12 * dot(d, e2)) / det, c2 = (d11 * dot(d, e2) - d12 * dot(d, e1)) / det;
    const Vec2 uv = a.corner_uv[3 * t] * (1 - c1 - c2) + a.corner_uv[3 * t + 1] * c1 + a.corner_uv[3 * t + 2] * c2;
    const uint32_t x = a.texels.texel[i] % n, y = a.texels.texel[i] / n;
    EXPECT_NEAR(uv.x, (x + 0.5) / n, 1e-4);
    EXPECT_NEAR(uv.y, 1 - (y + 0.5) / n, 1e-4);
  }
}

TEST(SurfaceAtlas, ChartsShareTheirGutter) {
  // G empty texels between neighbours, not 2G: no texel within G of a
  // chart's footprint lies in another chart's footprint, so two charts'
  // texels are at least G + 1 steps apart; and neighbours do come closer
  // than the 2G + 1 that a gutter owned by each chart kept them.
  TriMesh m = droplets(60);
  append(m, closed_box(8, {0.3, 0.2, 0.1}), {2, 0, 0});
  append(m, torus(48, 16, 0.2, 0.07), {0, 2, 0});
  for (int gutter : {4, 3, 1, 0}) {
    SCOPED_TRACE("gutter " + std::to_string(gutter));
    const AtlasOptions o = options(1024, gutter);
    const SurfaceAtlas a = build_surface_atlas(m, o);
    ASSERT_FALSE(a.report.packing_overflow);
    check_atlas(m, a, o, {.density_share = 0.95});
    EXPECT_EQ(gutter_violations(m, a, gutter), 0u);
    const int closest = closest_chart_texels(a, 2 * gutter + 2);
    EXPECT_GE(closest, gutter + 1);
    if (gutter >= 3) {
      EXPECT_LE(closest, 2 * gutter);
    }
  }
}

TEST(SurfaceAtlas, ReportSplitsTheAtlasIntoChartsGuttersAndPacking) {
  // Known answer by brute force: the texels within ceil(G/2) of a chart's
  // footprint are the charts with their half of the gutters; the chart
  // texels among them are the utilization, the others are lost to gutters
  // and everything else to packing.
  TriMesh m = closed_box(6, {1.0, 0.6, 0.3});
  append(m, droplets(12), {2, 0, 0});
  for (int gutter : {4, 3}) {
    SCOPED_TRACE("gutter " + std::to_string(gutter));
    const AtlasOptions o = options(256, gutter);
    const SurfaceAtlas a = build_surface_atlas(m, o);
    const int n = o.resolution, r = (gutter + 1) / 2;
    std::vector<uint8_t> claimed(std::size_t(n) * n, 0);
    for (const auto& f : footprints(m, a))
      for (const auto& [x, y] : f)
        for (int yy = std::max(0, y - r); yy <= std::min(n - 1, y + r); ++yy)
          for (int xx = std::max(0, x - r); xx <= std::min(n - 1, x + r); ++xx) claimed[std::size_t(yy) * n + xx] = 1;
    const double share = double(std::count(claimed.begin(), claimed.end(), 1)) / (double(n) * n);
    EXPECT_NEAR(a.report.utilization + a.report.lost_to_gutters, share, 1e-12);
    EXPECT_NEAR(a.report.lost_to_packing, 1 - share, 1e-12);
    EXPECT_GT(a.report.lost_to_gutters, 0);
    EXPECT_GT(a.report.lost_to_packing, 0);
  }
}

TEST(SurfaceAtlas, EmptyMeshGivesAnEmptyAtlas) {
  const SurfaceAtlas a = build_surface_atlas(TriMesh{}, options(64));
  EXPECT_EQ(a.chart_count, 0);
  EXPECT_TRUE(a.corner_uv.empty());
  EXPECT_EQ(a.texels.size(), 0u);
}

using test::dam_break_frame;

TEST(SurfaceAtlas, DamBreakFramesHoldTheBounds) {
  LAPFLOW_NEED_SHARED(dam_break_frame(1));
  for (int frame : {1, 30, 60, 100}) {
    SCOPED_TRACE("frame " + std::to_string(frame));
    const TriMesh m = read_mesh(dam_break_frame(frame));
    const AtlasOptions o = options(2048);
    const SurfaceAtlas a = build_surface_atlas(m, o);
    check_atlas(m, a, o, {.density_share = 0.95, .utilization = 0.5});
  }
}

/// ../shared/data/SCENE/SCENE.NNNN.ply (it may be absent).
std::string shared_frame(const std::string& scene, int frame) {
  char name[32];
  std::snprintf(name, sizeof name, ".%04d.ply", frame);
  return std::string(LAPFLOW_SOURCE_DIR "/../shared/data/") + scene + "/" + scene + name;
}

TEST(SurfaceAtlas, SharedFramesReachTheUtilizationFloorAt4096) {
  // Issue 15: at least 68% of a 4096^2 atlas in chart texels on every frame
  // of the shared dam_break and splash. The two lowest frames of each after
  // the change (docs/atlas.md, "Denser atlases"), and dam_break 28, the
  // lowest before it.
  const std::pair<const char*, int> frames[] = {{"dam_break", 65}, {"dam_break", 75}, {"dam_break", 28},
                                                {"splash", 11}, {"splash", 12}};
  for (const auto& [scene, frame] : frames)
    LAPFLOW_NEED_SHARED(shared_frame(scene, frame));
  for (const auto& [scene, frame] : frames) {
    SCOPED_TRACE(shared_frame(scene, frame));
    const TriMesh m = read_mesh(shared_frame(scene, frame));
    const AtlasOptions o = options(4096);
    const SurfaceAtlas a = build_surface_atlas(m, o);
    EXPECT_GE(a.report.utilization, 0.68);
    EXPECT_GE(a.report.area_in_density_bounds, 0.99);
    EXPECT_EQ(a.report.flipped_triangles, 0u);
    EXPECT_FALSE(a.report.packing_overflow);
    EXPECT_EQ(gutter_violations(m, a, o.gutter), 0u);
    EXPECT_NEAR(a.report.utilization + a.report.lost_to_gutters + a.report.lost_to_packing, 1.0, 1e-12);
  }
}

TEST(SurfaceAtlas, SharedFrameIsTheSameAtlasForOneAndTwoThreads) {
  LAPFLOW_NEED_SHARED(shared_frame("splash", 30));
  const TriMesh m = read_mesh(shared_frame("splash", 30));
  const AtlasOptions o = options(2048);
  set_thread_count(1);
  const SurfaceAtlas one = build_surface_atlas(m, o);
  set_thread_count(2);
  const SurfaceAtlas two = build_surface_atlas(m, o);
  set_thread_count(0);
  EXPECT_EQ(one.chart_of_triangle, two.chart_of_triangle);
  EXPECT_TRUE(one.corner_uv == two.corner_uv);
  EXPECT_EQ(one.texels.texel, two.texels.texel);
}

TEST(SurfaceAtlas, SharedFrameBuiltTogetherIsTheAtlasBuiltAlone) {
  LAPFLOW_NEED_SHARED(shared_frame("splash", 12));
  expect_built_together_as_alone(read_mesh(shared_frame("splash", 12)));
}

}  // namespace
}  // namespace lapflow
