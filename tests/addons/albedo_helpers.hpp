#pragma once
// Colour comparisons of the Blender render tests: what the camera saw
// against the atlas's colour.
#include <algorithm>
#include <array>
#include <cmath>

namespace lapflow::test {

using Rgb = std::array<double, 3>;

/// The colour's share of each channel (its hue and saturation, not its brightness).
inline Rgb chromaticity(const Rgb& c) {
  const double s = c[0] + c[1] + c[2];
  return {c[0] / s, c[1] / s, c[2] / s};
}
/// The largest difference between the two colours' channel shares.
inline double chroma_distance(const Rgb& a, const Rgb& b) {
  const Rgb ca = chromaticity(a), cb = chromaticity(b);
  return std::max({std::abs(ca[0] - cb[0]), std::abs(ca[1] - cb[1]), std::abs(ca[2] - cb[2])});
}
/// Rec. 709 luminance.
inline double luma(const Rgb& c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

}  // namespace lapflow::test
