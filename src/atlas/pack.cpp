// Packing of the atlas charts at one texel density (the texel map is
// texels.cpp's).
// Each chart is turned to its minimum-area bounding rectangle; all charts
// share one scale. stb_rect_pack's skyline packer on the padded boxes gives
// a scale that surely fits; from there the footprints (every texel a
// chart's triangles touch) are packed bottom-left on a bit image of the
// atlas, with quarter turns and gutters shared by neighbours, at the
// largest scale that fits.
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstring>
#include <array>
#include <numeric>
#include <unordered_map>
#include <vector>

#include "atlas/internal.hpp"
#include "lapflow/core/parallel.hpp"

namespace {
/// stb_rect_pack sorts with qsort, which leaves equal boxes in an order the C
/// library chooses; a stable sort keeps the packing identical everywhere.
void stable_sort_bytes(void* base, std::size_t count, std::size_t size, int (*compare)(const void*, const void*)) {
  std::vector<std::size_t> order(count);
  std::iota(order.begin(), order.end(), std::size_t(0));
  char* bytes = static_cast<char*>(base);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return compare(bytes + a * size, bytes + b * size) < 0; });
  std::vector<char> copy(bytes, bytes + count * size);
  for (std::size_t i = 0; i < count; ++i) std::memcpy(bytes + i * size, copy.data() + order[i] * size, size);
}
}  // namespace

#define STBRP_SORT stable_sort_bytes
#define STBRP_STATIC
#define STB_RECT_PACK_IMPLEMENTATION
#include <stb/stb_rect_pack.h>

namespace lapflow::atlas_detail {

std::vector<Vec2> convex_hull(std::vector<Vec2> pts) {
  std::sort(pts.begin(), pts.end(), [](const Vec2& a, const Vec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
  if (pts.size() < 3) return pts;
  std::vector<Vec2> hull(2 * pts.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    while (k >= 2 && cross(hull[k - 1] - hull[k - 2], pts[i] - hull[k - 2]) <= 0) --k;
    hull[k++] = pts[i];
  }
  for (std::size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(hull[k - 1] - hull[k - 2], pts[i] - hull[k - 2]) <= 0) --k;
    hull[k++] = pts[i];
  }
  hull.resize(k - 1);
  return hull;
}

namespace {

/// A chart turned to its minimum-area rectangle: uv' = R (uv - 0) - lo, so
/// that it spans [0, w] x [0, h] with w >= h.
struct ChartFrame {
  Vec2 dir{1, 0};  ///< unit vector mapped to +u
  Vec2 lo{};
  double w = 0, h = 0;
  bool quarter = false;  ///< rotated a further 90 degrees so that w >= h
  Vec2 apply(const Vec2& p) const {
    Vec2 r{dot(p, dir), cross(dir, p)};
    if (quarter) r = {-r.y, r.x};
    return r - lo;
  }
};

ChartFrame min_area_frame(const std::vector<Vec2>& pts) {
  const std::vector<Vec2> hull = convex_hull(pts);
  ChartFrame best;
  double best_area = INFINITY;
  auto consider = [&](const Vec2& dir) {
    ChartFrame f;
    f.dir = dir;
    Vec2 lo{INFINITY, INFINITY}, hi{-INFINITY, -INFINITY};
    for (const Vec2& p : hull) {
      const Vec2 r = f.apply(p);
      lo = {std::min(lo.x, r.x), std::min(lo.y, r.y)};
      hi = {std::max(hi.x, r.x), std::max(hi.y, r.y)};
    }
    const double area = (hi.x - lo.x) * (hi.y - lo.y);
    if (area < best_area * (1 - 1e-12)) {
      best_area = area;
      f.lo = lo;
      f.w = hi.x - lo.x;
      f.h = hi.y - lo.y;
      best = f;
    }
  };
  if (hull.size() < 3) {
    consider({1, 0});
    if (hull.size() == 2 && norm(hull[1] - hull[0]) > 0) consider((hull[1] - hull[0]) / norm(hull[1] - hull[0]));
  } else {
    // The minimum-area rectangle has a side on a hull edge (Freeman & Shapira).
    for (std::size_t i = 0; i < hull.size(); ++i) {
      const Vec2 e = hull[(i + 1) % hull.size()] - hull[i];
      const double l = norm(e);
      if (l > 0) consider(e / l);
    }
  }
  if (!std::isfinite(best_area)) best = ChartFrame{}, best.lo = pts.empty() ? Vec2{} : pts[0];
  if (best.h > best.w) {
    // Lying boxes pack better in a skyline sorted by height.
    best.quarter = true;
    best.lo = {0, 0};
    Vec2 lo{INFINITY, INFINITY};
    for (const Vec2& p : hull.empty() ? pts : hull) {
      const Vec2 r = best.apply(p);
      lo = {std::min(lo.x, r.x), std::min(lo.y, r.y)};
    }
    best.lo = lo;
    std::swap(best.w, best.h);
  }
  return best;
}

/// Whole texels an extent of `extent` texels is given (at least one), with
/// at least kSpare texel to spare on each side once centred: far more than
/// rounding of the final uv moves a corner.
constexpr double kSpare = 1e-5;
int whole_texels(double extent) { return std::max(1, int(std::ceil(extent + 2 * kSpare))); }

/// Turns chart-frame coordinates by a multiple of 90 degrees (no mirror).
Vec2 orient(const Vec2& p, int o) {
  switch (o & 3) {
    case 1: return {-p.y, p.x};
    case 2: return {-p.x, -p.y};
    case 3: return {p.y, -p.x};
    default: return p;
  }
}

// ---- footprints -------------------------------------------------------------

/// Texels: a footprint also claims the texels its triangles come this close
/// to, so that rounding of the final uv can never move a triangle onto a
/// texel its footprint left out.
constexpr double kTouch = 1e-6;

/// Calls cells(row, first, last) for every row of unit cells a triangle
/// touches (within kTouch), with the first and last column it touches in
/// that row; row j spans [j, j+1]. Rows outside [0, rows) and columns
/// outside [0, cols) are left out. A degenerate triangle touches the cells
/// of its segment or point.
template <class Cells>
void touched_cells(const Vec2& a, const Vec2& b, const Vec2& c, int rows, int cols, Cells&& cells) {
  const Vec2 p[3] = {a, b, c};
  const double ymin = std::min({a.y, b.y, c.y}), ymax = std::max({a.y, b.y, c.y});
  const int j0 = std::max(0, int(std::floor(ymin - kTouch))), j1 = std::min(rows - 1, int(std::floor(ymax + kTouch)));
  for (int j = j0; j <= j1; ++j) {
    // The triangle's x extent within the row is reached on its edges
    // clipped to the row.
    const double ylo = j - kTouch, yhi = j + 1 + kTouch;
    double xmin = INFINITY, xmax = -INFINITY;
    for (int k = 0; k < 3; ++k) {
      Vec2 s = p[k], e = p[(k + 1) % 3];
      if (s.y > e.y) std::swap(s, e);
      if (e.y < ylo || s.y > yhi) continue;
      double x0 = s.x, x1 = e.x;
      if (e.y > s.y) {
        const double dx = (e.x - s.x) / (e.y - s.y);
        if (s.y < ylo) x0 = s.x + (ylo - s.y) * dx;
        if (e.y > yhi) x1 = s.x + (yhi - s.y) * dx;
      }
      xmin = std::min({xmin, x0, x1});
      xmax = std::max({xmax, x0, x1});
    }
    if (!(xmin <= xmax)) continue;
    const int c0 = std::max(0, int(std::floor(xmin - kTouch))), c1 = std::min(cols - 1, int(std::floor(xmax + kTouch)));
    if (c0 <= c1) cells(j, c0, c1);
  }
}

/// Sets bits [a, b] (inclusive, a <= b) of a row of 64-bit words.
void set_bits(uint64_t* row, int a, int b) {
  const int wa = a >> 6, wb = b >> 6;
  const uint64_t ma = ~uint64_t(0) << (a & 63), mb = ~uint64_t(0) >> (63 - (b & 63));
  if (wa == wb) {
    row[wa] |= ma & mb;
    return;
  }
  row[wa] |= ma;
  for (int w = wa + 1; w < wb; ++w) row[w] = ~uint64_t(0);
  row[wb] |= mb;
}

/// The highest set bit in [a, b] of a row of words, or -1.
int highest_bit(const uint64_t* row, int a, int b) {
  const int wa = a >> 6, wb = b >> 6;
  uint64_t m = row[wb] & (~uint64_t(0) >> (63 - (b & 63)));
  if (wa == wb) m &= ~uint64_t(0) << (a & 63);
  if (m) return (wb << 6) + 63 - __builtin_clzll(m);
  if (wa == wb) return -1;
  for (int w = wb - 1; w > wa; --w)
    if (row[w]) return (w << 6) + 63 - __builtin_clzll(row[w]);
  m = row[wa] & (~uint64_t(0) << (a & 63));
  return m ? (wa << 6) + 63 - __builtin_clzll(m) : -1;
}

/// The first bit at or after x (below `bits`) that is set (want = true) or
/// clear (want = false); `bits` when there is none.
int next_bit(const uint64_t* row, int bits, int x, bool want) {
  const int words = (bits + 63) >> 6;
  int w = x >> 6;
  if (w >= words) return bits;
  uint64_t m = (want ? row[w] : ~row[w]) & (~uint64_t(0) << (x & 63));
  while (!m) {
    if (++w >= words) return bits;
    m = want ? row[w] : ~row[w];
  }
  return std::min(bits, (w << 6) + __builtin_ctzll(m));
}

/// A chart's conservative footprint on the packing grid in one orientation:
/// every cell its triangles touch, as runs per row (row 0 at the bottom).
struct Footprint {
  struct Run {
    int32_t row, first, last;  ///< inclusive columns
  };
  int w = 0, h = 0;
  Vec2 shift;             ///< cells: a chart point's place is orient(frame(p) * scale, o) + shift
  std::vector<Run> runs;  ///< by row, then column
  std::size_t cells = 0;
  /// The longest run (row, first column, length): a position is possible
  /// only where it lies in a free run of its grid row.
  int key_row = 0, key_first = 0, key_len = 0;
  /// The longest run of a few rows, longest first (row, length): a grid row
  /// whose longest free run is shorter rules a position out at once.
  std::vector<std::pair<int, int>> probes;
};

/// Fills the key run and the probes from the runs.
void index_runs(Footprint& f) {
  constexpr std::size_t kProbes = 8;
  std::vector<std::pair<int, int>> longest(f.h, {0, 0});  // (length, row)
  for (const Footprint::Run& r : f.runs) {
    const int len = r.last - r.first + 1;
    longest[r.row] = std::max(longest[r.row], {len, r.row});
    if (len > f.key_len) f.key_len = len, f.key_row = r.row, f.key_first = r.first;
  }
  std::sort(longest.begin(), longest.end(), [](const auto& a, const auto& b) {
    return a.first > b.first || (a.first == b.first && a.second < b.second);
  });
  f.probes.clear();
  for (std::size_t i = 0; i < longest.size() && i < kProbes; ++i) f.probes.emplace_back(longest[i].second, longest[i].first);
}

/// A chart in its minimum-area frame (metres), as its footprints need it.
struct ChartOutline {
  Vec2 lo, hi;  ///< bounding box of every corner
  /// Directed boundary edges (those of its triangles not cancelled by the
  /// reverse edge of a neighbour), counter-clockwise around the chart.
  std::vector<std::pair<Vec2, Vec2>> edges;
  /// Rasterise the triangles one by one instead: a chart with a flipped or
  /// collapsed proper triangle (its outline's winding would not bound it),
  /// or one collapsed to points.
  bool by_triangles = false;
};

ChartOutline chart_outline(const Vec2* corners, std::size_t count) {
  ChartOutline ol;
  ol.lo = ol.hi = count ? corners[0] : Vec2{};
  struct Edge {
    Vec2 a, b;  ///< a before b (x, then y)
    int sign;   ///< +1 when the triangle runs a -> b
  };
  auto less = [](const Vec2& a, const Vec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); };
  std::vector<Edge> edges;
  edges.reserve(count);
  for (std::size_t t = 0; t + 2 < count; t += 3) {
    const Vec2* p = corners + t;
    for (int k = 0; k < 3; ++k) {
      ol.lo = {std::min(ol.lo.x, p[k].x), std::min(ol.lo.y, p[k].y)};
      ol.hi = {std::max(ol.hi.x, p[k].x), std::max(ol.hi.y, p[k].y)};
    }
    if (p[0] == p[1] && p[1] == p[2]) continue;  // a degenerate triangle, collapsed onto a vertex
    if (!(cross(p[1] - p[0], p[2] - p[0]) > 0)) ol.by_triangles = true;
    for (int k = 0; k < 3; ++k) {
      const Vec2 a = p[k], b = p[(k + 1) % 3];
      if (!(a == b)) edges.push_back(less(a, b) ? Edge{a, b, 1} : Edge{b, a, -1});
    }
  }
  // Corners of a vertex are the same doubles in every triangle of a chart,
  // so an inner edge meets its reverse exactly.
  std::sort(edges.begin(), edges.end(), [&](const Edge& x, const Edge& y) {
    return less(x.a, y.a) || (x.a == y.a && less(x.b, y.b));
  });
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    int sum = 0;
    for (; j < edges.size() && edges[j].a == edges[i].a && edges[j].b == edges[i].b; ++j) sum += edges[j].sign;
    for (int k = 0; k < std::abs(sum); ++k)
      ol.edges.push_back(sum > 0 ? std::pair{edges[i].a, edges[i].b} : std::pair{edges[i].b, edges[i].a});
    i = j;
  }
  if (ol.edges.empty()) ol.by_triangles = true;
  return ol;
}

/// The footprint of a chart (outline, and corners in its frame, 3 per
/// triangle, metres) at `scale` cells per metre turned by o quarters,
/// centred in the fewest whole cells its box needs.
Footprint rasterize_footprint(const ChartOutline& ol, const Vec2* corners, std::size_t count, double scale, int o) {
  Footprint f;
  Vec2 lo{INFINITY, INFINITY}, hi{-INFINITY, -INFINITY};
  for (const Vec2& c : {ol.lo, ol.hi, Vec2{ol.lo.x, ol.hi.y}, Vec2{ol.hi.x, ol.lo.y}}) {
    const Vec2 q = orient(c * scale, o);
    lo = {std::min(lo.x, q.x), std::min(lo.y, q.y)};
    hi = {std::max(hi.x, q.x), std::max(hi.y, q.y)};
  }
  f.w = whole_texels(hi.x - lo.x);
  f.h = whole_texels(hi.y - lo.y);
  f.shift = Vec2{0.5 * (f.w - (hi.x - lo.x)), 0.5 * (f.h - (hi.y - lo.y))} - lo;
  const int words = (f.w + 63) >> 6;
  std::vector<uint64_t> bits(std::size_t(words) * f.h, 0);
  auto mark = [&](int j, int c0, int c1) { set_bits(&bits[std::size_t(j) * words], c0, c1); };
  auto at = [&](const Vec2& p) { return orient(p * scale, o) + f.shift; };
  if (ol.by_triangles) {
    for (std::size_t t = 0; t + 2 < count; t += 3)
      touched_cells(at(corners[t]), at(corners[t + 1]), at(corners[t + 2]), f.h, f.w, mark);
  } else {
    // The cells the outline touches, and those its rows' centre lines cross
    // inside it (nonzero winding): a cell the chart touches but its outline
    // does not lies wholly inside. Far fewer edges than triangles.
    struct Crossing {
      int row;
      double x;
      int dir;
    };
    std::vector<Crossing> crossings;
    for (const auto& [a0, b0] : ol.edges) {
      const Vec2 a = at(a0), b = at(b0);
      touched_cells(a, b, b, f.h, f.w, mark);
      const double ymin = std::min(a.y, b.y), ymax = std::max(a.y, b.y);
      for (int j = std::max(0, int(std::ceil(ymin - 0.5))); j < f.h && j + 0.5 < ymax; ++j)
        if (j + 0.5 >= ymin) crossings.push_back({j, a.x + (j + 0.5 - a.y) * (b.x - a.x) / (b.y - a.y), b.y > a.y ? 1 : -1});
    }
    std::sort(crossings.begin(), crossings.end(), [](const Crossing& p, const Crossing& q) {
      return p.row < q.row || (p.row == q.row && p.x < q.x);
    });
    for (std::size_t i = 0; i < crossings.size();) {
      int winding = 0;
      double start = 0;
      std::size_t k = i;
      for (; k < crossings.size() && crossings[k].row == crossings[i].row; ++k) {
        const int before = winding;
        winding += crossings[k].dir;
        if (before == 0) start = crossings[k].x;
        if (winding == 0) {
          const int c0 = std::max(0, int(std::floor(start))), c1 = std::min(f.w - 1, int(std::floor(crossings[k].x)));
          if (c0 <= c1) mark(crossings[i].row, c0, c1);
        }
      }
      i = k;
    }
  }
  for (int j = 0; j < f.h; ++j) {
    const uint64_t* row = &bits[std::size_t(j) * words];
    for (int x = next_bit(row, f.w, 0, true); x < f.w;) {
      const int end = next_bit(row, f.w, x, false);
      f.runs.push_back({j, x, end - 1});
      f.cells += std::size_t(end - x);
      x = next_bit(row, f.w, end, true);
    }
  }
  index_runs(f);
  return f;
}

/// The same footprint turned by half a turn: orientation o + 2.
Footprint half_turn(const Footprint& f) {
  Footprint g;
  g.w = f.w;
  g.h = f.h;
  g.shift = Vec2{double(f.w), double(f.h)} - f.shift;
  g.cells = f.cells;
  g.runs.reserve(f.runs.size());
  for (auto it = f.runs.rbegin(); it != f.runs.rend(); ++it)
    g.runs.push_back({f.h - 1 - it->row, f.w - 1 - it->last, f.w - 1 - it->first});
  index_runs(g);
  return g;
}

// ---- bottom-left packing of footprints -----------------------------------------

struct Placement {
  int orientation = 0;
  Vec2 offset;  ///< texels: atlas position = orient(frame(p) * scale, orientation) + offset
};

/// Bottom-left packing on a bit image of the atlas (one bit per cell of the
/// packing grid, a texel up to 8192^2). Charts, in the given order, each go
/// where their footprint's top is lowest (then its bottom), over the quarter
/// turns, anywhere the footprint fits: small charts drop into the holes
/// left between large ones. The bit image holds every placed footprint
/// dilated by the gutter (a square of side 2G+1 cells per cell), so a
/// footprint that misses every set bit is at least G empty cells from every
/// other chart: neighbours share their gutter. A border of ceil(G/2) is kept
/// along the atlas's edges (a renderer that wraps sees G across the seam).
class BitmapPacker {
 public:
  /// `cols`: grid width = height in cells; `gutter`, `border` in cells;
  /// `step`: rows between the first-fit probes of a search (a slide down
  /// and left recovers the rows in between); charts whose footprint is
  /// narrower and lower than `small` cells try quarter turns, not half turns.
  BitmapPacker(int cols, int gutter, int border, int step, int small)
      : cols_(cols), gutter_(gutter), border_(border), words_((cols + 63) >> 6), rows_(2 * cols), step_(step),
        small_(small) {}

  /// The height a packing may use (cells).
  int rows_available() const { return cols_ - border_; }

  /// Places every chart of `order`; returns the height used (cells, the
  /// highest footprint top; INT32_MAX when a chart fits nowhere in twice the
  /// grid's height). The height beyond the grid is what predicts the next
  /// scale of a packing that did not fit.
  int pack(const std::vector<std::array<Footprint, 4>>& fp, const std::vector<int>& order,
           std::vector<Placement>& placement) {
    occ_.assign(std::size_t(rows_) * words_, 0);
    free_run_.assign(rows_, 0);
    free_at_.assign(rows_, border_);
    for (int y = 0; y < rows_; ++y) {
      uint64_t* row = &occ_[std::size_t(y) * words_];
      if (cols_ - border_ < words_ * 64) set_bits(row, cols_ - border_, words_ * 64 - 1);
      if (y < border_) set_bits(row, 0, cols_ - 1);
      else if (border_ > 0) set_bits(row, 0, border_ - 1);
      free_run_[y] = y < border_ ? 0 : cols_ - 2 * border_;
    }
    placement.assign(fp.size(), {});
    first_row_.clear();
    int top = 0;
    for (int c : order) {
      int best_top = INT32_MAX, best_y = INT32_MAX, best_o = 0, best_x = 0;
      const int turns = std::max(fp[c][0].w, fp[c][0].h) < small_ ? 2 : 4;
      for (int o = 0; o < turns; ++o) {
        const Footprint& f = fp[c][o];
        // Small footprints of one box size and turn are mostly alike
        // (droplets, by the thousand): a search starts where the last one
        // first fitted. For the same footprint that loses nothing, as the
        // claimed cells only grow.
        int unused = 0;
        int& from = turns == 2 ? first_row_[(int64_t(f.w) << 32) | (int64_t(f.h) << 2) | o] : unused;
        int x = 0, y = from;
        if (f.w > cols_ || f.h > rows_ || !first_fit(f, best_top, x, y)) continue;
        from = y;
        slide(f, x, y);
        if (y + f.h < best_top || (y + f.h == best_top && y < best_y))
          best_top = y + f.h, best_y = y, best_o = o, best_x = x;
      }
      if (best_top == INT32_MAX) return INT32_MAX;
      const Footprint& f = fp[c][best_o];
      claim(f, best_x, best_y);
      top = std::max(top, best_top);
      placement[c].orientation = best_o;
      placement[c].offset = f.shift + Vec2{double(best_x), double(best_y)};
    }
    return top;
  }

 private:
  /// The first position, every step_-th row from row fy (a multiple of
  /// step_) up and then by column, where the footprint fits with a top that
  /// may, after the slide, come below `top_limit`.
  bool first_fit(const Footprint& f, int top_limit, int& fx, int& fy) const {
    std::size_t hint = 0;
    for (int y = fy; y + f.h <= rows_ && y + f.h - (step_ - 1) < top_limit; y += step_) {
      bool possible = true;
      for (const auto& [row, len] : f.probes) possible = possible && free_run_[y + row] >= len;
      if (!possible) continue;
      // Only columns where the key run lies in a free run of its grid row,
      // one free run at a time.
      const uint64_t* key = &occ_[std::size_t(y + f.key_row) * words_];
      for (int x = 0; x + f.w <= cols_;) {
        const int s = next_bit(key, cols_, x + f.key_first, false);
        if (s >= cols_) break;
        const int e = next_bit(key, cols_, s, true);
        x = std::max(x, s - f.key_first);
        if (e - s < f.key_len) {
          x = e - f.key_first;
          continue;
        }
        const int last = std::min(e - f.key_first - f.key_len, cols_ - f.w);
        while (x <= last) {
          const int next = blocked(f, x, y, hint);
          if (next < 0) {
            fx = x, fy = y;
            return true;
          }
          x = next;
        }
        x = std::max(x, last + 1);
      }
    }
    return false;
  }

  /// Moves a fitting footprint down, then left, as long as it fits.
  void slide(const Footprint& f, int& x, int& y) const {
    std::size_t hint = 0;
    for (bool moved = true; moved;) {
      moved = false;
      while (y > 0 && blocked(f, x, y - 1, hint) < 0) --y, moved = true;
      while (x > 0 && blocked(f, x - 1, y, hint) < 0) --x, moved = true;
    }
  }

  /// -1 when the footprint at (x, y) misses every claimed cell; otherwise
  /// the next column where it might not: where the first run found blocked
  /// (`hint`, the run blocked last time, is tried first) lies past the
  /// claimed cell in a free run of its row as long as itself.
  int blocked(const Footprint& f, int x, int y, std::size_t& hint) const {
    const std::size_t nr = f.runs.size();
    for (std::size_t k = 0; k < nr; ++k) {
      const std::size_t i = hint + k < nr ? hint + k : hint + k - nr;
      const Footprint::Run& r = f.runs[i];
      const uint64_t* row = &occ_[std::size_t(y + r.row) * words_];
      const int hb = highest_bit(row, x + r.first, x + r.last);
      if (hb < 0) continue;
      hint = i;
      const int len = r.last - r.first + 1;
      int s = next_bit(row, cols_, hb + 1, false);
      while (s < cols_) {
        const int e = next_bit(row, cols_, s, true);
        if (e - s >= len) break;
        s = next_bit(row, cols_, e, false);
      }
      return s < cols_ ? s - r.first : cols_;
    }
    return -1;
  }

  /// Claims the footprint at (x, y) dilated by the gutter, and updates the
  /// longest free run of the rows it reached.
  void claim(const Footprint& f, int x, int y) {
    const int g = gutter_;
    for (const Footprint::Run& r : f.runs) {
      const int a = std::max(0, x + r.first - g), b = std::min(cols_ - 1, x + r.last + g);
      for (int yy = std::max(0, y + r.row - g); yy <= std::min(rows_ - 1, y + r.row + g); ++yy)
        set_bits(&occ_[std::size_t(yy) * words_], a, b);
    }
    // Free runs only shrink: a row's longest one changes only where the
    // claim reached into it.
    const int x0 = x - g, x1 = x + f.w - 1 + g;
    for (int yy = std::max(0, y - g); yy <= std::min(rows_ - 1, y + f.h - 1 + g); ++yy) {
      if (free_at_[yy] > x1 || free_at_[yy] + free_run_[yy] <= x0) continue;
      const uint64_t* row = &occ_[std::size_t(yy) * words_];
      int longest = 0, at = 0;
      for (int s = next_bit(row, cols_, 0, false); s < cols_;) {
        const int e = next_bit(row, cols_, s, true);
        if (e - s > longest) longest = e - s, at = s;
        s = next_bit(row, cols_, e, false);
      }
      free_run_[yy] = longest;
      free_at_[yy] = at;
    }
  }

  int cols_, gutter_, border_, words_, rows_, step_, small_;
  std::vector<uint64_t> occ_;  ///< rows_ x words_ bits, row 0 at the bottom; bits past cols_ set
  std::vector<int> free_run_;  ///< longest run of free cells per row
  std::vector<int> free_at_;   ///< where it starts
  std::unordered_map<int64_t, int> first_row_;  ///< per small footprint box and turn: the row its last search first fitted at
};

/// Texels of the atlas within `radius` (a square) of a chart's conservative
/// footprint: the charts with their half of the gutters.
std::size_t claimed_texels(const std::vector<Vec2>& corner_uv, int n, int radius) {
  const int words = (n + 63) >> 6;
  std::vector<uint64_t> bits(std::size_t(words) * n, 0);
  for (std::size_t t = 0; 3 * t + 2 < corner_uv.size(); ++t)
    touched_cells(corner_uv[3 * t] * n, corner_uv[3 * t + 1] * n, corner_uv[3 * t + 2] * n, n, n,
                  [&](int j, int c0, int c1) { set_bits(&bits[std::size_t(j) * words], c0, c1); });
  // Square dilation: along rows one texel at a time, then across rows.
  std::vector<uint64_t> tmp(bits.size());
  for (int step = 0; step < radius; ++step) {
    for (int y = 0; y < n; ++y) {
      const uint64_t* r = &bits[std::size_t(y) * words];
      uint64_t* d = &tmp[std::size_t(y) * words];
      for (int w = 0; w < words; ++w)
        d[w] = r[w] | (r[w] << 1) | (r[w] >> 1) | (w > 0 ? r[w - 1] >> 63 : 0) | (w + 1 < words ? r[w + 1] << 63 : 0);
    }
    bits.swap(tmp);
  }
  std::size_t count = 0;
  const uint64_t last = (n & 63) ? (uint64_t(1) << (n & 63)) - 1 : ~uint64_t(0);
  for (int y = 0; y < n; ++y)
    for (int w = 0; w < words; ++w) {
      uint64_t v = 0;
      for (int yy = std::max(0, y - radius); yy <= std::min(n - 1, y + radius); ++yy) v |= bits[std::size_t(yy) * words + w];
      if (w + 1 == words) v &= last;
      count += std::size_t(__builtin_popcountll(v));
    }
  return count;
}

/// Searches the largest scale (texels per metre) at which the bottom-left
/// packer fits every chart, from `scale`, at which the charts are known to
/// fit (`place` holds that packing and is replaced by a better one).
/// Packings at one scale run in two orders (footprint area, then footprint
/// height: two tasks) and keep the lower; thousands of charts take one.
double pack_footprints(const Charts& charts, const std::vector<Vec2>& local, int n, int gutter, double scale,
                       std::vector<Placement>& place) {
  const int nc = charts.count;
  // Cells of the packing grid: a texel up to 8192^2, more above.
  const int cell = std::max(1, (n + 8191) / 8192), cols = n / cell;
  const int orders = nc > 400 ? 1 : 2;
  std::vector<BitmapPacker> packers(orders, BitmapPacker(cols, (gutter + cell - 1) / cell,
                                                         ((gutter + 1) / 2 + cell - 1) / cell,
                                                         std::max(1, cols / 512), std::max(1, cols / 64)));
  std::vector<ChartOutline> outlines(nc);
  parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c)
      outlines[c] = chart_outline(&local[3 * std::size_t(charts.offsets[c])],
                                  3 * std::size_t(charts.offsets[c + 1] - charts.offsets[c]));
  }, 8);
  double area = 0;  // of the charts, square metres
  for (std::size_t i = 0; i + 2 < local.size(); i += 3) area += 0.5 * std::abs(cross(local[i + 1] - local[i], local[i + 2] - local[i]));

  std::vector<std::array<Footprint, 4>> fp(nc);
  std::vector<std::vector<Placement>> trial(orders);
  std::vector<int> used(orders);
  auto pack_at = [&](double s) {
    parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
      for (std::size_t c = b; c < e; ++c) {
        const Vec2* corners = &local[3 * std::size_t(charts.offsets[c])];
        const std::size_t count = 3 * std::size_t(charts.offsets[c + 1] - charts.offsets[c]);
        for (int o = 0; o < 2; ++o) {
          fp[c][o] = rasterize_footprint(outlines[c], corners, count, s / cell, o);
          fp[c][o + 2] = half_turn(fp[c][o]);
        }
      }
    }, 4);
    parallel_for(std::size_t(orders), [&](std::size_t b, std::size_t e) {
      for (std::size_t k = b; k < e; ++k) {
        // Large charts first: they shape the holes that small ones fill.
        // Ties: chart order.
        std::vector<int> order(nc);
        std::iota(order.begin(), order.end(), 0);
        std::stable_sort(order.begin(), order.end(), [&](int x, int y) {
          return k == 0 ? fp[x][0].cells > fp[y][0].cells : fp[x][0].h > fp[y][0].h;
        });
        used[k] = packers[k].pack(fp, order, trial[k]);
      }
    }, 1);
    const int pick = orders > 1 && used[1] < used[0] ? 1 : 0;
    return pick;
  };
  // The first scale: what about three quarters of the atlas in charts needs
  // (the box packer's scale is far below); then the used height predicts
  // the next (area grows with the square of the scale), bisecting when the
  // prediction leaves the bracket, until it is 0.4% wide.
  const double avail = packers[0].rows_available();
  double lo = scale, hi = INFINITY, best = scale;
  double s = std::max(scale, std::sqrt(0.74 * double(n) * n / std::max(area, 1e-300)));
  for (int it = 0; it < 8 && !(hi < lo * 1.004); ++it) {
    const int pick = pack_at(s);
    const int h = used[pick];
    const bool fits = h <= avail;
    if (fits) {
      lo = best = s;
      place = trial[pick];
      for (Placement& p : place) p.offset = p.offset * double(cell);
    } else {
      hi = std::min(hi, s);
    }
    double next = h < INT32_MAX ? s * std::sqrt(avail / std::max(1, h)) * (fits ? 1.0 : 0.997) : 0;
    if (!(next > lo && next < hi)) next = std::isfinite(hi) ? 0.5 * (lo + hi) : lo * 1.1;
    s = next;
  }
  return best;
}

}  // namespace

PackResult pack_charts(const Charts& charts, int resolution, int gutter, std::vector<Vec2>& corner_uv) {
  const int nc = charts.count;
  std::vector<ChartFrame> frames(nc);
  // Corners in their chart's minimum-area frame (metres), in chart order.
  std::vector<Vec2> local(3 * charts.triangles.size());
  parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
    std::vector<Vec2> pts;
    for (std::size_t c = b; c < e; ++c) {
      pts.clear();
      for (int32_t i = charts.offsets[c]; i < charts.offsets[c + 1]; ++i)
        for (int k = 0; k < 3; ++k) pts.push_back(corner_uv[3 * std::size_t(charts.triangles[i]) + k]);
      frames[c] = min_area_frame(pts);
      for (std::size_t i = 0; i < pts.size(); ++i) local[3 * std::size_t(charts.offsets[c]) + i] = frames[c].apply(pts[i]);
    }
  }, 16);

  // A scale that surely fits: stb_rect_pack's skyline on the boxes with half
  // the gutter on every side (so G between boxes and G/2 to the edges),
  // bisected.
  const int n = resolution;
  std::vector<stbrp_rect> rects(nc);
  std::vector<stbrp_node> nodes(n);
  auto try_pack = [&](double s, int m) {
    for (int c = 0; c < nc; ++c) {
      const double w = frames[c].w * s, h = frames[c].h * s;
      if (!(w < n) || !(h < n)) return false;
      rects[c].id = c;
      rects[c].w = whole_texels(w) + 2 * m;
      rects[c].h = whole_texels(h) + 2 * m;
      if (rects[c].w > n || rects[c].h > n) return false;
    }
    for (int heuristic : {STBRP_HEURISTIC_Skyline_BL_sortHeight, STBRP_HEURISTIC_Skyline_BF_sortHeight}) {
      stbrp_context ctx;
      stbrp_init_target(&ctx, n, n, nodes.data(), n);
      stbrp_setup_heuristic(&ctx, heuristic);
      if (stbrp_pack_rects(&ctx, rects.data(), nc)) return true;
    }
    return false;
  };

  PackResult result;
  double area = 0;
  for (const ChartFrame& f : frames) area += f.w * f.h;
  double s_hi = area > 0 ? double(n) / std::sqrt(area) : 1.0;
  double best = 0;
  int g = gutter, m = (gutter + 1) / 2;
  if (nc > 0) {
    // Find a scale that packs (shrinking geometrically), then bisect up to
    // the largest one that still packs.
    double s = s_hi;
    for (;;) {
      int steps = 0;
      while (!try_pack(s, m) && steps < 80) s *= 0.8, ++steps;
      if (steps < 80) break;
      if (m == 0) break;
      m = g = 0;  // too many charts for this resolution: drop the gutter
      result.overflow = true;
      s = s_hi;
    }
    if (try_pack(s, m)) {
      best = s;
      double lo = s, hi = std::min(s_hi, s / 0.8);
      if (hi <= lo) hi = lo * 1.25;
      for (int it = 0; it < 14; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (try_pack(mid, m)) lo = best = mid;
        else hi = mid;
      }
      try_pack(best, m);
    } else {
      result.overflow = true;
    }
  }
  std::vector<Placement> place(nc);
  for (int c = 0; c < nc; ++c) {
    const stbrp_rect& r = rects[c];
    const double w = frames[c].w * best, h = frames[c].h * best;
    place[r.id].offset = best > 0 && r.was_packed
                             ? Vec2{r.x + m + 0.5 * (whole_texels(w) - w), r.y + m + 0.5 * (whole_texels(h) - h)}
                             : Vec2{0.5 * n, 0.5 * n};  // unpackable: a point, never outside [0,1]
  }
  // Bottom-left packing of the footprints beats boxes on fluid charts by far.
  if (nc > 0 && best > 0) best = pack_footprints(charts, local, n, g, best, place);
  result.texels_per_metre = best;

  const double scale = best;
  parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c)
      for (int32_t i = charts.offsets[c]; i < charts.offsets[c + 1]; ++i)
        for (int k = 0; k < 3; ++k) {
          Vec2& p = corner_uv[3 * std::size_t(charts.triangles[i]) + k];
          const Vec2 q = place[c].offset + orient(local[3 * std::size_t(i) + k] * scale, place[c].orientation);
          p = {std::clamp(q.x / n, 0.0, 1.0), std::clamp(q.y / n, 0.0, 1.0)};
        }
  }, 16);
  result.claimed_texels = claimed_texels(corner_uv, n, (g + 1) / 2);
  return result;
}

}  // namespace lapflow::atlas_detail
