// `lapflow preview`: reading a bake's frames, framing the camera, putting
// panels side by side. The renderer is in preview_render.cpp, the labels in
// preview_label.cpp, the video in preview_video.cpp.
#include "lapflow/addons/preview.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include "lapflow/core/errors.hpp"
#include "lapflow/surface/mesh.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace fs = std::filesystem;

PreviewFrame make_preview_frame(UvMesh mesh, Image color, Image displacement, double radius) {
  PreviewFrame f;
  f.mesh = std::move(mesh);
  f.normals = vertex_normals(f.mesh.mesh);
  f.radius = radius;
  if (!color.empty()) {
    Exemplar ex;
    if (!displacement.empty()) {
      ex.displacement = displacement.width == color.width && displacement.height == color.height
                            ? std::move(displacement)
                            : resize_image(displacement, color.width, color.height);
      f.bump = true;
    }
    ex.color = std::move(color);
    f.texture = build_exemplar_mips(ex);
  }
  return f;
}

std::optional<PreviewShow> parse_preview_show(const std::string& text) {
  if (text == "color") return PreviewShow::Color;
  if (text == "layers") return PreviewShow::Layers;
  return std::nullopt;
}

Vec3 preview_layer_color(int layer) {
  static const Vec3 palette[] = {{0.90, 0.22, 0.04}, {0.06, 0.25, 0.90}, {0.10, 0.65, 0.12}, {0.85, 0.70, 0.05},
                                 {0.65, 0.08, 0.70}, {0.05, 0.65, 0.70}, {0.95, 0.45, 0.55}, {0.40, 0.22, 0.08}};
  if (layer < 0) return {0.5, 0.5, 0.5};
  return palette[std::size_t(layer) % std::size(palette)];
}

Image tint_by_layer(const Image& color, const Image& layers) {
  if (layers.width != color.width || layers.height != color.height || layers.channels != 1)
    throw std::invalid_argument("tint_by_layer: the layer image is not one channel of the colour atlas's size");
  Image out = color;
  const std::size_t n = std::size_t(color.width) * color.height, ch = std::size_t(color.channels);
  parallel_for(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p) {
      float* px = &out.pixels[p * ch];
      const double lum = 0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2];
      // The square root lifts dark textures (lava's crust) so that their tint still reads.
      const double shade = 0.3 + 0.7 * std::min(1.0, std::sqrt(std::max(0.0, lum)));
      const float l = layers.pixels[p];
      const Vec3 tint = preview_layer_color(l >= 0 ? int(std::lround(l)) : -1);
      for (int c = 0; c < 3; ++c) px[c] = float(tint[c] * shade);
    }
  }, 1 << 14);
  return out;
}

namespace {

/// The `layer` channel of frame `frame`'s AOV (PreviewShow::Layers).
Image read_layer_channel(const BakeManifest& bake, int frame) {
  const std::string aov = bake.frame_file("aov", frame);
  std::error_code ec;
  if (!fs::exists(aov, ec))
    throw InputError(aov, "missing: --show layers reads the AOV's layer channel; bake (or render) with --aov", frame);
  const std::vector<std::string> names = image_channel_names(aov);
  const auto at = std::find(names.begin(), names.end(), "layer");
  if (at == names.end())
    throw InputError(aov, "no channel 'layer': the bake has one exemplar, and --show layers needs exemplar layers "
                          "(bake with --layer)", frame);
  const Image all = read_image(aov, ColorSpace::Linear);
  const std::size_t c = std::size_t(at - names.begin()), ch = std::size_t(all.channels);
  if (c >= ch) throw InputError(aov, "the channel list and the pixels disagree", frame);
  Image layer(all.width, all.height, 1);
  for (std::size_t p = 0; p < layer.pixels.size(); ++p) layer.pixels[p] = all.pixels[p * ch + c];
  return layer;
}

}  // namespace

PreviewFrame load_preview_frame(const BakeManifest& bake, int frame, PreviewShow show) {
  const std::string obj = bake.frame_file("obj", frame), color = bake.frame_file("color", frame),
                    disp = bake.frame_file("disp", frame);
  std::error_code ec;
  if (!fs::exists(obj, ec)) throw InputError(obj, "missing: the bake has no mesh for this frame", frame);
  if (!fs::exists(color, ec)) throw InputError(color, "missing: the bake has no colour atlas for this frame", frame);
  UvMesh mesh = read_uv_mesh(obj);
  if (mesh.corner_uv.empty() && !mesh.mesh.empty())
    throw InputError(obj, "no texture coordinates (vt): not a lapflow bake frame", frame);
  Image c = read_image(color, ColorSpace::Linear);
  if (c.channels < 3) throw InputError(color, "the colour atlas needs R, G, B channels", frame);
  if (show == PreviewShow::Layers) {
    const Image layer = read_layer_channel(bake, frame);
    if (layer.width != c.width || layer.height != c.height)
      throw InputError(bake.frame_file("aov", frame),
                       fmt::format("{}x{}, but the colour atlas is {}x{}", layer.width, layer.height, c.width, c.height),
                       frame);
    c = tint_by_layer(c, layer);
  }
  Image h;
  if (fs::exists(disp, ec)) {
    h = read_image(disp, ColorSpace::Linear);
    if (h.channels != 1) {  // keep the first channel
      Image one(h.width, h.height, 1);
      for (std::size_t i = 0; i < one.pixels.size(); ++i) one.pixels[i] = h.pixels[i * h.channels];
      h = std::move(one);
    }
  }
  return make_preview_frame(std::move(mesh), std::move(c), std::move(h), bake.options.patch.radius);
}

PreviewExtent preview_extent(const BakeManifest& bake, const std::vector<int>& frames, std::size_t max_points) {
  // Each frame's OBJ on its own task; results by index, merged in order.
  std::vector<Box3> boxes(frames.size());
  std::vector<std::vector<Vec3>> points(frames.size());
  std::vector<std::optional<InputError>> errors(frames.size());
  const std::size_t per_frame = std::max<std::size_t>(1, max_points / std::max<std::size_t>(1, frames.size()));
  parallel_for(frames.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const std::string obj = bake.frame_file("obj", frames[i]);
      try {
        std::error_code ec;
        if (!fs::exists(obj, ec)) throw InputError(obj, "missing: the bake has no mesh for this frame", frames[i]);
        const TriMesh m = read_uv_mesh(obj).mesh;
        boxes[i] = bounding_box(m);
        const std::size_t n = m.positions.size(), step = std::max<std::size_t>(1, (n + per_frame - 1) / per_frame);
        for (std::size_t v = 0; v < n; v += step) points[i].push_back(m.positions[v]);
      } catch (const InputError& err) {
        errors[i] = err;
      }
    }
  }, 1);
  PreviewExtent extent;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (errors[i]) throw *errors[i];
    if (!boxes[i].empty()) {
      extent.box.extend(boxes[i].lo);
      extent.box.extend(boxes[i].hi);
    }
    extent.points.insert(extent.points.end(), points[i].begin(), points[i].end());
  }
  return extent;
}

PreviewCamera frame_camera(const std::vector<Vec3>& points_in, const Vec3& up_in, double aspect, double azimuth,
                           double elevation, double fov, double min_distance) {
  std::vector<Vec3> fallback;
  const std::vector<Vec3>* points = &points_in;
  if (points_in.empty()) {
    for (int k = 0; k < 8; ++k) fallback.push_back({(k & 1) ? 0.5 : -0.5, (k & 2) ? 0.5 : -0.5, (k & 4) ? 0.5 : -0.5});
    points = &fallback;
  }
  Box3 box;
  for (const Vec3& p : *points) box.extend(p);
  const Vec3 c = box.center();
  const Vec3 up = norm(up_in) > 0 ? normalized(up_in) : Vec3{0, 0, 1};
  // The "front" of the scene: -Y for a Z-up world (Blender), +Z for a Y-up one (Houdini, Maya).
  Vec3 front = std::abs(up.z) > 0.5 ? Vec3{0, -1, 0} : Vec3{0, 0, 1};
  front = normalized(front - up * dot(front, up));
  const Vec3 side = cross(up, front);
  const double az = azimuth * std::numbers::pi / 180, el = elevation * std::numbers::pi / 180;
  const Vec3 to_eye = normalized((front * std::cos(az) + side * std::sin(az)) * std::cos(el) + up * std::sin(el));
  const Vec3 forward = -to_eye;
  Vec3 right = cross(forward, up);
  if (norm(right) < 1e-9) right = std::abs(up.x) < 0.9 ? cross(forward, Vec3{1, 0, 0}) : cross(forward, Vec3{0, 1, 0});
  right = normalized(right);
  const Vec3 cam_up = cross(right, forward);
  const double tan_v = std::tan(0.5 * fov * std::numbers::pi / 180) * 0.9;  // 10% margin
  const double tan_h = tan_v * aspect;

  // The eye at c + right a + cam_up b - forward d sees point (x, y, z) (camera
  // frame about c) at depth z + d; it is inside when |x - a| <= tan_h (z + d).
  // Some a fits every point iff max(x - tan_h z) - min(x + tan_h z) <= 2 tan_h d:
  // that gives the smallest d, and a is the middle of the feasible interval.
  double hx = -INFINITY, lx = INFINITY, hy = -INFINITY, ly = INFINITY;
  for (const Vec3& p : *points) {
    const Vec3 q = p - c;
    const double x = dot(q, right), y = dot(q, cam_up), z = dot(q, forward);
    hx = std::max(hx, x - tan_h * z);
    lx = std::min(lx, x + tan_h * z);
    hy = std::max(hy, y - tan_v * z);
    ly = std::min(ly, y + tan_v * z);
  }
  double d = std::max((hx - lx) / (2 * tan_h), (hy - ly) / (2 * tan_v));
  d = std::max({d, min_distance, 1e-3 + 0.05 * norm(box.size())});
  const double a = 0.5 * (hx + lx), b = 0.5 * (hy + ly);  // midpoints: (hx - tan_h d + lx + tan_h d) / 2

  PreviewCamera cam;
  cam.up = up;
  cam.fov = fov;
  cam.target = c + right * a + cam_up * b;
  cam.eye = cam.target - forward * d;
  return cam;
}

PreviewCamera frame_camera(const Box3& box, const Vec3& up, double aspect, double azimuth, double elevation,
                           double fov) {
  std::vector<Vec3> corners;
  if (!box.empty())
    for (int k = 0; k < 8; ++k)
      corners.push_back({(k & 1) ? box.hi.x : box.lo.x, (k & 2) ? box.hi.y : box.lo.y, (k & 4) ? box.hi.z : box.lo.z});
  return frame_camera(corners, up, aspect, azimuth, elevation, fov);
}

std::vector<PreviewCamera> preview_cameras(const std::vector<Vec3>& points, const PreviewFraming& f,
                                           int pictures) {
  std::vector<PreviewCamera> cameras(static_cast<std::size_t>(std::max(pictures, 0)));
  double distance = 0;
  for (int pass = 0; pass < (f.turntable && !f.fixed ? 2 : 1); ++pass)
    for (int i = 0; i < pictures; ++i) {
      PreviewCamera& cam = cameras[std::size_t(i)];
      if (f.fixed) {
        cam = *f.fixed;
        if (f.turntable) {  // orbit the given eye about the target
          const double a = 2 * std::numbers::pi * i / pictures;
          const Vec3 q = cam.eye - cam.target, up = normalized(cam.up);
          const Vec3 along = up * dot(q, up), flat = q - along, side = cross(up, flat);
          cam.eye = cam.target + along + flat * std::cos(a) + side * std::sin(a);
        }
        continue;
      }
      const double az = f.turntable ? f.azimuth + 360.0 * i / pictures : f.azimuth;
      cam = frame_camera(points, f.up, f.aspect, az, f.elevation, f.fov, distance);
      if (pass == 0) distance = std::max(distance, norm(cam.eye - cam.target));
    }
  return cameras;
}

Image side_by_side(const std::vector<Image>& panels, int gap, const Vec3& gap_color) {
  if (panels.empty()) throw std::invalid_argument("side_by_side: no panels");
  const int w = panels[0].width, h = panels[0].height, ch = panels[0].channels;
  for (const Image& p : panels)
    if (p.width != w || p.height != h || p.channels != ch)
      throw std::invalid_argument("side_by_side: panels differ in size");
  const int n = int(panels.size());
  Image out(n * w + (n - 1) * gap, h, ch);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < out.width; ++x) {
      const int i = x / (w + gap), px = x - i * (w + gap);
      for (int c = 0; c < ch; ++c)
        out.at(x, y, c) = px < w ? panels[i].at(px, y, c) : float(c < 3 ? gap_color[c] : 1.0);
    }
  return out;
}

std::vector<int> preview_frames(const BakeManifest& bake, const std::optional<FrameRange>& range,
                                std::vector<int>* missing) {
  std::vector<int> frames;
  std::error_code ec;
  if (range) {
    if (range->last < range->first)
      throw UsageError("--frames " + std::to_string(range->first) + "-" + std::to_string(range->last) +
                       ": the range is empty");
    for (int f = range->first; f <= range->last; ++f) {
      const std::string obj = bake.frame_file("obj", f);
      if (std::find(bake.frames.begin(), bake.frames.end(), f) == bake.frames.end() || !fs::exists(obj, ec))
        throw InputError(obj, "missing: frame " + std::to_string(f) + " is not in this bake", f);
      frames.push_back(f);
    }
    return frames;
  }
  for (int f : bake.frames) {
    if (fs::exists(bake.frame_file("obj", f), ec))
      frames.push_back(f);
    else if (missing)
      missing->push_back(f);
  }
  if (frames.empty())
    throw InputError(bake.frames.empty() ? bake_manifest_path(bake.dir, bake.name) : bake.frame_file("obj", bake.frames[0]),
                     "missing: the bake has no frame on disk");
  return frames;
}

PreviewExtent preview_extent(const std::vector<BakeManifest>& bakes, const std::vector<int>& frames,
                             std::size_t max_points) {
  PreviewExtent extent;
  for (const BakeManifest& b : bakes) {
    const PreviewExtent e = preview_extent(b, frames, max_points / std::max<std::size_t>(1, bakes.size()));
    if (!e.box.empty()) {
      extent.box.extend(e.box.lo);
      extent.box.extend(e.box.hi);
    }
    extent.points.insert(extent.points.end(), e.points.begin(), e.points.end());
  }
  return extent;
}

void require_compared_frames(const std::vector<BakeManifest>& bakes, const std::vector<int>& frames) {
  for (std::size_t i = 1; i < bakes.size(); ++i)
    for (int f : frames) {
      const std::string obj = bakes[i].frame_file("obj", f);
      std::error_code ec;
      if (!fs::exists(obj, ec))
        throw InputError(obj, "missing: the bake compared with " + bakes.front().dir + " has no frame " +
                                  std::to_string(f), f);
    }
}

std::vector<std::string> panel_labels(const std::vector<BakeManifest>& bakes) {
  std::set<std::string> modes;
  for (const BakeManifest& b : bakes) modes.insert(raster_mode_name(b.options.raster.mode));
  std::vector<std::string> labels;
  for (const BakeManifest& b : bakes)
    labels.push_back(modes.size() == bakes.size() ? raster_mode_name(b.options.raster.mode)
                                                  : fs::path(b.dir).filename().string());
  return labels;
}

std::optional<Vec3> parse_up_axis(const std::string& text) {
  static const std::pair<const char*, Vec3> named[] = {{"z", {0, 0, 1}},  {"+z", {0, 0, 1}}, {"y", {0, 1, 0}},
                                                       {"+y", {0, 1, 0}}, {"x", {1, 0, 0}},  {"+x", {1, 0, 0}},
                                                       {"-z", {0, 0, -1}}, {"-y", {0, -1, 0}}, {"-x", {-1, 0, 0}}};
  for (const auto& [name, axis] : named)
    if (text == name) return axis;
  std::stringstream in(text);
  std::string item;
  std::vector<double> v;
  while (std::getline(in, item, ',')) {
    std::size_t used = 0;
    try {
      v.push_back(std::stod(item, &used));
    } catch (const std::exception&) {
      return std::nullopt;
    }
    if (used != item.size()) return std::nullopt;
  }
  if (v.size() != 3 || !std::isfinite(v[0] + v[1] + v[2]) || norm(Vec3{v[0], v[1], v[2]}) == 0) return std::nullopt;
  return normalized(Vec3{v[0], v[1], v[2]});
}

}  // namespace lapflow
