// Loading an exemplar: colour E, feature map F_m and displacement H, brought
// to one size and one channel layout so the rasterizer samples them blindly.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow {
namespace {

// Colour with 1 (grey), 2 (grey + alpha), 3 or 4 (RGBA) channels becomes RGB.
// Alpha is dropped: an exemplar covers its whole square.
Image to_rgb(const Image& img) {
  if (img.channels == 3) return img;
  Image out(img.width, img.height, 3);
  const std::size_t n = std::size_t(img.width) * img.height;
  for (std::size_t p = 0; p < n; ++p)
    for (int c = 0; c < 3; ++c) {
      const int src = img.channels >= 3 ? c : 0;
      out.pixels[p * 3 + c] = img.pixels[p * img.channels + src];
    }
  return out;
}

// A data map with several channels is reduced to its luminance (alpha
// ignored); painters often save grey maps as RGB.
Image to_grey(const Image& img) {
  if (img.channels == 1) return img;
  Image out(img.width, img.height, 1);
  const std::size_t n = std::size_t(img.width) * img.height;
  for (std::size_t p = 0; p < n; ++p) {
    const float* px = &img.pixels[p * img.channels];
    out.pixels[p] = img.channels >= 3 ? 0.2126f * px[0] + 0.7152f * px[1] + 0.0722f * px[2] : px[0];
  }
  return out;
}

// Same aspect ratio, up to the rounding of one pixel on the longer side.
bool same_aspect(const Image& a, const Image& b) {
  const double lhs = double(a.width) * b.height, rhs = double(b.width) * a.height;
  const double tolerance = double(std::max({a.width, a.height, b.width, b.height}));
  return std::abs(lhs - rhs) <= tolerance;
}

Image fit_to(const Image& map, const Image& color, const std::string& map_path, const std::string& color_path,
             const char* what) {
  if (map.width == color.width && map.height == color.height) return map;
  if (!same_aspect(map, color))
    throw InputError(map_path, fmt::format("{} is {}x{} but the colour image {} is {}x{}: the aspect ratios differ",
                                           what, map.width, map.height, color_path, color.width, color.height));
  fmt::print(stderr, "warning: {}: {} is {}x{}, resampled to the colour image's {}x{}\n", map_path, what,
             map.width, map.height, color.width, color.height);
  return resize_image(map, color.width, color.height);
}

std::string exemplar_name(const std::string& color_path) {
  std::string stem = std::filesystem::path(color_path).stem().string();
  for (const char* suffix : {".color", "_color", ".colour", "_colour", ".albedo", "_albedo"}) {
    const std::string s(suffix);
    if (stem.size() > s.size() && stem.compare(stem.size() - s.size(), s.size(), s) == 0)
      return stem.substr(0, stem.size() - s.size());
  }
  return stem;
}

}  // namespace

Exemplar load_exemplar(const std::string& color_path, const std::string& feature_path,
                       const std::string& displacement_path) {
  Exemplar ex;
  ex.name = exemplar_name(color_path);
  ex.color = to_rgb(read_image(color_path, ColorSpace::Auto));

  Image feature = to_grey(read_image(feature_path, ColorSpace::Linear));
  // Tolerate float round-off from tools that write EXR feature maps.
  constexpr float kSlack = 1e-4f;
  for (int y = 0; y < feature.height; ++y)
    for (int x = 0; x < feature.width; ++x) {
      float& f = feature.at(x, y, 0);
      if (f < -kSlack || f > 1 + kSlack)
        throw InputError(feature_path, fmt::format("pixel ({}, {}): feature value {} is outside [0, 1]", x, y, f));
      f = std::clamp(f, 0.f, 1.f);
    }
  ex.feature = fit_to(feature, ex.color, feature_path, color_path, "feature map");
  // Bilinear/box resampling of values in [0,1] stays in [0,1] up to rounding.
  for (float& f : ex.feature.pixels) f = std::clamp(f, 0.f, 1.f);

  if (displacement_path.empty()) {
    ex.displacement = ex.feature;
  } else {
    Image disp = to_grey(read_image(displacement_path, ColorSpace::Linear));
    ex.displacement = fit_to(disp, ex.color, displacement_path, color_path, "displacement map");
  }
  return ex;
}

bool is_exemplar_sequence(const std::string& path) {
  std::error_code ec;
  if (path.empty() || std::filesystem::is_regular_file(path, ec)) return false;
  try {
    return FramePattern(path).has_frame_token();
  } catch (const UsageError&) {
    return false;
  }
}

std::vector<std::string> exemplar_frame_files(const std::string& path) {
  if (!is_exemplar_sequence(path)) return {path};
  const FramePattern pattern(path);
  std::vector<std::string> files;
  for (int f : pattern.frames_on_disk()) files.push_back(pattern.path(f));
  if (files.empty()) throw InputError(path, "no frame of this animated exemplar is on disk");
  return files;
}

std::vector<Exemplar> load_exemplar_frames(const std::string& color_path, const std::string& feature_path,
                                           const std::string& displacement_path) {
  if (!is_exemplar_sequence(color_path)) return {load_exemplar(color_path, feature_path, displacement_path)};
  const FramePattern color(color_path);
  const std::vector<int> frames = color.frames_on_disk();
  if (frames.empty()) throw InputError(color_path, "no frame of this animated exemplar is on disk");
  if (frames.size() > kMaxExemplarFrames)
    throw InputError(color_path, fmt::format("{} frames; an animated exemplar has at most {}", frames.size(),
                                             kMaxExemplarFrames));
  for (std::size_t i = 1; i < frames.size(); ++i)
    if (frames[i] != frames[0] + int(i))
      throw InputError(color.path(frames[0] + int(i)),
                       fmt::format("missing: the exemplar sequence has frames {} to {} with gaps", frames.front(),
                                   frames.back()));
  // A feature or displacement map that is one image serves every frame.
  const auto frame_file = [](const std::string& path, int f) {
    return is_exemplar_sequence(path) ? FramePattern(path).path(f) : path;
  };
  std::vector<Exemplar> out;
  out.reserve(frames.size());
  for (int f : frames) {
    for (const std::string* side : {&feature_path, &displacement_path}) {
      std::error_code ec;
      const std::string file = frame_file(*side, f);
      if (!side->empty() && !std::filesystem::is_regular_file(file, ec))
        throw InputError(file, fmt::format("missing: the colour sequence {} has frame {}", color_path, f));
    }
    out.push_back(load_exemplar(color.path(f), frame_file(feature_path, f), frame_file(displacement_path, f)));
    const Image& first = out.front().color;
    const Image& now = out.back().color;
    if (now.width != first.width || now.height != first.height)
      throw InputError(color.path(f), fmt::format("{}x{}: the sequence's first frame ({}) is {}x{}; every frame of an "
                                                  "animated exemplar has one size",
                                                  now.width, now.height, color.path(frames.front()), first.width,
                                                  first.height));
  }
  return out;
}

}  // namespace lapflow
