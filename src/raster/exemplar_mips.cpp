// What the rasterizer precomputes from the exemplar once per bake: the
// box-filtered mip pyramid (antialiasing: exemplar texels are often much
// smaller than atlas texels) and the erosion map's constant M.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"
#include "raster/sampling.hpp"

namespace lapflow {
namespace {

// 2x2 box filter; an odd last column/row is averaged with itself (clamped),
// which keeps every level covering the same [0,1]^2.
Image half_size(const Image& src) {
  const int w = std::max(1, src.width / 2), h = std::max(1, src.height / 2);
  Image dst(w, h, src.channels);
  parallel_for(std::size_t(h), [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (int x = 0; x < w; ++x) {
        const int sx0 = std::min(2 * x, src.width - 1), sx1 = std::min(2 * x + 1, src.width - 1);
        const int sy0 = std::min(int(2 * y), src.height - 1), sy1 = std::min(int(2 * y + 1), src.height - 1);
        for (int c = 0; c < src.channels; ++c)
          dst.at(x, int(y), c) =
              0.25f * (src.at(sx0, sy0, c) + src.at(sx1, sy0, c) + src.at(sx0, sy1, c) + src.at(sx1, sy1, c));
      }
  }, 16);
  return dst;
}

}  // namespace

ExemplarMips build_exemplar_mips(const Exemplar& ex) {
  if (ex.color.empty() || ex.color.channels < 3)
    throw std::invalid_argument("build_exemplar_mips: the exemplar has no RGB colour image");
  const bool has_disp = ex.displacement.width == ex.color.width && ex.displacement.height == ex.color.height &&
                        ex.displacement.channels >= 1;
  Image base(ex.color.width, ex.color.height, 4);
  for (int y = 0; y < base.height; ++y)
    for (int x = 0; x < base.width; ++x) {
      for (int c = 0; c < 3; ++c) base.at(x, y, c) = ex.color.at(x, y, c);
      base.at(x, y, 3) = has_disp ? ex.displacement.at(x, y, 0) : 0.f;
    }
  ExemplarMips mips;
  mips.levels.push_back(std::move(base));
  while (mips.levels.back().width > 1 || mips.levels.back().height > 1)
    mips.levels.push_back(half_size(mips.levels.back()));
  return mips;
}

ErosionMap build_erosion_map(const Image& feature, double epsilon) {
  if (feature.empty() || feature.channels != 1)
    throw std::invalid_argument("build_erosion_map: the feature map must have exactly 1 channel");
  ErosionMap map;
  map.feature = feature;
  map.epsilon = epsilon;
  // M over the pixel centres, as the paper's "maximum over the exemplar".
  double m = 0;
  for (int y = 0; y < feature.height; ++y)
    for (int x = 0; x < feature.width; ++x) {
      const double u = (x + 0.5) / feature.width, v = 1.0 - (y + 0.5) / feature.height;
      const double d = std::sqrt((u - 0.5) * (u - 0.5) + (v - 0.5) * (v - 0.5));
      const double D = std::max(0.0, 1.0 - d / 0.5);
      m = std::max(m, std::sqrt(std::max(0.0, double(feature.at(x, y, 0))) + D));
    }
  map.inv_max = m > 0 ? 1.0 / m : 1.0;
  return map;
}

RasterExemplar prepare_raster_exemplar(const Exemplar& exemplar, double epsilon) {
  RasterExemplar r;
  r.mips = build_exemplar_mips(exemplar);
  r.erosion = build_erosion_map(exemplar.feature, epsilon);
  r.tables = std::make_shared<ExemplarTables>();
  return r;
}

RasterExemplar prepare_raster_exemplar(std::span<const Exemplar> frames, double epsilon) {
  if (frames.empty()) throw std::invalid_argument("prepare_raster_exemplar: no frames");
  RasterExemplar r = prepare_raster_exemplar(frames[0], epsilon);
  r.later.resize(frames.size() - 1);
  parallel_for(
      r.later.size(),
      [&](std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k) r.later[k] = prepare_raster_exemplar(frames[k + 1], epsilon);
      },
      1);
  return r;
}

int ExemplarClock::frame_of(const Patch& patch, int count) const {
  if (count <= 1) return 0;
  const double age = double(frame) - double(patch.birth_frame);
  const double phase = loop == ExemplarLoop::Hold ? 0.0 : hash_to_unit(hash64(seed, patch.id, 0x65786c70)) * count;
  const double t = std::floor(std::max(0.0, age) * rate + phase);
  switch (loop) {
    case ExemplarLoop::Hold:
      return int(std::min(t, double(count - 1)));
    case ExemplarLoop::PingPong: {
      const double period = 2.0 * (count - 1);
      const int m = int(t - period * std::floor(t / period));
      return m < count ? m : int(period) - m;
    }
    case ExemplarLoop::Loop:
      break;
  }
  return int(t - count * std::floor(t / count));
}

namespace detail {

// One row or column of a running maximum over a window of 2 k + 1 samples
// (clamped at the ends), in O(1) per sample: the van Herk / Gil-Werman
// prefix and suffix maxima over blocks of 2 k + 1.
static void running_max(const float* in, std::size_t stride, int n, int k, float* out, std::vector<float>& pre,
                        std::vector<float>& suf) {
  const int w = 2 * k + 1;
  pre.resize(std::size_t(n)), suf.resize(std::size_t(n));
  for (int i = 0; i < n; ++i) pre[i] = (i % w == 0) ? in[i * stride] : std::max(pre[i - 1], in[i * stride]);
  for (int i = n - 1; i >= 0; --i)
    suf[i] = (i == n - 1 || (i + 1) % w == 0) ? in[i * stride] : std::max(suf[i + 1], in[i * stride]);
  for (int i = 0; i < n; ++i) {
    if (i - k >= 0 && i + k <= n - 1) {
      out[i * stride] = std::max(suf[i - k], pre[i + k]);  // a full window spans one block or two
      continue;
    }
    const int a = std::max(0, i - k), b = std::min(n - 1, i + k);  // clamped at an end: directly
    float m = in[a * stride];
    for (int j = a + 1; j <= b; ++j) m = std::max(m, in[j * stride]);
    out[i * stride] = m;
  }
}

Image max_filter(const Image& img, int kx, int ky) {
  Image tmp = img, out = img;
  std::vector<float> pre, suf;
  if (kx > 0)
    for (int y = 0; y < img.height; ++y)
      running_max(&img.pixels[std::size_t(y) * img.width], 1, img.width, kx, &tmp.pixels[std::size_t(y) * img.width],
                  pre, suf);
  if (ky > 0)
    for (int x = 0; x < img.width; ++x)
      running_max(&tmp.pixels[std::size_t(x)], std::size_t(img.width), img.height, ky, &out.pixels[std::size_t(x)], pre,
                  suf);
  else
    out = std::move(tmp);
  return out;
}

void MinPyramid::build(const Image& img) {
  levels.assign(1, img.pixels);
  widths.assign(1, img.width);
  heights.assign(1, img.height);
  while (widths.back() > 1 || heights.back() > 1) {
    const int w = widths.back(), h = heights.back(), W = (w + 1) / 2, H = (h + 1) / 2;
    const std::vector<float>& in = levels.back();
    std::vector<float> next(std::size_t(W) * H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const int xa = 2 * x, xb = std::min(2 * x + 1, w - 1), ya = 2 * y, yb = std::min(2 * y + 1, h - 1);
        next[std::size_t(y) * W + x] =
            std::min({in[std::size_t(ya) * w + xa], in[std::size_t(ya) * w + xb], in[std::size_t(yb) * w + xa],
                      in[std::size_t(yb) * w + xb]});
      }
    levels.push_back(std::move(next));
    widths.push_back(W);
    heights.push_back(H);
  }
}

float MinPyramid::min_over(int x0, int y0, int x1, int y1) const {
  // The level where the rectangle spans at most two blocks each way.
  std::size_t k = 0;
  while (k + 1 < levels.size() && ((x1 >> k) - (x0 >> k) > 1 || (y1 >> k) - (y0 >> k) > 1)) ++k;
  const int w = widths[k];
  const std::vector<float>& l = levels[k];
  float m = l[std::size_t(y0 >> k) * w + std::size_t(x0 >> k)];
  for (int y = y0 >> k; y <= (y1 >> k); ++y)
    for (int x = x0 >> k; x <= (x1 >> k); ++x) m = std::min(m, l[std::size_t(y) * w + std::size_t(x)]);
  return m;
}

}  // namespace detail

bool erosion_keeps(const ErosionMap& map, double u, double v, double w, RasterMode mode) {
  return detail::keeps(map, u, v, w, mode);
}

void sample_exemplar(const ExemplarMips& mips, double u, double v, double lod, float out[4], bool trilinear) {
  detail::sample(mips, u, v, lod, out, trilinear);
}

}  // namespace lapflow
