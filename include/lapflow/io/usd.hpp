#pragma once
/// \file usd.hpp A bake as a USD shot, laid out as simulation caches are
/// (docs/usd.md): one text layer per frame holding that frame's time samples,
/// and a top-level stage that stitches them with value clips (the topology
/// changes every frame, so one attribute's time samples cannot interpolate
/// across frames) and binds a UsdPreviewSurface material that reads each
/// frame's atlases. Written as USDA text: no USD library is packaged for
/// Debian 12. Every file is written atomically, or into a StagedFiles group.
#include <span>
#include <string>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/surface/mesh.hpp"

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// The prim name of the clip layers' mesh: every frame layer defines
/// `/surface`, which the stage maps onto `/ROOT/surface`.
inline constexpr const char* kUsdClipPrim = "surface";

/// Writes frame `frame`'s layer: a Mesh `/surface` whose `points`,
/// `faceVertexCounts`, `faceVertexIndices`, `normals` (per vertex,
/// area-weighted), `extent`, indexed `primvars:st` (the UV mesh's corners:
/// uv_mesh_corners, the OBJ's `vt` in the same order) and, when `velocities`
/// is not empty (one per vertex, m/s), `velocities` are time samples at time
/// code `frame`. Vertex i is the mesh's vertex i, as in the OBJ. Points, st
/// and velocities are the floats nearest the doubles, written exactly
/// (shortest round-trip text). Throws OutputError when the file cannot be
/// written, std::invalid_argument when the atlas or velocities do not fit the mesh.
void write_usd_frame_layer(const std::string& path, int frame, const TriMesh& mesh, const SurfaceAtlas& atlas,
                           std::span<const Vec3> velocities, StagedFiles* staged = nullptr);

/// One frame of the stage: its time code and its files, as paths relative
/// to the stage's folder.
struct UsdStageFrame {
  int frame = 0;
  std::string layer;         ///< write_usd_frame_layer's file
  std::string color;         ///< the colour atlas (linear RGBA)
  std::string displacement;  ///< the height atlas (H in [0, 1])
};

struct UsdStage {
  std::string name;             ///< the bake's name; the root prim is its identifier form (usd_prim_name)
  std::vector<UsdStageFrame> frames;  ///< in time order; at least one
  double fps = 24;              ///< timeCodesPerSecond and framesPerSecond
  char up_axis = 'Z';           ///< 'Y' or 'Z'
  /// UsdPreviewSurface displacement in metres: scale x (H - 0.5).
  double displacement_scale = 0;
  std::string clip_manifest;    ///< write_usd_clip_manifest's file, relative to the stage's folder
};

/// Writes the top-level stage: time codes from the first frame to the last,
/// fps, metres, up axis; `/ROOT` (an Xform) holding the Mesh `surface` whose
/// clip set names each frame's layer (`assetPaths`, `active`, `times`) and
/// the clip manifest, and declares every clipped attribute with its
/// interpolation; and `/ROOT/Looks/atlas`, a UsdPreviewSurface whose
/// UsdUVTexture shaders read each frame's colour and height atlases
/// (`inputs:file` with a default value and a time sample per frame) through
/// a UsdPrimvarReader_float2 of `st`. Frames missing from `frames` hold
/// the previous frame's clip. Throws OutputError when it cannot be written.
void write_usd_stage(const std::string& path, const UsdStage& stage, StagedFiles* staged = nullptr);

/// Writes the clip manifest: the attributes the frame layers author, so a
/// reader opens the stage without reading every clip.
void write_usd_clip_manifest(const std::string& path, StagedFiles* staged = nullptr);

/// `name` as a USD prim name: letters, digits and '_' only, not starting
/// with a digit ("dam-break.v2" -> "dam_break_v2", "3d" -> "_3d").
std::string usd_prim_name(const std::string& name);

}  // namespace lapflow
