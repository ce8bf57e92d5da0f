#pragma once
/// \file patches.hpp Deformable texture patches (ALGORITHM.md steps 1-5): the
/// Lagrangian half of the paper. Each stage is a free function over plain data.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lapflow/surface/mesh.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// One texture patch: an open triangle mesh with its own topology, carrying
/// rest uv coordinates into the exemplar ([0,1]^2, centre at (0.5, 0.5), uv
/// distance 0.5 is about r on the surface).
struct Patch {
  uint32_t id = 0;          ///< stable, unique within a bake
  int birth_frame = 0;      ///< its layer: older is on top, ties broken by id
  Vec3 center;              ///< current 3D position of the creation point (metres)
  Vec3 center_normal;       ///< surface normal at creation (unit)
  Vec2 center_uv{0.5, 0.5};
  std::vector<Vec3> positions;         ///< current 3D position per vertex (metres)
  std::vector<Vec2> rest_uv;           ///< fixed at creation
  std::vector<Tri> triangles;
  std::vector<int32_t> surface_triangle;  ///< fluid triangle each vertex lies on this frame (-1 unknown)
  std::vector<float> quality;          ///< Q_V in [0,1]
  std::vector<uint8_t> border;         ///< B_V in {0,1}
  std::vector<float> weight;           ///< w_V = Q_V * B_V
  std::vector<float> triangle_quality; ///< Q_T per triangle
  std::vector<float> triangle_delta;   ///< Sorkine distortion delta per triangle (inf if folded/degenerate)
  /// Where in its uv square the patch won atlas texels on the last frame: a
  /// kHeldCells x kHeldCells bit grid over [0,1]^2 (row v, column u; empty
  /// when it won none or was just born). The erosion test gives these cells
  /// a slack (RasterOptions::hold): hysteresis in patch space, so a texel
  /// does not change hands when only the atlas's sampling moved.
  std::vector<uint64_t> held;
  /// The velocity moved none of its vertices on the last advection (every
  /// sample zero, as below --min-speed): the liquid under it is at rest, so
  /// the rasterizer holds what it closed there too (RasterOptions::hold;
  /// docs/temporal.md). False for a patch born this frame.
  bool at_rest = false;
  /// Its exemplar layer (BakeOptions::layers), chosen where it was born and
  /// kept for life: the texture follows the flow and erosion reads this
  /// layer's feature map. 0 in a bake of one exemplar.
  uint16_t layer = 0;
  /// Frames in a row its centre has lain where the layer rules choose
  /// another layer; the bake retires it when this reaches
  /// BakeOptions::layer_switch (docs/layers.md).
  uint16_t layer_off = 0;

  bool alive() const { return !triangles.empty(); }
  std::size_t vertex_count() const { return positions.size(); }
};

/// Resolution of Patch::held: cells of 1/128 of the uv square, r/64 on the
/// surface, whatever the atlas resolution.
inline constexpr int kHeldCells = 128;
inline constexpr std::size_t kHeldWords = std::size_t(kHeldCells) * kHeldCells / 64;

/// How far, in cells of Patch::held (r/64), a bound patch may win texels
/// beyond the cells it held (RasterOptions::rest_bound), when the cells were
/// marked by texels spanning `texel_uv` of the uv square: two such texels.
/// Marks cover a won region but for a band about a cell wide along its
/// borders (a new sampling of the surface), and a chart's outer texels do
/// not mark at all (passes exempts the texels next to a chart's border).
inline int rest_reach_cells(double texel_uv) {
  return std::max(2, int(std::ceil(2 * std::min(texel_uv, 1.0) * kHeldCells - 1e-9)));
}

/// True when (u, v) lies in a cell of `held` (kHeldWords words, or empty).
inline bool held_at(const uint64_t* cells, double u, double v) {
  if (!(u >= 0 && u <= 1 && v >= 0 && v <= 1)) return false;
  const int cu = std::min(int(u * kHeldCells), kHeldCells - 1), cv = std::min(int(v * kHeldCells), kHeldCells - 1);
  const std::size_t bit = std::size_t(cv) * kHeldCells + std::size_t(cu);
  return (cells[bit >> 6] >> (bit & 63)) & 1u;
}
inline bool held_at(const std::vector<uint64_t>& held, double u, double v) {
  return !held.empty() && held_at(held.data(), u, v);
}

/// Patches in stack order: oldest first (birth_frame, then id). The rasterizer
/// walks them in this order; hole filling appends at the bottom.
struct PatchSet {
  std::vector<Patch> patches;
  uint32_t next_id = 0;
};

/// A point on the fluid surface.
struct SurfacePoint {
  Vec3 position;
  Vec3 normal;  ///< unit
  int triangle = -1;
};

/// How a new patch's triangles are made even before flattening
/// (docs/patches.md). Isotropic and CgalIsotropic are the same remeshing
/// algorithm; Lattice resamples instead where it can. CLI: `--remesher
/// lattice|isotropic|cgal` (`grid` and `fast` are the old names).
enum class Remesher {
  Isotropic,      ///< isotropic remeshing on plain arrays, specialised for small disks (patches/remesh.cpp)
  CgalIsotropic,  ///< CGAL::Polygon_mesh_processing::isotropic_remeshing (patches/cgal.cpp)
  Lattice,        ///< an equilateral lattice (edge 0.8 remesh_edge r, the remesher's mean edge) in
                  ///< p's tangent plane lifted onto the fluid (patches/lattice.cpp); Isotropic
                  ///< where the cut is not a height field over that plane
};

struct PatchOptions {
  double radius = 0.1;            ///< r in metres: the exemplar spans 2r on the surface
  /// Isotropic remeshing of each new patch before flattening (`remesher`), then
  /// trimmed to distance r of p. On by default: an unremeshed cut has few
  /// vertices, most of them on its border where B_V = 0, so its weights start
  /// low; remeshed patches keep more texture for the same flow (docs/patches.md).
  bool remesh = true;
  double remesh_edge = 1.0 / 6;   ///< target edge length as a fraction of r
  Remesher remesher = Remesher::Lattice;  ///< the same weights and lifetimes as Isotropic, for less work (docs/patches.md)
  /// Orientation: random angle from hash(seed, patch id) unless `align` is
  /// set, in which case u follows `align_direction` projected on the tangent plane.
  bool align = false;
  Vec3 align_direction{1, 0, 0};
  uint64_t seed = 0;
  /// Anticipated shear (docs/temporal.md, "Anticipated shear"): a new patch
  /// is laid on the surface already deformed by the inverse of what the
  /// local flow will do to it over `anticipate` of its predicted life, so
  /// its distortion falls towards 1 before it grows and it lives longer
  /// before erosion retires it; scaled down where the flow is unsteady.
  /// 0 = the paper's conformal patch. Needs `velocity`: the frame's field
  /// (not owned); without it every patch is conformal.
  double anticipate = 0.5;
  const VelocityField* velocity = nullptr;
  /// The previous frame's field (not owned; null on a first frame): the
  /// prediction assumes a steady flow, so it is scaled down where the flow
  /// changed since that frame.
  const VelocityField* previous_velocity = nullptr;
  double dt = 1.0 / 24;            ///< seconds per frame, for the prediction
  int anticipate_horizon = 48;     ///< frames looked ahead at most
};

struct SeedOptions {
  double spacing = 1.0;  ///< Poisson-disk minimum distance as a multiple of r
};

struct AdvectOptions {
  double dt = 1.0 / 24;            ///< seconds between frames
  /// Sub-steps so that |v| * h <= fraction * r: a step never jumps farther
  /// than a few patch radii between two velocity samples. Accuracy is kept
  /// by the turn rule below; this one only bounds how far from both surfaces
  /// a velocity is sampled, so it can be loose: 4 rather than 1 saves
  /// sub-steps with every patch test unchanged (docs/patches.md).
  double max_step_fraction = 4.0;
  /// Sub-steps so that the velocity turns by at most this angle (radians)
  /// per step: RK2's error grows with the cube of the turn (vortices), not
  /// with the speed (a fast translation is integrated exactly in one step).
  double max_turn = 0.05;
  double max_projection = 0.25;    ///< remove vertices moved farther than this * r by projection
  /// Where the liquid crosses its own surface (a step leaves the surface by
  /// more than max_projection along its normal while the surface is still
  /// within max_projection of where the vertex was: an outflow or inflow
  /// face), the vertex keeps to the surface with the tangential part of its
  /// step instead of being removed. Off: removed, as in the paper.
  /// docs/temporal.md, "Through-flow faces".
  bool through_flow = true;
  /// Where the liquid runs off the edge of its surface (liquid leaving the
  /// domain at an open end: a step along the surface that ends farther than
  /// max_projection from it, while the surface is still where the vertex
  /// was), the vertex keeps its advected position off the surface
  /// (surface_triangle -1) and goes on with the flow while it stays within
  /// r / 2 of the surface, so its triangles still cover the surface before
  /// the edge instead of being cut away there. Off: removed, as in the paper.
  /// docs/temporal.md, "Run-off edges".
  bool run_off = true;
};

struct WeightOptions {
  double delta_max = 3.0;        ///< distortion at which Q_T reaches 0
  double center_radius = 0.125;  ///< rest-uv distance from (0.5,0.5) where B_V = 1 on the boundary
  /// A patch at rest (Patch::at_rest) keeps the weights it had: where the
  /// velocity is zero the texture must not change, and a surface that is
  /// re-meshed or creeps below --min-speed would otherwise erode it
  /// (docs/temporal.md). Set with RasterOptions::hold.
  bool keep_at_rest = false;
};

/// Poisson-disk samples on the surface: minimum EUCLIDEAN distance
/// `min_distance` (metres) between samples of the same connected component
/// (patches never cross components); every component with non-zero area gets
/// at least one; deterministic for a seed at any thread count.
std::vector<SurfacePoint> seed_points(const TriMesh& mesh, double min_distance, uint64_t seed);

/// Vertex -> triangle adjacency of one frame's mesh (CSR), which patch
/// creation walks. Build it once per frame when creating many patches.
struct SurfaceAdjacency {
  std::vector<int32_t> offsets;    ///< vertex_count + 1 entries
  std::vector<int32_t> triangles;  ///< triangles around each vertex, ascending
};
SurfaceAdjacency build_surface_adjacency(const TriMesh& mesh);

/// Creates a patch at `at` (ALGORITHM.md steps 2-3 and initial weights), or
/// nothing when the surface there cannot hold one (degenerate triangle, or a
/// patch LSCM cannot flatten). The new patch gets id `id` and birth frame
/// `frame`. `at.triangle` < 0 is looked up by closest point; a zero
/// `at.normal` takes the normal of that triangle. `adjacency` must be built
/// from `surface.mesh()`. Thread-safe.
std::optional<Patch> create_patch(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                                  const SurfacePoint& at, uint32_t id, int frame, const PatchOptions& options,
                                  const WeightOptions& weights);
/// The same, building the adjacency on the fly (O(mesh size) per call).
std::optional<Patch> create_patch(const SurfaceQuery& surface, const SurfacePoint& at, uint32_t id, int frame,
                                  const PatchOptions& options, const WeightOptions& weights);

/// How many patches seed_patches would create on `mesh` at frame `frame`
/// (its Poisson samples): the yardstick of a bounded population.
std::size_t fresh_seeding_count(const TriMesh& mesh, int frame, const PatchOptions& options,
                                const SeedOptions& seeding);

/// First frame: seeds the whole surface and creates one patch per sample.
void seed_patches(const SurfaceQuery& surface, int frame, const PatchOptions& options, const SeedOptions& seeding,
                  const WeightOptions& weights, PatchSet& patches);

struct AdvectStats {
  std::size_t vertices_moved = 0, vertices_removed = 0, triangles_removed = 0, patches_removed = 0;
  double max_residual = 0;  ///< largest distance of a kept vertex to the surface after projection (metres)
};

/// ALGORITHM.md step 4: moves every patch vertex and centre with the velocity
/// from frame f-1 (field `v_prev`, surface at time t) to frame f (`v_next`,
/// t + dt) by Heun's RK2 (velocity linear in time in between), sub-stepped,
/// then projects onto `next`; removes what moved too far, isolated vertices
/// and patches left with no triangle (order of the others kept). Updates
/// surface_triangle; the weights are update_weights' job (step 5). Same
/// result for any thread count.
AdvectStats advect_patches(const SurfaceQuery& next, const VelocityField& v_prev, const VelocityField& v_next,
                           const PatchOptions& patch_options, const AdvectOptions& options, PatchSet& patches);

/// ALGORITHM.md step 5: Q_T, Q_V, B_V, w_V of one patch against the surface
/// normals of `surface` (for the fold test).
void patch_weights(const TriMesh& surface, double radius, const WeightOptions& options, Patch& patch);
/// Step 5 for every patch (after advection), in parallel.
void update_weights(const TriMesh& surface, double radius, const WeightOptions& options, PatchSet& patches);

/// Writes all patches as one binary PLY with per-vertex `patch_id`, `u`, `v`,
/// `w` and per-face `patch_id` (atomically, or into the group `staged`).
void write_patches_ply(const std::string& path, const PatchSet& patches, StagedFiles* staged = nullptr);

}  // namespace lapflow
