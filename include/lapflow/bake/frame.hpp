#pragma once
/// \file frame.hpp One frame of a bake: everything known about it (mesh,
/// surface queries, velocity, atlases, textures, statistics),
/// and load_frame(), the one way every command reads a frame and its
/// velocity. The patches are not part of it: they carry over from frame to
/// frame (PatchSet).
#include <cstddef>
#include <memory>
#include <string>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/raster/raster.hpp"
#include "lapflow/surface/mesh.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {

/// Where frames come from and how their velocity is read: the rules `lapflow
/// bake`, `lapflow patches`, `lapflow eval` and the benchmark share.
struct FrameSource {
  std::string mesh_pattern;          ///< per-frame PLY/OBJ pattern (io/mesh_io.hpp's FramePattern)
  std::string velocity_vdb_pattern;  ///< per-frame OpenVDB files; per-vertex velocities when empty
  std::string velocity_grid;         ///< grid name; tries vel, v, velocity when empty
  double min_speed = 0;              ///< m/s: slower velocities count as zero
  bool allow_zero_velocity = false;  ///< a mesh without velocity is still (else an InputError)
  /// Accept a frame with sizes, speeds or property types no liquid has
  /// (units_problems in io/mesh_io.hpp); else it is an InputError naming
  /// the file and frame.
  bool units_ok = false;
  /// Per-vertex velocities are sampled once per frame on voxels of
  /// `velocity_voxel` mean edge lengths within `velocity_band` voxels of the
  /// surface, then read trilinearly (band 0 = an exact closest-point query
  /// for every sample).
  int velocity_band = 6;
  double velocity_voxel = 2.0;
  /// PLY vertex properties read into Frame::attributes (what layer rules
  /// read besides speed and curvature); a frame without one of them is an
  /// InputError naming the file.
  std::vector<std::string> attributes;
};

/// Statistics of one baked frame (one line of NAME.stats.jsonl).
struct FrameStats {
  int frame = 0;
  std::size_t triangles = 0, vertices = 0;
  std::size_t patches_alive = 0, patches_born = 0, patches_retired = 0, patches_lost = 0;
  std::size_t patch_vertices_removed = 0;
  /// Deaths by cause: lost to projection (patches_lost), and the retired
  /// ones split into eroded away (no vertex weight reaches epsilon, or every
  /// triangle over delta-max) and hidden (under older patches: it kept
  /// nothing visible).
  std::size_t retired_eroded = 0, retired_hidden = 0, retired_merged = 0;
  /// With exemplar layers (`layered`): retired because their centre lay
  /// where the rules choose another layer (BakeOptions::layer_switch);
  /// counted in patches_retired too.
  std::size_t retired_layer = 0;
  bool layered = false;
  /// Patches a fresh Poisson seeding of this frame would create (the
  /// population's yardstick).
  std::size_t fresh_seeding = 0;
  int charts = 0;
  double utilization = 0;
  std::size_t chart_texels = 0;
  double coverage = 0;                    ///< chart texels a patch kept / chart texels
  std::size_t forced_texels = 0;          ///< chart texels given a neighbour's patch where hole filling failed
  std::size_t closed_texels = 0;          ///< chart texels of small holes closed by their neighbours
  std::size_t held_texels = 0;            ///< hole texels given back to the patch that held the point
  /// The tracking raster (BakeOptions::track_texel), where births and
  /// retirements are decided; the fields above are the output raster's
  /// (zero for `lapflow track`, which draws no output).
  struct Tracking {
    int resolution = 0;
    double texel_size = 0;               ///< metres per tracking texel on the surface (area-weighted mean)
    std::size_t chart_texels = 0, forced_texels = 0, closed_texels = 0, held_texels = 0;
    double utilization = 0;
    /// Wall seconds of its steps: setup (the triangle locator and the
    /// raster's buffers), draw, holes (births and closed holes), resolve
    /// (the texels won and the held cells) and retire (with the merge test).
    double seconds_setup = 0, seconds_draw = 0, seconds_holes = 0, seconds_resolve = 0, seconds_retire = 0;
  } tracking;
  /// Wall seconds per stage. read: the wait for the frame read ahead; atlas:
  /// the atlas's own build time, on the read-ahead thread (so it overlaps
  /// the previous frame, except on the first); raster: draw, holes, resolve,
  /// retire and dilate together (each also on its own); total: this frame's
  /// share of the bake's wall time (frames sum to the bake); state: encoding
  /// NAME.state.N.bin in memory (its writing is part of write).
  double seconds_read = 0, seconds_advect = 0, seconds_weights = 0, seconds_seed = 0, seconds_atlas = 0,
         seconds_raster = 0, seconds_write = 0, seconds_total = 0, seconds_state = 0;
  double seconds_draw = 0, seconds_holes = 0, seconds_resolve = 0, seconds_retire = 0, seconds_dilate = 0;
  double seconds_track = 0;  ///< the tracking raster (draw, holes, counts, retire), within `raster`
  double peak_rss_mb = 0;
  std::string velocity_source;
};

/// A frame's input as read from disk: the mesh and, with a VDB pattern, the
/// velocity grid. Checks the velocity rules of FrameSource (a missing
/// velocity is an InputError naming the file unless allowed) and, unless
/// FrameSource::units_ok, the units (check_frame_units).
struct FrameInput {
  int number = 0;
  std::string path;                     ///< the mesh file
  TriMesh mesh;                         ///< with per-vertex velocities when the file has them
  std::unique_ptr<VelocityGrid> grid;   ///< set with FrameSource::velocity_vdb_pattern
  std::vector<std::vector<float>> attributes;  ///< FrameSource::attributes, per vertex
};
FrameInput read_frame_input(const FrameSource& source, int frame);

/// Throws InputError naming `path` and `frame` when the frame has sizes,
/// speeds or property types no liquid has (units_problems: every problem in
/// the one line, which ends saying that --units-ok bakes anyway). The vertex
/// velocities count when the velocity comes from them (`vertex_velocity`);
/// a `grid` is sampled at the vertices the triangles use.
void check_frame_units(const std::string& path, int frame, const MeshFile& file, bool vertex_velocity,
                       const VelocityGrid* grid = nullptr);

/// Everything about one frame. Members refer to each other (the surface
/// query to the mesh, the velocity to both), so a Frame stays where it was
/// made: load_frame() hands it out behind a pointer.
struct Frame {
  Frame() = default;
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;

  int number = 0;
  std::string path;                     ///< the mesh file
  TriMesh mesh;
  std::unique_ptr<SurfaceQuery> surface;          ///< closest points on `mesh`
  std::unique_ptr<VelocityGrid> velocity_grid;    ///< with a VDB pattern
  VelocityField velocity;                         ///< after FrameSource's rules (band, min-speed)
  std::string velocity_source;                    ///< "vertex", "vdb:NAME", "zero", ...
  /// FrameSource::attributes, in that order: one value per vertex each.
  std::vector<std::vector<float>> attributes;
  SurfaceAtlas atlas;                             ///< step 6 (build_surface_atlas): the output's
  SurfaceAtlas tracking_atlas;                    ///< the same at the tracking resolution
  FrameTextures textures;                         ///< the atlas images once resolved
  FrameStats stats;
};

/// Reads frame `frame`: its mesh, the closest-point structure and the
/// velocity field under `source`'s rules. The atlas and the rest are the
/// stages' to fill. Throws InputError naming the file and frame.
std::unique_ptr<Frame> load_frame(const FrameSource& source, int frame);
/// The same without the velocity field (`lapflow render`): the mesh and the
/// closest-point structure, and with `velocity_grid` the frame's VDB grid
/// when the source has one (for surface_velocities).
std::unique_ptr<Frame> load_frame_surface(const FrameSource& source, int frame, bool velocity_grid = false);

/// The simulation's velocity at each vertex of the frame's mesh, in m/s,
/// as the simulator gave it (no min-speed): the VDB grid sampled at each
/// vertex when the frame has one, else the mesh's own per-vertex
/// velocities; empty when it has neither. What the USD layer's `velocities` hold (motion blur).
std::vector<Vec3> surface_velocities(const Frame& frame);

}  // namespace lapflow
