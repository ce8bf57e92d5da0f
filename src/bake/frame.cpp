// Reading a frame and its velocity, the same way for every command.
#include "lapflow/bake/frame.hpp"

#include <algorithm>

#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow {

void check_frame_units(const std::string& path, int frame, const MeshFile& file, bool vertex_velocity,
                       const VelocityGrid* grid) {
  std::vector<std::string> problems = units_problems(file.mesh, file.declared, vertex_velocity);
  if (grid && !file.mesh.empty()) {
    // The speeds the bake will advect with, where the surface is.
    const TriMesh& m = file.mesh;
    std::vector<uint8_t> used(m.vertex_count(), 0);
    for (const Tri& t : m.triangles)
      for (int32_t v : t) used[std::size_t(v)] = 1;
    std::vector<double> speed(m.vertex_count(), 0);
    parallel_for(speed.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t v = b; v < e; ++v)
        if (used[v]) speed[v] = norm(grid->sample(m.positions[v]));
    }, 4096);
    const auto fastest = std::max_element(speed.begin(), speed.end());
    if (fastest != speed.end() && !(*fastest <= kMaxLiquidSpeed))
      problems.push_back(speed_problem(*fastest, std::size_t(fastest - speed.begin()),
                                       "the VDB grid '" + grid->grid_name() + "'"));
  }
  if (problems.empty()) return;
  std::string what;
  for (const std::string& p : problems) what += (what.empty() ? "" : "; ") + p;
  throw InputError(path, what + " (--units-ok to bake anyway)", frame);
}

FrameInput read_frame_input(const FrameSource& source, int frame) {
  FrameInput in;
  in.number = frame;
  in.path = FramePattern(source.mesh_pattern).path(frame);
  MeshFile file;
  try {
    file = read_mesh_file(in.path, true, source.attributes);
  } catch (const InputError& e) {
    throw e.with_frame(frame);
  }
  if (!source.velocity_vdb_pattern.empty()) {
    const std::string vdb = FramePattern(source.velocity_vdb_pattern).path(frame);
    try {
      in.grid = std::make_unique<VelocityGrid>(vdb, source.velocity_grid);
    } catch (const InputError& e) {
      throw e.with_frame(frame);
    }
  } else if (!file.mesh.has_velocities() && !file.mesh.empty() && !source.allow_zero_velocity) {
    throw InputError(in.path,
                     "no per-vertex velocity (vx vy vz) and no --velocity-vdb; pass --allow-zero-velocity to bake a "
                     "still texture",
                     frame);
  }
  if (!source.units_ok) check_frame_units(in.path, frame, file, !in.grid, in.grid.get());
  in.mesh = std::move(file.mesh);
  in.attributes = std::move(file.attributes);
  return in;
}

namespace {

std::unique_ptr<Frame> frame_from_input(FrameInput in) {
  auto f = std::make_unique<Frame>();
  f->number = in.number;
  f->path = std::move(in.path);
  f->mesh = std::move(in.mesh);
  f->surface = std::make_unique<SurfaceQuery>(f->mesh);
  f->velocity_grid = std::move(in.grid);
  f->attributes = std::move(in.attributes);
  return f;
}

}  // namespace

std::unique_ptr<Frame> load_frame_surface(const FrameSource& source, int frame, bool velocity_grid) {
  FrameSource meshes_only = source;
  if (!velocity_grid) meshes_only.velocity_vdb_pattern.clear();
  meshes_only.allow_zero_velocity = true;
  return frame_from_input(read_frame_input(meshes_only, frame));
}

std::unique_ptr<Frame> load_frame(const FrameSource& source, int frame) {
  std::unique_ptr<Frame> f = frame_from_input(read_frame_input(source, frame));
  if (f->velocity_grid) {
    f->velocity = grid_velocity_field(*f->velocity_grid);
    f->velocity_source = "vdb:" + f->velocity_grid->grid_name();
  } else if (f->mesh.has_velocities()) {
    f->velocity = vertex_velocity_field(*f->surface);
    f->velocity_source = "vertex";
    if (source.velocity_band > 0) {
      f->velocity = banded_velocity_field(std::move(f->velocity), f->mesh,
                                          source.velocity_voxel * mean_edge_length(f->mesh), source.velocity_band);
      f->velocity_source = "vertex (band of " + std::to_string(source.velocity_band) + " voxels)";
    }
  } else {
    f->velocity = [](const Vec3&) { return Vec3{}; };
    f->velocity_source = "zero";
  }
  if (source.min_speed > 0) f->velocity = with_min_speed(std::move(f->velocity), source.min_speed);
  return f;
}

std::vector<Vec3> surface_velocities(const Frame& frame) {
  const TriMesh& m = frame.mesh;
  if (!frame.velocity_grid) return m.velocities;  // empty when the mesh has none
  std::vector<Vec3> v(m.vertex_count());
  parallel_for(v.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) v[i] = frame.velocity_grid->sample(m.positions[i]);
  }, 4096);
  return v;
}

}  // namespace lapflow
