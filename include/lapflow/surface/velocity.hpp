#pragma once
/// \file velocity.hpp Velocity fields that can be sampled anywhere near the surface.
#include <functional>
#include <memory>
#include <string>

#include "lapflow/surface/mesh.hpp"
#include "lapflow/surface/surface_query.hpp"

namespace lapflow {

/// Velocity in m/s at a point in metres. Must be thread-safe.
using VelocityField = std::function<Vec3(const Vec3&)>;

/// Per-vertex velocities of `query.mesh()` interpolated barycentrically at
/// the closest surface point. The query (and its mesh) must outlive the field.
/// A mesh with velocities gives a field holding a VertexVelocity
/// (`field.target<VertexVelocity>()`).
VelocityField vertex_velocity_field(const SurfaceQuery& query);

/// The sampler behind vertex_velocity_field. Advection asks it directly for
/// points it knows lie on a given triangle of the mesh (a patch vertex on the
/// triangle it was projected onto last frame), which needs no search.
class VertexVelocity {
 public:
  explicit VertexVelocity(const SurfaceQuery& query);
  Vec3 operator()(const Vec3& p) const;
  const SurfaceQuery& query() const { return *query_; }
  /// The velocity at p when p is within `tolerance` metres of triangle t
  /// (interpolated at p's closest point on t), otherwise false. Any point of
  /// the surface at distance <= tolerance is as good a closest point as the
  /// search's: the two answers differ by at most tolerance times the
  /// velocity's gradient.
  bool on_triangle(const Vec3& p, int t, double tolerance, Vec3& velocity) const;
  /// The velocity at p's closest surface point when one lies within `radius`
  /// metres (its distance in `distance`), otherwise false. The closest point
  /// within a radius that holds one is the closest point: same answer as
  /// operator(), fewer nodes visited when a good radius is known.
  bool within(const Vec3& p, double radius, Vec3& velocity, double& distance) const;

 private:
  /// Per-vertex velocities interpolated at barycentrics (b1, b2) of triangle t.
  Vec3 interpolate(int t, double b1, double b2) const;
  const SurfaceQuery* query_;
  double near_;
};

/// Zero below `min_speed` (m/s): real solvers leave a few cm/s of noise on
/// liquid at rest, which would make a texture creep.
VelocityField with_min_speed(VelocityField field, double min_speed);

/// `exact` sampled once on the voxels (size `voxel_size`, metres) within
/// `band_voxels` of the mesh's vertices and read back trilinearly; points
/// whose 8 voxels are not all in the band use `exact`. Velocities are stored
/// in float. Advection samples velocities millions of times a frame: this
/// trades one exact sample per band voxel for cheap lookups.
VelocityField banded_velocity_field(VelocityField exact, const TriMesh& mesh, double voxel_size, int band_voxels);

/// Mean edge length of the mesh's triangles (metres; 0 for an empty mesh).
double mean_edge_length(const TriMesh& mesh);

/// A vector grid read from an OpenVDB file, sampled trilinearly in world space.
class VelocityGrid {
 public:
  /// Reads grid `grid_name` from `path`; an empty name tries `vel`, `v`,
  /// `velocity` in that order. Throws InputError when the file cannot be read
  /// or has no such vector grid (naming the grids it does have).
  VelocityGrid(const std::string& path, const std::string& grid_name = "");
  ~VelocityGrid();
  VelocityGrid(VelocityGrid&&) noexcept;
  VelocityGrid& operator=(VelocityGrid&&) noexcept;
  Vec3 sample(const Vec3& p) const;
  const std::string& grid_name() const;
  Box3 active_bounds() const;  ///< world-space bounds of the active voxels

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Field backed by a grid; the grid must outlive the field.
VelocityField grid_velocity_field(const VelocityGrid& grid);

}  // namespace lapflow
