// Isotropic remeshing of a new patch on plain arrays: the same algorithm as
// CGAL's isotropic_remeshing (Botsch & Kobbelt 2004: split edges longer than
// 4/3 L, collapse edges shorter than 4/5 L, flip toward valence 6 (4 on the
// border), tangential relaxation) specialised for what patch creation hands
// it: a small oriented manifold disk (possibly with holes) of a few hundred
// triangles. Projection is left to the caller (the Embree snap onto the
// fluid). Border edges are split and collapsed along the border and border
// vertices relax along it, as the CGAL call in cgal_patch.cpp does.
//
// Why not CGAL here: on ~300-triangle patches CGAL spends most of its time in
// Surface_mesh bookkeeping, boost bimaps and per-call property maps (profile in
// docs/patches.md). This is a corner table (three halfedges per triangle,
// halfedge h in face h / 3, `origin_[h]` and `twin_[h]`), faces marked dead on
// collapse and compacted once at the end, with scratch arrays reused per
// thread. Every pass walks edges in index order (collapses in order of length,
// ties by index), so the result depends only on the input.
#include <algorithm>
#include <cmath>
#include <functional>

#include "lapflow/core/stamp_set.hpp"
#include "patches/internal.hpp"

namespace lapflow::detail {
namespace {

inline int next_he(int h) { return h % 3 == 2 ? h - 2 : h + 1; }
inline int prev_he(int h) { return h % 3 == 0 ? h + 2 : h - 1; }

// CGAL's test for flipping regardless of valence: a needle (longest over
// shortest edge above 4) or a cap (an angle above 160 degrees).
bool badly_shaped(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double l0 = norm2(b - a), l1 = norm2(c - b), l2 = norm2(a - c);
  const double lo = std::min({l0, l1, l2}), hi = std::max({l0, l1, l2});
  if (hi > 16 * lo) return true;
  // A cap's wide angle faces the longest edge and is obtuse (most triangles
  // stop here, with no square root).
  const double rest = l0 + l1 + l2 - hi;
  if (hi <= rest) return false;
  const double cos160 = std::cos(160.0 / 180 * M_PI);
  const double prod = (l0 + l1 + l2 - hi - lo) * lo;  // squared lengths of the two shorter edges, multiplied
  return rest - hi < 2 * cos160 * std::sqrt(prod);
}

class IsotropicRemesher {
 public:
  bool build(const PatchMesh& m);
  void split_long_edges(double high2);
  void collapse_short_edges(double low2, double high2);
  void flip_for_valence();
  void relax();
  bool extract(PatchMesh& out) const;

 private:
  int to(int h) const { return origin_[next_he(h)]; }
  // Outgoing halfedges of v in order: for a border vertex, starting with the
  // border halfedge leaving v and ending with the one whose previous
  // halfedge (entering v) is on the border.
  void ring(int v, std::vector<int>& out) const;
  // Neighbour vertices of v from its ring (plus the far end of the incoming
  // border halfedge for a border vertex).
  void neighbours(const std::vector<int>& ring, std::vector<int>& out) const {
    out.clear();
    for (int h : ring) out.push_back(to(h));
    if (!ring.empty() && twin_[prev_he(ring.back())] < 0) out.push_back(origin_[prev_he(ring.back())]);
  }
  Vec3 face_normal(int f) const {  // length: twice the area
    const Vec3& a = pos_[origin_[3 * f]];
    return cross(pos_[origin_[3 * f + 1]] - a, pos_[origin_[3 * f + 2]] - a);
  }
  Vec3 ring_normal(const std::vector<int>& ring) const {
    Vec3 n{};
    for (int h : ring) n = n + face_normal(h / 3);
    return n;
  }
  // Whether an edge joins u and w (walks u's fan without storing it).
  bool joined(int u, int w) const {
    const int start = out_he_[u];
    int h = start;
    do {
      if (to(h) == w || origin_[prev_he(h)] == w) return true;
      h = twin_[prev_he(h)];
    } while (h >= 0 && h != start);
    if (h >= 0) return false;  // went all the way round
    for (h = start; twin_[h] >= 0;) {  // the rest of a border fan
      h = next_he(twin_[h]);
      if (to(h) == w || origin_[prev_he(h)] == w) return true;
    }
    return false;
  }
  void split(int h, double t);  // new vertex at origin + t (target - origin)
  bool collapse_allowed(int h, const Vec3& q, double high2);
  // Requires ring_a_ to hold the ring of origin(h) (collapse_allowed leaves it there).
  void collapse(int h, const Vec3& q);
  // Border neighbours of border vertex v from its ring: u -> v -> w along the border.
  void border_neighbours(const std::vector<int>& ring, int& u, int& w) const {
    w = to(ring.front());
    u = origin_[prev_he(ring.back())];
  }
  double border_turn_cos(int v);  // cos of the border's turn at v (1 = straight)

  std::vector<Vec3> pos_;
  std::vector<int> out_he_;      // one outgoing halfedge per vertex (-1: dead or isolated)
  std::vector<uint8_t> border_;  // vertex on the patch border
  std::vector<int> origin_;      // per halfedge; -1 when its face is dead
  std::vector<int> twin_;        // per halfedge; -1 on the border
  // Scratch.
  std::vector<int> ring_a_, ring_b_, ring_c_, nb_a_, nb_b_, valence_;
  StampSet around_a_;  // nb_a_, for the link condition
  std::vector<std::pair<double, int>> queue_;
};

void IsotropicRemesher::ring(int v, std::vector<int>& out) const {
  out.clear();
  const int start = out_he_[v];
  if (start < 0) return;
  int h = start;
  // Rewind to the border halfedge leaving v (only a border vertex has one).
  if (border_[v])
    while (twin_[h] >= 0) h = next_he(twin_[h]);
  const int first = h;
  for (;;) {
    out.push_back(h);
    const int t = twin_[prev_he(h)];
    if (t < 0 || t == first) break;
    h = t;
  }
}

bool IsotropicRemesher::build(const PatchMesh& m) {
  const int nv = int(m.positions.size()), nt = int(m.triangles.size());
  pos_.assign(m.positions.begin(), m.positions.end());
  origin_.resize(3 * std::size_t(nt));
  twin_.assign(3 * std::size_t(nt), -1);
  out_he_.assign(nv, -1);
  border_.assign(nv, 0);
  // Twins through the outgoing halfedges of each vertex (counting sort by
  // origin): the twin of a -> b is the halfedge b -> a.
  valence_.assign(nv + 1, 0);
  for (int t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = m.triangles[t][k], b = m.triangles[t][(k + 1) % 3];
      if (a < 0 || a >= nv || b < 0 || b >= nv || a == b) return false;
      origin_[3 * t + k] = a;
      out_he_[a] = 3 * t + k;
      ++valence_[a + 1];
    }
  for (int v = 0; v < nv; ++v) valence_[v + 1] += valence_[v];
  nb_a_.resize(3 * std::size_t(nt));  // halfedges by origin
  nb_b_.assign(valence_.begin(), valence_.end() - 1);
  for (int h = 0; h < 3 * nt; ++h) nb_a_[nb_b_[origin_[h]]++] = h;
  for (int h = 0; h < 3 * nt; ++h) {
    const int a = origin_[h], b = to(h);
    int found = -1, back = 0, forth = 0;
    for (int i = valence_[b]; i < valence_[b + 1]; ++i)
      if (to(nb_a_[i]) == a) found = nb_a_[i], ++back;
    for (int i = valence_[a]; i < valence_[a + 1]; ++i) forth += to(nb_a_[i]) == b;
    // One triangle each way at most: a -> b twice is an edge with two
    // triangles of the same orientation (or more than two triangles).
    if (forth != 1 || back > 1) return false;
    if (found >= 0) {
      twin_[h] = found;
    } else {
      border_[a] = border_[b] = 1;
    }
  }
  // Every vertex must be one fan (split_nonmanifold_vertices did that): the
  // ring from its stored halfedge must hold all its outgoing halfedges.
  valence_.assign(nv, 0);
  for (int h = 0; h < 3 * nt; ++h) ++valence_[origin_[h]];
  for (int v = 0; v < nv; ++v) {
    if (out_he_[v] < 0) continue;
    ring(v, ring_a_);
    if (int(ring_a_.size()) != valence_[v]) return false;
    // The ring ends on the border exactly when the vertex is on it.
    if ((twin_[ring_a_.front()] < 0) != bool(border_[v])) return false;
  }
  return true;
}

// Splits edge h at fraction t into two (four) triangles; the parts of the
// edge keep indices h and twin(h) for the part next to their origin.
void IsotropicRemesher::split(int h, double t) {
  const int hn = next_he(h), hp = prev_he(h), o = twin_[h];
  const int a = origin_[h], b = origin_[hn], c = origin_[hp];
  const int m = int(pos_.size());
  pos_.push_back(pos_[a] + (pos_[b] - pos_[a]) * t);
  border_.push_back(o < 0);
  // Face (a, b, c) becomes (a, m, c) and (m, b, c).
  const int F = int(origin_.size());
  origin_.insert(origin_.end(), {m, b, c});
  twin_.insert(twin_.end(), {-1, -1, -1});
  const int x = twin_[hn];
  origin_[hn] = m;
  twin_[F + 1] = x;
  if (x >= 0) twin_[x] = F + 1;
  twin_[hn] = F + 2, twin_[F + 2] = hn;
  out_he_[b] = F + 1;
  out_he_.push_back(F);
  if (o >= 0) {
    // Face (b, a, d) becomes (b, m, d) and (m, a, d).
    const int on = next_he(o), op = prev_he(o), d = origin_[op];
    const int G = int(origin_.size());
    origin_.insert(origin_.end(), {m, a, d});
    twin_.insert(twin_.end(), {-1, -1, -1});
    const int y = twin_[on];
    origin_[on] = m;
    twin_[G + 1] = y;
    if (y >= 0) twin_[y] = G + 1;
    twin_[on] = G + 2, twin_[G + 2] = on;
    out_he_[a] = G + 1;
    twin_[h] = G, twin_[G] = h;
    twin_[o] = F, twin_[F] = o;
  } else {
    out_he_[a] = h;
  }
}

void IsotropicRemesher::split_long_edges(double high2) {
  // Longest first, as CGAL does: the new edges of a split (halves and the
  // joins to the opposite vertices) are then never longer than the edge
  // split, so the process ends even on slivers (splitting in index order
  // need not: the join to a sliver's far vertex can stay long forever).
  // The heap holds (squared length, halfedge); an entry whose edge changed
  // since is re-queued with its current length.
  queue_.clear();
  auto push = [&](int h) {
    const double l2 = norm2(pos_[to(h)] - pos_[origin_[h]]);
    if (l2 > high2) {
      queue_.push_back({l2, h});
      std::push_heap(queue_.begin(), queue_.end());
    }
  };
  for (int h = 0; h < int(origin_.size()); ++h)
    if (origin_[h] >= 0 && (twin_[h] < 0 || twin_[h] > h)) push(h);
  while (!queue_.empty()) {
    std::pop_heap(queue_.begin(), queue_.end());
    const auto [l2, h] = queue_.back();
    queue_.pop_back();
    if (norm2(pos_[to(h)] - pos_[origin_[h]]) != l2) {
      push(h);
      continue;
    }
    // In halves, as CGAL does. (Splitting into k ~ length / L equal pieces
    // instead saves the collapses that undo short halves, but leaves patches
    // with far fewer triangles than CGAL's: a different mesh density, so not
    // done; docs/patches.md, "The array remesher".)
    const int o = twin_[h], F = int(origin_.size());
    split(h, 0.5);
    push(h);           // a -> m
    push(F + 1);       // b -> c, moved
    push(F + 2);       // c -> m
    if (o >= 0) {
      push(o);         // b -> m
      push(F + 4);     // a -> d, moved
      push(F + 5);     // d -> m
    }
  }
}

double IsotropicRemesher::border_turn_cos(int v) {
  ring(v, ring_c_);
  int u, w;
  border_neighbours(ring_c_, u, w);
  const Vec3 d0 = pos_[v] - pos_[u], d1 = pos_[w] - pos_[v];
  const double l = norm(d0) * norm(d1);
  return l > 0 ? dot(d0, d1) / l : -1;
}

// Topology and geometry checks for collapsing halfedge h (origin a removed,
// its edges moved to b, b placed at q): link condition, no ear left
// dangling, no face flipped or made degenerate, no edge longer than high.
bool IsotropicRemesher::collapse_allowed(int h, const Vec3& q, double high2) {
  const int o = twin_[h], a = origin_[h], b = to(h);
  const int f = h / 3, g = o >= 0 ? o / 3 : -1;
  if (o >= 0 && border_[a] && border_[b]) return false;  // would pinch the patch
  if (twin_[next_he(h)] < 0 && twin_[prev_he(h)] < 0) return false;
  if (o >= 0 && twin_[next_he(o)] < 0 && twin_[prev_he(o)] < 0) return false;
  ring(a, ring_a_);
  ring(b, ring_b_);
  neighbours(ring_a_, nb_a_);
  neighbours(ring_b_, nb_b_);
  // Only the edges and faces of an end that moves change (q is b's place
  // inside the patch, a's or b's along the border).
  const bool a_moves = !(q == pos_[a]), b_moves = !(q == pos_[b]);
  if (a_moves)
    for (int v : nb_a_)
      if (v != b && norm2(pos_[v] - q) > high2) return false;
  if (b_moves)
    for (int v : nb_b_)
      if (v != a && norm2(pos_[v] - q) > high2) return false;
  // Link condition: a and b share exactly the opposite vertices of their edge.
  around_a_.clear(pos_.size());
  for (int v : nb_a_) around_a_.insert(std::size_t(v));
  int shared = 0;
  for (int v : nb_b_) shared += around_a_.contains(std::size_t(v));
  if (shared != (o >= 0 ? 2 : 1)) return false;
  // Faces that survive keep their orientation and some area.
  for (const std::vector<int>* r : {&ring_a_, &ring_b_}) {
    if (!(r == &ring_a_ ? a_moves : b_moves)) continue;
    const Vec3 reference = ring_normal(*r);
    for (int e : *r) {
      const int face = e / 3;
      if (face == f || face == g) continue;
      const Vec3 before = face_normal(face);
      const Vec3& p1 = pos_[to(e)];
      const Vec3& p2 = pos_[origin_[prev_he(e)]];
      const Vec3 after = cross(p1 - q, p2 - q);
      const double scale2 = std::max(norm2(p1 - q), norm2(p2 - q));
      if (!(norm2(after) > 1e-12 * scale2 * scale2)) return false;
      if (!(dot(after, reference) > 0) || dot(after, before) < 0) return false;
    }
  }
  return true;
}

void IsotropicRemesher::collapse(int h, const Vec3& q) {
  const int hn = next_he(h), hp = prev_he(h), o = twin_[h];
  const int a = origin_[h], b = origin_[hn], c = origin_[hp];
  for (int e : ring_a_) origin_[e] = b;
  const int x = twin_[hn], y = twin_[hp];  // c -> b and (now) b -> c
  if (x >= 0) twin_[x] = y;
  if (y >= 0) twin_[y] = x;
  out_he_[c] = x >= 0 ? x : next_he(y);
  out_he_[b] = y >= 0 ? y : next_he(x);
  if (o >= 0) {
    const int on = next_he(o), op = prev_he(o), d = origin_[op];
    const int x2 = twin_[on], y2 = twin_[op];  // d -> b and b -> d
    if (x2 >= 0) twin_[x2] = y2;
    if (y2 >= 0) twin_[y2] = x2;
    out_he_[d] = x2 >= 0 ? x2 : next_he(y2);
    for (int k = 0; k < 3; ++k) origin_[3 * (o / 3) + k] = -1, twin_[3 * (o / 3) + k] = -1;
  }
  for (int k = 0; k < 3; ++k) origin_[3 * (h / 3) + k] = -1, twin_[3 * (h / 3) + k] = -1;
  pos_[b] = q;
  border_[b] = border_[b] || border_[a];
  out_he_[a] = -1;
}

void IsotropicRemesher::collapse_short_edges(double low2, double high2) {
  // Shortest first (ties by index), as CGAL does: a min-heap of (squared
  // length, halfedge); after a collapse the short edges around the kept
  // vertex are queued (again). An edge whose collapse is refused is not
  // tried again unless a later collapse next to it queues it anew.
  queue_.clear();
  const auto later = std::greater<std::pair<double, int>>();
  auto push = [&](int h) {
    const double l2 = norm2(pos_[to(h)] - pos_[origin_[h]]);
    if (l2 < low2) {
      queue_.push_back({l2, h});
      std::push_heap(queue_.begin(), queue_.end(), later);
    }
  };
  for (int h = 0; h < int(origin_.size()); ++h)
    if (origin_[h] >= 0 && (twin_[h] < 0 || twin_[h] > h)) push(h);
  while (!queue_.empty()) {
    std::pop_heap(queue_.begin(), queue_.end(), later);
    const auto [l2, h0] = queue_.back();
    queue_.pop_back();
    if (origin_[h0] < 0) continue;  // face gone
    if (norm2(pos_[to(h0)] - pos_[origin_[h0]]) != l2) {
      push(h0);  // moved since: queued again if still short
      continue;
    }
    const int a = origin_[h0], b = to(h0);
    const int o = twin_[h0];
    // A border vertex stays where it is (the patch keeps its outline). A
    // border edge has no twin to collapse the other way, but the collapse
    // of halfedge h0 with q = pos[a] is the collapse of b into a (index b
    // survives at a's place); the straighter end of the border goes first.
    bool done = false;
    if (o < 0) {
      const bool a_straighter = border_turn_cos(a) >= border_turn_cos(b);
      const Vec3 keep_first = a_straighter ? pos_[b] : pos_[a], keep_second = a_straighter ? pos_[a] : pos_[b];
      for (const Vec3& q : {keep_first, keep_second})
        if (collapse_allowed(h0, q, high2)) {
          collapse(h0, q);
          done = true;
          break;
        }
    } else {
      // As CGAL: the kept end stays where it is, so only the removed end's
      // edges change length; a border end is never the removed one.
      const int first = border_[a] && !border_[b] ? o : h0;
      const int second = border_[a] != border_[b] ? -1 : o;
      for (int e : {first, second})
        if (e >= 0 && collapse_allowed(e, pos_[to(e)], high2)) {
          collapse(e, pos_[to(e)]);
          done = true;
          break;
        }
    }
    if (done) {
      // The surviving vertex: b, or a's index when h0 went the other way.
      const int kept = out_he_[b] >= 0 ? b : a;
      ring(kept, ring_c_);
      for (int e : ring_c_) push(e);
      if (border_[kept]) push(prev_he(ring_c_.back()));  // the incoming border edge
    }
  }
}

void IsotropicRemesher::flip_for_valence() {
  const int nv = int(pos_.size());
  // Valence: outgoing halfedges, plus the incoming border one on the border.
  valence_.assign(nv, 0);
  for (int h = 0; h < int(origin_.size()); ++h)
    if (origin_[h] >= 0) ++valence_[origin_[h]];
  for (int v = 0; v < nv; ++v) valence_[v] += border_[v];
  auto target = [&](int v) { return border_[v] ? 4 : 6; };
  for (int h = 0; h < int(origin_.size()); ++h) {
    const int o = twin_[h];
    if (origin_[h] < 0 || o < h) continue;  // dead, border, or seen from its twin
    const int hn = next_he(h), hp = prev_he(h), on = next_he(o), op = prev_he(o);
    const int a = origin_[h], b = origin_[hn], c = origin_[hp], d = origin_[op];
    if (c == d) continue;
    const int va = valence_[a], vb = valence_[b], vc = valence_[c], vd = valence_[d];
    if (va - 1 < (border_[a] ? 2 : 3) || vb - 1 < (border_[b] ? 2 : 3)) continue;
    const int before = std::abs(va - target(a)) + std::abs(vb - target(b)) + std::abs(vc - target(c)) +
                       std::abs(vd - target(d));
    const int after = std::abs(va - 1 - target(a)) + std::abs(vb - 1 - target(b)) + std::abs(vc + 1 - target(c)) +
                      std::abs(vd + 1 - target(d));
    // CGAL's rules: flip toward the valence targets, or regardless of
    // valence when either triangle is a needle (longest / shortest edge > 4)
    // or a cap (an angle over 160 degrees); never make an "axe cut" (the new
    // diagonal must give the pair of triangles whose area-weighted normals
    // agree at least as well).
    const Vec3 &pa = pos_[a], &pb = pos_[b], &pc = pos_[c], &pd = pos_[d];
    if (after >= before && !badly_shaped(pa, pb, pc) && !badly_shaped(pb, pa, pd)) continue;
    const Vec3 nf = cross(pb - pa, pc - pa), ng = cross(pa - pb, pd - pb);  // current pair
    const Vec3 n1 = cross(pa - pc, pd - pc), n2 = cross(pb - pd, pc - pd);  // (c, a, d), (d, b, c)
    if (dot(nf, ng) > dot(n1, n2)) continue;
    if (joined(c, d)) continue;  // the new edge exists already
    // Both new triangles face the way both old ones and their outer
    // neighbours do, and have some area.
    const double s2 = norm2(pd - pc);
    if (!(norm2(n1) > 1e-12 * s2 * s2) || !(norm2(n2) > 1e-12 * s2 * s2)) continue;
    bool consistent = dot(n1, n2) > 0;
    for (const Vec3& n : {n1, n2}) consistent = consistent && dot(n, nf) > 0 && dot(n, ng) > 0;
    const int outer[4] = {twin_[hn], twin_[hp], twin_[on], twin_[op]};
    for (int k = 0; k < 4 && consistent; ++k)
      if (outer[k] >= 0) consistent = dot(face_normal(outer[k] / 3), k == 1 || k == 2 ? n1 : n2) > 0;
    if (!consistent) continue;
    // Flip: faces become (c, a, d) in h's slots and (d, b, c) in o's.
    const int t_hn = twin_[hn], t_hp = twin_[hp], t_on = twin_[on], t_op = twin_[op];
    origin_[h] = c, origin_[hn] = a, origin_[hp] = d;
    origin_[o] = d, origin_[on] = b, origin_[op] = c;
    twin_[h] = t_hp;
    if (t_hp >= 0) twin_[t_hp] = h;
    twin_[hn] = t_on;
    if (t_on >= 0) twin_[t_on] = hn;
    twin_[o] = t_op;
    if (t_op >= 0) twin_[t_op] = o;
    twin_[on] = t_hn;
    if (t_hn >= 0) twin_[t_hn] = on;
    twin_[hp] = op, twin_[op] = hp;
    out_he_[a] = hn, out_he_[b] = on, out_he_[c] = h, out_he_[d] = o;
    --valence_[a], --valence_[b], ++valence_[c], ++valence_[d];
  }
}

void IsotropicRemesher::relax() {
  // One Gauss-Seidel sweep in vertex order. Inside: towards the area-weighted
  // centroid of the incident triangles, in the tangent plane. On the border:
  // towards the middle of the two border neighbours, along the border, where
  // the border is nearly straight (corners stay). A move that would flip an
  // incident triangle is not made.
  for (int v = 0; v < int(pos_.size()); ++v) {
    if (out_he_[v] < 0) continue;
    ring(v, ring_a_);
    const Vec3 p = pos_[v];
    Vec3 q = p;
    if (border_[v]) {
      int u, w;
      border_neighbours(ring_a_, u, w);
      const Vec3 d0 = p - pos_[u], d1 = pos_[w] - p;
      const double l = norm(d0) * norm(d1);
      if (!(l > 0) || dot(d0, d1) < 0.9 * l) continue;
      const Vec3 t = normalized(pos_[w] - pos_[u]);
      q = p + t * dot(t, (pos_[u] + pos_[w]) * 0.5 - p);
    } else {
      Vec3 sum{}, n{};
      double area = 0;
      for (int e : ring_a_) {
        const Vec3 fn = face_normal(e / 3);
        const double w = norm(fn);
        sum = sum + (p + pos_[to(e)] + pos_[origin_[prev_he(e)]]) * (w / 3);
        area += w;
        n = n + fn;
      }
      if (!(area > 0) || !(norm2(n) > 0)) continue;
      n = normalized(n);
      const Vec3 move = sum / area - p;
      q = p + move - n * dot(n, move);
    }
    bool ok = true;
    for (int e : ring_a_) {
      const Vec3& p1 = pos_[to(e)];
      const Vec3& p2 = pos_[origin_[prev_he(e)]];
      const Vec3 before = cross(p1 - p, p2 - p), after = cross(p1 - q, p2 - q);
      if (!(dot(before, after) > 0)) {
        ok = false;
        break;
      }
    }
    if (ok) pos_[v] = q;
  }
}

bool IsotropicRemesher::extract(PatchMesh& out) const {
  std::vector<int32_t> remap(pos_.size(), -1);
  out.positions.clear();
  out.triangles.clear();
  for (int f = 0; f < int(origin_.size()) / 3; ++f) {
    if (origin_[3 * f] < 0) continue;
    Tri t;
    for (int k = 0; k < 3; ++k) {
      int32_t& r = remap[origin_[3 * f + k]];
      if (r < 0) r = int32_t(out.positions.size()), out.positions.push_back(pos_[origin_[3 * f + k]]);
      t[k] = r;
    }
    out.triangles.push_back(t);
  }
  return !out.triangles.empty();
}

}  // namespace

bool isotropic_remesh(PatchMesh& mesh, double target_edge, int iterations) {
  if (mesh.triangles.empty() || !(target_edge > 0)) return false;
  thread_local IsotropicRemesher remesher;
  if (!remesher.build(mesh)) return false;
  const double high = 4.0 / 3 * target_edge, low = 4.0 / 5 * target_edge;
  for (int i = 0; i < iterations; ++i) {
    remesher.split_long_edges(high * high);
    remesher.collapse_short_edges(low * low, high * high);
    remesher.flip_for_valence();
    remesher.relax();
  }
  return remesher.extract(mesh);
}

}  // namespace lapflow::detail
