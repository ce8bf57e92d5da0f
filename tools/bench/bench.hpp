#pragma once
// Sections of the lapflow benchmark program (lapflow_bench), one function per
// stage family, each in its own tools/bench/bench_*.cpp.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace lapflow::bench {

/// FNV-1a, 64-bit, over `bytes` bytes, continuing from `h`: the benches'
/// digest of what they computed (equal digests before and after an
/// optimisation mean the output did not change).
inline constexpr uint64_t kFnvOffset = 1469598103934665603ull;
inline uint64_t fnv1a(const void* data, std::size_t bytes, uint64_t h = kFnvOffset) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

/// Rasterizer alone (tools/bench/bench_raster.cpp): a plane of 2 * grid_cells^2
/// fluid triangles covered by about `target_patches` patches, one atlas per
/// resolution in `resolutions` (texels per side). threads = 0: all cores.
void bench_raster(const std::vector<int>& resolutions, int grid_cells = 224, int target_patches = 5000,
                  int threads = 0);

/// Patches (issue 3, tools/bench/bench_patches.cpp): advect + project about 1M
/// patch vertices, create + remesh + flatten one ~200-triangle patch, seed a
/// ~100k-triangle frame with ~5k patches. Uses `data_dir`/dam_break when
/// present, synthetic meshes otherwise. Prints one line per measurement.
void bench_patches(const std::string& data_dir);

/// The Poisson seeding a bake runs every frame for `fresh_seeding`, timed on
/// shared splash, dam_break and channel frames (tools/bench/bench_patches.cpp).
void bench_fresh_seeding(const std::string& data_dir);

/// Surface atlas (issue 4, tools/bench/bench_atlas.cpp): charts + LSCM + packing +
/// texel map at 4096^2 on 2 threads for noisy cube-spheres of about 25k, 50k
/// and 100k triangles (linearity) and for every 5th frame of
/// `data_dir`/dam_break when present. Prints seconds per stage, charts,
/// utilization and texel-density share per mesh.
void bench_atlas(const std::string& data_dir);

/// The UV-mesh OBJ writer (issue 15, tools/bench/bench_atlas.cpp): on the shared
/// splash frames 1, 12, 24 and 48, the best of three write_uv_mesh_obj calls
/// against writing the same number of bytes already formatted, so formatting
/// and file writing are told apart.
void bench_obj(const std::string& data_dir);

/// One frame of a finished bake computed again `repeats` times in one
/// process (tools/bench/bench_replay.cpp): the tracking from the previous frame's
/// state (the bake keeps the last two; `lapflow track` keeps all) and the
/// output from its result, each step timed, nothing else running. Prints a
/// row per repeat (with a digest of the images and patches, which must not
/// change), then the minimum and the median of each step.
void bench_replay(const std::string& bake_dir, int frame, int repeats);

/// Frame `frame` of the bake in `bake_dir` (its colour and displacement
/// EXRs and its state) written again `rounds` times each way, with direct
/// writes and through the page cache, alternated (tools/bench/bench_write.cpp):
/// wall and CPU per round, then the minimum and median of each way.
void bench_write(const std::string& bake_dir, int frame, int rounds);

}  // namespace lapflow::bench
