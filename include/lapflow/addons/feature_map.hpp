#pragma once
/// \file feature_map.hpp Feature maps for exemplars that come without one.
///
/// The erosion test (ALGORITHM.md step 7) keeps a texel of a distorted patch
/// while sqrt(F_m + D) / M is large: high F_m marks the texture's elements,
/// which erode last, low F_m their borders, where erosion starts. An artist
/// with only a colour image gets F_m here from one of three methods:
///  - luminance: Rec. 709 luminance of the linear colour, stretched to [0,1];
///  - edges: one minus the colour gradient magnitude (Sobel on a slightly
///    blurred image), so that element borders are low;
///  - distance: the Euclidean distance to the nearest strong edge (the
///    "feature distance" of Lefebvre & Hoppe 2006), high inside elements.
/// All work on lapflow::Image, are deterministic at any thread count, and
/// return one channel in [0,1].
#include <string>
#include <vector>

#include "lapflow/io/image.hpp"

namespace lapflow {

enum class FeatureMethod { Luminance, Edges, Distance };

/// "luminance" | "edges" | "distance" and back (throws UsageError).
FeatureMethod parse_feature_method(const std::string& name);
std::string feature_method_name(FeatureMethod method);

struct FeatureMapOptions {
  FeatureMethod method = FeatureMethod::Distance;
  /// Gaussian blur of the colour before the gradient (edges, distance), in
  /// pixels; 0 = none. Removes pixel noise and JPEG ringing from the edges.
  double edge_sigma = 1.0;
  /// distance: a pixel is a strong edge when its gradient magnitude, divided
  /// by the image's robust maximum (edge_percentile), is at least this.
  double edge_threshold = 0.5;
  /// Percentile (0-100] of the gradient magnitude that maps to edge strength 1
  /// (a robust maximum: a few very sharp pixels do not dim every other edge).
  double edge_percentile = 99.0;
  /// distance: distance in pixels that maps to 1 (larger is clamped);
  /// 0 = automatic: the 99th percentile of the distances, so that the
  /// interiors of typical elements reach 1 whatever the exemplar's scale.
  double distance_max = 0;
  /// Gaussian blur of the result, in pixels; 0 = none (softens the erosion front).
  double blur_sigma = 0;
  /// 1 - F at the end: for textures whose elements are dark (cracks, grout).
  bool invert = false;
};

/// Rec. 709 luminance of linear RGB (the first channel of a grey image),
/// one channel, not normalised. Alpha is ignored.
Image luminance(const Image& color);

/// Gradient magnitude of `img` (every colour channel, alpha ignored):
/// sqrt(sum_c Gx_c^2 + Gy_c^2) / 8 with 3x3 Sobel kernels and clamped borders,
/// after a Gaussian blur of `sigma` pixels (0 = none). One channel, not
/// normalised: a unit step between two flat regions peaks at 0.5 on the step
/// (without blur).
Image gradient_magnitude(const Image& img, double sigma);

/// Exact Euclidean distance, in pixels, from every pixel to the nearest pixel
/// where `seeds` is > 0.5 (Felzenszwalb & Huttenlocher 2012, separable lower
/// envelope of parabolas). One channel; every value is +infinity when there is
/// no seed.
Image distance_transform(const Image& seeds);

/// Separable Gaussian blur of every channel, `sigma` in pixels (kernel cut at
/// 3 sigma, clamped borders). Returns `img` unchanged for sigma <= 0.
Image gaussian_blur(const Image& img, double sigma);

/// The feature map F_m of a colour exemplar (linear, as read_image returns
/// it): one channel in [0,1], the colour image's size. Throws
/// std::invalid_argument on an empty image or options out of range.
Image make_feature_map(const Image& color, const FeatureMapOptions& options);

/// Pearson correlation of two one-channel images of the same size (NaN when
/// either is constant): how well a generated map agrees with a reference.
double image_correlation(const Image& a, const Image& b);

}  // namespace lapflow
