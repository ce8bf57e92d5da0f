// `lapflow patches`: patches seeded on the first frame and advected through
// the sequence with no hole filling and no atlas, one PLY of patches per
// frame (patch_id, rest uv, weight), to look at how patches ride the flow.
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "lapflow/bake/frame.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow {

struct PatchDumpOptions {
  FrameSource source;       ///< meshes and velocity: the bake's rules and defaults
  std::vector<int> frames;  ///< in order (resolve_frames)
  std::string out_dir;      ///< OUT; created when missing
  std::string name;         ///< files OUT/NAME.patches.%04d.ply
  PatchOptions patch;
  SeedOptions seeding;
  WeightOptions weights;
  double fps = 24;              ///< dt = frame step / fps
  std::size_t max_memory = 0;   ///< bytes; 0 = default_memory_budget()
};

/// The patches after one frame.
struct PatchDumpFrame {
  int frame = 0;
  bool seeded = false;  ///< the first frame: the patches were seeded on it
  AdvectStats advect;   ///< the step into this frame (zero on the first)
  std::size_t patches = 0, vertices = 0, triangles = 0;
  double median_delta = 0, mean_weight = 0;
  double eroded = 0;  ///< fraction of triangles with delta >= delta_max or folded
  std::string path;   ///< the PLY written
};

/// Seeds on the first frame, advects through the rest and writes each
/// frame's PLY; `on_frame` is called after each. Patches only die (no hole
/// filling). The bake's memory model (patches and meshes only) refuses a
/// radius whose patches would not fit `max_memory` before the seeding
/// (InputError). Throws UsageError for options out of range.
void dump_patches(const PatchDumpOptions& options, const std::function<void(const PatchDumpFrame&)>& on_frame = {});

}  // namespace lapflow
