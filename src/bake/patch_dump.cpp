// `lapflow patches`'s frame loop (bake/patch_dump.hpp).
#include "lapflow/bake/patch_dump.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <memory>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/surface/surface_query.hpp"

namespace lapflow {
namespace {

void count(const PatchSet& set, double delta_max, PatchDumpFrame& c) {
  c.patches = set.patches.size();
  c.vertices = c.triangles = 0;
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
  c.median_delta = 0;
  if (!deltas.empty()) {
    std::nth_element(deltas.begin(), deltas.begin() + deltas.size() / 2, deltas.end());
    c.median_delta = deltas[deltas.size() / 2];
  }
  c.eroded = c.triangles ? double(over) / double(c.triangles) : 0;
  c.mean_weight = c.vertices ? wsum / double(c.vertices) : 0;
}

}  // namespace

void dump_patches(const PatchDumpOptions& o, const std::function<void(const PatchDumpFrame&)>& on_frame) {
  if (!(o.patch.radius > 0)) throw UsageError("--radius must be positive (world units)");
  if (!(o.fps > 0)) throw UsageError("--fps must be positive");
  if (!(o.seeding.spacing > 0)) throw UsageError("--spacing must be positive");
  if (!(o.weights.delta_max > 1)) throw UsageError("--delta-max must be greater than 1");
  if (o.frames.empty()) throw UsageError("no frames to advect");
  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  if (ec) throw OutputError(o.out_dir + ": cannot create the output folder: " + ec.message());
  auto out_path = [&](int frame) {
    return (std::filesystem::path(o.out_dir) / fmt::format("{}.patches.{:04d}.ply", o.name, frame)).string();
  };

  PatchSet set;
  std::unique_ptr<Frame> prev = load_frame(o.source, o.frames.front());
  {
    // The bake's memory model, patches and meshes only (no atlas, no
    // exemplar), before the first seeding: a radius in the wrong unit is
    // refused, never an allocation that fails.
    BakeOptions budget;
    budget.patch = o.patch;
    budget.seeding = o.seeding;
    budget.atlas.resolution = 0;
    budget.max_memory = o.max_memory;
    BakeInputSizes sizes;
    sizes.first_mesh = prev->path;
    sizes.area = surface_area(prev->mesh);
    sizes.triangles = prev->mesh.triangle_count();
    sizes.vertices = prev->mesh.vertex_count();
    check_bake_budget(budget, sizes);
  }
  seed_patches(*prev->surface, prev->number, o.patch, o.seeding, o.weights, set);
  PatchDumpFrame f;
  f.frame = prev->number;
  f.seeded = true;
  f.path = out_path(prev->number);
  write_patches_ply(f.path, set);
  count(set, o.weights.delta_max, f);
  if (on_frame) on_frame(f);
  AdvectOptions ao;
  for (std::size_t i = 1; i < o.frames.size(); ++i) {
    std::unique_ptr<Frame> next = load_frame(o.source, o.frames[i]);
    ao.dt = double(next->number - prev->number) / o.fps;
    f = PatchDumpFrame{};
    f.frame = next->number;
    f.advect = advect_patches(*next->surface, prev->velocity, next->velocity, o.patch, ao, set);
    update_weights(next->mesh, o.patch.radius, o.weights, set);
    f.path = out_path(next->number);
    write_patches_ply(f.path, set);
    count(set, o.weights.delta_max, f);
    if (on_frame) on_frame(f);
    prev = std::move(next);
  }
}

}  // namespace lapflow
