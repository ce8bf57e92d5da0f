// ALGORITHM.md steps 2-3: cut a patch out of the fluid surface around a point,
// remesh it, flatten it with LSCM and place it in the unit square.
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <unordered_map>

#include <Eigen/Dense>

#include "lapflow/core/parallel.hpp"
#include "lapflow/core/stamp_set.hpp"
#include "lapflow/patches/patches.hpp"
#include "patches/internal.hpp"

namespace lapflow {
namespace detail {

void split_nonmanifold_vertices(PatchMesh& mesh) {
  const std::size_t nt = mesh.triangles.size();
  // Corners (t, k) around the same vertex are in one fan when their triangles
  // share an edge at that vertex; union-find over corners.
  std::vector<int> parent(nt * 3);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<std::pair<uint64_t, int>> spokes;  // (vertex, other end) -> corner
  spokes.reserve(nt * 6);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const uint64_t v = uint32_t(mesh.triangles[t][k]);
      spokes.push_back({(v << 32) | uint32_t(mesh.triangles[t][(k + 1) % 3]), int(3 * t + k)});
      spokes.push_back({(v << 32) | uint32_t(mesh.triangles[t][(k + 2) % 3]), int(3 * t + k)});
    }
  std::sort(spokes.begin(), spokes.end());
  for (std::size_t i = 1; i < spokes.size(); ++i)
    if (spokes[i].first == spokes[i - 1].first) {
      const int a = find(spokes[i - 1].second), b = find(spokes[i].second);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  // The fan holding the vertex's first corner keeps it; the others get copies.
  std::vector<int> owner(mesh.positions.size(), -1);  // root corner that kept the vertex
  std::unordered_map<int, int> copy_of_root;
  for (std::size_t c = 0; c < nt * 3; ++c) {
    int32_t& v = mesh.triangles[c / 3][c % 3];
    const int root = find(int(c));
    if (owner[v] < 0) owner[v] = root;
    if (owner[v] == root) continue;
    auto [it, inserted] = copy_of_root.try_emplace(root, int(mesh.positions.size()));
    if (inserted) {
      mesh.positions.push_back(mesh.positions[v]);
      owner.push_back(root);
    }
    v = it->second;
  }
}

}  // namespace detail

SurfaceAdjacency build_surface_adjacency(const TriMesh& mesh) {
  SurfaceAdjacency adj;
  adj.offsets.assign(mesh.positions.size() + 1, 0);
  for (const Tri& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++adj.offsets[t[k] + 1];
  std::partial_sum(adj.offsets.begin(), adj.offsets.end(), adj.offsets.begin());
  adj.triangles.resize(adj.offsets.back());
  std::vector<int32_t> fill(adj.offsets.begin(), adj.offsets.end() - 1);
  for (int32_t t = 0; t < int32_t(mesh.triangles.size()); ++t)
    for (int k = 0; k < 3; ++k) adj.triangles[fill[mesh.triangles[t][k]]++] = t;
  return adj;
}

namespace {

using detail::PatchMesh;
using detail::PatchPath;

// Step 2: fluid triangles within distance r of p, facing along n_p, edge-
// connected to p's triangle, as a manifold mesh of their own. Edges that are
// non-manifold or inconsistently oriented in the fluid are not crossed, so the
// patch is a valid oriented surface.
// `fluid_triangles` (when given) gets the fluid triangle of each patch triangle.
PatchMesh cut_patch(const TriMesh& fluid, const SurfaceAdjacency& adj, int seed_triangle, const Vec3& p,
                    const Vec3& n_p, double r, std::vector<int32_t>* fluid_triangles = nullptr) {
  const double r2 = r * r;
  auto accept = [&](int t) {
    const Tri& f = fluid.triangles[t];
    const Vec3 n = triangle_normal_area2(fluid, t);
    if (!(dot(n, n_p) > 0)) return false;
    const Vec3 q = closest_point_on_triangle(p, fluid.positions[f[0]], fluid.positions[f[1]], fluid.positions[f[2]]).point;
    return norm2(q - p) <= r2;
  };
  // Per-thread sets over the fluid's triangles and vertices instead of hash
  // sets (patches are cut by the thousand, a few hundred triangles each).
  struct Scratch {
    StampSet seen, kept, vertex;
    std::vector<int32_t> local;  // fluid vertex -> patch vertex, for the vertices in `vertex`
  };
  thread_local Scratch z;
  z.seen.clear(fluid.triangles.size());
  z.kept.clear(fluid.triangles.size());
  z.vertex.clear(fluid.positions.size());
  if (z.local.size() < fluid.positions.size()) z.local.resize(fluid.positions.size());
  // Directed edge a -> b is in the patch when a kept triangle (one around a)
  // has it.
  auto has_directed = [&](int32_t a, int32_t b) {
    for (int32_t i = adj.offsets[a]; i < adj.offsets[a + 1]; ++i) {
      const int32_t u = adj.triangles[i];
      if (!z.kept.contains(std::size_t(u))) continue;
      const Tri& g = fluid.triangles[u];
      for (int k = 0; k < 3; ++k)
        if (g[k] == a && g[(k + 1) % 3] == b) return true;
    }
    return false;
  };
  auto fits = [&](const Tri& f) {
    for (int k = 0; k < 3; ++k)
      if (has_directed(f[k], f[(k + 1) % 3])) return false;
    return true;
  };
  std::vector<int> kept, queue{seed_triangle};
  z.seen.insert(std::size_t(seed_triangle));
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int t = queue[head];
    const Tri& f = fluid.triangles[t];
    if (!fits(f)) continue;
    kept.push_back(t);
    z.kept.insert(std::size_t(t));
    for (int k = 0; k < 3; ++k) {
      const int32_t a = f[k], b = f[(k + 1) % 3];
      for (int32_t i = adj.offsets[a]; i < adj.offsets[a + 1]; ++i) {
        const int u = adj.triangles[i];
        if (z.seen.contains(std::size_t(u))) continue;
        const Tri& g = fluid.triangles[u];
        if (g[0] != b && g[1] != b && g[2] != b) continue;  // shares only a vertex
        z.seen.insert(std::size_t(u));
        if (accept(u)) queue.push_back(u);
      }
    }
  }
  PatchMesh m;
  m.triangles.reserve(kept.size());
  for (int t : kept) {
    Tri g{};
    for (int k = 0; k < 3; ++k) {
      const int32_t v = fluid.triangles[t][k];
      if (z.vertex.insert(std::size_t(v))) {
        z.local[v] = int32_t(m.positions.size());
        m.positions.push_back(fluid.positions[v]);
      }
      g[k] = z.local[v];
    }
    m.triangles.push_back(g);
  }
  detail::split_nonmanifold_vertices(m);
  if (fluid_triangles) fluid_triangles->assign(kept.begin(), kept.end());
  return m;
}

// Triangles within `limit` (dist per triangle) and edge-connected to the
// nearest one (which is kept whatever its distance).
std::vector<uint8_t> connected_within(const std::vector<Tri>& triangles, const std::vector<double>& dist,
                                      double limit) {
  const std::size_t nt = triangles.size();
  std::vector<uint8_t> keep(nt, 0);
  if (nt == 0) return keep;
  const int nearest = int(std::min_element(dist.begin(), dist.end()) - dist.begin());
  // Edge-connected pieces of the triangles within the limit: union-find over
  // the triangles, joined through shared edges (sorted edge keys).
  std::vector<std::pair<uint64_t, int>> edges;
  edges.reserve(3 * nt);
  for (std::size_t t = 0; t < nt; ++t)
    if (dist[t] <= limit || int(t) == nearest)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = triangles[t][k], b = triangles[t][(k + 1) % 3];
        edges.push_back({(uint64_t(std::min(a, b)) << 32) | std::max(a, b), int(t)});
      }
  std::sort(edges.begin(), edges.end());
  std::vector<int> parent(nt);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (std::size_t i = 1; i < edges.size(); ++i)
    if (edges[i].first == edges[i - 1].first) parent[find(edges[i].second)] = find(edges[i - 1].second);
  const int root = find(nearest);
  for (std::size_t t = 0; t < nt; ++t) keep[t] = (dist[t] <= limit || int(t) == nearest) && find(int(t)) == root;
  return keep;
}

// The kept triangles over the vertices they use, numbered in order of first
// use; `used` gets each new vertex's old index.
std::vector<Tri> kept_triangles(const std::vector<Tri>& triangles, const std::vector<uint8_t>& keep,
                                std::size_t vertex_count, std::vector<int32_t>& used) {
  std::vector<Tri> out;
  std::vector<int32_t> remap(vertex_count, -1);
  used.clear();
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    if (!keep[t]) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      int32_t& v = remap[triangles[t][k]];
      if (v < 0) v = int32_t(used.size()), used.push_back(triangles[t][k]);
      g[k] = v;
    }
    out.push_back(g);
  }
  return out;
}

template <class T>
std::vector<T> gather(const std::vector<T>& values, const std::vector<int32_t>& used) {
  std::vector<T> out;
  out.reserve(used.size());
  for (const int32_t i : used) out.push_back(values[i]);
  return out;
}

// Step 2's distance rule applied again to a remeshed patch: the cut keeps
// whole fluid triangles, so on a coarse fluid mesh it reaches r plus one
// fluid edge; after remeshing at r/6 the part beyond r (outside the exemplar,
// so eroded anyway) can go, which halves the vertex count on Mantaflow
// meshes. Keeps the edge-connected piece holding the triangle nearest p.
void trim_to_ball(PatchMesh& m, const Vec3& p, double r) {
  const std::size_t nt = m.triangles.size();
  if (nt == 0) return;
  std::vector<double> dist(nt);
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& f = m.triangles[t];
    dist[t] = norm(closest_point_on_triangle(p, m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]).point - p);
  }
  const std::vector<uint8_t> keep = connected_within(m.triangles, dist, r);
  std::vector<int32_t> used;
  m.triangles = kept_triangles(m.triangles, keep, m.positions.size(), used);
  m.positions = gather(m.positions, used);
}

// Linear map of a 3D tangent direction into uv on one triangle.
Vec2 uv_direction(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec2& u0, const Vec2& u1, const Vec2& u2,
                  const Vec3& dir) {
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const double g11 = dot(e1, e1), g12 = dot(e1, e2), g22 = dot(e2, e2);
  const double det = g11 * g22 - g12 * g12;
  if (!(det > 0)) return {};
  const double r1 = dot(e1, dir), r2 = dot(e2, dir);
  const double a = (g22 * r1 - g12 * r2) / det, b = (g11 * r2 - g12 * r1) / det;
  return (u1 - u0) * a + (u2 - u0) * b;
}

// Anticipated shear (PatchOptions::anticipate, docs/temporal.md).
//
// The flow's future deformation of a patch at p is predicted by advecting a
// ring of probes (radius r/2 around p) and p itself through this frame's
// velocity, as if the flow were steady: Heun steps of one frame, each
// projected back onto this frame's surface. Following the streamline takes
// in how the flow changes along the patch's path, which the gradient at p
// alone misses. The deformation after k frames is the least-squares linear
// map A_k (3x2) from the probes' tangent coordinates at p to their offsets
// from p's image; its right stretch S_k = sqrt(A_k^T A_k) is in p's tangent
// frame, rotation left out.
struct Prediction {
  Vec3 t1, t2;  ///< p's tangent frame
  /// The stretch to lay the patch with, in (t1, t2): S_m^-1, where m is
  /// `anticipate` of the frames the probes take to reach delta_max (or of
  /// the frames they could be followed, at most the horizon). I when the flow
  /// has no strain.
  Eigen::Matrix2d V = Eigen::Matrix2d::Identity();
};

double delta_of(const Eigen::Matrix2d& F) {
  const Eigen::Matrix2d G = F.transpose() * F;
  return detail::delta_from_gram(G(0, 0), G(0, 1), G(1, 1));
}

Prediction predict_stretch(const SurfaceQuery& surface, const Vec3& p, const Vec3& n_p, const PatchOptions& options,
                           double delta_max) {
  Prediction out;
  detail::tangent_frame(n_p, out.t1, out.t2);
  const double r = options.radius, dt = options.dt;
  const VelocityField& v = *options.velocity;
  constexpr int kRing = 8;
  std::vector<Vec3> x(kRing + 1);
  x[0] = p;
  Eigen::Matrix<double, 2, kRing> X;  // probes' tangent coordinates at p
  for (int i = 0; i < kRing; ++i) {
    const double a = 2 * M_PI * i / kRing;
    const ClosestHit hit = surface.closest(p + (out.t1 * std::cos(a) + out.t2 * std::sin(a)) * (0.5 * r), r);
    if (!hit.found) return out;
    x[i + 1] = hit.point;
    X.col(i) << dot(hit.point - p, out.t1), dot(hit.point - p, out.t2);
  }
  const Eigen::Matrix2d XXt = X * X.transpose();
  if (!(XXt.determinant() > 0)) return out;
  // Unsteadiness: how much the velocity at the probes changed since the
  // previous frame, against the speed there.
  double anticipate = options.anticipate;
  // The velocity at the probes, where the first step starts.
  std::vector<Vec3> vx(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) vx[i] = v(x[i]);
  if (options.previous_velocity) {
    double change = 0, speed = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      change += norm(vx[i] - (*options.previous_velocity)(x[i]));
      speed += norm(vx[i]);
    }
    // Full anticipation up to 0.1, none from 0.3: a steady stream (channel)
    // stays under the first, splash's median birth is past the second
    // (docs/temporal.md, "Anticipated shear").
    const double unsteady = speed > 0 ? change / speed : 0;
    anticipate *= std::clamp((0.3 - unsteady) / 0.2, 0.0, 1.0);
    if (!(anticipate > 0)) return out;
  }
  const Eigen::Matrix<double, kRing, 2> fit = X.transpose() * XXt.inverse();
  // S_k for k = 0, 1, ...: the probes after k frames.
  std::vector<Eigen::Matrix2d> S{Eigen::Matrix2d::Identity()};
  int life = options.anticipate_horizon;
  for (int k = 1; k <= options.anticipate_horizon; ++k) {
    bool lost = false, moved = false;
    for (std::size_t i = 0; i < x.size(); ++i) {
      Vec3& q = x[i];
      const Vec3 k1 = k == 1 ? vx[i] : v(q), k2 = v(q + k1 * dt);
      const ClosestHit hit = surface.closest(q + (k1 + k2) * (0.5 * dt), r);
      if (!hit.found) lost = true;
      else moved |= hit.point != q, q = hit.point;
    }
    if (!moved) return out;  // at rest (steady: it stays so)
    if (lost) {
      life = k - 1;
      break;
    }
    Eigen::Matrix<double, 3, kRing> Y;
    for (int i = 0; i < kRing; ++i) {
      const Vec3 y = x[i + 1] - x[0];
      Y.col(i) << y.x, y.y, y.z;
    }
    const Eigen::Matrix<double, 3, 2> A = Y * fit;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(A.transpose() * A);
    if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 0)) {
      life = k - 1;
      break;
    }
    S.push_back(eig.eigenvectors() * eig.eigenvalues().cwiseSqrt().asDiagonal() * eig.eigenvectors().transpose());
    if (delta_of(S.back()) >= delta_max) {
      life = k;
      break;
    }
  }
  // S at m frames, linear between whole frames.
  const double m = std::min(anticipate * life, double(S.size() - 1));
  const int k = std::min(int(m), int(S.size()) - 2);
  if (k < 0) return out;
  const Eigen::Matrix2d Sm = S[k] + (m - k) * (S[k + 1] - S[k]);
  if (!Sm.allFinite() || !(Sm.determinant() > 0) || !(delta_of(Sm) > 1 + 1e-9)) return out;
  // Lay at the anticipated stretch with the patch's own area: S_m^-1 scaled
  // to determinant 1 (the surface's growth is not anticipated).
  const Eigen::Matrix2d Vt = Sm.inverse() * std::sqrt(Sm.determinant());
  if (Vt.allFinite()) out.V = Vt;
  return out;
}

// The 2x2 map from p's tangent coordinates to the patch's rest uv (metres),
// fitted over the patch's vertices within r/2 of the centre (LSCM is nearly
// a rotation there).
Eigen::Matrix2d tangent_to_uv(const Patch& patch, const Vec3& p, const Prediction& pred, double r) {
  Eigen::Matrix2d XXt = Eigen::Matrix2d::Zero(), UXt = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < patch.positions.size(); ++i) {
    const Vec3 d = patch.positions[i] - p;
    if (norm2(d) > 0.25 * r * r) continue;
    const Eigen::Vector2d xi(dot(d, pred.t1), dot(d, pred.t2));
    const Eigen::Vector2d ui((patch.rest_uv[i].x - 0.5) * 2 * r, (patch.rest_uv[i].y - 0.5) * 2 * r);
    XXt += xi * xi.transpose();
    UXt += ui * xi.transpose();
  }
  return XXt.determinant() > 0 ? Eigen::Matrix2d(UXt * XXt.inverse()) : Eigen::Matrix2d::Identity();
}

// Rest uv through V^-1 about the centre: the texture-to-surface map becomes V.
void unstretch(Patch& patch, const Eigen::Matrix2d& V) {
  if (V.isIdentity(0)) return;
  const Eigen::Matrix2d Vinv = V.inverse();
  for (Vec2& uv : patch.rest_uv) {
    const Eigen::Vector2d d = Vinv * Eigen::Vector2d(uv.x - 0.5, uv.y - 0.5);
    uv = {0.5 + d(0), 0.5 + d(1)};
  }
}

// An anticipated patch laid wider than r keeps the triangles within uv
// distance 0.5 of the centre (the texture disk, what trim_to_ball keeps of a
// conformal patch) that are edge-connected to the one nearest the centre.
void trim_to_texture_disk(Patch& patch) {
  const std::size_t nt = patch.triangles.size();
  std::vector<double> dist(nt);
  const Vec3 c{0.5, 0.5, 0};
  auto lift = [&](int32_t v) { return Vec3{patch.rest_uv[v].x, patch.rest_uv[v].y, 0}; };
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& f = patch.triangles[t];
    dist[t] = norm(closest_point_on_triangle(c, lift(f[0]), lift(f[1]), lift(f[2])).point - c);
  }
  const std::vector<uint8_t> keep = connected_within(patch.triangles, dist, 0.5);
  std::vector<int32_t> used;
  patch.triangles = kept_triangles(patch.triangles, keep, patch.positions.size(), used);
  patch.positions = gather(patch.positions, used);
  patch.rest_uv = gather(patch.rest_uv, used);
  patch.surface_triangle = gather(patch.surface_triangle, used);
}

// Steps 2-3 around `at` (its fluid triangle `seed`, normal n_p), the cut
// reaching `reach` from p: r, or farther for an anticipated patch, whose
// texture covers an ellipse on the surface. Weights are left to the caller.
std::optional<Patch> lay_patch(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency, int seed,
                               const SurfacePoint& at, const Vec3& n_p, double reach, uint32_t id, int frame,
                               const PatchOptions& options, detail::PatchTrace& trace) {
  const TriMesh& fluid = surface.mesh();
  const double r = options.radius;
  // Remeshing relaxes vertices tangentially without projecting them back
  // (CGAL's projection builds an AABB tree per patch, half the cost of the
  // remesh); this snap onto the fluid also finds the triangle under each
  // vertex, which the fold test and the rasterizer need.
  std::vector<int32_t> under;
  auto snap = [&](PatchMesh& m) {
    under.assign(m.positions.size(), -1);
    for (std::size_t v = 0; v < m.positions.size(); ++v) {
      // A small radius first (remeshed vertices are within the chord error
      // of the fluid): the same closest point when there is one, found faster.
      ClosestHit hit = surface.closest(m.positions[v], r / 64);
      if (!hit.found) hit = surface.closest(m.positions[v], 0.25 * r);
      if (!hit.found) continue;
      // Project once more from the snapped point: that is what advection does
      // next frame, and on a shared edge it may pick the other triangle; doing
      // it now makes a still scene bake identical atlases from frame 1 on.
      // The snapped point is on the surface up to rounding, so a tiny radius
      // finds the same answer as r/4 with a cheaper search.
      const ClosestHit again = surface.closest(hit.point, 1e-6 * r);
      if (again.found) hit = again;
      under[v] = hit.triangle;
      m.positions[v] = hit.point;
    }
  };
  std::vector<Vec2> uv;
  bool flat = false;
  PatchMesh mesh;
  if (options.remesh && options.remesher == Remesher::Lattice) {
    // Resampling needs the fluid up to one lattice edge beyond r (the
    // triangles within r reach that far); where the cut is no height field
    // over the tangent plane, the isotropic remesher takes the usual cut below.
    // The remesher's edges lie between 4/5 and 4/3 of its target and average
    // little more than the lower bound; a lattice of 0.8 of the target gives
    // the same vertex density, so the same weights (B_V = 0 on the border
    // weighs more in a coarser patch). docs/patches.md, "Lattice resampling".
    constexpr double kLatticeEdge = 0.8;
    const double edge = kLatticeEdge * options.remesh_edge * r;
    std::vector<int32_t> cut_triangles;
    const PatchMesh wide = cut_patch(fluid, adjacency, seed, at.position, n_p, reach + edge, &cut_triangles);
    trace.lattice = detail::lattice_resample(surface, wide, cut_triangles, at.position, n_p, reach, edge, mesh, under);
    if (trace.lattice == detail::LatticeResult::Resampled &&
        detail::lscm_flatten(mesh.positions, mesh.triangles, uv)) {
      flat = true;
      trace.path = PatchPath::Lattice;
    }
  }
  if (!flat) mesh = cut_patch(fluid, adjacency, seed, at.position, n_p, reach);
  if (options.remesh && !flat) {
    PatchMesh remeshed = mesh;
    // When the fluid triangles are much larger than r the cut is far larger
    // than the patch; cap the remeshed size (before trimming) so one patch
    // never costs more than a few thousand triangles.
    double area = 0;
    for (const Tri& f : mesh.triangles)
      area += 0.5 * norm(cross(mesh.positions[f[1]] - mesh.positions[f[0]], mesh.positions[f[2]] - mesh.positions[f[0]]));
    constexpr double kMaxRemeshTriangles = 4000;
    const double edge = std::max(options.remesh_edge * r, std::sqrt(area / (0.433 * kMaxRemeshTriangles)));
    const bool remeshed_ok = options.remesher == Remesher::CgalIsotropic ? detail::cgal_remesh(remeshed, edge)
                                                                : detail::isotropic_remesh(remeshed, edge);
    if (remeshed_ok) {
      trim_to_ball(remeshed, at.position, reach);
      snap(remeshed);
      if (detail::lscm_flatten(remeshed.positions, remeshed.triangles, uv)) {
        mesh = std::move(remeshed);
        flat = true;
        trace.path = PatchPath::Remeshed;
      }
    }
  }
  if (!flat) {
    trace.path = PatchPath::Cut;
    snap(mesh);
    if (!detail::lscm_flatten(mesh.positions, mesh.triangles, uv)) return std::nullopt;
  }

  // p's uv: barycentric in the patch triangle closest to p.
  int host = -1;
  double best = INFINITY, hb1 = 0, hb2 = 0;
  double area3 = 0, area_uv = 0;
  for (int t = 0; t < int(mesh.triangles.size()); ++t) {
    const Tri& f = mesh.triangles[t];
    const Vec3 &a = mesh.positions[f[0]], &b = mesh.positions[f[1]], &c = mesh.positions[f[2]];
    area3 += 0.5 * norm(cross(b - a, c - a));
    area_uv += 0.5 * cross(uv[f[1]] - uv[f[0]], uv[f[2]] - uv[f[0]]);
    const TrianglePoint q = closest_point_on_triangle(at.position, a, b, c);
    const double d = norm2(q.point - at.position);
    if (d < best) best = d, host = t, hb1 = q.b1, hb2 = q.b2;
  }
  if (host < 0 || !(area_uv > 0) || !(area3 > 0)) return std::nullopt;
  const Tri& hf = mesh.triangles[host];
  const Vec2 uv_p = uv[hf[0]] * (1 - hb1 - hb2) + uv[hf[1]] * hb1 + uv[hf[2]] * hb2;

  // Step 3 placement: uniform scale so uv area * (2r)^2 = 3D area, then rotate.
  const double scale = std::sqrt(area3 / area_uv) / (2 * r);
  double angle = 2 * M_PI * hash_to_unit(hash64(options.seed, id, 0x9a7c4e5ull));
  if (options.align) {
    const Vec3 t = options.align_direction - n_p * dot(options.align_direction, n_p);
    const Vec2 d = uv_direction(mesh.positions[hf[0]], mesh.positions[hf[1]], mesh.positions[hf[2]], uv[hf[0]],
                                uv[hf[1]], uv[hf[2]], t);
    if (norm(d) > 0 && norm(t) > 1e-9 * norm(options.align_direction)) angle = -std::atan2(d.y, d.x);
  }
  const double cs = std::cos(angle) * scale, sn = std::sin(angle) * scale;
  Patch patch;
  patch.id = id;
  patch.birth_frame = frame;
  patch.center = at.position;
  patch.center_normal = n_p;
  patch.rest_uv.resize(uv.size());
  for (std::size_t v = 0; v < uv.size(); ++v) {
    const Vec2 d = uv[v] - uv_p;
    patch.rest_uv[v] = {0.5 + cs * d.x - sn * d.y, 0.5 + sn * d.x + cs * d.y};
  }
  patch.positions = std::move(mesh.positions);
  patch.triangles = std::move(mesh.triangles);
  patch.surface_triangle = std::move(under);
  return patch;
}

}  // namespace

namespace detail {

std::optional<Patch> create_patch_traced(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                                         const SurfacePoint& at, uint32_t id, int frame, const PatchOptions& options,
                                         const WeightOptions& weights, PatchTrace& trace) {
  trace = {};
  const TriMesh& fluid = surface.mesh();
  const double r = options.radius;
  if (fluid.triangles.empty() || !(r > 0) || !is_finite(at.position)) return std::nullopt;
  int seed = at.triangle;
  if (seed < 0 || seed >= int(fluid.triangles.size())) {
    const ClosestHit hit = surface.closest(at.position, INFINITY);
    if (!hit.found) return std::nullopt;
    seed = hit.triangle;
  }
  const Vec3 face_n = normalized(triangle_normal_area2(fluid, seed));
  if (norm2(face_n) == 0) return std::nullopt;  // degenerate triangle: nothing to lay a texture on
  Vec3 n_p = normalized(at.normal);
  if (norm2(n_p) == 0) n_p = face_n;
  if (!(dot(face_n, n_p) > 0)) n_p = face_n;  // the rule keeps p's own triangle in every case

  if (!(options.anticipate > 0 && options.velocity)) {
    std::optional<Patch> patch = lay_patch(surface, adjacency, seed, at, n_p, r, id, frame, options, trace);
    if (patch) patch_weights(fluid, r, weights, *patch);
    return patch;
  }
  // Anticipated: the texture disk covers the ellipse V (disk of radius r) on
  // the surface, so the patch is laid out to V's longer axis (with a margin
  // for the fit of its uv frame), its rest uv taken through V^-1 and trimmed
  // to the texture disk.
  const Prediction pred = predict_stretch(surface, at.position, n_p, options, weights.delta_max);
  const double reach = Eigen::JacobiSVD<Eigen::Matrix2d>(pred.V).singularValues()(0);
  const bool wide = reach > 1 + 1e-9;
  std::optional<Patch> patch =
      lay_patch(surface, adjacency, seed, at, n_p, wide ? r * (1.1 * reach) : r, id, frame, options, trace);
  if (!patch) return std::nullopt;
  if (wide) {
    const Eigen::Matrix2d B = tangent_to_uv(*patch, at.position, pred, r);
    unstretch(*patch, B * pred.V * B.inverse());
    trim_to_texture_disk(*patch);
  }
  patch_weights(fluid, r, weights, *patch);
  return patch;
}

}  // namespace detail

std::optional<Patch> create_patch(const SurfaceQuery& surface, const SurfaceAdjacency& adjacency,
                                  const SurfacePoint& at, uint32_t id, int frame, const PatchOptions& options,
                                  const WeightOptions& weights) {
  detail::PatchTrace trace;
  return detail::create_patch_traced(surface, adjacency, at, id, frame, options, weights, trace);
}

std::optional<Patch> create_patch(const SurfaceQuery& surface, const SurfacePoint& at, uint32_t id, int frame,
                                  const PatchOptions& options, const WeightOptions& weights) {
  return create_patch(surface, build_surface_adjacency(surface.mesh()), at, id, frame, options, weights);
}

}  // namespace lapflow
