#pragma once
/// \file uv_mesh.hpp The fluid mesh with its per-corner atlas UVs as OBJ + MTL,
/// the file renderers load next to the colour and displacement atlases.
#include <cstdint>
#include <string>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/surface/mesh.hpp"

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// What the MTL names. Texture paths are written as given (relative to the
/// MTL's folder, as renderers resolve them); an empty path omits the line.
struct UvMeshMaterial {
  std::string name = "lapflow_atlas";  ///< `newmtl` / `usemtl` name
  std::string color_texture;           ///< `map_Kd`: the colour atlas
  std::string displacement_texture;    ///< `disp` and `map_disp`: the displacement atlas
};

/// The UV mesh's texture coordinates: one per distinct (vertex, chart, uv)
/// corner, so corners of one vertex inside one chart share it and a chart
/// seam splits it. The OBJ's `vt` lines and the USD layer's indexed `st`.
struct UvMeshCorners {
  std::vector<uint32_t> uv_of_corner;  ///< per triangle corner 3 t + k: its coordinate's index
  std::vector<uint32_t> corner_of_uv;  ///< per coordinate: the first corner that has it
};
/// Throws std::invalid_argument when `atlas` was built for another mesh.
UvMeshCorners uv_mesh_corners(const TriMesh& mesh, const SurfaceAtlas& atlas);

/// The MTL written beside an OBJ: the OBJ path with its extension replaced by `.mtl`.
std::string uv_mesh_mtl_path(const std::string& obj_path);

/// Writes `obj_path` and its MTL (uv_mesh_mtl_path), both atomically, or
/// into the group `staged` (which the caller commits).
/// `v` lines are the source vertices in order (output vertex i is source
/// vertex i, so provenance is the index); one `vt` per distinct (vertex,
/// chart, uv) corner; `vn` per vertex (area-weighted); `f v/vt/vn` per
/// triangle in source order. Throws OutputError when a file cannot be written.
void write_uv_mesh_obj(const std::string& obj_path, const TriMesh& mesh, const SurfaceAtlas& atlas,
                       const UvMeshMaterial& material, StagedFiles* staged = nullptr);

}  // namespace lapflow
