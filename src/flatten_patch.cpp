// Least-squares conformal maps (Levy, Petitjean, Ray, Maillot 2002) solved
// directly with Eigen. CGAL's LSCM_parameterizer_3 gives the same map (a test
// checks it) but spends most of its time in set-up and its own CG solver; a
// sparse Cholesky on the (complex, Hermitian) normal equations is several
// times faster on the 100-1000 triangle patches lapflow creates by the thousand.
#include <Eigen/Sparse>

#include <algorithm>
#include <cmath>
#include <complex>

#include "patch_internal.hpp"

namespace lapflow::detail {
namespace {

// Border vertices (on an edge used by one triangle), in vertex order.
std::vector<int> border_vertices(const PatchMesh& m) {
  std::vector<std::pair<uint64_t, int>> edges;
  edges.reserve(m.triangles.size() * 3);
  for (const Tri& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k], b = t[(k + 1) % 3];
      edges.push_back({(uint64_t(std::min(a, b)) << 32) | std::max(a, b), 0});
    }
  std::sort(edges.begin(), edges.end());
  std::vector<uint8_t> on_border(m.positions.size(), 0);
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    if (j - i == 1) {
      on_border[edges[i].first >> 32] = 1;
      on_border[edges[i].first & 0xffffffffu] = 1;
    }
    i = j;
  }
  std::vector<int> out;
  for (int v = 0; v < int(on_border.size()); ++v)
    if (on_border[v]) out.push_back(v);
  return out;
}

int farthest_from(const PatchMesh& m, const std::vector<int>& candidates, const Vec3& p) {
  int best = candidates.front();
  double best_d = -1;
  for (int v : candidates) {
    const double d = norm2(m.positions[v] - p);
    if (d > best_d) best_d = d, best = v;
  }
  return best;
}

}  // namespace

bool lscm_flatten(const PatchMesh& mesh, std::vector<Vec2>& uv, int pin_a, int pin_b, Vec2 uv_a, Vec2 uv_b) {
  const int nv = int(mesh.positions.size());
  if (nv < 3 || mesh.triangles.empty()) return false;
  if (pin_a < 0 || pin_b < 0 || pin_a == pin_b) {
    // Pins far apart make the map least sensitive to where they are.
    std::vector<int> cand = border_vertices(mesh);
    if (cand.size() < 2) {
      cand.clear();
      for (const Tri& t : mesh.triangles) cand.insert(cand.end(), t.begin(), t.end());
      std::sort(cand.begin(), cand.end());
      cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
    }
    pin_a = farthest_from(mesh, cand, mesh.positions[cand.front()]);
    pin_b = farthest_from(mesh, cand, mesh.positions[pin_a]);
    if (pin_a == pin_b) return false;
    uv_a = {0, 0};
    uv_b = {norm(mesh.positions[pin_b] - mesh.positions[pin_a]), 0};
  }

  // Complex form (Levy et al. 2002, section 3.3): z = u + i v per vertex. On
  // a triangle with local coordinates q_j, the Cauchy-Riemann residual of the
  // linear map is sum_j c_j z_j with c_j = i (q_{j+2} - q_{j+1}) / sqrt(2 d)
  // (d twice the area), and its squared modulus is the conformal energy of
  // the triangle. The normal equations M z = b, M = C^H C, are Hermitian with
  // one unknown per free vertex: half the size of the real system, so the
  // ordering and factorization are about 4x and 2x cheaper. M is assembled
  // directly (lower triangle only, which is all SimplicialLDLT reads).
  using Complex = std::complex<double>;
  std::vector<int> index(nv, -1);
  int nf = 0;
  for (int v = 0; v < nv; ++v)
    if (v != pin_a && v != pin_b) index[v] = nf++;
  std::vector<Eigen::Triplet<Complex>> trip;
  trip.reserve(mesh.triangles.size() * 6 + nv);
  Eigen::VectorXcd rhs = Eigen::VectorXcd::Zero(nf);
  const Complex z_a(uv_a.x, uv_a.y), z_b(uv_b.x, uv_b.y);
  int used = 0;
  for (const Tri& t : mesh.triangles) {
    const Vec3 &p0 = mesh.positions[t[0]], &p1 = mesh.positions[t[1]], &p2 = mesh.positions[t[2]];
    const Vec3 e1 = p1 - p0, e2 = p2 - p0;
    const Vec3 n = cross(e1, e2);
    const double d = norm(n);  // twice the area
    const double l1 = norm(e1);
    if (!(d > 1e-300) || !(l1 > 0)) continue;  // degenerate: no conformality to ask for
    ++used;
    const Vec3 X = e1 / l1, Y = cross(n / d, X);
    const Complex q[3] = {{0, 0}, {l1, 0}, {dot(e2, X), dot(e2, Y)}};
    const Complex w(0, 1.0 / std::sqrt(2 * d));
    Complex c[3], fixed = 0;
    for (int j = 0; j < 3; ++j) {
      c[j] = w * (q[(j + 2) % 3] - q[(j + 1) % 3]);
      if (index[t[j]] < 0) fixed += c[j] * (t[j] == pin_a ? z_a : z_b);
    }
    for (int j = 0; j < 3; ++j) {
      const int a = index[t[j]];
      if (a < 0) continue;
      rhs[a] -= std::conj(c[j]) * fixed;
      for (int k = 0; k < 3; ++k) {
        const int b = index[t[k]];
        if (b >= 0 && b <= a) trip.emplace_back(a, b, std::conj(c[j]) * c[k]);
      }
    }
  }
  if (used == 0 || nf == 0) return false;
  // A vertex touched only by degenerate triangles has an empty row; a tiny
  // diagonal keeps the factorization defined without moving anything else.
  double trace = 0;
  for (const auto& e : trip)
    if (e.row() == e.col()) trace += e.value().real();
  const double eps = 1e-14 * (trace > 0 ? trace / nf : 1.0);
  for (int k = 0; k < nf; ++k) trip.emplace_back(k, k, eps);
  Eigen::SparseMatrix<Complex> M(nf, nf);
  M.setFromTriplets(trip.begin(), trip.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<Complex>, Eigen::Lower> solver(M);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::VectorXcd x = solver.solve(rhs);
  if (solver.info() != Eigen::Success || !x.allFinite()) return false;

  uv.assign(nv, Vec2{});
  for (int v = 0; v < nv; ++v)
    if (index[v] >= 0) uv[v] = {x[index[v]].real(), x[index[v]].imag()};
  uv[pin_a] = uv_a;
  uv[pin_b] = uv_b;
  return true;
}

double lscm_energy(const PatchMesh& mesh, const std::vector<Vec2>& uv) {
  double energy = 0;
  for (const Tri& t : mesh.triangles) {
    const Vec3 e1 = mesh.positions[t[1]] - mesh.positions[t[0]], e2 = mesh.positions[t[2]] - mesh.positions[t[0]];
    const Vec3 n = cross(e1, e2);
    const double d = norm(n), l1 = norm(e1);
    if (!(d > 1e-300) || !(l1 > 0)) continue;
    const Vec3 X = e1 / l1, Y = cross(n / d, X);
    const Vec2 q[3] = {{0, 0}, {l1, 0}, {dot(e2, X), dot(e2, Y)}};
    double r1 = 0, r2 = 0;
    for (int j = 0; j < 3; ++j) {
      const Vec2 e = q[(j + 2) % 3] - q[(j + 1) % 3];
      const double gx = -e.y / d, gy = e.x / d;
      r1 += uv[t[j]].x * gx - uv[t[j]].y * gy;
      r2 += uv[t[j]].x * gy + uv[t[j]].y * gx;
    }
    energy += 0.5 * d * (r1 * r1 + r2 * r2);
  }
  return energy;
}

}  // namespace lapflow::detail
