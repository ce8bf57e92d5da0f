// ALGORITHM.md steps 2-3: cut a patch out of the fluid surface around a point,
// remesh it, flatten it with LSCM and place it in the unit square.
#include <algorithm>
#include <cmath>
#include <deque>
#include <numeric>
#include <unordered_map>
#include <unordered_set>

#include "lapflow/core/parallel.hpp"
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
  std::unordered_set<uint64_t> directed;  // directed edges already in the patch
  auto key = [](int32_t a, int32_t b) { return (uint64_t(uint32_t(a)) << 32) | uint32_t(b); };
  auto fits = [&](const Tri& f) {
    for (int k = 0; k < 3; ++k)
      if (directed.count(key(f[k], f[(k + 1) % 3]))) return false;
    return true;
  };
  std::vector<int> kept;
  std::unordered_set<int> seen{seed_triangle};
  std::deque<int> queue{seed_triangle};
  while (!queue.empty()) {
    const int t = queue.front();
    queue.pop_front();
    const Tri& f = fluid.triangles[t];
    if (!fits(f)) continue;
    kept.push_back(t);
    for (int k = 0; k < 3; ++k) directed.insert(key(f[k], f[(k + 1) % 3]));
    for (int k = 0; k < 3; ++k) {
      const int32_t a = f[k], b = f[(k + 1) % 3];
      for (int32_t i = adj.offsets[a]; i < adj.offsets[a + 1]; ++i) {
        const int u = adj.triangles[i];
        if (seen.count(u)) continue;
        const Tri& g = fluid.triangles[u];
        if (g[0] != b && g[1] != b && g[2] != b) continue;  // shares only a vertex
        seen.insert(u);
        if (accept(u)) queue.push_back(u);
      }
    }
  }
  PatchMesh m;
  std::unordered_map<int32_t, int32_t> local;
  m.triangles.reserve(kept.size());
  for (int t : kept) {
    Tri g{};
    for (int k = 0; k < 3; ++k) {
      const int32_t v = fluid.triangles[t][k];
      auto [it, inserted] = local.try_emplace(v, int32_t(m.positions.size()));
      if (inserted) m.positions.push_back(fluid.positions[v]);
      g[k] = it->second;
    }
    m.triangles.push_back(g);
  }
  detail::split_nonmanifold_vertices(m);
  if (fluid_triangles) fluid_triangles->assign(kept.begin(), kept.end());
  return m;
}

// Step 2's distance rule applied again to a remeshed patch: the cut keeps
// whole fluid triangles, so on a coarse fluid mesh it reaches r plus one
// fluid edge; after remeshing at r/6 the part beyond r (outside the exemplar,
// so eroded anyway) can go, which halves the vertex count on Mantaflow
// meshes. Keeps the edge-connected piece holding the triangle nearest p.
void trim_to_ball(PatchMesh& m, const Vec3& p, double r) {
  const std::size_t nt = m.triangles.size();
  std::vector<double> dist(nt);
  int nearest = -1;
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& f = m.triangles[t];
    dist[t] = norm(closest_point_on_triangle(p, m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]).point - p);
    if (nearest < 0 || dist[t] < dist[nearest]) nearest = int(t);
  }
  if (nearest < 0) return;
  // Edge-connected pieces of the triangles within r: union-find over the
  // triangles, joined through shared edges (sorted edge keys).
  std::vector<std::pair<uint64_t, int>> edges;
  edges.reserve(3 * nt);
  for (std::size_t t = 0; t < nt; ++t)
    if (dist[t] <= r || int(t) == nearest)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = m.triangles[t][k], b = m.triangles[t][(k + 1) % 3];
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
  std::vector<uint8_t> keep(nt, 0);
  const int root = find(nearest);
  for (std::size_t t = 0; t < nt; ++t) keep[t] = (dist[t] <= r || int(t) == nearest) && find(int(t)) == root;
  PatchMesh out;
  std::vector<int32_t> remap(m.positions.size(), -1);
  for (std::size_t t = 0; t < nt; ++t) {
    if (!keep[t]) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      int32_t& v = remap[m.triangles[t][k]];
      if (v < 0) v = int32_t(out.positions.size()), out.positions.push_back(m.positions[m.triangles[t][k]]);
      g[k] = v;
    }
    out.triangles.push_back(g);
  }
  m = std::move(out);
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
    // 0.83 of it (0.139 r for r/6 on dam_break); a lattice of 0.8 of the
    // target gives the same vertex density, so the same weights (B_V = 0 on
    // the border weighs more in a coarser patch). docs/patches.md.
    constexpr double kLatticeEdge = 0.8;
    const double edge = kLatticeEdge * options.remesh_edge * r;
    std::vector<int32_t> cut_triangles;
    const PatchMesh wide = cut_patch(fluid, adjacency, seed, at.position, n_p, r + edge, &cut_triangles);
    trace.lattice = detail::lattice_resample(surface, wide, cut_triangles, at.position, n_p, r, edge, mesh, under);
    if (trace.lattice == detail::LatticeResult::Resampled &&
        detail::lscm_flatten(mesh.positions, mesh.triangles, uv)) {
      flat = true;
      trace.path = PatchPath::Lattice;
    }
  }
  if (!flat) mesh = cut_patch(fluid, adjacency, seed, at.position, n_p, r);
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
      trim_to_ball(remeshed, at.position, r);
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
  patch_weights(fluid, r, weights, patch);
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
