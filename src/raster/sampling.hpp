#pragma once
// Inline exemplar lookups for the rasterizer's inner loops (the public
// wrappers in raster.hpp call these). Kept header-only so the raster and
// resolve passes inline them: they run once per covered texel.
#include <algorithm>
#include <cmath>

#include "lapflow/raster/raster.hpp"

namespace lapflow::detail {

/// Bilinear lookup of an n-channel image at (u, v), v = 0 at the bottom row,
/// clamped at the borders: the same convention as sample_bilinear.
template <int C>
inline void bilinear(const Image& img, double u, double v, float* out) {
  const double fx = std::clamp(u * img.width - 0.5, 0.0, double(img.width - 1));
  const double fy = std::clamp((1.0 - v) * img.height - 0.5, 0.0, double(img.height - 1));
  const int x0 = int(fx), y0 = int(fy);
  const int x1 = std::min(x0 + 1, img.width - 1), y1 = std::min(y0 + 1, img.height - 1);
  const float ax = float(fx - x0), ay = float(fy - y0);
  const float* p00 = &img.pixels[(std::size_t(y0) * img.width + x0) * C];
  const float* p10 = &img.pixels[(std::size_t(y0) * img.width + x1) * C];
  const float* p01 = &img.pixels[(std::size_t(y1) * img.width + x0) * C];
  const float* p11 = &img.pixels[(std::size_t(y1) * img.width + x1) * C];
  for (int c = 0; c < C; ++c) {
    const float top = p00[c] * (1 - ax) + p10[c] * ax;
    const float bottom = p01[c] * (1 - ax) + p11[c] * ax;
    out[c] = top * (1 - ay) + bottom * ay;
  }
}

inline bool keeps(const ErosionMap& map, double u, double v, double w, RasterMode mode) {
  if (!(u >= 0 && u <= 1 && v >= 0 && v <= 1)) return false;  // also rejects NaN
  if (mode == RasterMode::NoErosion) return true;
  if (mode == RasterMode::Blend) return w > 0;  // every covering patch contributes, weighted by w
  float f;
  bilinear<1>(map.feature, u, v, &f);
  const double d = std::sqrt((u - 0.5) * (u - 0.5) + (v - 0.5) * (v - 0.5));
  const double D = std::max(0.0, 1.0 - d / 0.5);
  return std::sqrt(double(f) + D) * map.inv_max - map.epsilon >= 1.0 - w;
}

/// The erosion test where the patch holds (u, v) (RasterOptions::hold):
/// `held.feature` is the feature map's maximum over `reach` in uv, D(u, v)
/// is raised by its largest change over that distance, and the bar is
/// lowered by `margin`.
inline bool keeps_held(const ErosionMap& held, double reach, double margin, double u, double v, double w) {
  if (!(u >= 0 && u <= 1 && v >= 0 && v <= 1)) return false;
  float f;
  bilinear<1>(held.feature, u, v, &f);
  const double d = std::sqrt((u - 0.5) * (u - 0.5) + (v - 0.5) * (v - 0.5));
  const double D = std::min(1.0, std::max(0.0, 1.0 - d / 0.5) + 2 * reach);
  return std::sqrt(double(f) + D) * held.inv_max - held.epsilon >= 1.0 - w - margin;
}

inline void sample(const ExemplarMips& mips, double u, double v, double lod, float out[4], bool trilinear = true) {
  const int last = int(mips.levels.size()) - 1;
  if (lod <= 0 || last == 0) {
    bilinear<4>(mips.levels[0], u, v, out);
    return;
  }
  if (!trilinear) {  // nearest level: half the cost, a step when lod crosses .5 between frames
    bilinear<4>(mips.levels[std::min(int(lod + 0.5), last)], u, v, out);
    return;
  }
  const int l0 = std::min(int(lod), last);
  const int l1 = std::min(l0 + 1, last);
  const float t = l0 == last ? 0.f : float(lod - l0);
  bilinear<4>(mips.levels[l0], u, v, out);
  if (t == 0.f) return;
  float hi[4];
  bilinear<4>(mips.levels[l1], u, v, hi);
  for (int c = 0; c < 4; ++c) out[c] += (hi[c] - out[c]) * t;
}

}  // namespace lapflow::detail
