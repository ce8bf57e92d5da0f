#pragma once
/// \file budget.hpp The memory a bake will need, estimated from its inputs'
/// sizes and its options before anything large is allocated, and the check
/// against the budget (`--max-memory`). The model, its constants and the
/// measurements behind them are in docs/robustness.md.
#include <cstddef>
#include <string>

#include "lapflow/io/image.hpp"

namespace lapflow {

struct BakeOptions;

/// Sizes of a bake's inputs, read without decoding anything large: the first
/// frame's mesh (which a bake reads first anyway) and the exemplar images'
/// headers.
struct BakeInputSizes {
  std::string first_mesh;          ///< path of the first frame's mesh
  double area = 0;                 ///< m², first frame
  std::size_t triangles = 0, vertices = 0;  ///< first frame
  /// Largest mesh file of the frames over the first one's (bytes): a
  /// sequence whose surface grows needs more per frame than the first.
  double growth = 1;
  ImageHeader color, feature, displacement;  ///< displacement.width = 0 when there is none
  /// An animated exemplar's frames (the headers are its first frame's).
  std::size_t frames = 1;
  /// With exemplar layers (BakeOptions::layers), the above are the first
  /// layer's and these every layer's, in order.
  struct Layer {
    std::string color_path, feature_path, displacement_path;
    ImageHeader color, feature, displacement;
    std::size_t frames = 1;
  };
  std::vector<Layer> layers;
};

/// Reads BakeInputSizes for resolved inputs (exemplar paths filled): the
/// first frame's mesh and the image headers. Throws InputError.
BakeInputSizes read_bake_input_sizes(const BakeOptions& options);

/// The estimate, in bytes, by what needs the memory.
struct BakeMemoryEstimate {
  double covering_patches = 0;  ///< area / (pi (spacing r)^2): patches that cover the first frame once
  double patches = 0;           ///< the population the estimate provisions for
  double vertices_per_patch = 0;
  double atlas = 0;             ///< per-texel buffers of the frames in flight
  double tracking = 0;          ///< the tracking atlas's (BakeOptions::track_texel): index, texel maps, keys
  double patch_bytes = 0;       ///< the patch population
  double state = 0;             ///< the patch state encoded for NAME.state.N.bin while it is written
  double seeding = 0;           ///< Poisson-disk candidates (first frame, and the per-frame fresh count)
  double meshes = 0;            ///< the frames in flight: meshes, closest-point BVH, velocity band, atlas tables
  double exemplar = 0;          ///< decoded exemplar, its mip pyramid and erosion maps
  double base = 0;              ///< the program and its libraries
  double total = 0;
};

/// Patches beyond this many are refused whatever the memory: a radius that
/// small for the surface is a unit or typing mistake (the default radius
/// gives about 1500).
inline constexpr double kMaxPatches = 2e7;

/// The memory model of docs/robustness.md.
BakeMemoryEstimate estimate_bake_memory(const BakeOptions& options, const BakeInputSizes& sizes);

/// Throws UsageError (exit 2) when the estimate exceeds `options.max_memory`
/// (0: default_memory_budget()) or the patches exceed kMaxPatches, with one
/// line naming the option or file to change, e.g. "--radius 1e-06 m on 5.3 m²
/// of surface would need 1.7e+12 patches". Returns the estimate.
BakeMemoryEstimate check_bake_budget(const BakeOptions& options, const BakeInputSizes& sizes);

/// Memory `lapflow atlas` needs for a mesh of `triangles` at `resolution`
/// (with `texels_png`: the chart-texel PNG as well).
double estimate_atlas_memory(std::size_t triangles, int resolution, bool texels_png);

/// Throws InputError naming `path` when decoding the image `header` and
/// working on it at `bytes_per_pixel` bytes per pixel (in all) would exceed
/// `budget` bytes.
void check_image_budget(const std::string& path, const ImageHeader& header, double bytes_per_pixel,
                        std::size_t budget);

}  // namespace lapflow
