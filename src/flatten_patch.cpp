// Least-squares conformal maps (Levy, Petitjean, Ray, Maillot 2002) solved
// directly with Eigen. CGAL's LSCM_parameterizer_3 gives the same map (a test
// checks it) but spends most of its time in set-up and its own CG solver; a
// sparse Cholesky on the normal equations is several times faster on the
// 100-1000 triangle patches lapflow creates by the thousand.
#include <Eigen/Sparse>

#include <algorithm>
#include <cmath>

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

  // Unknowns: (u, v) of every free vertex.
  std::vector<int> index(nv, -1);
  int nf = 0;
  for (int v = 0; v < nv; ++v)
    if (v != pin_a && v != pin_b) index[v] = nf++;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(mesh.triangles.size() * 12);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(2 * mesh.triangles.size());
  int row = 0;
  for (const Tri& t : mesh.triangles) {
    const Vec3 &p0 = mesh.positions[t[0]], &p1 = mesh.positions[t[1]], &p2 = mesh.positions[t[2]];
    const Vec3 e1 = p1 - p0, e2 = p2 - p0;
    const Vec3 n = cross(e1, e2);
    const double d = norm(n);  // twice the area
    const double l1 = norm(e1);
    if (!(d > 1e-300) || !(l1 > 0)) continue;  // degenerate: no conformality to ask for
    const Vec3 X = e1 / l1, Y = cross(n / d, X);
    const Vec2 q[3] = {{0, 0}, {l1, 0}, {dot(e2, X), dot(e2, Y)}};
    // Cauchy-Riemann residuals of the linear map on this triangle, weighted
    // so that their squares sum to the conformal energy (area * |residual|^2).
    const double w = 1.0 / std::sqrt(2 * d);
    for (int j = 0; j < 3; ++j) {
      const Vec2 e = q[(j + 2) % 3] - q[(j + 1) % 3];
      const double gx = -e.y * w, gy = e.x * w;  // gradient of the hat function, times d * w
      const int v = t[j];
      const double cu[2] = {gx, gy}, cv[2] = {-gy, gx};
      for (int r = 0; r < 2; ++r) {
        if (index[v] >= 0) {
          trip.emplace_back(row + r, 2 * index[v], cu[r]);
          trip.emplace_back(row + r, 2 * index[v] + 1, cv[r]);
        } else {
          const Vec2 fixed = v == pin_a ? uv_a : uv_b;
          rhs[row + r] -= cu[r] * fixed.x + cv[r] * fixed.y;
        }
      }
    }
    row += 2;
  }
  if (row == 0) return false;
  Eigen::SparseMatrix<double> A(row, 2 * nf);
  A.setFromTriplets(trip.begin(), trip.end());
  Eigen::SparseMatrix<double> AtA = A.transpose() * A;
  const Eigen::VectorXd Atb = A.transpose() * rhs.head(row);
  // A vertex touched only by degenerate triangles has an empty row; a tiny
  // diagonal keeps the factorization defined without moving anything else.
  double trace = 0;
  for (int k = 0; k < AtA.outerSize(); ++k) trace += AtA.coeff(k, k);
  const double eps = 1e-14 * (trace > 0 ? trace / AtA.rows() : 1.0);
  for (int k = 0; k < AtA.rows(); ++k) AtA.coeffRef(k, k) += eps;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(AtA);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::VectorXd x = solver.solve(Atb);
  if (solver.info() != Eigen::Success || !x.allFinite()) return false;

  uv.assign(nv, Vec2{});
  for (int v = 0; v < nv; ++v) {
    if (index[v] >= 0) uv[v] = {x[2 * index[v]], x[2 * index[v] + 1]};
  }
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
