// Feature maps from a colour exemplar: luminance, edges, feature distance.
// Plain separable image filters over lapflow::Image; every output pixel is
// written by index from inputs that do not change during the pass, so the
// result is the same at any thread count.
#include "lapflow/addons/feature_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

// The sRGB transfer function: edges are found on display-encoded values, where
// equal steps look equally strong (in linear light every edge inside dark
// grout or cracks would be faint).
float linear_to_srgb(float c) {
  c = std::clamp(c, 0.f, 1.f);
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

int colour_channels(const Image& img) {
  // Alpha (the last of 2 or 4 channels) carries no texture.
  return (img.channels == 2 || img.channels == 4) ? img.channels - 1 : img.channels;
}

void check_image(const Image& img, const char* what) {
  if (img.width <= 0 || img.height <= 0 || img.channels <= 0 ||
      img.pixels.size() != std::size_t(img.width) * img.height * img.channels)
    throw std::invalid_argument(std::string(what) + ": empty or inconsistent image");
}

// Value at percentile p (0-100] of `values` (nearest rank, on a copy).
float percentile(std::vector<float> values, double p) {
  if (values.empty()) return 0.f;
  const std::size_t n = values.size();
  std::size_t k = std::size_t(std::ceil(std::clamp(p, 0.0, 100.0) / 100.0 * double(n)));
  k = std::clamp<std::size_t>(k, 1, n) - 1;
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
  return values[k];
}

// Felzenszwalb-Huttenlocher 1D squared distance transform of f (n samples at
// stride `stride`) into d: d[q] = min_p (q - p)^2 + f[p]. Lower envelope of
// the parabolas rooted at every sample; v/z are scratch of n and n+1.
void distance_1d(const double* f, std::size_t stride, int n, double* d, std::vector<int>& v,
                 std::vector<double>& z) {
  const double inf = std::numeric_limits<double>::infinity();
  int k = 0;
  v[0] = 0;
  z[0] = -inf;
  z[1] = inf;
  for (int q = 1; q < n; ++q) {
    const double fq = f[std::size_t(q) * stride] + double(q) * q;
    auto intersection = [&](int p) { return (fq - (f[std::size_t(p) * stride] + double(p) * p)) / (2.0 * (q - p)); };
    // z[0] = -inf stops the loop at k = 0.
    double s = intersection(v[k]);
    while (s <= z[k]) s = intersection(v[--k]);
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = inf;
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q) ++k;
    const double dq = q - v[k];
    d[std::size_t(q) * stride] = dq * dq + f[std::size_t(v[k]) * stride];
  }
}

Image normalise_min_max(Image img) {
  const auto [lo, hi] = std::minmax_element(img.pixels.begin(), img.pixels.end());
  const float a = *lo, b = *hi;
  // A flat image has no features to tell apart: keep everything equally.
  for (float& x : img.pixels) x = b > a ? (x - a) / (b - a) : 1.f;
  return img;
}

// Gradient magnitude divided by its robust maximum, clamped to [0,1].
Image edge_strength(const Image& color, const FeatureMapOptions& o) {
  Image encoded(color.width, color.height, colour_channels(color));
  const std::size_t count = std::size_t(color.width) * color.height;
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p)
      for (int c = 0; c < encoded.channels; ++c)
        encoded.pixels[p * encoded.channels + c] = linear_to_srgb(color.pixels[p * color.channels + c]);
  }, 4096);
  Image g = gradient_magnitude(encoded, o.edge_sigma);
  float top = percentile(g.pixels, o.edge_percentile);
  if (top <= 0.f) top = *std::max_element(g.pixels.begin(), g.pixels.end());
  for (float& x : g.pixels) x = top > 0.f ? std::min(1.f, x / top) : 0.f;
  return g;
}

}  // namespace

FeatureMethod parse_feature_method(const std::string& name) {
  if (name == "luminance") return FeatureMethod::Luminance;
  if (name == "edges") return FeatureMethod::Edges;
  if (name == "distance") return FeatureMethod::Distance;
  throw UsageError("unknown feature-map method '" + name + "' (luminance, edges or distance)");
}

std::string feature_method_name(FeatureMethod method) {
  switch (method) {
    case FeatureMethod::Luminance: return "luminance";
    case FeatureMethod::Edges: return "edges";
    case FeatureMethod::Distance: return "distance";
  }
  return "?";
}

Image luminance(const Image& color) {
  check_image(color, "luminance");
  Image out(color.width, color.height, 1);
  const int ch = color.channels;
  const bool rgb = colour_channels(color) >= 3;
  parallel_for(out.pixels.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p) {
      const float* px = &color.pixels[p * ch];
      out.pixels[p] = rgb ? 0.2126f * px[0] + 0.7152f * px[1] + 0.0722f * px[2] : px[0];
    }
  }, 4096);
  return out;
}

Image gaussian_blur(const Image& img, double sigma) {
  check_image(img, "gaussian_blur");
  if (!(sigma > 0)) return img;
  const int radius = std::max(1, int(std::ceil(3 * sigma)));
  std::vector<float> kernel(std::size_t(2 * radius + 1));
  double sum = 0;
  for (int i = -radius; i <= radius; ++i) sum += kernel[std::size_t(i + radius)] = float(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (float& k : kernel) k = float(k / sum);
  const int w = img.width, h = img.height, ch = img.channels;
  // Horizontal then vertical pass (clamped at the borders), each row written by one task.
  auto pass = [&](const Image& src, Image& dst, int dx, int dy) {
    parallel_for(std::size_t(h), [&](std::size_t b, std::size_t e) {
      for (int y = int(b); y < int(e); ++y)
        for (int x = 0; x < w; ++x)
          for (int c = 0; c < ch; ++c) {
            float acc = 0;
            for (int i = -radius; i <= radius; ++i)
              acc += kernel[std::size_t(i + radius)] *
                     src.at(std::clamp(x + i * dx, 0, w - 1), std::clamp(y + i * dy, 0, h - 1), c);
            dst.at(x, y, c) = acc;
          }
    }, 4);
  };
  Image tmp(w, h, ch), out(w, h, ch);
  pass(img, tmp, 1, 0);
  pass(tmp, out, 0, 1);
  return out;
}

Image gradient_magnitude(const Image& img, double sigma) {
  check_image(img, "gradient_magnitude");
  const Image src = gaussian_blur(img, sigma);
  const int w = src.width, h = src.height, ch = colour_channels(src);
  Image out(w, h, 1);
  parallel_for(std::size_t(h), [&](std::size_t b, std::size_t e) {
    for (int y = int(b); y < int(e); ++y) {
      const int ym = std::max(y - 1, 0), yp = std::min(y + 1, h - 1);
      for (int x = 0; x < w; ++x) {
        const int xm = std::max(x - 1, 0), xp = std::min(x + 1, w - 1);
        double sum = 0;
        for (int c = 0; c < ch; ++c) {
          const double gx = (src.at(xp, ym, c) + 2 * src.at(xp, y, c) + src.at(xp, yp, c)) -
                            (src.at(xm, ym, c) + 2 * src.at(xm, y, c) + src.at(xm, yp, c));
          const double gy = (src.at(xm, yp, c) + 2 * src.at(x, yp, c) + src.at(xp, yp, c)) -
                            (src.at(xm, ym, c) + 2 * src.at(x, ym, c) + src.at(xp, ym, c));
          sum += gx * gx + gy * gy;
        }
        out.at(x, y, 0) = float(std::sqrt(sum) / 8.0);
      }
    }
  }, 4);
  return out;
}

Image distance_transform(const Image& seeds) {
  check_image(seeds, "distance_transform");
  const int w = seeds.width, h = seeds.height;
  // A large finite value, not infinity: the parabola intersections stay finite.
  constexpr double kFar = 1e20;
  std::vector<double> grid(std::size_t(w) * h), cols(grid.size());
  for (std::size_t p = 0; p < grid.size(); ++p) grid[p] = seeds.pixels[p * seeds.channels] > 0.5f ? 0.0 : kFar;
  // Columns, then rows of the column result: exact squared Euclidean distance.
  parallel_for(std::size_t(w), [&](std::size_t b, std::size_t e) {
    std::vector<int> v(static_cast<std::size_t>(h));
    std::vector<double> z(static_cast<std::size_t>(h) + 1);
    for (std::size_t x = b; x < e; ++x) distance_1d(&grid[x], std::size_t(w), h, &cols[x], v, z);
  }, 8);
  Image out(w, h, 1);
  parallel_for(std::size_t(h), [&](std::size_t b, std::size_t e) {
    std::vector<int> v(static_cast<std::size_t>(w));
    std::vector<double> z(static_cast<std::size_t>(w) + 1);
    std::vector<double> row(static_cast<std::size_t>(w));
    for (std::size_t y = b; y < e; ++y) {
      distance_1d(&cols[y * std::size_t(w)], 1, w, row.data(), v, z);
      for (int x = 0; x < w; ++x)
        out.pixels[y * std::size_t(w) + std::size_t(x)] =
            row[std::size_t(x)] >= kFar * 0.5 ? std::numeric_limits<float>::infinity()
                                              : float(std::sqrt(row[std::size_t(x)]));
    }
  }, 8);
  return out;
}

Image make_feature_map(const Image& color, const FeatureMapOptions& o) {
  check_image(color, "make_feature_map");
  if (o.edge_sigma < 0 || o.blur_sigma < 0 || o.distance_max < 0)
    throw std::invalid_argument("feature map: sigma and distance_max must be >= 0");
  if (!(o.edge_threshold > 0 && o.edge_threshold <= 1))
    throw std::invalid_argument("feature map: edge_threshold must be in (0, 1]");
  if (!(o.edge_percentile > 0 && o.edge_percentile <= 100))
    throw std::invalid_argument("feature map: edge_percentile must be in (0, 100]");
  Image f;
  switch (o.method) {
    case FeatureMethod::Luminance:
      f = normalise_min_max(luminance(color));
      break;
    case FeatureMethod::Edges:
      // Element borders are where the colour changes: low there, so that a
      // distorted patch erodes along them first.
      f = edge_strength(color, o);
      for (float& x : f.pixels) x = 1.f - x;
      break;
    case FeatureMethod::Distance: {
      Image edges = edge_strength(color, o);
      for (float& x : edges.pixels) x = x >= float(o.edge_threshold) ? 1.f : 0.f;
      f = distance_transform(edges);
      std::vector<float> finite;
      finite.reserve(f.pixels.size());
      for (float d : f.pixels)
        if (std::isfinite(d)) finite.push_back(d);
      double scale = o.distance_max;
      if (scale == 0) scale = percentile(finite, 99.0);
      // No edge at all (a flat image): no border to erode along.
      for (float& d : f.pixels) d = std::isfinite(d) && scale > 0 ? std::min(1.f, float(d / scale)) : 1.f;
      break;
    }
  }
  if (o.blur_sigma > 0) f = gaussian_blur(f, o.blur_sigma);
  for (float& x : f.pixels) x = std::clamp(o.invert ? 1.f - x : x, 0.f, 1.f);
  return f;
}

double image_correlation(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height || a.channels != 1 || b.channels != 1)
    throw std::invalid_argument("image_correlation: needs two one-channel images of the same size");
  const std::size_t n = a.pixels.size();
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < n; ++i) ma += a.pixels[i], mb += b.pixels[i];
  ma /= double(n);
  mb /= double(n);
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double da = a.pixels[i] - ma, db = b.pixels[i] - mb;
    sab += da * db;
    saa += da * da;
    sbb += db * db;
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace lapflow
