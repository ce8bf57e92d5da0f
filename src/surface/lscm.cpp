// Least-squares conformal maps (Levy, Petitjean, Ray, Maillot 2002) solved
// directly: the one LSCM of lapflow, flattening both patches and atlas charts.
// CGAL's LSCM_parameterizer_3 gives the same map (a test checks it) but spends
// most of its time in set-up and its own CG solver; a sparse Cholesky on the
// (complex, Hermitian) normal equations is several times faster on the
// 100-1000 triangle patches lapflow creates by the thousand. Eigen's
// SimplicialLDLT (lscm_flatten_reference) spends most of its time on such small
// systems in AMD's bookkeeping, triplet sorting and symbolic analysis;
// lscm_flatten builds the matrix on the vertex adjacency, orders it by exact
// minimum degree on a bit matrix (which also yields the factor's pattern) and
// factors it with a short up-looking LDL^H. Same map to rounding; timings in
// docs/patches.md and docs/performance.md.
#include <Eigen/Sparse>

#include <algorithm>
#include <bit>
#include <cmath>
#include <complex>
#include <span>

#include "surface/lscm.hpp"

namespace lapflow::detail {
namespace {

// The arrays a caller hands over, viewed as one mesh.
struct Mesh {
  std::span<const Vec3> positions;
  std::span<const Tri> triangles;
};

// Border vertices (on an edge used by one triangle), in vertex order.
std::vector<int> border_vertices(const Mesh& m) {
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

// Vertex adjacency of a triangle list in CSR form (no duplicates, no self;
// neighbours in order of first appearance), with the vertices on a border
// edge (an edge used by one triangle) and the vertices used by any triangle.
struct VertexAdjacency {
  std::vector<int> offset, neighbour;
  // Per triangle t and corner k, the slot of t[k+1] in t[k]'s list (entry
  // 6t + 2k) and of t[k] in t[k+1]'s list (6t + 2k + 1); -1 for a repeated
  // vertex.
  std::vector<int> triangle_slot;
  std::vector<uint8_t> on_border, used;
};

VertexAdjacency vertex_adjacency(const Mesh& m) {
  const int nv = int(m.positions.size()), nt = int(m.triangles.size());
  VertexAdjacency a;
  a.on_border.assign(nv, 0);
  a.used.assign(nv, 0);
  // Each triangle edge {p, q} lists q under p and p under q (entries kept
  // with their triangle), so an edge used by one triangle leaves a neighbour
  // listed once.
  std::vector<int> start(nv + 1, 0);
  for (const Tri& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      const int p = t[k], q = t[(k + 1) % 3];
      if (q != p) ++start[p + 1], ++start[q + 1];
    }
  for (int v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<int> list(start[nv]), entry(6 * std::size_t(nt), -1), fill(start.begin(), start.end() - 1);
  std::vector<int> self_edges;  // per vertex, edges {p, p} of triangles with a repeated vertex
  for (int f = 0; f < nt; ++f) {
    const Tri& t = m.triangles[f];
    for (int k = 0; k < 3; ++k) {
      const int p = t[k], q = t[(k + 1) % 3];
      a.used[p] = 1;
      if (q == p) {
        if (self_edges.empty()) self_edges.assign(nv, 0);
        ++self_edges[p];
        continue;
      }
      entry[6 * f + 2 * k] = fill[p], list[fill[p]++] = q;
      entry[6 * f + 2 * k + 1] = fill[q], list[fill[q]++] = p;
    }
  }
  // An edge {p, p} used once is a border edge too, for the pins to be those
  // of lscm_flatten_reference.
  for (int v = 0; v < int(self_edges.size()); ++v)
    if (self_edges[v] == 1) a.on_border[v] = 1;
  // Deduplicate each list with a mark per neighbour (no sort): the first
  // entry of u under v makes a slot, later ones point to it and count a use.
  // Written without branches: first or repeated is a coin toss per entry.
  a.offset.assign(nv + 1, 0);
  a.neighbour.resize(list.size());
  std::vector<int> mark(nv, -1), slot_of(nv), uses(list.size()), entry_slot(list.size());
  int slots = 0;
  for (int v = 0; v < nv; ++v) {
    for (int e = start[v]; e < start[v + 1]; ++e) {
      const int u = list[e];
      const bool fresh = mark[u] != v;
      const int slot = fresh ? slots : slot_of[u];
      mark[u] = v, slot_of[u] = slot;
      a.neighbour[slots] = u;  // kept only when fresh (slots <= e: in range)
      uses[slot] = (fresh ? 0 : uses[slot]) + 1;
      entry_slot[e] = slot;
      slots += fresh;
    }
    a.offset[v + 1] = slots;
    bool border = false;
    for (int s = a.offset[v]; s < slots; ++s) border |= uses[s] == 1;
    a.on_border[v] |= border;
  }
  a.neighbour.resize(slots);
  a.triangle_slot.resize(entry.size());
  for (std::size_t i = 0; i < entry.size(); ++i) a.triangle_slot[i] = entry[i] < 0 ? -1 : entry_slot[entry[i]];
  return a;
}

// Beyond this many unknowns the bit-matrix ordering below grows as n^2 and
// Eigen's AMD ordering catches up (docs/performance.md): larger systems go to
// the Eigen solver.
constexpr int kMaxMinimumDegreeSize = 1536;

// Counting set bits is the inner loop of the ordering below; std::popcount
// is a library call unless the target has a popcount instruction, so on x86-64
// builds without one the function is also compiled for it and picked at load
// time (GCC function multi-versioning).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__POPCNT__)
#define LAPFLOW_POPCOUNT_CLONES __attribute__((target_clones("popcnt", "default")))
#else
#define LAPFLOW_POPCOUNT_CLONES
#endif

// A fill-reducing order of the free unknowns and the pattern of the
// Cholesky factor L it gives.
struct Elimination {
  std::vector<int> order;                   // vertex at each position
  std::vector<int> position;                // per vertex, -1 for pins
  std::vector<int> column_count;            // entries below the diagonal per column of L
  std::vector<int> row_start, row_columns;  // columns of each row of L, increasing
};

// Exact minimum degree ordering of the free vertices (index[v] >= 0) of the
// adjacency graph: eliminate a vertex of least degree, join its neighbours
// into a clique, repeat. The elimination graph is kept as one bit row per
// vertex, which for a few hundred unknowns costs a few words per update, far
// less than the quotient-graph bookkeeping of AMD, and gives about the same
// fill on patch meshes (docs/patches.md, "Creation (steps 2-3)"). A vertex's row when it is eliminated is the
// pattern of its column of L, so the factor's pattern comes for free.
// kWords > 0: the bit rows have that many words (known to the compiler, so
// the row updates unroll); 0: as many as nf needs.
template <int kWords>
LAPFLOW_POPCOUNT_CLONES Elimination minimum_degree(const VertexAdjacency& adj, const std::vector<int>& index, int nf) {
  const int words = kWords > 0 ? kWords : (nf + 63) / 64;
  std::vector<uint64_t> bits(std::size_t(nf) * words, 0);
  std::vector<int> vertex(nf), degree(nf, 0);
  for (int v = 0; v < int(index.size()); ++v) {
    const int a = index[v];
    if (a < 0) continue;
    vertex[a] = v;
    uint64_t* row = &bits[std::size_t(a) * words];
    for (int s = adj.offset[v]; s < adj.offset[v + 1]; ++s) {
      const int b = index[adj.neighbour[s]];
      if (b >= 0) row[b >> 6] |= uint64_t(1) << (b & 63), ++degree[a];
    }
  }
  // Degree buckets: circular doubly linked lists, newest first; node nf + d
  // is the head of degree d (no branches on empty lists).
  std::vector<int> next(2 * std::size_t(nf) + 1), prev(2 * std::size_t(nf) + 1);
  for (int h = nf; h <= 2 * nf; ++h) next[h] = prev[h] = h;
  auto insert = [&](int a) {
    const int h = nf + degree[a];
    next[a] = next[h], prev[a] = h;
    prev[next[h]] = a, next[h] = a;
  };
  auto remove = [&](int a) {
    next[prev[a]] = next[a];
    prev[next[a]] = prev[a];
  };
  for (int a = nf - 1; a >= 0; --a) insert(a);
  Elimination e;
  e.column_count.resize(nf);
  std::vector<int> eliminated(nf);                 // free index at each position
  std::vector<std::pair<int, int>> entries;  // (row as free index, column position) of L
  entries.reserve(std::size_t(nf) * 12);
  int min_degree = 0;
  for (int step = 0; step < nf; ++step) {
    while (next[nf + min_degree] == nf + min_degree) ++min_degree;
    const int a = next[nf + min_degree];
    remove(a);
    eliminated[step] = a;
    // a's row now is the pattern of its column of L.
    e.column_count[step] = degree[a];
    const uint64_t* row_a = &bits[std::size_t(a) * words];
    for (int w = 0; w < words; ++w)
      for (uint64_t m = row_a[w]; m; m &= m - 1) {
        const int b = w * 64 + std::countr_zero(m);
        entries.emplace_back(b, step);
        uint64_t* row_b = &bits[std::size_t(b) * words];
        int d = 0;
        for (int x = 0; x < words; ++x) {
          uint64_t r = row_b[x] | row_a[x];
          if (x == a >> 6) r &= ~(uint64_t(1) << (a & 63));
          if (x == b >> 6) r &= ~(uint64_t(1) << (b & 63));
          row_b[x] = r;
          d += std::popcount(r);
        }
        remove(b);
        degree[b] = d;
        insert(b);
        min_degree = std::min(min_degree, d);
      }
  }

  e.order.resize(nf);
  e.position.assign(index.size(), -1);
  std::vector<int> position_of(nf);  // by free index
  for (int k = 0; k < nf; ++k) {
    e.order[k] = vertex[eliminated[k]];
    e.position[e.order[k]] = k;
    position_of[eliminated[k]] = k;
  }
  // Rows of L, columns increasing (entries were made in column order).
  e.row_start.assign(nf + 1, 0);
  for (const auto& [row, column] : entries) ++e.row_start[position_of[row] + 1];
  for (int k = 0; k < nf; ++k) e.row_start[k + 1] += e.row_start[k];
  e.row_columns.resize(entries.size());
  std::vector<int> fill(e.row_start.begin(), e.row_start.end() - 1);
  for (const auto& [row, column] : entries) e.row_columns[fill[position_of[row]]++] = column;
  return e;
}

Elimination minimum_degree(const VertexAdjacency& adj, const std::vector<int>& index, int nf) {
  switch ((nf + 63) / 64) {
    case 1: return minimum_degree<1>(adj, index, nf);
    case 2: return minimum_degree<2>(adj, index, nf);
    case 3: return minimum_degree<3>(adj, index, nf);
    case 4: return minimum_degree<4>(adj, index, nf);
    case 5: return minimum_degree<5>(adj, index, nf);
    case 6: return minimum_degree<6>(adj, index, nf);
    default: return minimum_degree<0>(adj, index, nf);
  }
}

// Sparse L D L^H factorization of a Hermitian matrix (up-looking, after
// Davis's LDL, the algorithm of Eigen's SimplicialLDLT, with the pattern from
// the ordering instead of an elimination tree). Complex numbers are pairs of
// doubles and products are written out: std::complex's product checks for
// infinities on every multiply.
class HermitianLdlt {
 public:
  // The matrix is that of lscm_flatten: diag[v] and off_re/off_im[slot] =
  // M(v, u) per adjacency slot, in the order and pattern of `e`. False when
  // singular (a zero pivot).
  bool factorize(const VertexAdjacency& adj, const Elimination& e, const std::vector<double>& diag,
                 const std::vector<double>& off_re, const std::vector<double>& off_im) {
    const int n = int(e.order.size());
    n_ = n;
    start_.assign(n + 1, 0);
    for (int k = 0; k < n; ++k) start_[k + 1] = start_[k] + e.column_count[k];
    row_.resize(start_[n]);
    lx_.resize(2 * std::size_t(start_[n]));
    d_.resize(n);
    std::vector<double> inv_d(n);
    // Row k of L solves L(0:k, 0:k) D y = A(0:k, k), y_i = D_i conj(L(k, i)).
    // Complex numbers are (re, im) pairs in consecutive doubles.
    std::vector<double> y(2 * std::size_t(n), 0.0);
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (int k = 0; k < n; ++k) {
      const int v = e.order[k];
      for (int s = adj.offset[v]; s < adj.offset[v + 1]; ++s) {
        const int i = e.position[adj.neighbour[s]];
        if (i < 0 || i >= k) continue;
        // A(i, k) = M(u, v) = conj(M(v, u)).
        y[2 * i] = off_re[s];
        y[2 * i + 1] = -off_im[s];
      }
      double d = diag[v];
      for (int c = e.row_start[k]; c < e.row_start[k + 1]; ++c) {
        const int i = e.row_columns[c];
        const double yr = y[2 * i], yi = y[2 * i + 1];
        y[2 * i] = y[2 * i + 1] = 0;
        const int end = fill[i];
        for (int p = start_[i]; p < end; ++p) {
          double* out = &y[2 * row_[p]];
          const double lr = lx_[2 * p], li = lx_[2 * p + 1];
          out[0] -= lr * yr - li * yi;
          out[1] -= lr * yi + li * yr;
        }
        // L(k, i) = conj(y_i) / D_i; D_k -= L(k, i) y_i = |y_i|^2 / D_i.
        const double lr = yr * inv_d[i], li = -yi * inv_d[i];
        d -= lr * yr - li * yi;
        row_[end] = k;
        lx_[2 * end] = lr;
        lx_[2 * end + 1] = li;
        fill[i] = end + 1;
      }
      if (d == 0) return false;
      d_[k] = d;
      inv_d[k] = 1 / d;
    }
    return true;
  }

  // Solves in place, right-hand side and answer in factorization order.
  void solve(std::vector<double>& x_re, std::vector<double>& x_im) const {
    for (int j = 0; j < n_; ++j) {
      const double xr = x_re[j], xi = x_im[j];
      for (int p = start_[j]; p < start_[j + 1]; ++p) {
        const double lr = lx_[2 * p], li = lx_[2 * p + 1];
        x_re[row_[p]] -= lr * xr - li * xi;
        x_im[row_[p]] -= lr * xi + li * xr;
      }
    }
    for (int j = 0; j < n_; ++j) x_re[j] /= d_[j], x_im[j] /= d_[j];
    for (int j = n_ - 1; j >= 0; --j) {
      double xr = x_re[j], xi = x_im[j];
      for (int p = start_[j]; p < start_[j + 1]; ++p) {
        // x_j -= conj(L(r, j)) x_r
        const double lr = lx_[2 * p], li = lx_[2 * p + 1];
        const double br = x_re[row_[p]], bi = x_im[row_[p]];
        xr -= lr * br + li * bi;
        xi -= lr * bi - li * br;
      }
      x_re[j] = xr, x_im[j] = xi;
    }
  }

 private:
  int n_ = 0;
  std::vector<int> start_, row_;
  std::vector<double> lx_, d_;
};

int farthest_from(const Mesh& m, const std::vector<int>& candidates, const Vec3& p) {
  int best = candidates.front();
  double best_d = -1;
  for (int v : candidates) {
    const double d = norm2(m.positions[v] - p);
    if (d > best_d) best_d = d, best = v;
  }
  return best;
}

// A triangle in its own plane: q[0] = 0, q[1] on +x, q[2] above; d = twice
// its area. False (nothing to ask of the map) when it is degenerate. Every
// LSCM path uses this one computation: on a triangle whose area is rounding
// noise, q[2].y = dot(e2, Y) is not d / l1, and the map depends on which one
// is used.
bool local_frame(const Mesh& mesh, const Tri& t, Vec2 q[3], double& d) {
  const Vec3 e1 = mesh.positions[t[1]] - mesh.positions[t[0]], e2 = mesh.positions[t[2]] - mesh.positions[t[0]];
  const Vec3 n = cross(e1, e2);
  d = norm(n);
  const double l1 = norm(e1);
  if (!(d > 1e-300) || !(l1 > 0)) return false;
  const Vec3 X = e1 / l1, Y = cross(n / d, X);
  q[0] = {0, 0};
  q[1] = {l1, 0};
  q[2] = {dot(e2, X), dot(e2, Y)};
  return true;
}

}  // namespace

bool lscm_flatten(std::span<const Vec3> positions, std::span<const Tri> triangles, std::vector<Vec2>& uv, int pin_a,
                  int pin_b, Vec2 uv_a, Vec2 uv_b) {
  const Mesh mesh{positions, triangles};
  const int nv = int(mesh.positions.size());
  if (nv < 3 || mesh.triangles.empty()) return false;
  const VertexAdjacency adj = vertex_adjacency(mesh);
  if (pin_a < 0 || pin_b < 0 || pin_a == pin_b) {
    // Pins far apart make the map least sensitive to where they are.
    std::vector<int> cand;
    for (int v = 0; v < nv; ++v)
      if (adj.on_border[v]) cand.push_back(v);
    if (cand.size() < 2) {
      cand.clear();
      for (int v = 0; v < nv; ++v)
        if (adj.used[v]) cand.push_back(v);
    }
    pin_a = farthest_from(mesh, cand, mesh.positions[cand.front()]);
    pin_b = farthest_from(mesh, cand, mesh.positions[pin_a]);
    if (pin_a == pin_b) return false;
    uv_a = {0, 0};
    uv_b = {norm(mesh.positions[pin_b] - mesh.positions[pin_a]), 0};
  }
  std::vector<int> index(nv, -1);
  int nf = 0;
  for (int v = 0; v < nv; ++v)
    if (v != pin_a && v != pin_b) index[v] = nf++;
  if (nf > kMaxMinimumDegreeSize) return lscm_flatten_reference(positions, triangles, uv, pin_a, pin_b, uv_a, uv_b);

  // Complex form (Levy et al. 2002, section 3.3), as in lscm_flatten_reference:
  // M z = b with M = C^H C Hermitian, one unknown per free vertex. M(v, u) is
  // accumulated on the adjacency slot of u in v's list, in triangle order as
  // the reference does. Complex numbers are written out as real pairs here and
  // in HermitianLdlt: std::complex's product checks for infinities on each
  // multiply, which made it the costliest part of the assembly.
  std::vector<double> off_re(adj.neighbour.size(), 0.0), off_im(adj.neighbour.size(), 0.0);
  std::vector<double> diag(nv, 0.0), rhs_re(nv, 0.0), rhs_im(nv, 0.0);
  int used = 0;
  for (const Tri& t : mesh.triangles) {
    Vec2 q[3];
    double d;  // twice the area
    if (!local_frame(mesh, t, q, d)) continue;  // degenerate: no conformality to ask for
    ++used;
    const double w = 1.0 / std::sqrt(2 * d);
    // c_j = i w (q_{j+2} - q_{j+1}); fixed = sum over pinned corners of c_j z_j.
    double c_re[3], c_im[3], fixed_re = 0, fixed_im = 0;
    for (int j = 0; j < 3; ++j) {
      const Vec2 e = q[(j + 2) % 3] - q[(j + 1) % 3];
      c_re[j] = -w * e.y, c_im[j] = w * e.x;
      if (index[t[j]] < 0) {
        const Vec2 z = t[j] == pin_a ? uv_a : uv_b;
        fixed_re += c_re[j] * z.x - c_im[j] * z.y;
        fixed_im += c_re[j] * z.y + c_im[j] * z.x;
      }
    }
    const int* slot = &adj.triangle_slot[6 * (&t - mesh.triangles.data())];
    for (int j = 0; j < 3; ++j) {
      const int a = t[j];
      if (index[a] < 0) continue;
      // rhs -= conj(c_j) fixed, M(a, a) += |c_j|^2, M(a, b) += conj(c_j) c_k
      // for the next corner k (slot 2j) and the previous one (slot 2k + 1).
      rhs_re[a] -= c_re[j] * fixed_re + c_im[j] * fixed_im;
      rhs_im[a] -= c_re[j] * fixed_im - c_im[j] * fixed_re;
      diag[a] += c_re[j] * c_re[j] + c_im[j] * c_im[j];
      const int next = (j + 1) % 3, prev = (j + 2) % 3;
      const int s_next = slot[2 * j], s_prev = slot[2 * prev + 1];
      if (index[t[next]] >= 0) {
        off_re[s_next] += c_re[j] * c_re[next] + c_im[j] * c_im[next];
        off_im[s_next] += c_re[j] * c_im[next] - c_im[j] * c_re[next];
      }
      if (index[t[prev]] >= 0) {
        off_re[s_prev] += c_re[j] * c_re[prev] + c_im[j] * c_im[prev];
        off_im[s_prev] += c_re[j] * c_im[prev] - c_im[j] * c_re[prev];
      }
    }
  }
  if (used == 0 || nf == 0) return false;
  // A vertex touched only by degenerate triangles has an empty row; a tiny
  // diagonal keeps the factorization defined without moving anything else.
  double trace = 0;
  for (int v = 0; v < nv; ++v) trace += diag[v];
  const double eps = 1e-14 * (trace > 0 ? trace / nf : 1.0);
  for (int v = 0; v < nv; ++v) diag[v] += eps;

  const Elimination elim = minimum_degree(adj, index, nf);
  const std::vector<int>& order = elim.order;
  const std::vector<int>& position = elim.position;
  HermitianLdlt ldlt;
  if (!ldlt.factorize(adj, elim, diag, off_re, off_im)) return false;
  std::vector<double> x_re(nf), x_im(nf);
  for (int k = 0; k < nf; ++k) x_re[k] = rhs_re[order[k]], x_im[k] = rhs_im[order[k]];
  ldlt.solve(x_re, x_im);
  for (int k = 0; k < nf; ++k)
    if (!std::isfinite(x_re[k]) || !std::isfinite(x_im[k])) return false;

  uv.assign(nv, Vec2{});
  for (int v = 0; v < nv; ++v)
    if (index[v] >= 0) uv[v] = {x_re[position[v]], x_im[position[v]]};
  uv[pin_a] = uv_a;
  uv[pin_b] = uv_b;
  return true;
}

bool lscm_flatten_reference(std::span<const Vec3> positions, std::span<const Tri> triangles, std::vector<Vec2>& uv,
                            int pin_a, int pin_b, Vec2 uv_a, Vec2 uv_b) {
  const Mesh mesh{positions, triangles};
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
  // ordering and factorization are cheaper (docs/performance.md, "Figures
  // from code comments"). M is assembled
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
    Vec2 f[3];
    double d;  // twice the area
    if (!local_frame(mesh, t, f, d)) continue;  // degenerate: no conformality to ask for
    ++used;
    const Complex q[3] = {{f[0].x, f[0].y}, {f[1].x, f[1].y}, {f[2].x, f[2].y}};
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

double lscm_energy(std::span<const Vec3> positions, std::span<const Tri> triangles, const std::vector<Vec2>& uv) {
  const Mesh mesh{positions, triangles};
  double energy = 0;
  for (const Tri& t : mesh.triangles) {
    Vec2 q[3];
    double d;
    if (!local_frame(mesh, t, q, d)) continue;
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
