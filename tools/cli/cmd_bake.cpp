// `lapflow bake`: the product. Parses options (and a TOML scene file whose
// keys mirror them), resolves defaults, and runs the frame loop.
#include <algorithm>
#include <filesystem>
#include <map>

#include "cli_common.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/bake.hpp"

namespace lapflow::cli {

void bake_with_progress(BakeOptions& o) {
  // From here a SIGINT / SIGTERM stops the bake between frames; neither
  // leaves a half file.
  const StopHandlersScope stop_handlers;
  const BakeMemoryEstimate memory = resolve_bake_options(o);

  const std::vector<int> frames = resolve_frames(FramePattern(o.mesh_pattern), o.frames);
  const std::string verb = o.track_only ? "track" : "bake";
  info("lapflow {}: {} frames {}-{} of {}", verb, frames.size(), frames.front(), frames.back(), o.mesh_pattern);
  info("  exemplar {} | radius {:.4g} m | atlas {}x{} | tracking texel {:.4g} r | seed {} | {} threads",
       o.exemplar_color, o.patch.radius, o.atlas.resolution, o.atlas.resolution, o.track_texel, o.seed,
       thread_count_label());
  info("  memory estimate {} (atlas {}, tracking {}, {:.0f} patches {}, meshes {}, exemplar {}) of --max-memory {}",
       format_bytes(memory.total), format_bytes(memory.atlas), format_bytes(memory.tracking), memory.patches,
       format_bytes(memory.patch_bytes + memory.state + memory.seeding), format_bytes(memory.meshes), format_bytes(memory.exemplar),
       format_bytes(double(o.max_memory > 0 ? o.max_memory : default_memory_budget())));
  Progress progress(verb, frames.size());
  double seconds = 0;
  std::size_t baked = 0;  // fewer than frames.size() when --resume skipped the frames already there
  bake(o, [&](const FrameStats& s) {
    seconds += s.seconds_total;
    ++baked;
    progress.step(fmt::format("frame {}: {} tris, {} patches (+{} -{}), tracked at {}px, coverage {:.2f}%, {:.2f}s",
                              s.frame, s.triangles, s.patches_alive, s.patches_born,
                              s.patches_retired + s.patches_lost, s.tracking.resolution, 100 * s.coverage,
                              s.seconds_total));
  });
  progress.finish();
  if (baked < frames.size() && !o.until_frame)
    info("resumed: {} of the {} frames were already {} in {}", frames.size() - baked, frames.size(),
         o.track_only ? "tracked" : "baked", o.out_dir);
  info("done: {} frames in {:.1f} s ({:.2f} s/frame), peak memory {:.0f} MiB; outputs in {}", baked, seconds,
       seconds / double(std::max<std::size_t>(baked, 1)), peak_rss_mb(), o.out_dir);
}

namespace {

struct BakeCli {
  BakeOptions o;
  std::string frames, orientation = "random", exr_type = "half", compression = "rle", mode = "erosion";
  std::string keep_states = "2";
  bool no_remesh = false;
  bool paper = false;
};

/// --keep-states: all, last (1), none (0) or a count.
int parse_keep_states(const std::string& text) {
  if (text == "all") return -1;
  if (text == "last") return 1;
  if (text == "none") return 0;
  std::size_t used = 0;
  int n = -1;
  try {
    n = std::stoi(text, &used);
  } catch (const std::exception&) {
  }
  if (used != text.size() || n < 0)
    throw UsageError("--keep-states: '" + text + "' is not all, last, none or a count of frames");
  return n;
}

void run_bake(BakeCli& c) {
  apply_global_options();
  BakeOptions& o = c.o;
  o.seed = globals().seed;
  if (!c.frames.empty()) o.frames = parse_frame_range(c.frames);
  resolve_exemplar_paths(o.exemplar_color, o.exemplar_feature, o.exemplar_displacement);
  if (o.name.empty()) o.name = default_output_name(o.mesh_pattern);
  o.patch.remesh = !c.no_remesh;
  o.patch.align = parse_orientation(c.orientation, o.patch.align_direction);
  o.exr.type = c.exr_type == "float" ? ExrPixelType::Float : ExrPixelType::Half;
  static const std::map<std::string, ExrCompression> compressions{
      {"piz", ExrCompression::Piz}, {"zip", ExrCompression::Zip}, {"dwaa", ExrCompression::Dwaa},
      {"none", ExrCompression::None}, {"rle", ExrCompression::Rle}};
  o.exr.compression = compressions.at(c.compression);
  o.raster.mode = parse_raster_mode(c.mode);
  if (c.paper) {
    o.raster.use_paper_hole_filling();
    o.patch.anticipate = 0;
    o.advect.through_flow = false;
    o.advect.run_off = false;
  }
  o.keep_states = parse_keep_states(c.keep_states);
  if (o.track_only) o.keep_states = -1;  // render needs every frame's
  bake_with_progress(o);
}

}  // namespace

void add_bake_options(CLI::App& cmd, BakeCli& c);
void add_track_command(CLI::App& app);

void add_bake_command(CLI::App& app) {
  static BakeCli c;
  CLI::App* cmd = app.add_subcommand("bake", "Bake a liquid sequence into per-frame EXR atlases and UV meshes");
  cmd->description(
      "Bake a liquid sequence into per-frame EXR atlases and UV meshes.\n\n"
      "Reads one mesh per frame (PLY or OBJ, with per-vertex velocity vx vy vz or an OpenVDB velocity grid),\n"
      "covers the first frame with Poisson-disk texture patches, carries them along the flow frame by frame,\n"
      "erodes each patch where it is too distorted (guided by the exemplar's feature map), fills holes with\n"
      "new patches and writes, per frame N in --out:\n"
      "  NAME.N.obj + NAME.N.mtl   the frame's mesh with atlas UVs (MTL points at the two EXRs)\n"
      "  NAME.color.N.exr          R G B A (A = 1 inside charts), gutter dilated\n"
      "  NAME.disp.N.exr           Y: displacement from the exemplar's height map\n"
      "  NAME.aov.N.exr            patch_id u v w per texel (with --aov)\n"
      "  NAME.patches.N.ply        the patches (with --dump-patches)\n"
      "  NAME.state.N.bin          the patch state at the end of frame N, for --resume (the last 2 frames'\n"
      "                            by default: --keep-states)\n"
      "  NAME.stats.jsonl          one JSON line per frame: counts, coverage, seconds per stage, memory\n"
      "Every file of a frame is written to a temporary name; they are renamed into place together, the OBJ\n"
      "last: a frame whose OBJ is there is complete. A bake first removes the temporary files (.NAME.*.tmp*)\n"
      "that killed runs of it left in --out (never those of a process still running). SIGINT or SIGTERM stops at the next frame boundary (a frame being\n"
      "written is finished, one being computed is dropped); a second one stops at once. Neither leaves a\n"
      "temporary file.\n"
      "--resume continues a killed or stopped bake after its last complete frame with a state, with the same\n"
      "options (checked against NAME.bake.json: a difference is exit 2 naming it), and gives the same bytes in\n"
      "every file as an uninterrupted bake. Without --resume a bake starts from the first frame.\n\n"
      "A scene file (lapflow bake scene.toml) holds the same options as keys (mesh = \"...\", radius = 0.05);\n"
      "options given on the command line override it. Paths in it are relative to the file.\n\n"
      "Exit codes: 0 ok, 2 bad input or usage (the message names the file, frame and element) or an output\n"
      "problem (--out not a writable folder, disk full: the message names the folder or file), 130 / 143\n"
      "stopped by SIGINT / SIGTERM (the message names the last complete frame), 1 internal error.");
  add_bake_options(*cmd, c);
  add_global_options(*cmd);
  cmd->callback([] { run_bake(c); });
}

void add_track_command(CLI::App& app) {
  static BakeCli c;
  static int until = 0;
  CLI::App* cmd = app.add_subcommand("track", "The sequential pass of a farm bake: patch states, no atlas");
  cmd->description(
      "The sequential half of a bake: reads the frames, advects the patches, decides births and retirements at\n"
      "the tracking resolution (--track-texel) and writes, per frame N in --out, NAME.state.N.bin (every frame's\n"
      "is kept), plus NAME.bake.json and NAME.stats.jsonl. It writes no atlas and no UV mesh: `lapflow render`\n"
      "makes them from the states, any frame on its own, at any --resolution. It takes a scene file and options\n"
      "exactly as `lapflow bake` does; `lapflow bake` is track + render in one process, with the same files.\n"
      "--resume continues after the last tracked frame (the output options may differ); --until F stops after\n"
      "frame F (a chunk of a farm's chain: docs/farm.md).\n\n"
      "Exit codes as for bake.");
  add_bake_options(*cmd, c);
  cmd->add_option("--until", until, "Stop after this frame (the manifest still names every frame of --frames)")
      ->group("Output");
  add_global_options(*cmd);
  cmd->callback([] {
    c.o.track_only = true;
    if (until != 0) c.o.until_frame = until;
    run_bake(c);
  });
}

void add_bake_options(CLI::App& cmd, BakeCli& c) {
  BakeOptions& o = c.o;
  o.patch.radius = 0;       // automatic unless given
  o.atlas.resolution = 0;   // automatic unless given
  cmd.add_option("--mesh", o.mesh_pattern,
                 "Per-frame meshes: name.%04d.ply, name.####.ply, name.$F4.ply or name.$F.ply (PLY or OBJ)")
      ->group("Input");
  cmd.add_option("--frames", c.frames, "Frame range A-B (default: every frame found on disk)")->group("Input");
  cmd.add_option("--velocity-vdb", o.velocity_vdb_pattern,
                 "Per-frame OpenVDB velocity files (default: per-vertex vx vy vz of the meshes)")
      ->group("Input");
  cmd.add_option("--velocity-grid", o.velocity_grid, "Grid name in the VDB files (default: vel, v, velocity)")
      ->group("Input");
  cmd.add_option("--fps", o.fps, "Frames per second; dt = 1/fps")->capture_default_str()->group("Input");
  cmd.add_option("--min-speed", o.min_speed, "Velocities slower than this (m/s) count as zero: stops creep at rest")
      ->capture_default_str()
      ->group("Input");
  cmd.add_flag("--allow-zero-velocity", o.allow_zero_velocity, "Accept meshes without velocity (a still texture)")
      ->group("Input");
  cmd.add_flag("--units-ok", o.units_ok, units_ok_help("bake"))->group("Input");
  cmd.add_option("--velocity-band", o.velocity_band,
                 "Per-vertex velocity is sampled once per frame on voxels within N voxels of the surface and read "
                 "trilinearly; 0 = exact closest-point sampling everywhere (slower)")
      ->check(CLI::Range(0, 16))
      ->capture_default_str()
      ->group("Input");
  cmd.add_option("--velocity-voxel", o.velocity_voxel, "Voxel size of that band, in mean edge lengths of the frame's mesh")
      ->check(CLI::Range(0.25, 16.0))
      ->capture_default_str()
      ->group("Input");
  cmd.add_option("--exemplar", o.exemplar_color,
                 "Colour exemplar (PNG/JPEG/TIFF/EXR), or the name of a shipped exemplar (pebbles, lava, squares, "
                 "scales, foam)")
      ->group("Exemplar");
  cmd.add_option("--feature", o.exemplar_feature,
                 "Feature map in [0,1], same aspect (default: NAME.feature.* beside the exemplar)")
      ->group("Exemplar");
  cmd.add_option("--displacement", o.exemplar_displacement,
                 "Displacement map (default: NAME.disp.* beside the exemplar, else the feature map)")
      ->group("Exemplar");
  cmd.add_option("--out", o.out_dir, "Output folder (created)")->group("Output");
  cmd.add_option("--name", o.name, "Output file prefix (default: the mesh pattern's name)")->group("Output");
  o.name.clear();
  cmd.add_flag("--resume", o.resume,
               "Continue after the last complete frame in --out that has a state (NAME.state.N.bin), with the same "
               "options; bake from the first frame when there is none")
      ->group("Output");
  cmd.add_option("--keep-states", c.keep_states,
                 "Patch states kept in --out: the last N frames' (all, last = 1, none = 0: no --resume)")
      ->capture_default_str()
      ->group("Output");
  cmd.add_flag("--write-behind", o.background_write,
               "Write each frame's files on another thread while the next frame computes (the same files; one "
               "more frame of images in memory, and a frame's stats line comes after the next frame's "
               "computation)")
      ->group("Output");
  cmd.add_flag("--aov", o.aov, "Also write NAME.aov.N.exr: patch_id, u, v, w per texel")->group("Output");
  cmd.add_flag("--dump-patches", o.dump_patches, "Also write the patches of every frame as NAME.patches.N.ply")
      ->group("Output");
  cmd.add_option("--exr-type", c.exr_type, "EXR pixel type of colour and displacement")
      ->check(CLI::IsMember({"half", "float"}))
      ->capture_default_str()
      ->group("Output");
  cmd.add_option("--compression", c.compression,
                 "EXR compression: rle (lossless, fastest), piz (lossless, 8-27% smaller, 5x the CPU), zip "
                 "(lossless, smallest, slowest), dwaa (lossy), none")
      ->check(CLI::IsMember({"piz", "zip", "rle", "dwaa", "none"}))
      ->capture_default_str()
      ->group("Output");
  cmd.add_option("--radius", o.patch.radius,
                 "Patch radius r in scene units: the exemplar spans 2r on the surface (0 = about 1500 patches); "
                 "a radius that needs more patches than --max-memory holds (or 2e7) is refused")
      ->capture_default_str()
      ->group("Patches");
  cmd.add_option("--spacing", o.seeding.spacing,
                 "Poisson-disk distance between seeds, in units of r (patches grow as 1/spacing^2: a spacing whose "
                 "patches would not fit --max-memory is refused)")
      ->capture_default_str()
      ->group("Patches");
  cmd.add_flag("--no-remesh", c.no_remesh, "Do not remesh new patches isotropically before flattening")
      ->group("Patches");
  add_remesher_option(cmd, o.patch.remesher)
      ->group("Patches");
  cmd.add_option("--remesh-edge", o.patch.remesh_edge,
                 "Remeshing target edge length, in units of r (a patch's memory grows as 1/edge^2: an edge whose "
                 "patches would not fit --max-memory is refused)")
      ->capture_default_str()
      ->group("Patches");
  cmd.add_option("--orientation", c.orientation,
                 "random (from seed and patch id) or world:x,y,z (u along that direction on the tangent plane)")
      ->capture_default_str()
      ->group("Patches");
  CLI::Option* through_flow =
      cmd.add_flag("--through-flow,!--no-through-flow", o.advect.through_flow,
                   "Where the liquid crosses its own surface (an outflow or inflow face: a vertex's step leaves the "
                   "surface along its normal while the surface stays), the texture keeps to the surface with the "
                   "tangential part of the step instead of being cut away there and born again every frame (on by "
                   "default; --no-through-flow: removed, as in the paper; docs/temporal.md)")
          ->group("Patches");
  CLI::Option* run_off =
      cmd.add_flag("--run-off,!--no-run-off", o.advect.run_off,
                   "Where the liquid runs off the edge of its surface (leaving the domain at an open end), the "
                   "texture goes over the edge with it instead of being cut away or piled up before the edge (on by "
                   "default; --no-run-off: removed or projected onto the edge, as in the paper; docs/temporal.md)")
          ->group("Patches");
  CLI::Option* anticipate =
      cmd.add_option("--anticipate", o.patch.anticipate,
                     "New patches are born deformed against the flow they will meet (predicted as if the flow were "
                     "steady, less where it is not) by this fraction of their predicted life, so their distortion "
                     "falls before it grows and they live longer (0 = the paper's conformal patch; "
                     "docs/temporal.md)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 1.0))
          ->group("Erosion");
  cmd.add_option("--delta-max", o.weights.delta_max, "Distortion at which a patch is fully eroded (Sorkine delta)")
      ->capture_default_str()
      ->group("Erosion");
  cmd.add_option("--epsilon", o.raster.epsilon, "Erosion offset epsilon of the paper")
      ->capture_default_str()
      ->group("Erosion");
  CLI::Option* small_hole =
      cmd.add_option("--small-hole", o.raster.small_hole,
                     "Holes no wider than this times the radius are closed by the patches around them instead of "
                     "a new patch (0 = a new patch for every hole, as in the paper)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 1.0))
          ->group("Erosion");
  CLI::Option* rest_hole =
      cmd.add_option("--rest-hole", o.raster.rest_hole,
                     "Holes no wider than this times the radius whose rim is held only by patches at rest (below "
                     "--min-speed) are closed by those patches: the strip a slowly spreading still liquid uncovers "
                     "continues their texture instead of a new patch popping in (0 = --small-hole there too)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 4.0))
          ->group("Erosion");
  CLI::Option* hold =
      cmd.add_flag("--hold,!--no-hold", o.raster.hold,
                   "Hysteresis of the erosion test where a patch won texels before, so a texel does not change "
                   "hands when only the atlas's sampling moved, and a patch at rest keeps its weights and the "
                   "small holes it closed (on by default; --no-hold: the paper's memoryless test; "
                   "docs/temporal.md)")
          ->group("Erosion");
  CLI::Option* rest_bound =
      cmd.add_flag("--rest-bound,!--no-rest-bound", o.raster.rest_bound,
                   "With --hold: a patch at rest (below --min-speed) takes no surface farther than two tracking "
                   "texels from what it held, so the strip a spreading still liquid uncovers continues the patch "
                   "beside it instead of whichever patch's far edge reaches over the rim; the output atlas shows "
                   "every patch only where the tracking did (on by default; --no-rest-bound: a patch wins wherever "
                   "its erosion test passes; docs/temporal.md)")
          ->group("Erosion");
  cmd.add_option("--hold-margin", o.raster.hold_margin,
                 "Where a patch won texels before, its erosion test passes with w lower by this much")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0))
      ->group("Erosion");
  CLI::Option* merge =
      cmd.add_option("--merge", o.raster.merge,
                     "Retire a patch that won fewer texels than this fraction of pi r^2 when other patches keep "
                     "every one of them (0 = only patches that won nothing retire, as in the paper)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 1.0))
          ->group("Erosion");
  cmd.add_flag("--paper", c.paper,
               "The paper's patches, hole filling and retirement as published, for comparisons: conformal new "
               "patches, every hole a new patch, no hysteresis, only patches that won nothing retire (= "
               "--anticipate 0 --no-through-flow --no-run-off --small-hole 0 --rest-hole 0 --no-hold --no-rest-bound --merge 0). The "
               "population then grows on steady flow "
               "and a still liquid keeps churning (docs/temporal.md)")
      ->excludes(small_hole)
      ->excludes(rest_hole)
      ->excludes(hold)
      ->excludes(rest_bound)
      ->excludes(merge)
      ->excludes(anticipate)
      ->excludes(through_flow)
      ->excludes(run_off)
      ->group("Erosion");
  cmd.add_option("--mode", c.mode,
                 "erosion (the paper), blend (the 2019 baseline: every covering patch alpha-blended by its weight; "
                 "ghosts) or advect (no erosion, no retirement: a purely advected texture that stretches)")
      ->check(CLI::IsMember({"erosion", "blend", "advect"}))
      ->capture_default_str()
      ->group("Erosion");
  cmd.add_option("--resolution", o.atlas.resolution,
                 "Atlas width = height in texels, 16-32768 (0 = from the exemplar's density, 512-4096); a "
                 "resolution whose buffers do not fit --max-memory is refused before the bake starts")
      ->capture_default_str()
      ->group("Atlas");
  cmd.add_option("--gutter", o.atlas.gutter,
                 "Empty texels between two charts, shared by the two; colour is dilated into them")
      ->capture_default_str()
      ->group("Atlas");
  cmd.add_option("--track-texel", o.track_texel,
                 "Births, retirements and held cells are decided on an atlas of their own with texels of this "
                 "times the radius on the surface, whatever --resolution: a preview and a final of another "
                 "resolution show the same patches (docs/farm.md)")
      ->capture_default_str()
      ->check(CLI::Range(1.0 / 1024, 1.0))
      ->group("Atlas");
  add_max_memory_option(cmd, o.max_memory,
                        "Before reading more than the first frame, the bake estimates its memory from the surface "
                        "area, --radius, --resolution and the exemplar's size (docs/robustness.md) and refuses (exit "
                        "2) what would not fit")
      ->group("Limits");
}

}  // namespace lapflow::cli
