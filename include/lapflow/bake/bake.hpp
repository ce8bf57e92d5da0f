#pragma once
/// \file bake.hpp The bake: the whole frame loop over one per-frame state
/// (ALGORITHM.md steps 1-10). The CLI and the scene file fill BakeOptions.
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/raster/raster.hpp"

namespace lapflow {

struct BakeOptions {
  // Inputs
  std::string mesh_pattern;               ///< per-frame PLY/OBJ pattern
  std::optional<FrameRange> frames;       ///< all frames on disk when empty
  std::string velocity_vdb_pattern;       ///< per-frame OpenVDB files; vertex velocities when empty
  std::string velocity_grid;              ///< grid name; tries vel, v, velocity when empty
  double fps = 24;                        ///< dt = 1/fps seconds
  double min_speed = 0;                   ///< m/s: slower velocities count as zero
  bool allow_zero_velocity = false;       ///< accept a sequence with no velocity
  /// Bake frames with sizes, speeds or property types no liquid has
  /// (units_problems, io/mesh_io.hpp); else the first such frame is an
  /// InputError naming the file and frame. Does not change the output.
  bool units_ok = false;
  /// Per-vertex velocities are sampled once per frame on voxels of
  /// `velocity_voxel` mean edge lengths within `velocity_band` voxels of the
  /// surface, then read trilinearly (band 0 = an exact closest-point query
  /// for every sample).
  int velocity_band = 6;
  double velocity_voxel = 2.0;
  std::string exemplar_color, exemplar_feature, exemplar_displacement;
  /// Exemplar layers (docs/layers.md), in the order their rules are tried;
  /// empty: one layer, the exemplar_* files.
  std::vector<ExemplarLayer> layers;
  /// Each layer's rule by name (layer, rule text); the last layer has none.
  std::vector<std::pair<std::string, std::string>> layer_rules;
  /// Frames in a row a patch's centre must lie where the rules choose
  /// another layer before the patch is retired, so that the new layer's
  /// patches take the place (docs/layers.md, "Changing regions").
  int layer_switch = 6;
  /// An animated exemplar's rate in frames per second (0: one exemplar
  /// frame a bake frame) and what it plays past its last frame
  /// (docs/layers.md, "Animated exemplars").
  double exemplar_fps = 0;
  ExemplarLoop exemplar_loop = ExemplarLoop::Loop;
  // Outputs
  std::string out_dir;
  std::string name = "lapflow";
  bool aov = false;
  bool dump_patches = false;
  ExrOptions exr;
  /// Also write the frame as a USD layer (NAME.usd.N.usda) and keep the
  /// shot's stage NAME.usda naming every frame on disk (io/usd.hpp).
  bool usd = true;
  /// The stage's upAxis: 'Z' (Blender, Mantaflow) or 'Y' (Houdini, Maya).
  char up_axis = 'Z';
  /// Read the next frame (mesh, Embree scene, velocity band) and build its
  /// surface atlas on another thread while the current one computes.
  bool prefetch_read = true;
  /// Write each frame's files on another thread while the next frame
  /// computes: one more frame of images in memory.
  bool background_write = false;
  /// Bytes the bake may use: resolve_bake_options refuses options and
  /// inputs whose estimate (bake/budget.hpp, docs/robustness.md) exceeds it.
  /// 0 = 80% of physical memory.
  std::size_t max_memory = 0;
  /// Continue after the last complete frame of out_dir that has a state
  /// (NAME.state.N.bin), when its NAME.bake.json has the same options;
  /// otherwise, and without a state, bake from the first frame. Without
  /// `resume` a bake always starts from the first frame.
  bool resume = false;
  /// The frames whose NAME.state.N.bin stays on disk: the last `keep_states`
  /// (-1: all of them, 0: none, and no resume is possible).
  int keep_states = 2;
  /// The patch dynamics (coverage, holes, births, retirement: everything
  /// that carries over to the next frame) are decided on an atlas of its
  /// own whose texels measure about `track_texel` x r on the surface,
  /// whatever the output --resolution (docs/farm.md, "Tracking
  /// resolution"): a 1024^2 preview and a 6144^2 final show the same patches.
  double track_texel = 1.0 / 32;
  /// `lapflow track`: decide and write NAME.state.N.bin for every frame
  /// (keep_states is ignored: all are kept), and no atlas image or UV mesh.
  bool track_only = false;
  /// Stop after this frame (a chunk of a farm's tracking chain); the
  /// manifest still names every frame of `frames`.
  std::optional<int> until_frame;
  // Stages
  uint64_t seed = 1;
  PatchOptions patch;                     ///< patch.radius = r in metres (0 = automatic)
  SeedOptions seeding;
  AdvectOptions advect;                   ///< advect.dt is set from fps
  WeightOptions weights;
  AtlasOptions atlas;                     ///< atlas.resolution 0 = automatic
  RasterOptions raster;
};

/// The gutter of the tracking atlas, in its texels: decisions need no colour
/// dilation, only charts that do not touch.
constexpr int kTrackingGutter = 2;

/// The resolution of the tracking atlas of a frame whose surface has area
/// `area`: texels of track_texel x radius on the surface at the packer's
/// usual utilization (0.7), a multiple of 8 in [64, 16384].
int tracking_resolution(double area, double radius, double track_texel);

/// Where BakeOptions says the frames and their velocities come from.
FrameSource frame_source(const BakeOptions& options);

/// Fills automatic values (radius, resolution) from the first frame and the
/// exemplar's header, checks every option, and checks the memory the bake
/// will need against max_memory before anything large is allocated
/// (check_bake_budget). Returns that estimate. Throws UsageError / InputError.
BakeMemoryEstimate resolve_bake_options(BakeOptions& options);

/// Bakes every frame; `on_frame` is called after each frame is written.
/// Files per frame N (4 digits) in out_dir: NAME.N.obj + NAME.N.mtl,
/// NAME.color.N.exr, NAME.disp.N.exr, NAME.aov.N.exr (with aov),
/// NAME.patches.N.ply (with dump_patches), NAME.state.N.bin (the last
/// keep_states frames); NAME.stats.jsonl for the sequence.
/// A frame's files are renamed into place together, the OBJ last: frame N
/// is complete when NAME.N.obj exists. First removes this bake's stale
/// temporary files from out_dir. With `resume`, continues after the last
/// complete frame with a state, with the same bytes in every file as an
/// uninterrupted bake; an InputError names the manifest whose options differ
/// (and each difference) or the damaged state file. Throws InputError for bad input,
/// OutputError naming the folder or file that cannot be written (earlier
/// frames stay intact), and Interrupted when stop_signal() (interrupt.hpp)
/// asks to stop: checked before each frame and before writing one.
void bake(const BakeOptions& options, const std::function<void(const FrameStats&)>& on_frame = {});

/// Step 6 of a frame: its tracking atlas (tracking_resolution, kTrackingGutter)
/// and, unless options.track_only, its output atlas. The bake's reader builds
/// them ahead of the frame.
void build_frame_atlases(Frame& frame, const BakeOptions& options);

/// The tracking half of one frame, as `bake` and `lapflow track` run it: the
/// patches advected from `previous` (none: the first frame) and their weights
/// (steps 4-5), the seeding when no patch is left (steps 1-3), then steps 7-9
/// at the tracking resolution (draw, hole filling with births, the texels
/// each patch won, retirement). `frame` must have its tracking atlas.
/// `patches` leave as the frame's state. Fills the tracking's part of
/// frame.stats and returns the tracking raster's counts.
RasterStats track_frame(Frame& frame, const Frame* previous, PatchSet& patches, ExemplarLayers exemplars,
                        const BakeOptions& options);

/// The output of one frame from the patches as they leave it, as `bake` and
/// `lapflow render` both draw it (docs/farm.md): the frame's output atlas
/// must be built. Draws the patches at the output resolution, closes the
/// holes without births (close_holes), resolves the images into
/// frame.textures and dilates the gutter. Fills the output's part of
/// frame.stats: draw, holes, resolve, dilate and raster seconds, charts,
/// utilization, chart, forced, closed and held texels, coverage.
void render_frame(Frame& frame, const PatchSet& patches, ExemplarLayers exemplars, const BakeOptions& options);

/// Peak resident memory of this process so far, in MiB.
double peak_rss_mb();

/// Makes the C library keep freed large blocks for reuse instead of returning
/// them to the kernel. A bake allocates the same large frame buffers every
/// frame (images, texel maps, EXR conversion buffers); glibc serves large
/// blocks with fresh mmap pages, which the kernel zeroes on first touch, page
/// by page, every frame. After this call they come from the heap and are
/// reused. All threads share that one heap: a thread's own arena serves
/// anything larger than its heap from mmap whatever the settings, and the
/// texel map (built on the read-ahead thread) and the EXR half buffers are
/// allocated off the main thread. Process-wide: call it once from main(),
/// before any thread starts (the lapflow CLI and the benchmark do). Peak
/// memory is unchanged; memory freed between frames stays mapped. The cost
/// it saves is in docs/performance.md. On one heap, long-lived small blocks
/// settle between the frames' large arrays and the heap fragments
/// (docs/performance.md, "Memory and large blocks"); the executables
/// therefore serve blocks of 8 MiB and more from LargeBlocks
/// (lapflow/core/large_blocks.hpp) through their operator new.
void keep_freed_memory_for_reuse();

}  // namespace lapflow
