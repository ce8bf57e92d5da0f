// The texel map of an atlas (build_texel_map): every texel whose centre
// lies in a triangle's uv image, with that triangle (the lowest index on
// shared edges), sorted by texel index.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "atlas/internal.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow::atlas_detail {

TexelMap build_texel_map(const std::vector<Vec2>& corner_uv, int resolution) {
  // Bands of 16 image rows, each rasterised by one task into a small owner
  // buffer that stays in cache: triangles in increasing index claim only free
  // texels, so ties on shared edges go to the lowest index without atomics.
  // Two passes (count, then fill at the band's offset) keep the output sorted
  // without a merge.
  const int n = resolution;
  const std::size_t nt = corner_uv.size() / 3;
  constexpr int kBand = 16;
  const int bands = (n + kBand - 1) / kBand;
  std::vector<int32_t> top(nt, -1), bottom(nt, -1);  // image rows (from the top) of each triangle
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      const Vec2 a = corner_uv[3 * t] * n, bb = corner_uv[3 * t + 1] * n, c = corner_uv[3 * t + 2] * n;
      if (!(cross(bb - a, c - a) > 0)) continue;
      const int yb0 = std::max(0, int(std::ceil(std::min({a.y, bb.y, c.y}) - 0.5)));
      const int yb1 = std::min(n - 1, int(std::floor(std::max({a.y, bb.y, c.y}) - 0.5)));
      if (yb0 > yb1) continue;
      top[t] = n - 1 - yb1;
      bottom[t] = n - 1 - yb0;
    }
  }, 1024);
  std::vector<std::size_t> band_offs(std::size_t(bands) + 1, 0);
  for (std::size_t t = 0; t < nt; ++t)
    if (top[t] >= 0)
      for (int k = top[t] / kBand; k <= bottom[t] / kBand; ++k) ++band_offs[k + 1];
  for (int k = 0; k < bands; ++k) band_offs[k + 1] += band_offs[k];
  std::vector<int32_t> band_tris(band_offs[bands]);
  {
    std::vector<std::size_t> fill(band_offs.begin(), band_offs.end() - 1);
    for (std::size_t t = 0; t < nt; ++t)
      if (top[t] >= 0)
        for (int k = top[t] / kBand; k <= bottom[t] / kBand; ++k) band_tris[fill[k]++] = int32_t(t);
  }

  auto raster_band = [&](int k, std::vector<int32_t>& owner) {
    const int row0 = k * kBand, row1 = std::min(n, row0 + kBand);
    owner.assign(std::size_t(row1 - row0) * n, INT32_MAX);
    for (std::size_t i = band_offs[k]; i < band_offs[k + 1]; ++i) {
      const int32_t t = band_tris[i];
      const Vec2 a = corner_uv[3 * std::size_t(t)] * n, b = corner_uv[3 * std::size_t(t) + 1] * n,
                 c = corner_uv[3 * std::size_t(t) + 2] * n;
      const double area2 = cross(b - a, c - a);
      // Inclusive edges with a little slack so that no texel centre on a
      // shared edge falls between two triangles.
      const double eps = -1e-9 * area2;
      const int x0 = std::max(0, int(std::ceil(std::min({a.x, b.x, c.x}) - 0.5)));
      const int x1 = std::min(n - 1, int(std::floor(std::max({a.x, b.x, c.x}) - 0.5)));
      const Vec2 corner[3] = {a, b, c};
      for (int y = std::max(row0, top[t]); y <= std::min(row1 - 1, bottom[t]); ++y) {
        const double py = (n - 1 - y) + 0.5;
        int32_t* row = owner.data() + std::size_t(y - row0) * n;
        // Only the pixels near the triangle's span on this row are tested
        // (the exact test below decides): the span of the edges' crossings
        // of the row, a pixel wider on each side against round-off.
        double lo = INFINITY, hi = -INFINITY;
        for (int k = 0; k < 3; ++k) {
          const Vec2 &p0 = corner[k], &p1 = corner[(k + 1) % 3];
          if ((p0.y - py) * (p1.y - py) > 0) continue;  // the edge does not reach the row
          const double x = p0.y == p1.y ? p0.x : p0.x + (p1.x - p0.x) * ((py - p0.y) / (p1.y - p0.y));
          const double x_other = p0.y == p1.y ? p1.x : x;
          lo = std::min({lo, x, x_other}), hi = std::max({hi, x, x_other});
        }
        if (!(lo <= hi)) lo = std::min({a.x, b.x, c.x}), hi = std::max({a.x, b.x, c.x});
        const int sx0 = std::max(x0, int(std::floor(lo - 0.5)) - 1);
        const int sx1 = std::min(x1, int(std::ceil(hi - 0.5)) + 1);
        for (int x = sx0; x <= sx1; ++x) {
          if (row[x] != INT32_MAX) continue;
          const Vec2 p{x + 0.5, py};
          if (cross(c - b, p - b) >= eps && cross(a - c, p - c) >= eps && cross(b - a, p - a) >= eps) row[x] = t;
        }
      }
    }
    return row0;
  };

  // Band owner buffers are kept between the passes (a quarter of the size
  // of the output arrays; cheaper than rasterising twice).
  std::vector<std::vector<int32_t>> owners(bands);
  std::vector<std::size_t> count(std::size_t(bands) + 1, 0);
  parallel_for(std::size_t(bands), [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      raster_band(int(k), owners[k]);
      count[k + 1] = std::size_t(std::count_if(owners[k].begin(), owners[k].end(), [](int32_t t) { return t != INT32_MAX; }));
    }
  }, 1);
  for (int k = 0; k < bands; ++k) count[k + 1] += count[k];
  TexelMap map;
  const std::size_t total = count[bands];
  // The two arrays are first touched by different tasks (page faults of
  // hundreds of megabytes at 4096^2 are a large part of the cost).
  parallel_for(2, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      if (i == 0) map.texel.resize(total);
      if (i == 1) map.triangle.resize(total);
    }
  }, 1);
  parallel_for(std::size_t(bands), [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      std::vector<int32_t> owner = std::move(owners[k]);
      const int row0 = int(k) * kBand;
      std::size_t out = count[k];
      // Row by row (no division per texel).
      const std::size_t rows = owner.size() / std::size_t(n);
      for (std::size_t r = 0; r < rows; ++r) {
        const std::size_t y = std::size_t(row0) + r;
        const int32_t* row = owner.data() + r * std::size_t(n);
        for (std::size_t x = 0; x < std::size_t(n); ++x) {
          const int32_t t = row[x];
          if (t == INT32_MAX) continue;
          map.texel[out] = uint32_t(y * n + x);
          map.triangle[out] = t;
          ++out;
        }
      }
    }
  }, 1);
  return map;
}

}  // namespace lapflow::atlas_detail
