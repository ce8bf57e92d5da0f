// `lapflow patches`: seeds patches on the first frame, advects them through
// the sequence and writes one PLY of patches per frame (patch_id, rest uv,
// weight), to look at how patches ride the flow in Houdini or Blender. No
// hole filling here (the bake does it), so patches only die.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>

#include "cli_common.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/patches/patches.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

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

struct Counts {
  std::size_t patches = 0, vertices = 0, triangles = 0;
  double median_delta = 0, mean_weight = 0;
  double eroded = 0;  ///< fraction of triangles with delta >= delta_max or folded
};

Counts count(const PatchSet& set, double delta_max) {
  Counts c;
  c.patches = set.patches.size();
  double wsum = 0;
  std::vector<float> deltas;
  std::size_t over = 0;
  for (const Patch& p : set.patches) {
    c.vertices += p.positions.size();
    c.triangles += p.triangles.size();
    deltas.insert(deltas.end(), p.triangle_delta.begin(), p.triangle_delta.end());
    for (float d : p.triangle_delta) over += !(d < delta_max);
    for (float w : p.weight) wsum += w;
  }
  if (!deltas.empty()) {
    std::nth_element(deltas.begin(), deltas.begin() + deltas.size() / 2, deltas.end());
    c.median_delta = deltas[deltas.size() / 2];
  }
  c.eroded = c.triangles ? double(over) / double(c.triangles) : 0;
  c.mean_weight = c.vertices ? wsum / double(c.vertices) : 0;
  return c;
}

void run_patches(const PatchesCommand& c) {
  apply_global_options();
  if (!(c.radius > 0)) throw UsageError("--radius must be positive (world units)");
  if (!(c.fps > 0)) throw UsageError("--fps must be positive");
  if (!(c.spacing > 0)) throw UsageError("--spacing must be positive");
  if (!(c.delta_max > 1)) throw UsageError("--delta-max must be greater than 1");
  Vec3 align_direction;
  const bool align = parse_orientation(c.orientation, align_direction);
  const FramePattern meshes(c.source.mesh_pattern);
  std::optional<FrameRange> range;
  if (!c.frames.empty()) range = parse_frame_range(c.frames);
  const std::vector<int> frames = resolve_frames(meshes, range);
  const std::string name = c.name.empty() ? default_output_name(c.source.mesh_pattern) : c.name;
  std::error_code ec;
  std::filesystem::create_directories(c.out_dir, ec);
  if (ec) throw OutputError(c.out_dir + ": cannot create the output folder: " + ec.message());

  PatchOptions po;
  po.radius = c.radius;
  po.remesh = c.remesh;
  po.remesher = c.remesher;
  po.seed = globals().seed;
  po.align = align;
  po.align_direction = align_direction;
  SeedOptions so;
  so.spacing = c.spacing;
  WeightOptions wo;
  wo.delta_max = c.delta_max;
  AdvectOptions ao;

  auto out_path = [&](int frame) { return (std::filesystem::path(c.out_dir) / fmt::format("{}.patches.{:04d}.ply", name, frame)).string(); };
  PatchSet set;
  Progress progress("patches", frames.size());
  std::unique_ptr<Frame> prev = load_frame(c.source, frames.front());
  {
    // The bake's memory model, patches and meshes only (no atlas, no
    // exemplar), before the first seeding: a radius in the wrong unit is
    // refused, never an allocation that fails.
    BakeOptions budget;
    budget.patch = po;
    budget.seeding = so;
    budget.atlas.resolution = 0;
    budget.max_memory = c.max_memory;
    BakeInputSizes sizes;
    sizes.first_mesh = prev->path;
    sizes.area = surface_area(prev->mesh);
    sizes.triangles = prev->mesh.triangle_count();
    sizes.vertices = prev->mesh.vertex_count();
    check_bake_budget(budget, sizes);
  }
  seed_patches(*prev->surface, prev->number, po, so, wo, set);
  write_patches_ply(out_path(prev->number), set);
  const std::size_t seeded = set.patches.size();
  Counts n = count(set, wo.delta_max);
  progress.step(fmt::format("frame {}: seeded {} patches, {} vertices, median delta {:.3f}", prev->number, n.patches,
                            n.vertices, n.median_delta));
  std::size_t removed_total = 0;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    std::unique_ptr<Frame> next = load_frame(c.source, frames[i]);
    ao.dt = double(next->number - prev->number) / c.fps;
    const AdvectStats st = advect_patches(*next->surface, prev->velocity, next->velocity, po, ao, set);
    update_weights(next->mesh, po.radius, wo, set);
    removed_total += st.vertices_removed;
    write_patches_ply(out_path(next->number), set);
    n = count(set, wo.delta_max);
    progress.step(fmt::format("frame {}: {} patches alive ({} died), {} vertices ({} removed), median delta {:.3f}, "
                              "{:.1f}% triangles over delta-max, mean w {:.3f}",
                              next->number, n.patches, st.patches_removed, n.vertices, st.vertices_removed,
                              n.median_delta, 100 * n.eroded, n.mean_weight));
    prev = std::move(next);
  }
  progress.finish();
  info("patches: {} seeded on frame {}, {} alive after frame {}, {} vertices removed in all; wrote {}", seeded,
       frames.front(), set.patches.size(), frames.back(), removed_total,
       (std::filesystem::path(c.out_dir) / (name + ".patches.####.ply")).string());
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
