// `lapflow patches`: seeds patches on the first frame, advects them through
// the sequence and writes one PLY of patches per frame (patch_id, rest uv,
// weight), to look at how patches ride the flow in Houdini or Blender. The
// frame loop is the library's (dump_patches, bake/patch_dump.hpp).
#include <algorithm>
#include <filesystem>
#include <memory>
#include <optional>

#include "cli_common.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/patch_dump.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow::cli {
namespace {

struct PatchesCommand {
  FrameSource source;  ///< meshes and velocity: the bake's rules and defaults
  std::string frames, out_dir, name, orientation = "random";
  double radius = 0, fps = 24, spacing = 1, delta_max = 3;
  std::size_t max_memory = 0;  ///< bytes; 0 = default_memory_budget()
  bool remesh = true;
  Remesher remesher = PatchOptions{}.remesher;
};

void run_patches(const PatchesCommand& c) {
  apply_global_options();
  PatchDumpOptions o;
  o.source = c.source;
  std::optional<FrameRange> range;
  if (!c.frames.empty()) range = parse_frame_range(c.frames);
  o.frames = resolve_frames(FramePattern(c.source.mesh_pattern), range);
  o.out_dir = c.out_dir;
  o.name = c.name.empty() ? default_output_name(c.source.mesh_pattern) : c.name;
  o.patch.radius = c.radius;
  o.patch.remesh = c.remesh;
  o.patch.remesher = c.remesher;
  o.patch.seed = globals().seed;
  o.patch.align = parse_orientation(c.orientation, o.patch.align_direction);
  o.seeding.spacing = c.spacing;
  o.weights.delta_max = c.delta_max;
  o.fps = c.fps;
  o.max_memory = c.max_memory;

  Progress progress("patches", o.frames.size());
  std::size_t seeded = 0, removed_total = 0, alive = 0;
  dump_patches(o, [&](const PatchDumpFrame& f) {
    alive = f.patches;
    if (f.seeded) {
      seeded = f.patches;
      progress.step(fmt::format("frame {}: seeded {} patches, {} vertices, median delta {:.3f}", f.frame, f.patches,
                                f.vertices, f.median_delta));
      return;
    }
    removed_total += f.advect.vertices_removed;
    progress.step(fmt::format("frame {}: {} patches alive ({} died), {} vertices ({} removed), median delta {:.3f}, "
                              "{:.1f}% triangles over delta-max, mean w {:.3f}",
                              f.frame, f.patches, f.advect.patches_removed, f.vertices, f.advect.vertices_removed,
                              f.median_delta, 100 * f.eroded, f.mean_weight));
  });
  progress.finish();
  info("patches: {} seeded on frame {}, {} alive after frame {}, {} vertices removed in all; wrote {}", seeded,
       o.frames.front(), alive, o.frames.back(), removed_total,
       (std::filesystem::path(c.out_dir) / (o.name + ".patches.####.ply")).string());
}

}  // namespace

void add_patches_command(CLI::App& app) {
  auto c = std::make_shared<PatchesCommand>();
  auto* cmd = app.add_subcommand(
      "patches",
      "Seed texture patches on the first frame and advect them through the sequence (no hole filling, no atlas);\n"
      "writes OUT/NAME.patches.%04d.ply with per-vertex patch_id, u, v, w to inspect in Houdini or Blender.");
  cmd->add_option("--mesh", c->source.mesh_pattern, "Fluid mesh per frame: fluid.%04d.ply, fluid.####.ply, fluid.$F4.ply")
      ->required();
  cmd->add_option("--frames", c->frames, "Frame range A-B (default: every frame found on disk)");
  cmd->add_option("--radius", c->radius,
                  "Patch radius r in world units (the exemplar spans 2r); a radius whose patches would not fit "
                  "--max-memory (or number more than 2e7) is refused")
      ->required();
  cmd->add_option("--out", c->out_dir, "Output folder")->required();
  cmd->add_option("--name", c->name, "Output file prefix (default: from the mesh pattern)");
  cmd->add_option("--velocity-vdb", c->source.velocity_vdb_pattern,
                  "OpenVDB velocity grid per frame (default: PLY vertex velocity)");
  cmd->add_option("--velocity-grid", c->source.velocity_grid, "Grid name in the VDB files (default: vel, v, velocity)");
  cmd->add_flag("--allow-zero-velocity", c->source.allow_zero_velocity,
                "Accept meshes without velocity (patches then only follow the surface by projection)");
  cmd->add_flag("--units-ok", c->source.units_ok, units_ok_help("seed and advect"));
  cmd->add_option("--velocity-band", c->source.velocity_band,
                  "Per-vertex velocity sampled on a band of this many voxels around the surface, as in the bake (0 = "
                  "exact closest-point sampling)")
      ->capture_default_str();
  cmd->add_option("--velocity-voxel", c->source.velocity_voxel,
                  "Voxel size of that band, in mean edge lengths of the frame's mesh")
      ->capture_default_str();
  cmd->add_option("--fps", c->fps, "Frames per second (dt = 1/fps)")->capture_default_str();
  cmd->add_option("--min-speed", c->source.min_speed, "Velocities slower than this (m/s) count as 0")->capture_default_str();
  cmd->add_option("--spacing", c->spacing, "Poisson-disk distance of the seeds, in units of r")->capture_default_str();
  cmd->add_option("--delta-max", c->delta_max, "Distortion at which a triangle's quality reaches 0")
      ->capture_default_str();
  cmd->add_flag("--remesh,!--no-remesh", c->remesh, "Isotropic remeshing of each new patch (target edge r/6)")
      ->capture_default_str();
  add_remesher_option(*cmd, c->remesher);
  cmd->add_option("--orientation", c->orientation, "Patch rotation: random, or world:x,y,z to align u with a direction")
      ->capture_default_str();
  add_max_memory_option(*cmd, c->max_memory, "Patches that would not fit are refused (exit 2) before the first seeding.");
  add_global_options(*cmd);
  cmd->callback([c] { run_patches(*c); });
}

}  // namespace lapflow::cli
