// The memory a bake will need, decided before anything large is allocated.
// docs/robustness.md has the model, where each constant comes from and the
// measurements that check it.
#include "lapflow/bake/budget.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow {
namespace fs = std::filesystem;
namespace {

// Measured peaks are in docs/robustness.md; the constants come from what the
// code allocates and the measurement checks them.
// ---- per atlas texel (N^2 of them) ----------------------------------------
// The raster's texel index (int32), the colour (RGBA float) and displacement
// (float) images, and their half copies while the EXRs are written (freed
// blocks stay in the heap for reuse, keep_freed_memory_for_reuse, so the
// write phase's buffers add to the raster's in the peak).
constexpr double kAtlasTexelBytes = 4 + 16 + 4 + 8 + 2;
// --aov: patch_id u v w as float.
constexpr double kAovTexelBytes = 16;
// ---- per chart texel (a share kUtilization of the atlas) --------------------
// The texel map (texel, triangle) of this frame and of the next one, read
// ahead (2 x 8); the raster's keys (8), flags (1) and hole labels (4).
constexpr double kChartTexelBytes = 2 * 8 + 8 + 1 + 4;
// Blend mode's fixed-point sums (5 x 8) and best weights (8).
constexpr double kBlendChartTexelBytes = 48;
// Chart texels / atlas texels: what the packer reaches on the shared scenes
// and on thousands of droplet charts is in docs/atlas.md, "Denser atlases";
// provision for the high end.
constexpr double kUtilization = 0.85;
// ---- the fluid meshes --------------------------------------------------------
// Per fluid triangle of a frame in flight: the mesh (positions, velocities,
// triangles), Embree's BVH, the velocity band, the atlas's per-triangle
// tables (charts, LSCM, corner uv) and the raster's (normals, centroids,
// vertex-triangle and triangle-triangle lists, seams: the last about 48
// bytes a triangle in each of the two rasters of a frame). Checked by splash
// against dam_break at the same resolution (docs/robustness.md, "The
// measurement that checks it").
constexpr double kTriangleBytes = 432;
// Frames alive at once: the previous one (velocity), the current one and the
// next one being read ahead.
constexpr double kFramesInFlight = 3;
// ---- patches ------------------------------------------------------------------
// Per patch vertex: position 24, rest uv 16, surface triangle 4, quality 4,
// border 1, weight 4; per patch triangle: indices 12, quality 4, delta 4.
// Vectors grow by doubling: provision 1.5x.
constexpr double kPatchVertexRawBytes = 53, kPatchTriangleRawBytes = 20;
constexpr double kPatchVertexBytes = 1.5 * kPatchVertexRawBytes, kPatchTriangleBytes = 1.5 * kPatchTriangleRawBytes;
// Per patch: its struct, the held-cell grid (2 KiB) and the raster's
// per-patch tables. With the lattice's 204 vertices a patch comes to 32 KiB,
// which a small radius against the default checks (docs/robustness.md, "The
// measurement that checks it").
constexpr double kPatchFixedBytes = 4000;
// NAME.state.N.bin (src/bake/state.cpp), encoded in memory each frame and
// held until written: per patch a header of about 100 bytes and its held
// cells (2 KiB), and the vertex and triangle arrays as they are (the raw
// bytes above, without the vectors' slack). The byte string grows by
// doubling: provision 2x.
constexpr double kStatePatchBytes = 100 + 2048;
constexpr double kStateSlack = 2;
// A lattice patch has about 5.67 / e^2 vertices for a remesh edge e r (an
// equilateral lattice of edge 0.8 e r over a disk of radius r), twice as many
// triangles.
constexpr double kLatticeVertexFactor = 5.67;
// Population over the patches that cover the surface once (area / pi r^2):
// a Poisson seeding at spacing r holds about 2x that, and the population
// grows to under 4x a fresh seeding without the temporal options (channel,
// docs/temporal.md): 2 x 4 = 8x (docs/robustness.md, "The model").
constexpr double kPopulationFactor = 8;
// Poisson-disk candidates: 40 per area / d^2, 32 bytes each, twice (the
// first frame's seeding and the read-ahead's fresh-seeding count).
constexpr double kSeedingBytesPerUnit = 2 * 40 * 32;
// ---- exemplar -------------------------------------------------------------------
// Per exemplar pixel beyond the decoded files: RGB copy (12), grey feature
// and displacement (4 + 4), the mip pyramid of R G B H (16 x 4/3), the
// erosion map and its held maximum (4 + 4).
constexpr double kExemplarPixelBytes = 12 + 4 + 4 + 16 * 4.0 / 3 + 4 + 4;
// The program, its libraries, thread stacks and allocator slack: the peak of
// a 1024^2 dam_break bake less the parts above.
constexpr double kBaseBytes = 120.0 * (1 << 20);

std::string area_text(double area) { return fmt::format("{:.3g} m²", area); }

}  // namespace

BakeInputSizes read_bake_input_sizes(const BakeOptions& o) {
  BakeInputSizes s;
  const FramePattern meshes(o.mesh_pattern);
  const std::vector<int> frames = resolve_frames(meshes, o.frames);
  s.first_mesh = meshes.path(frames.front());
  MeshFile file;
  try {
    // With the attributes the layer rules read: a name the frames lack
    // is refused before anything is baked.
    file = read_mesh_file(s.first_mesh, true, frame_source(o).attributes);
  } catch (const InputError& e) {
    throw e.with_frame(frames.front());
  }
  // Units first: a mesh in millimetres would otherwise be refused for the
  // radius or memory it seems to need, a less helpful message. Every frame
  // is checked again as the bake reads it (read_frame_input).
  if (!o.units_ok) check_frame_units(s.first_mesh, frames.front(), file, o.velocity_vdb_pattern.empty());
  const TriMesh& first = file.mesh;
  s.area = surface_area(first);
  s.triangles = first.triangle_count();
  s.vertices = first.vertex_count();
  // File sizes only (a stat per frame): the largest frame over the first.
  std::error_code ec;
  const double first_bytes = double(fs::file_size(s.first_mesh, ec));
  if (!ec && first_bytes > 0) {
    double largest = first_bytes;
    for (int f : frames) {
      const auto bytes = fs::file_size(meshes.path(f), ec);
      if (!ec) largest = std::max(largest, double(bytes));
    }
    s.growth = largest / first_bytes;
  }
  // An animated exemplar's first frame, and its frame count.
  const auto header = [](const std::string& path, std::size_t* frames = nullptr) {
    const std::vector<std::string> files = exemplar_frame_files(path);
    if (frames) *frames = files.size();
    return read_image_header(files.front());
  };
  if (o.layers.empty()) {
    s.color = header(o.exemplar_color, &s.frames);
    if (!o.exemplar_feature.empty()) s.feature = header(o.exemplar_feature);
    if (!o.exemplar_displacement.empty()) s.displacement = header(o.exemplar_displacement);
    return s;
  }
  for (const ExemplarLayer& layer : o.layers) {
    BakeInputSizes::Layer& l = s.layers.emplace_back();
    l.color_path = layer.color, l.feature_path = layer.feature, l.displacement_path = layer.displacement;
    l.color = header(layer.color, &l.frames);
    if (!layer.feature.empty()) l.feature = header(layer.feature);
    if (!layer.displacement.empty()) l.displacement = header(layer.displacement);
  }
  s.color = s.layers[0].color, s.feature = s.layers[0].feature, s.displacement = s.layers[0].displacement;
  s.frames = s.layers[0].frames;
  return s;
}

BakeMemoryEstimate estimate_bake_memory(const BakeOptions& o, const BakeInputSizes& s) {
  BakeMemoryEstimate e;
  const double r = o.patch.radius, spacing = o.seeding.spacing;
  const double d = spacing * r;
  // Areas grow with the sequence roughly as the files do.
  const double area = s.area * s.growth;
  e.covering_patches = r > 0 ? s.area / (std::numbers::pi * d * d) : 0;
  e.patches = kPopulationFactor * (r > 0 ? area / (std::numbers::pi * d * d) : 0);
  double& vertices_per_patch = e.vertices_per_patch;
  if (o.patch.remesh) {
    const double edge = o.patch.remesh_edge;
    vertices_per_patch = kLatticeVertexFactor / (edge * edge);
  } else {
    // The fluid's own vertices within r.
    vertices_per_patch = s.area > 0 ? std::numbers::pi * r * r * double(s.vertices) / s.area : 0;
  }
  vertices_per_patch = std::max(vertices_per_patch, 16.0);
  e.patch_bytes =
      e.patches * (kPatchFixedBytes + vertices_per_patch * (kPatchVertexBytes + 2 * kPatchTriangleBytes));
  e.state = kStateSlack * e.patches *
            (kStatePatchBytes + vertices_per_patch * (kPatchVertexRawBytes + 2 * kPatchTriangleRawBytes));
  e.seeding = r > 0 ? kSeedingBytesPerUnit * std::min(area / (d * d), 5e8 / 40) : 0;

  const double n2 = double(o.atlas.resolution) * double(o.atlas.resolution);
  double chart = kChartTexelBytes;
  if (o.raster.mode == RasterMode::Blend) chart += kBlendChartTexelBytes;
  e.atlas = n2 * (kAtlasTexelBytes + (o.aov ? kAovTexelBytes : 0) + kUtilization * chart);
  // With background writing one more frame of images waits for the disk.
  if (o.background_write) e.atlas += n2 * (16 + 4 + (o.aov ? kAovTexelBytes : 0));
  // --texture tiled: OpenImageIO's texture maker holds each atlas in float
  // about twice while it writes it (measured at 6144^2: colour +1311 MiB,
  // displacement +327 MiB, written at once: 46 bytes a texel).
  if (o.exr.layout == ExrLayout::TiledMipmap) e.atlas += n2 * 47;

  // The tracking atlas: its index and chart buffers, no image.
  const double nt = double(tracking_resolution(area, r, o.track_texel));
  e.tracking = nt * nt * (4 + kUtilization * kChartTexelBytes);

  e.meshes = kFramesInFlight * kTriangleBytes * double(s.triangles) * s.growth;

  const auto exemplar_bytes = [](const ImageHeader& color, const ImageHeader& feature, const ImageHeader& disp) {
    return color.decoded_bytes() + feature.decoded_bytes() + disp.decoded_bytes() +
           double(color.width) * double(color.height) * kExemplarPixelBytes;
  };
  e.exemplar = double(s.frames) * exemplar_bytes(s.color, s.feature, s.displacement);
  for (std::size_t l = 1; l < s.layers.size(); ++l)
    e.exemplar += double(s.layers[l].frames) *
                  exemplar_bytes(s.layers[l].color, s.layers[l].feature, s.layers[l].displacement);
  e.base = kBaseBytes;
  e.total = e.atlas + e.tracking + e.patch_bytes + e.state + e.seeding + e.meshes + e.exemplar + e.base;
  return e;
}

BakeMemoryEstimate check_bake_budget(const BakeOptions& o, const BakeInputSizes& s) {
  const BakeMemoryEstimate e = estimate_bake_memory(o, s);
  const std::size_t budget = o.max_memory > 0 ? o.max_memory : default_memory_budget();
  const std::string radius = fmt::format("radius {:.3g} m on {} of surface ({})", o.patch.radius,
                                         area_text(s.area), s.first_mesh);
  // Each image on its own first, so that the message names the file whose
  // header is absurd (a 1 KB PNG that claims 100000x100000).
  std::vector<BakeInputSizes::Layer> images = s.layers;
  if (images.empty())
    images.push_back({o.exemplar_color, o.exemplar_feature, o.exemplar_displacement, s.color, s.feature, s.displacement,
                      s.frames});
  for (const BakeInputSizes::Layer& l : images) {
    check_image_budget(l.color_path, l.color, 4.0 * l.color.channels + kExemplarPixelBytes, budget);
    if (l.feature.width > 0) check_image_budget(l.feature_path, l.feature, 4.0 * l.feature.channels + 8, budget);
    if (l.displacement.width > 0)
      check_image_budget(l.displacement_path, l.displacement, 4.0 * l.displacement.channels + 8, budget);
  }
  if (e.covering_patches > kMaxPatches)
    throw UsageError(fmt::format("--{} would need {:.2g} patches (more than {:.0e}){}", radius, e.covering_patches,
                                 kMaxPatches,
                                 o.seeding.spacing != 1 ? fmt::format(" at --spacing {:.3g}", o.seeding.spacing)
                                                        : std::string(": is the radius in metres?")));
  if (e.total <= double(budget)) return e;
  // Name what takes most of it.
  struct Part {
    double bytes;
    std::string what;
  };
  const Part parts[] = {
      {e.atlas, fmt::format("--resolution {}: {} of atlas buffers", o.atlas.resolution, format_bytes(e.atlas))},
      {e.tracking, fmt::format("--track-texel {:.3g} at --radius {:.3g} m: a {}x{} tracking atlas, {}", o.track_texel,
                               o.patch.radius, tracking_resolution(s.area * s.growth, o.patch.radius, o.track_texel),
                               tracking_resolution(s.area * s.growth, o.patch.radius, o.track_texel),
                               format_bytes(e.tracking))},
      {e.patch_bytes + e.state + e.seeding,
       fmt::format("--{} would need {:.2g} patches of {:.3g} vertices (--spacing {:.3g}, --remesh-edge {:.3g}): {} "
                   "with their state file",
                   radius, e.patches, e.vertices_per_patch, o.seeding.spacing, o.patch.remesh_edge,
                   format_bytes(e.patch_bytes + e.state + e.seeding))},
      {e.meshes, fmt::format("{}: {} triangles per frame: {} for the frames in flight", s.first_mesh, s.triangles,
                             format_bytes(e.meshes))},
      {e.exemplar, s.layers.size() > 1
                       ? fmt::format("--layer: {} exemplars: {}", s.layers.size(), format_bytes(e.exemplar))
                       : fmt::format("--exemplar {}: {}x{} pixels: {}", images[0].color_path, s.color.width,
                                     s.color.height, format_bytes(e.exemplar))},
  };
  const Part& top = *std::max_element(std::begin(parts), std::end(parts),
                                      [](const Part& a, const Part& b) { return a.bytes < b.bytes; });
  throw UsageError(fmt::format("the bake would need about {} of memory, more than --max-memory {}; {} "
                               "(docs/robustness.md)",
                               format_bytes(e.total), format_bytes(double(budget)), top.what));
}

double estimate_atlas_memory(std::size_t triangles, int resolution, bool texels_png) {
  const double n2 = double(resolution) * double(resolution);
  // The texel map (8 bytes per chart texel, at most every texel) and its
  // raster bands (4 per texel): 12; with --texels the float RGB image (12)
  // and its 8- and 16-bit copies (3 + 6).
  return kBaseBytes + kTriangleBytes * double(triangles) + n2 * (12 + (texels_png ? 21 : 0));
}

void check_image_budget(const std::string& path, const ImageHeader& h, double bytes_per_pixel, std::size_t budget) {
  const double bytes = double(h.width) * double(h.height) * bytes_per_pixel;
  if (bytes > double(budget))
    throw InputError(path, fmt::format("the header says {}x{} pixels x {} channels: working on it needs about {}, "
                                       "more than --max-memory {}",
                                       h.width, h.height, h.channels, format_bytes(bytes),
                                       format_bytes(double(budget))));
}

}  // namespace lapflow
