#pragma once
/// \file mesh_io.hpp Reading fluid meshes and frame sequences.
#include <optional>
#include <string>
#include <vector>

#include "lapflow/surface/mesh.hpp"

namespace lapflow {

/// A mesh with texture coordinates per triangle corner (a baked NAME.N.obj).
struct UvMesh {
  TriMesh mesh;
  std::vector<Vec2> corner_uv;  ///< 3 per triangle (corner order), empty when the file has no `vt`
};

/// Reads an OBJ with its `vt` coordinates (f v/vt or v/vt/vn). Throws
/// InputError naming the file and line on malformed input, and when only some
/// faces have texture coordinates.
UvMesh read_uv_mesh(const std::string& path);

/// Reads one PLY (binary little/big endian or ASCII) or OBJ file. Polygons are
/// triangulated (fan). Per-vertex velocity is read from PLY properties
/// `vx vy vz`, `velocity_x/_y/_z` or `v_x/_y/_z` (float or double).
/// Throws InputError naming the file and the offending element for a missing,
/// truncated or malformed file, an index out of range, a non-finite
/// position or velocity, or bounds beyond kMaxMeshCoordinate (a corrupt
/// file's 3e38, or a mesh not in metres). An empty mesh (no triangles) is legal.
TriMesh read_mesh(const std::string& path);

/// How a mesh file declared the vertex data lapflow reads: each position and
/// velocity property with its PLY type as the header spells it. Empty for
/// OBJ (text, read as double).
struct MeshFileInfo {
  struct Property {
    std::string name;      ///< "x", "vx", "velocity_x", ...
    std::string type;      ///< "float", "int", "uint8", ...
    bool integer = false;  ///< an integer type (char to uint)
  };
  std::vector<Property> positions;   ///< x, y, z
  std::vector<Property> velocities;  ///< empty when the file has no velocity
  /// The vertex element's other number properties (a simulator's `foam`,
  /// `temperature`, ...): what a layer rule may read (docs/layers.md).
  std::vector<std::string> attributes;
};

/// A mesh as read from its file, with how the file declared its data.
struct MeshFile {
  TriMesh mesh;
  MeshFileInfo declared;
  /// Per-vertex values of the properties read_mesh_file was asked for by
  /// name, in that order (one per vertex each).
  std::vector<std::vector<float>> attributes;
};
/// read_mesh, also telling the declared property types. With `check_bounds`
/// false a mesh beyond kMaxMeshCoordinate is returned instead of refused
/// (lapflow inspect reports it); every other check stays. `attributes`
/// names PLY vertex properties of any number type (a simulator's `foam`,
/// `temperature`, ...) read into MeshFile::attributes as floats; a name the
/// file lacks, a list property, a non-finite value or an OBJ file (which has
/// no vertex properties) is an InputError naming the file and the property.
MeshFile read_mesh_file(const std::string& path, bool check_bounds = true,
                        const std::vector<std::string>& attributes = {});


/// read_mesh on bytes already in memory: `name` gives the format (its
/// extension, else PLY when the bytes start with the PLY magic) and names the
/// input in errors. The readers' entry point for the fuzzers (tests/fuzz).
TriMesh read_mesh_from_memory(const std::string& data, const std::string& name);
/// read_uv_mesh on an OBJ already in memory, `name` naming it in errors.
UvMesh read_uv_mesh_from_memory(const std::string& data, const std::string& name);

/// Largest coordinate (metres from the origin) of a vertex a triangle uses
/// that read_mesh accepts: 1000 km. No liquid simulation is that large, and
/// every size lapflow derives (radius, patch count, atlas density) would be
/// absurd.
inline constexpr double kMaxMeshCoordinate = 1e6;
/// Throws InputError naming `path` when a vertex of a triangle of `mesh`
/// lies farther than kMaxMeshCoordinate from the origin on any axis.
void check_mesh_bounds(const TriMesh& mesh, const std::string& path);

/// Sizes and speeds no liquid in metres and seconds has. `lapflow inspect`
/// warns about a frame beyond them, `lapflow bake` refuses it (exit 2) unless
/// --units-ok; both take them from here. Unlike kMaxMeshCoordinate they
/// are a question about the units, not a limit of lapflow's.
/// A side of the bounding box of the vertices triangles use, in metres.
inline constexpr double kMaxLiquidSize = 1000;
/// The length of a vertex velocity, in m/s (the fastest splash is tens).
inline constexpr double kMaxLiquidSpeed = 1000;

/// The thresholds above as a help text says them: "bounds more than 1 km
/// across, a vertex faster than 1 km/s, or a position or velocity property
/// declared with an integer PLY type (...)".
std::string units_thresholds_text();
/// The help of `--units-ok` for a command that would `verb` ("bake") such frames.
std::string units_ok_help(const std::string& verb);

/// What `mesh` (with the types its file `declared`) has that no liquid has,
/// one sentence each, empty when nothing: bounds over kMaxLiquidSize, a
/// vertex beyond kMaxMeshCoordinate, a used vertex faster than
/// kMaxLiquidSpeed, a position or velocity declared with an integer PLY type
/// (which cannot hold sub-millimetre coordinates). With `check_velocity`
/// false (the velocity comes from elsewhere) the vertex velocities are not
/// looked at. E.g. "mesh bounds 3.2e+38 m across: over 1 km, are the units
/// metres?".
std::vector<std::string> units_problems(const TriMesh& mesh, const MeshFileInfo& declared, bool check_velocity = true);
/// The sentence of units_problems for a `speed` (m/s) over kMaxLiquidSpeed
/// at `vertex`, from `source` ("the vertex velocity", "the VDB grid 'vel'").
std::string speed_problem(double speed, std::size_t vertex, const std::string& source);

/// Writes a mesh as binary little-endian PLY with float x y z and, when the
/// mesh has velocities, float vx vy vz (the layout of ../shared/data).
/// Written atomically.
void write_ply(const std::string& path, const TriMesh& m);

/// Inclusive frame range `A-B` (or a single frame `A`).
struct FrameRange {
  int first = 1, last = 1;
};
/// Parses "A-B" or "A"; throws UsageError.
FrameRange parse_frame_range(const std::string& text);

/// A per-frame file name pattern. Accepted forms: `name.%04d.ply` (printf),
/// `name.####.ply` (one # per digit), `name.$F4.ply` and `name.$F.ply`
/// (Houdini). A pattern with no frame token is one file used
/// for frame 1.
class FramePattern {
 public:
  explicit FramePattern(std::string pattern);
  const std::string& pattern() const { return pattern_; }
  bool has_frame_token() const { return width_ >= 0; }
  /// The file name for frame f.
  std::string path(int frame) const;
  /// Frames present on disk, sorted (matches any zero padding the token allows).
  std::vector<int> frames_on_disk() const;

 private:
  std::string pattern_, prefix_, suffix_;
  int width_ = -1;  ///< digits of zero padding; 0 = unpadded; -1 = no token
};

/// The frames to process: `range` if given (every frame in it must exist,
/// else InputError naming the first missing file), else all found on disk
/// (InputError when none).
std::vector<int> resolve_frames(const FramePattern& pattern, const std::optional<FrameRange>& range);
/// The name of a sequence's outputs: `dam_break` for
/// `/data/dam_break.%04d.ply` ("lapflow" when nothing is left).
std::string default_output_name(const std::string& mesh_pattern);

}  // namespace lapflow
