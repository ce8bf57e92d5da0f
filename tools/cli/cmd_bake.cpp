// `lapflow bake` and `lapflow track`: the product. The flags come from the
// option table (lapflow/bake/options.hpp); a TOML scene file's keys are the
// same names. Resolves the exemplar and the name, and runs the frame loop.
#include <algorithm>
#include <filesystem>

#include "cli_common.hpp"
#include "option_flags.hpp"
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
  std::string exemplar = o.exemplar_color;
  if (!o.layers.empty()) {
    exemplar = fmt::format("{} layers (", o.layers.size());
    for (std::size_t l = 0; l < o.layers.size(); ++l) exemplar += (l ? ", " : "") + o.layers[l].name;
    exemplar += ")";
  }
  info("  exemplar {} | radius {:.4g} m | atlas {}x{} | tracking texel {:.4g} r | seed {} | {} threads",
       exemplar, o.patch.radius, o.atlas.resolution, o.atlas.resolution, o.track_texel, o.seed,
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

void run_bake(BakeOptions& o) {
  apply_global_options();
  o.seed = globals().seed;
  if (o.layers.empty()) {
    resolve_exemplar_paths(o.exemplar_color, o.exemplar_feature, o.exemplar_displacement);
  } else {
    if (!o.exemplar_color.empty())
      throw UsageError("--exemplar and --layer: with layers, give every exemplar as a --layer");
    for (ExemplarLayer& layer : o.layers) resolve_exemplar_paths(layer.color, layer.feature, layer.displacement);
  }
  if (o.name.empty()) o.name = default_output_name(o.mesh_pattern);
  if (o.track_only) o.keep_states = -1;  // render needs every frame's
  bake_with_progress(o);
}

}  // namespace


void add_bake_command(CLI::App& app) {
  static BakeOptions o;
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
  add_bake_table_flags(*cmd, o);
  add_global_options(*cmd);
  cmd->callback([] { run_bake(o); });
}

void add_track_command(CLI::App& app) {
  static BakeOptions o;
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
  add_bake_table_flags(*cmd, o);
  cmd->add_option("--until", until, "Stop after this frame (the manifest still names every frame of --frames)")
      ->group("Output");
  add_global_options(*cmd);
  cmd->callback([] {
    o.track_only = true;
    if (until != 0) o.until_frame = until;
    run_bake(o);
  });
}

void add_options_command(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand("options", "Every option of bake and track: default, unit, range, what it changes");
  cmd->description(
      "Prints the option table of `lapflow bake` and `lapflow track` as Markdown, one table per stage: each\n"
      "option's default, unit, range, whether it changes the animation (the patches) or only the picture\n"
      "(`lapflow render` may set those anew), its key in NAME.bake.json, and what it does. A scene file's keys\n"
      "are the same names (min_speed = 0.05). docs/options.md is this output.");
  cmd->callback([] { fmt::print("{}", bake_options_markdown()); });
}

}  // namespace lapflow::cli
