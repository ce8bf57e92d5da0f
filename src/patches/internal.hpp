#pragma once
// Internal pieces of the patch stages (seed, create, flatten, advect, weights)
// shared between their translation units and the tests. Not public API.
#include <cmath>
#include <vector>

#include "lapflow/patches/patches.hpp"
#include "lapflow/core/vec.hpp"
#include "surface/lscm.hpp"

namespace lapflow::detail {

/// A small open triangle mesh in plain arrays (a patch before it gets uv;
/// lscm_flatten(m.positions, m.triangles, uv) flattens it).
struct PatchMesh {
  std::vector<Vec3> positions;
  std::vector<Tri> triangles;
};

/// The same map computed by CGAL's LSCM_parameterizer_3 with
/// Two_vertices_parameterizer_3(pin_a, pin_b), which places the pins at (0,0.5)
/// and (1,0.5). For tests that lscm_flatten agrees with CGAL.
bool cgal_lscm_flatten(const PatchMesh& mesh, int pin_a, int pin_b, std::vector<Vec2>& uv);

/// CGAL isotropic remeshing with target edge length `target_edge` (metres);
/// vertices are NOT projected back on the input (the caller snaps them onto
/// the fluid with its own closest-point query); border edges are constrained (split
/// and collapsed along the border only). Returns false (mesh untouched) when
/// CGAL cannot take the mesh (not a valid manifold polygon mesh).
bool cgal_remesh(PatchMesh& mesh, double target_edge, int iterations = 1);

/// The same remeshing (split > 4/3 L, collapse < 4/5 L, flip toward valence 6,
/// 4 on the border, tangential relaxation; border split, collapsed and relaxed
/// along itself; no projection) on plain arrays, cheaper than CGAL's on
/// patch-sized meshes since it skips Surface_mesh's bookkeeping
/// (patches/remesh.cpp; numbers in docs/patches.md). Deterministic. Returns false (mesh
/// untouched) when the mesh is not an oriented manifold (edges with more than
/// two triangles or opposite orientations, vertices with several fans).
bool isotropic_remesh(PatchMesh& mesh, double target_edge, int iterations = 1);

/// Duplicates every vertex whose incident triangles form several fans
/// (edge-connected groups around it), so the mesh becomes manifold at vertices.
/// Requires every edge to have at most two consistently oriented triangles.
void split_nonmanifold_vertices(PatchMesh& mesh);

/// Right-handed orthonormal frame (t1, t2, n) of unit normal n: t1 from the
/// coordinate axis least aligned with n.
inline void tangent_frame(const Vec3& n, Vec3& t1, Vec3& t2) {
  const Vec3 axis = std::fabs(n.x) <= std::fabs(n.y) && std::fabs(n.x) <= std::fabs(n.z) ? Vec3{1, 0, 0}
                    : std::fabs(n.y) <= std::fabs(n.z)                                  ? Vec3{0, 1, 0}
                                                                                        : Vec3{0, 0, 1};
  t1 = normalized(cross(axis, n));
  t2 = cross(n, t1);
}

/// Sorkine's delta = max(s1, 1/s2) of a linear map whose Gram matrix J^T J
/// is [[a, b], [b, c]] (s1 >= s2 its singular values, written when asked);
/// +inf when s2 is 0.
double delta_from_gram(double a, double b, double c, double* s1 = nullptr, double* s2 = nullptr);

/// Per-triangle distortion of the map rest uv (scaled by `scale`) -> 3D:
/// singular values s1 >= s2 of its Jacobian; returns delta = max(s1, 1/s2),
/// +inf when either triangle is degenerate.
double triangle_distortion(const Vec2& u0, const Vec2& u1, const Vec2& u2, const Vec3& p0, const Vec3& p1,
                           const Vec3& p2, double scale, double* s1 = nullptr, double* s2 = nullptr);

// ---- Tangent-plane lattice (patches/lattice.cpp) ----

/// What lattice_resample did with a cut.
enum class LatticeResult {
  Resampled,  ///< `out` holds the resampled patch
  Steep,      ///< a cut triangle tilts more than acos(min_cos) from n_p (or faces away): not a height field
  Overlap,    ///< a lattice point lies strictly inside two projected triangles: the cut folds over itself
  TooFew,     ///< fewer than a quarter of the triangles a flat disk of radius r would get
};

/// Resamples a cut (the fluid triangles `cut_triangles[t]` copied into `cut`,
/// as cut_patch makes it; it should reach r + edge from p) on an equilateral
/// lattice of edge `edge` (metres) laid in the plane through p normal to n_p,
/// each lattice point lifted onto the fluid triangle under it. Keeps the
/// lattice triangles within distance r of p (point-triangle distance, as
/// trim_to_ball) whose edges stay inside the cut, then the edge-connected
/// piece holding the one nearest p. Every output vertex is on the fluid with
/// its fluid triangle in `under`; every triangle's normal has a positive dot
/// with n_p. Anything but Resampled leaves `out` and `under` unspecified.
LatticeResult lattice_resample(const SurfaceQuery& surface, const PatchMesh& cut, const std::vector<int32_t>& cut_triangles,
                         const Vec3& p, const Vec3& n_p, double r, double edge, PatchMesh& out,
                         std::vector<int32_t>& under, double min_cos = 0.5);

/// How create_patch made a patch's mesh.
enum class PatchPath {
  Lattice,   ///< lattice_resample (Remesher::Lattice on a height-field cut)
  Remeshed,  ///< the cut remeshed (Isotropic or CgalIsotropic), trimmed to r and snapped
  Cut,       ///< the cut itself, snapped (remeshing off or failed)
};
struct PatchTrace {
  PatchPath path = PatchPath::Cut;
  LatticeResult lattice = LatticeResult::Resampled;  ///< what lattice_resample said (when it was tried)
};

/// create_patch, also telling which path it took (for tests and measurements).
std::optional<Patch> create_patch_traced(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                                         const SurfacePoint& at, uint32_t id, int frame, const PatchOptions& options,
                                         const WeightOptions& weights, PatchTrace& trace);

}  // namespace lapflow::detail
