// The lattice: a new patch resampled in its tangent plane (Remesher::Lattice): the
// cheap alternative to isotropic remeshing where the cut is a height field
// over p's tangent plane. The cut's fluid triangles are projected to that
// plane, a regular equilateral lattice centred at p (edge L) is located in
// the projected triangles by scan-converting each of them into the lattice,
// and every lattice point is lifted to the fluid triangle holding it by its
// barycentric coordinates, so it lies ON the fluid and the triangle under it
// is known without a closest-point search. Lattice triangles are kept when
// their three corners were located, no edge of theirs leaves the cut (a hole
// or a gap in between), and they are within distance r of p (trim_to_ball's
// rule); then the edge-connected piece holding the triangle nearest p.
//
// The lattice triangles are counter-clockwise in the plane (frame t1, t2, n_p,
// right-handed) and each lifted triangle projects back onto its lattice
// triangle, so no lifted triangle faces away from n_p. Where the cut is not a
// height field (a triangle tilted more than `min_cos` allows, a lattice point
// strictly inside two projected triangles, or too few triangles kept) nothing
// is written and the caller remeshes instead.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "lapflow/core/stamp_set.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "patches/internal.hpp"

namespace lapflow::detail {
namespace {

// One lattice point: the cut triangle holding it (the one it is deepest in)
// and its barycentric coordinates there.
struct LatticePoint {
  int32_t triangle = -1;
  double depth = -INFINITY;  // smallest barycentric coordinate in `triangle`
  double b[3] = {0, 0, 0};
  int32_t interior = 0;      // cut triangles holding it strictly inside
  Vec3 lifted;               // on the fluid, before the stillness query
  int32_t vertex = -1;       // index in the output mesh
  uint8_t edge_state[3] = {0, 0, 0};  // edges toward +a, +b, +b-a: 0 unknown, 1 inside the cut, 2 leaves it
};

// Does the segment s0-s1 touch the counter-clockwise triangle (a, b, c),
// fattened by `tol` (metres)? Separating axes: the triangle's edge normals,
// the segment's normal and its direction (the segment as a thin rectangle).
bool touches(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& s0, const Vec2& s1, double tol) {
  const Vec2 v[3] = {a, b, c};
  for (int k = 0; k < 3; ++k) {
    const Vec2 e = v[(k + 1) % 3] - v[k];
    const double t = tol * norm(e);
    if (cross(e, s0 - v[k]) < -t && cross(e, s1 - v[k]) < -t) return false;
  }
  const Vec2 d = s1 - s0;
  const double t = tol * norm(d);
  const double c0 = cross(d, a - s0), c1 = cross(d, b - s0), c2 = cross(d, c - s0);
  if ((c0 > t && c1 > t && c2 > t) || (c0 < -t && c1 < -t && c2 < -t)) return false;
  const double d0 = dot(d, a - s0), d1 = dot(d, b - s0), d2 = dot(d, c - s0), dd = dot(d, d);
  if (d0 < -t && d1 < -t && d2 < -t) return false;
  if (d0 > dd + t && d1 > dd + t && d2 > dd + t) return false;
  return true;
}

// Scratch arrays reused per thread. Reached through a function the compiler
// does not inline: in a shared library every use of a thread_local's address
// may otherwise become a __tls_get_addr call, thousands per patch.
struct Scratch {
  std::vector<LatticePoint> lattice;
  std::vector<Vec2> flat;
  std::vector<std::pair<uint64_t, int32_t>> edges;
  std::vector<int32_t> neighbour, queue;
  StampSet walked;  // triangles of the current walk
  std::vector<uint8_t> candidate;
};
[[gnu::noinline]] Scratch& thread_scratch() {
  thread_local Scratch scratch;
  return scratch;
}

}  // namespace

LatticeResult lattice_resample(const SurfaceQuery& surface, const PatchMesh& cut, const std::vector<int32_t>& cut_triangles,
                         const Vec3& p, const Vec3& n_p, double r, double edge, PatchMesh& out,
                         std::vector<int32_t>& under, double min_cos) {
  const Vec3 n = normalized(n_p);
  Vec3 t1, t2;
  tangent_frame(n, t1, t2);
  const double L = edge, h = 0.5 * std::sqrt(3.0) * L;
  // Lattice point (i, j) sits at ((i + j/2) L, j h) in the plane. Points are
  // needed up to r + L from p: a triangle within r of p reaches one edge
  // farther (the plane distance is never above the 3D distance).
  const double reach = r + L;
  const int J = int(std::ceil(reach / h)), I = int(std::ceil(reach / L + 0.5 * J)) + 1;
  const int width = 2 * I + 1;
  auto index = [&](int i, int j) { return (j + J) * width + (i + I); };
  Scratch& scratch = thread_scratch();
  std::vector<LatticePoint>& lattice = scratch.lattice;
  lattice.assign(std::size_t(width) * std::size_t(2 * J + 1), LatticePoint{});

  std::vector<Vec2>& flat = scratch.flat;
  flat.resize(cut.positions.size());
  for (std::size_t v = 0; v < cut.positions.size(); ++v) {
    const Vec3 d = cut.positions[v] - p;
    flat[v] = {dot(d, t1), dot(d, t2)};
  }

  // Scan-convert every cut triangle into the lattice.
  const double eps = 1e-9, tol = 1e-9 * L;
  for (int32_t t = 0; t < int32_t(cut.triangles.size()); ++t) {
    const Tri& f = cut.triangles[t];
    const Vec3 &A = cut.positions[f[0]], &B = cut.positions[f[1]], &C = cut.positions[f[2]];
    const Vec3 n3 = cross(B - A, C - A);
    const double area2 = norm(n3);
    if (!(area2 > 1e-12 * r * r)) continue;  // degenerate: covers nothing
    if (dot(n3, n) < min_cos * area2) return LatticeResult::Steep;
    const Vec2 &a = flat[f[0]], &b = flat[f[1]], &c = flat[f[2]];
    const double d = cross(b - a, c - a);
    if (!(d > 0)) return LatticeResult::Steep;
    const double ylo = std::min({a.y, b.y, c.y}), yhi = std::max({a.y, b.y, c.y});
    const double xlo = std::min({a.x, b.x, c.x}), xhi = std::max({a.x, b.x, c.x});
    const int jlo = std::max(-J, int(std::ceil((ylo - tol) / h))), jhi = std::min(J, int(std::floor((yhi + tol) / h)));
    for (int j = jlo; j <= jhi; ++j) {
      const int ilo = std::max(-I, int(std::ceil((xlo - tol) / L - 0.5 * j)));
      const int ihi = std::min(I, int(std::floor((xhi + tol) / L - 0.5 * j)));
      for (int i = ilo; i <= ihi; ++i) {
        const Vec2 q{(i + 0.5 * j) * L, j * h};
        if (dot(q, q) > reach * reach) continue;
        const double l0 = cross(b - q, c - q) / d, l1 = cross(c - q, a - q) / d, l2 = 1 - l0 - l1;
        const double depth = std::min({l0, l1, l2});
        if (depth < -eps) continue;
        LatticePoint& lp = lattice[index(i, j)];
        // Strictly inside two triangles: the projection overlaps itself.
        if (depth > eps && ++lp.interior > 1) return LatticeResult::Overlap;
        if (depth > lp.depth) lp.depth = depth, lp.triangle = t, lp.b[0] = l0, lp.b[1] = l1, lp.b[2] = l2;
      }
    }
  }
  for (LatticePoint& lp : lattice) {
    if (lp.triangle < 0) continue;
    double b0 = std::max(0.0, lp.b[0]), b1 = std::max(0.0, lp.b[1]), b2 = std::max(0.0, lp.b[2]);
    const double s = b0 + b1 + b2;
    const Tri& f = cut.triangles[lp.triangle];
    lp.lifted = (cut.positions[f[0]] * b0 + cut.positions[f[1]] * b1 + cut.positions[f[2]] * b2) / s;
  }

  // Edge neighbours in the cut (local vertex ids: an edge has at most two
  // triangles, oriented oppositely, as cut_patch guarantees).
  const int32_t nt = int32_t(cut.triangles.size());
  std::vector<std::pair<uint64_t, int32_t>>& edges = scratch.edges;
  std::vector<int32_t>& neighbour = scratch.neighbour;
  edges.clear();
  neighbour.assign(3 * std::size_t(nt), -1);
  for (int32_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t u = cut.triangles[t][k], v = cut.triangles[t][(k + 1) % 3];
      edges.push_back({(uint64_t(std::min(u, v)) << 32) | std::max(u, v), 3 * t + k});
    }
  std::sort(edges.begin(), edges.end());
  for (std::size_t e = 1; e < edges.size(); ++e)
    if (edges[e].first == edges[e - 1].first) {
      neighbour[edges[e].second] = edges[e - 1].second / 3;
      neighbour[edges[e - 1].second] = edges[e].second / 3;
    }

  // Does the lattice edge between two located points stay inside the cut?
  // Walk from one end's triangle across cut edges, through the triangles the
  // segment touches, to the other end's: a segment crossing a hole or a gap
  // (a border edge of the cut) cannot get there.
  StampSet& walked = scratch.walked;
  std::vector<int32_t>& queue = scratch.queue;
  auto inside_cut = [&](const LatticePoint& u, const Vec2& qu, const LatticePoint& v, const Vec2& qv) {
    if (u.triangle == v.triangle) return true;
    walked.clear(std::size_t(nt));
    queue.assign(1, u.triangle);
    walked.insert(std::size_t(u.triangle));
    for (std::size_t k = 0; k < queue.size() && k < 512; ++k) {
      const int32_t t = queue[k];
      for (int e = 0; e < 3; ++e) {
        const int32_t w = neighbour[3 * t + e];
        if (w < 0 || !walked.insert(std::size_t(w))) continue;
        const Tri& g = cut.triangles[w];
        if (!touches(flat[g[0]], flat[g[1]], flat[g[2]], qu, qv, 1e-7 * L)) continue;
        if (w == v.triangle) return true;
        queue.push_back(w);
      }
    }
    return false;
  };
  // Lattice edge from (i, j) in direction k (0: +a, 1: +b, 2: +b-a).
  auto edge_ok = [&](int i, int j, int k) {
    LatticePoint& u = lattice[index(i, j)];
    if (u.edge_state[k] == 0) {
      const int i2 = k == 0 ? i + 1 : (k == 1 ? i : i - 1), j2 = k == 0 ? j : j + 1;
      const LatticePoint& v = lattice[index(i2, j2)];
      const bool ok = inside_cut(u, Vec2{(i + 0.5 * j) * L, j * h}, v, Vec2{(i2 + 0.5 * j2) * L, j2 * h});
      u.edge_state[k] = ok ? 1 : 2;
    }
    return u.edge_state[k] == 1;
  };

  // Lattice triangles: 2 per cell (i, j), type 0 = (i,j) (i+1,j) (i,j+1) and
  // type 1 = (i+1,j) (i+1,j+1) (i,j+1), both counter-clockwise.
  auto corners = [&](int c, int (&v)[3]) {
    const int type = c % 2, cell = c / 2, i = cell % width - I, j = cell / width - J;
    if (type == 0) v[0] = index(i, j), v[1] = index(i + 1, j), v[2] = index(i, j + 1);
    else v[0] = index(i + 1, j), v[1] = index(i + 1, j + 1), v[2] = index(i, j + 1);
  };
  const int cells = width * (2 * J + 1);
  // 0 no, 1 within r and inside the cut, 2 kept, 3 holds a border vertex of the cut
  std::vector<uint8_t>& candidate = scratch.candidate;
  candidate.assign(2 * std::size_t(cells), 0);
  // A hole smaller than a lattice triangle crosses none of its edges: what
  // gives it away is its border inside the triangle. Every lattice triangle
  // holding a border vertex of the cut (on its closed area) is left out; the
  // cut's outer border lies beyond the kept triangles (the cut reaches
  // r + L), so this only removes triangles at holes, gaps and creases.
  auto block = [&](int i, int j, int type) {
    if (i >= -I && i < I && j >= -J && j < J) candidate[2 * index(i, j) + type] = 3;
  };
  for (int32_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      if (neighbour[3 * t + k] >= 0) continue;
      for (int end = 0; end < 2; ++end) {
        const Vec2& q = flat[cut.triangles[t][(k + end) % 3]];
        if (dot(q, q) > reach * reach) continue;
        // Lattice coordinates, rounded so that u, v are in [-e, 1 - e).
        const double e = 1e-9, y = q.y / h, x = q.x / L - 0.5 * y;
        const int j = int(std::floor(y + e)), i = int(std::floor(x + e));
        const double u = x - i, v = y - j;
        const int type = u + v < 1 ? 0 : 1;
        block(i, j, type);
        // On a lattice edge or point: the triangles on the other side too.
        if (std::fabs(u + v - 1) < e) block(i, j, 1 - type);
        if (u < e) block(i - 1, j, 1);
        if (v < e) block(i, j - 1, 1);
        if (u < e && v < e) block(i - 1, j - 1, 1), block(i - 1, j, 0), block(i, j - 1, 0);
      }
    }
  int nearest = -1;
  double nearest_d = INFINITY;
  for (int j = -J; j < J; ++j)
    for (int i = -I; i < I; ++i)
      for (int type = 0; type < 2; ++type) {
        const int c = 2 * index(i, j) + type;
        int v[3];
        corners(c, v);
        if (candidate[c] == 3) continue;
        const LatticePoint &a = lattice[v[0]], &b = lattice[v[1]], &d = lattice[v[2]];
        if (a.triangle < 0 || b.triangle < 0 || d.triangle < 0) continue;
        const double dist = norm(closest_point_on_triangle(p, a.lifted, b.lifted, d.lifted).point - p);
        if (dist > r && !(dist < nearest_d)) continue;
        // The three edges: type 0 has (i,j)+a, (i,j)+b, (i+1,j)+(b-a);
        // type 1 has (i+1,j)+b, (i,j+1)+a, (i+1,j)+(b-a).
        const bool ok = type == 0 ? edge_ok(i, j, 0) && edge_ok(i, j, 1) && edge_ok(i + 1, j, 2)
                                  : edge_ok(i + 1, j, 1) && edge_ok(i, j + 1, 0) && edge_ok(i + 1, j, 2);
        if (!ok) continue;
        if (dist <= r) candidate[c] = 1;
        if (dist < nearest_d) nearest_d = dist, nearest = c;
      }
  if (nearest < 0) return LatticeResult::TooFew;
  candidate[nearest] = 1;

  // The edge-connected piece holding the nearest triangle. Neighbours of type
  // 0 at (i,j): type 1 at (i,j), (i-1,j), (i,j-1); of type 1 at (i,j): type 0
  // at (i,j), (i+1,j), (i,j+1).
  queue.assign(1, nearest);
  candidate[nearest] = 2;
  for (std::size_t k = 0; k < queue.size(); ++k) {
    const int c = queue[k], type = c % 2, cell = c / 2, i = cell % width - I, j = cell / width - J;
    const int around[3][2] = {{0, 0}, {type == 0 ? -1 : 1, 0}, {0, type == 0 ? -1 : 1}};
    for (const auto& o : around) {
      const int i2 = i + o[0], j2 = j + o[1];
      if (i2 < -I || i2 >= I || j2 < -J || j2 >= J) continue;
      const int c2 = 2 * index(i2, j2) + (1 - type);
      if (candidate[c2] != 1) continue;
      candidate[c2] = 2;
      queue.push_back(c2);
    }
  }
  const double predicted = M_PI * r * r / (0.25 * std::sqrt(3.0) * L * L);
  if (double(queue.size()) < 0.25 * predicted) return LatticeResult::TooFew;

  // Output in lattice order. Stillness (create_patch's snap): a vertex must
  // be where advection's projection from it lands next frame, on the triangle
  // it picks, or a still scene would not bake identical atlases. A lifted
  // point well inside its fluid triangle (farther than 1e-9 r from its edges)
  // projects to itself, bit for bit (SurfaceQuery::closest returns the query
  // point when it is within rounding of the nearest triangle), on that
  // triangle: every other triangle is farther unless the surface intersects
  // itself there. Near an edge or a vertex the neighbouring triangle may win
  // the tie: one closest-point query with a tiny radius settles it, as the
  // snap does. (The test checks the result is idempotent.)
  auto still = [&](const LatticePoint& lp, Vec3& at, int32_t& triangle) {
    const Tri& f = cut.triangles[lp.triangle];
    const Vec3 &A = cut.positions[f[0]], &B = cut.positions[f[1]], &C = cut.positions[f[2]];
    const double longest = std::sqrt(std::max({norm2(B - A), norm2(C - B), norm2(A - C)}));
    if (lp.depth * norm(cross(B - A, C - A)) > 1e-9 * r * longest) {
      const TrianglePoint q = closest_point_on_triangle(lp.lifted, A, B, C);
      if (within_rounding_of_triangle(lp.lifted, q.point, A, B, C)) {
        at = lp.lifted;
        triangle = cut_triangles[lp.triangle];
        return;
      }
    }
    const ClosestHit hit = surface.closest(lp.lifted, 1e-6 * r);
    at = hit.found ? hit.point : lp.lifted;
    triangle = hit.found ? hit.triangle : cut_triangles[lp.triangle];
  };
  out.positions.clear();
  out.triangles.clear();
  under.clear();
  for (int c = 0; c < 2 * cells; ++c) {
    if (candidate[c] != 2) continue;
    int v[3];
    corners(c, v);
    Tri f;
    for (int k = 0; k < 3; ++k) {
      LatticePoint& lp = lattice[v[k]];
      if (lp.vertex < 0) {
        lp.vertex = int32_t(out.positions.size());
        Vec3 at;
        int32_t triangle;
        still(lp, at, triangle);
        out.positions.push_back(at);
        under.push_back(triangle);
      }
      f[k] = lp.vertex;
    }
    out.triangles.push_back(f);
  }
  // Two kept triangles touching only at a lattice point (around a hole or at
  // the trimmed rim): give each fan its own vertex, as the cut does. The six
  // triangles around (i, j) in counter-clockwise order (sectors from +a):
  // type 0 at (i,j), type 1 at (i-1,j), type 0 at (i-1,j), type 1 at
  // (i-1,j-1), type 0 at (i,j-1), type 1 at (i,j-1); a vertex is
  // non-manifold when its kept triangles make more than one run.
  bool bowtie = false;
  for (int j = -J + 1; j < J && !bowtie; ++j)
    for (int i = -I + 1; i < I && !bowtie; ++i) {
      if (lattice[index(i, j)].vertex < 0) continue;
      const int ring[6] = {2 * index(i, j),         2 * index(i - 1, j) + 1, 2 * index(i - 1, j),
                           2 * index(i - 1, j - 1) + 1, 2 * index(i, j - 1),     2 * index(i, j - 1) + 1};
      int runs = 0;
      for (int k = 0; k < 6; ++k) runs += candidate[ring[k]] == 2 && candidate[ring[(k + 5) % 6]] != 2;
      bowtie = runs > 1;
    }
  if (!bowtie) return LatticeResult::Resampled;
  const std::size_t before = out.positions.size();
  split_nonmanifold_vertices(out);
  for (std::size_t v = before; v < out.positions.size(); ++v) {
    const ClosestHit hit = surface.closest(out.positions[v], 1e-6 * r);
    under.push_back(hit.found ? hit.triangle : -1);
  }
  return LatticeResult::Resampled;
}

}  // namespace lapflow::detail
