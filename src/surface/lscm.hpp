#pragma once
// Least-squares conformal maps (Levy, Petitjean, Ray, Maillot 2002): the one
// LSCM of lapflow, used to flatten patches (patches/create.cpp) and atlas
// charts (atlas/flatten.cpp). Not a public header.
//
// The mesh is given as plain arrays: positions and triangles indexing them.
// Every position gets a uv and, unless pinned, an unknown, so a caller
// flattening part of a larger mesh renumbers the vertices it uses.
#include <span>
#include <vector>

#include "lapflow/core/vec.hpp"

namespace lapflow::detail {

/// Least-squares conformal map solved directly (exact minimum degree
/// ordering, sparse L D L^H; beyond 1536 unknowns the Eigen solver of
/// lscm_flatten_reference): `uv` gets one coordinate per vertex; vertices
/// `pin_a` and `pin_b` are pinned at `uv_a` and `uv_b` (pins < 0: two
/// far-apart border vertices chosen here, at (0,0) and (their 3D distance,
/// 0)). The energy is that of holomorphic maps, so triangles counter-clockwise
/// in 3D stay counter-clockwise in uv (up to the rare flip LSCM allows).
/// Triangles of zero area ask nothing of the map. Returns false when the
/// system is singular (no uv written). The mesh must be edge-connected.
bool lscm_flatten(std::span<const Vec3> positions, std::span<const Tri> triangles, std::vector<Vec2>& uv,
                  int pin_a = -1, int pin_b = -1, Vec2 uv_a = {0, 0}, Vec2 uv_b = {1, 0});

/// The same map from Eigen's SimplicialLDLT (triplets, AMD ordering): the
/// reference the tests compare lscm_flatten against, and lscm_flatten's path
/// for systems too large for its bit-matrix ordering. Same contract.
bool lscm_flatten_reference(std::span<const Vec3> positions, std::span<const Tri> triangles, std::vector<Vec2>& uv,
                            int pin_a = -1, int pin_b = -1, Vec2 uv_a = {0, 0}, Vec2 uv_b = {1, 0});

/// The conformal energy LSCM minimizes (sum over triangles of area times the
/// squared Cauchy-Riemann residual), in uv units squared.
double lscm_energy(std::span<const Vec3> positions, std::span<const Tri> triangles, const std::vector<Vec2>& uv);

}  // namespace lapflow::detail
