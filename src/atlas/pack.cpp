// Packing of the atlas charts at one texel density, and the texel map.
// Each chart is turned to its minimum-area bounding rectangle (the box a
// rectangle packer sees is then as tight as it gets), all charts share one
// scale, and a bisection finds the largest scale at which stb_rect_pack's
// skyline packer fits every padded box into the square.
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstring>
#include <array>
#include <numeric>
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

/// Texels a chart span of `extent` texels needs so that its conservative
/// footprint stays inside: floor(extent) + 1.
int span_texels(double extent) { return int(std::floor(extent)) + 1; }

/// Turns chart-frame coordinates by a multiple of 90 degrees (no mirror).
Vec2 orient(const Vec2& p, int o) {
  switch (o & 3) {
    case 1: return {-p.y, p.x};
    case 2: return {-p.x, -p.y};
    case 3: return {p.y, -p.x};
    default: return p;
  }
}

/// The outline of a chart on a grid of B x B texel blocks, dilated by the
/// margin: per block column, the lowest and highest block row it covers.
struct Profile {
  int width = 0, height = 0;
  std::vector<int> lo, hi;  ///< block rows, inclusive; lo > hi for an empty column
  Vec2 origin;              ///< texel position of the chart-frame origin relative to the profile's corner
};

/// Horizon ("Tetris") packing after Lévy et al. 2002, section 5: charts are
/// dropped one by one onto the horizon of those already placed, at the
/// column and quarter turn that waste the least area under them, so the
/// saw-tooth and concave outlines of fluid charts interlock instead of each
/// claiming its whole bounding box.
class HorizonPacker {
  static constexpr double kTouch = 1e-6;  ///< blocks

 public:
  HorizonPacker(const Charts& charts, const std::vector<ChartFrame>& frames, const std::vector<Vec2>& corner_uv,
                int resolution, int margin)
      : charts_(charts) {
    block_ = std::max(1, resolution / 1024);
    cols_ = resolution / block_;
    margin_blocks_ = (margin + block_ - 1) / block_;
    // A region's extent in any vertical slab is reached on its boundary, so
    // the outline (edges used by one triangle of the chart) is all the
    // profiles need: far fewer segments than triangles.
    outline_.resize(charts.count);
    parallel_for(std::size_t(charts.count), [&](std::size_t b, std::size_t e) {
      std::vector<std::pair<Vec2, Vec2>> edges;
      auto less = [](const Vec2& a, const Vec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); };
      for (std::size_t c = b; c < e; ++c) {
        edges.clear();
        for (int32_t i = charts.offsets[c]; i < charts.offsets[c + 1]; ++i)
          for (int k = 0; k < 3; ++k) {
            Vec2 a = corner_uv[3 * std::size_t(charts.triangles[i]) + k],
                 d = corner_uv[3 * std::size_t(charts.triangles[i]) + (k + 1) % 3];
            if (less(d, a)) std::swap(a, d);
            edges.emplace_back(a, d);
          }
        std::sort(edges.begin(), edges.end(), [&](const auto& x, const auto& y) {
          return less(x.first, y.first) || (x.first == y.first && less(x.second, y.second));
        });
        std::vector<std::pair<Vec2, Vec2>>& out = outline_[c];
        for (std::size_t i = 0; i < edges.size();) {
          std::size_t j = i + 1;
          while (j < edges.size() && edges[j] == edges[i]) ++j;
          if (j - i == 1) out.emplace_back(frames[c].apply(edges[i].first), frames[c].apply(edges[i].second));
          i = j;
        }
        if (out.empty() && !edges.empty()) {
          const Vec2 q = frames[c].apply(edges[0].first);
          out.emplace_back(q, q);  // a chart collapsed to a point
        }
      }
    }, 8);
  }

  struct Placement {
    int orientation = 0;
    Vec2 offset;  ///< texels: atlas position = orient(frame(p)) * scale + offset
  };

  /// Packs at `scale` texels per metre; returns the used height in texels
  /// (larger than the resolution when it does not fit) and the placements.
  int pack(double scale, std::vector<Placement>& placement) const {
    const int nc = charts_.count;
    std::vector<std::array<Profile, 4>> prof(nc);
    parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
      for (std::size_t c = b; c < e; ++c)
        for (int o = 0; o < 4; ++o) prof[c][o] = profile(int(c), o, scale);
    }, 8);
    // Large charts first: they shape the horizon that small ones fill. Two
    // orders (by box area, by box height) and the better of the two.
    // Thousands of droplet charts: one order is enough and halves the cost.
    // The two orders run as two tasks; the lower horizon wins (ties: area order).
    const int orders = nc > 400 ? 1 : 2;
    std::array<std::vector<Placement>, 2> trial;
    std::array<int, 2> used{INT32_MAX, INT32_MAX};
    parallel_for(std::size_t(orders), [&](std::size_t b, std::size_t e) {
      for (std::size_t by_height = b; by_height < e; ++by_height) {
        std::vector<int> order(nc);
        std::iota(order.begin(), order.end(), 0);
        std::vector<double> key(nc);
        for (int c = 0; c < nc; ++c)
          key[c] = by_height ? double(std::max(prof[c][0].width, prof[c][0].height))
                             : double(prof[c][0].width) * prof[c][0].height;
        std::stable_sort(order.begin(), order.end(), [&](int x, int y) { return key[x] > key[y]; });
        used[by_height] = drop(prof, order, trial[by_height]);
      }
    }, 1);
    const int pick = used[1] < used[0] ? 1 : 0;
    placement = std::move(trial[pick]);
    return used[pick];
  }

  int rows_available() const { return cols_ * block_; }

 private:
  /// Drops the charts in `order` onto the horizon; returns the height used (texels).
  int drop(const std::vector<std::array<Profile, 4>>& prof, const std::vector<int>& order,
           std::vector<Placement>& placement) const {
    const int nc = int(prof.size());
    std::vector<int> sky(cols_, 0);
    int top = 0;
    placement.assign(nc, {});
    std::vector<int> steps, candidates;
    std::vector<std::pair<int, int>> lows;  // (horizon height, column) of each step
    const std::size_t kSteps = nc > 400 ? 24 : 64;
    for (int c : order) {
      double best_score = INFINITY;
      int best_o = 0, best_x = 0, best_y = 0;
      // Candidate columns: against every step of the horizon (left or right
      // aligned), as skyline packers do, plus a stride across the whole width
      // for wide charts whose outline may interlock anywhere. Keeps the cost
      // low with thousands of droplet charts.
      // Only the lowest steps: a ragged horizon under thousands of droplet
      // charts has hundreds, and a low step is where bottom-left wins.
      lows.clear();
      lows.emplace_back(sky[0], 0);
      for (int x = 1; x < cols_; ++x)
        if (sky[x] != sky[x - 1]) lows.emplace_back(std::min(sky[x], sky[x - 1]), x);
      if (lows.size() > kSteps) {
        std::nth_element(lows.begin(), lows.begin() + kSteps, lows.end());
        lows.resize(kSteps);
      }
      steps.clear();
      for (const auto& [h, x] : lows) steps.push_back(x);
      steps.push_back(cols_);
      for (int o = 0; o < 4; ++o) {
        const Profile& p = prof[c][o];
        if (p.width > cols_) continue;
        candidates.clear();
        for (int x : steps) {
          if (x + p.width <= cols_) candidates.push_back(x);
          if (x - p.width >= 0) candidates.push_back(x - p.width);
        }
        if (p.width > 16)
          for (int x = 0; x + p.width <= cols_; x += std::max({1, p.width / 16, cols_ / 64})) candidates.push_back(x);
        std::sort(candidates.begin(), candidates.end());
        candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
        for (int x0 : candidates) {
          int y = 0;
          for (int i = 0; i < p.width; ++i)
            if (p.lo[i] <= p.hi[i]) y = std::max(y, sky[x0 + i] - p.lo[i]);
          // Lowest resulting top first (bottom-left), then least area wasted
          // under the chart: measured best on the dam-break frames.
          long waste = 0;
          int chart_top = 0;
          for (int i = 0; i < p.width; ++i)
            if (p.lo[i] <= p.hi[i]) {
              waste += y + p.lo[i] - sky[x0 + i];
              chart_top = std::max(chart_top, y + p.hi[i] + 1);
            }
          const double score = double(chart_top) * 1e9 + double(waste);
          if (score < best_score) best_score = score, best_o = o, best_x = x0, best_y = y;
        }
      }
      if (!std::isfinite(best_score)) return INT32_MAX;  // a chart wider than the atlas
      const Profile& p = prof[c][best_o];
      for (int i = 0; i < p.width; ++i)
        if (p.lo[i] <= p.hi[i]) {
          sky[best_x + i] = best_y + p.hi[i] + 1;
          top = std::max(top, sky[best_x + i]);
        }
      placement[c].orientation = best_o;
      placement[c].offset = p.origin + Vec2{double(best_x * block_), double(best_y * block_)};
    }
    return top * block_;
  }

  Profile profile(int c, int o, double scale) const {
    Profile p;
    const auto& segs = outline_[c];
    Vec2 lo{INFINITY, INFINITY};
    for (const auto& [a, d] : segs)
      for (const Vec2& q : {orient(a * scale, o), orient(d * scale, o)}) lo = {std::min(lo.x, q.x), std::min(lo.y, q.y)};
    if (!std::isfinite(lo.x)) lo = {0, 0};
    // A quarter texel in from the block corner keeps footprints off exact
    // texel boundaries; the margin ring is added in whole blocks.
    const double inset = 0.25;
    const Vec2 shift = Vec2{inset, inset} - lo;
    const int mb = margin_blocks_, b = block_;
    std::vector<int> lo_c, hi_c;
    auto touch = [&](int col, double y0, double y1) {
      if (col >= int(lo_c.size())) lo_c.resize(col + 1, INT32_MAX), hi_c.resize(col + 1, INT32_MIN);
      // The slack claims a block the outline only touches (or may touch
      // after rounding of the final placement).
      lo_c[col] = std::min(lo_c[col], int(std::floor(y0 / b - kTouch)));
      hi_c[col] = std::max(hi_c[col], int(std::floor(y1 / b + kTouch)));
    };
    for (const auto& [a0, d0] : segs) {
      Vec2 a = orient(a0 * scale, o) + shift, d = orient(d0 * scale, o) + shift;
      if (d.x < a.x) std::swap(a, d);
      const int c0 = std::max(0, int(std::floor(a.x / b - kTouch))), c1 = int(std::floor(d.x / b + kTouch));
      for (int col = c0; col <= c1; ++col) {
        // The segment clipped to the slab [col*b, (col+1)*b].
        const double sx0 = std::max(a.x, double(col * b)), sx1 = std::min(d.x, double((col + 1) * b));
        const double dx = d.x - a.x;
        const double y0 = dx > 0 ? a.y + (d.y - a.y) * (sx0 - a.x) / dx : a.y;
        const double y1 = dx > 0 ? a.y + (d.y - a.y) * (sx1 - a.x) / dx : d.y;
        touch(col, std::min(y0, y1), std::max(y0, y1));
      }
    }
    const int w = int(lo_c.size());
    p.width = w + 2 * mb;
    p.lo.assign(p.width, INT32_MAX);
    p.hi.assign(p.width, INT32_MIN);
    // Dilate by mb blocks: the profile is shifted by mb so rows stay >= 0.
    for (int i = 0; i < w; ++i) {
      if (lo_c[i] > hi_c[i]) continue;
      for (int j = i; j <= i + 2 * mb; ++j) {
        p.lo[j] = std::min(p.lo[j], lo_c[i]);
        p.hi[j] = std::max(p.hi[j], hi_c[i] + 2 * mb);
      }
    }
    p.height = 0;
    for (int j = 0; j < p.width; ++j)
      if (p.lo[j] <= p.hi[j]) p.height = std::max(p.height, p.hi[j] + 1);
    p.origin = shift + Vec2{double(mb * b), double(mb * b)};
    return p;
  }

  const Charts& charts_;
  std::vector<std::vector<std::pair<Vec2, Vec2>>> outline_;  ///< per chart, in its min-area frame (metres)
  int block_ = 1, cols_ = 0, margin_blocks_ = 0;
};

}  // namespace

PackResult pack_charts(const Charts& charts, int resolution, int margin, std::vector<Vec2>& corner_uv) {
  const int nc = charts.count;
  std::vector<ChartFrame> frames(nc);
  parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
    std::vector<Vec2> pts;
    for (std::size_t c = b; c < e; ++c) {
      pts.clear();
      for (int32_t i = charts.offsets[c]; i < charts.offsets[c + 1]; ++i)
        for (int k = 0; k < 3; ++k) pts.push_back(corner_uv[3 * std::size_t(charts.triangles[i]) + k]);
      frames[c] = min_area_frame(pts);
    }
  }, 16);

  const int n = resolution;
  std::vector<stbrp_rect> rects(nc);
  std::vector<stbrp_node> nodes(n);
  auto try_pack = [&](double s, int m) {
    for (int c = 0; c < nc; ++c) {
      const double w = frames[c].w * s, h = frames[c].h * s;
      if (!(w < n) || !(h < n)) return false;
      rects[c].id = c;
      rects[c].w = span_texels(w) + 2 * m;
      rects[c].h = span_texels(h) + 2 * m;
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
  int m = margin;
  if (nc > 0) {
    // Find a scale that packs (shrinking geometrically), then bisect up to
    // the largest one that still packs.
    double s = s_hi;
    for (;;) {
      int steps = 0;
      while (!try_pack(s, m) && steps < 80) s *= 0.8, ++steps;
      if (steps < 80) break;
      if (m == 0) break;
      m = 0;  // too many charts for this resolution: drop the gutter
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
  // Horizon packing usually beats boxes on fluid charts: search its largest
  // fitting scale from the box packer's, predicting the next scale from the
  // height used (area grows with the square of the scale).
  std::vector<HorizonPacker::Placement> place(nc);
  for (int c = 0; c < nc; ++c) {
    const stbrp_rect& r = rects[c];
    const double w = frames[c].w * best, h = frames[c].h * best;
    place[r.id].offset = best > 0 && r.was_packed
                             ? Vec2{r.x + m + 0.5 * (span_texels(w) - w), r.y + m + 0.5 * (span_texels(h) - h)}
                             : Vec2{0.5 * n, 0.5 * n};  // unpackable: a point, never outside [0,1]
  }
  if (nc > 0 && best > 0) {
    const HorizonPacker packer(charts, frames, corner_uv, n, m);
    const double avail = packer.rows_available();
    double lo = best, hi = INFINITY, s = best * 1.1;
    std::vector<HorizonPacker::Placement> trial;
    for (int it = 0; it < 8 && !(hi < lo * 1.004); ++it) {
      const int used = packer.pack(s, trial);
      const bool fits = used <= avail;
      if (fits) {
        lo = s;
        best = s;
        place = trial;
      } else {
        hi = std::min(hi, s);
      }
      double next = s * std::sqrt(avail / std::max(1, used)) * (fits ? 1.0 : 0.997);
      if (!(next > lo && next < hi)) next = std::isfinite(hi) ? 0.5 * (lo + hi) : lo * 1.1;
      s = next;
    }
    // The used height is not monotonic in the scale (a chart that no longer
    // fits a gap moves up): probe a few scales above the best to exploit it.
    for (const double f : {1.008, 1.016, 1.025, 1.035, 1.05}) {
      if (!(best * f < hi * 1.06)) break;
      if (packer.pack(best * f, trial) <= avail) {
        place = trial;
        best = best * f;
        hi = std::max(hi, best);
      }
    }
  }
  result.texels_per_metre = best;

  const double scale = best;
  parallel_for(std::size_t(nc), [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c)
      for (int32_t i = charts.offsets[c]; i < charts.offsets[c + 1]; ++i)
        for (int k = 0; k < 3; ++k) {
          Vec2& p = corner_uv[3 * std::size_t(charts.triangles[i]) + k];
          const Vec2 q = place[c].offset + orient(frames[c].apply(p) * scale, place[c].orientation);
          p = {std::clamp(q.x / n, 0.0, 1.0), std::clamp(q.y / n, 0.0, 1.0)};
        }
  }, 16);
  return result;
}

TexelMap build_texel_map(const std::vector<Vec2>& corner_uv, int resolution) {
  // Bands of 16 image rows, each rasterised by one task into a small owner
  // buffer that stays in cache: triangles in increasing index claim only free
  // texels, so ties on shared edges go to the lowest index without atomics.
  // Two passes (count, then fill at the band's offset) keep the output sorted
  // without a merge.
  const int n = resolution;
  const std::size_t nt = corner_uv.size() / 3;
  constexpr int kBand = 16;
  const int bands = (n + kBand - 1) / kBand;
  std::vector<int32_t> top(nt, -1), bottom(nt, -1);  // image rows (from the top) of each triangle
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      const Vec2 a = corner_uv[3 * t] * n, bb = corner_uv[3 * t + 1] * n, c = corner_uv[3 * t + 2] * n;
      if (!(cross(bb - a, c - a) > 0)) continue;
      const int yb0 = std::max(0, int(std::ceil(std::min({a.y, bb.y, c.y}) - 0.5)));
      const int yb1 = std::min(n - 1, int(std::floor(std::max({a.y, bb.y, c.y}) - 0.5)));
      if (yb0 > yb1) continue;
      top[t] = n - 1 - yb1;
      bottom[t] = n - 1 - yb0;
    }
  }, 1024);
  std::vector<std::size_t> band_offs(std::size_t(bands) + 1, 0);
  for (std::size_t t = 0; t < nt; ++t)
    if (top[t] >= 0)
      for (int k = top[t] / kBand; k <= bottom[t] / kBand; ++k) ++band_offs[k + 1];
  for (int k = 0; k < bands; ++k) band_offs[k + 1] += band_offs[k];
  std::vector<int32_t> band_tris(band_offs[bands]);
  {
    std::vector<std::size_t> fill(band_offs.begin(), band_offs.end() - 1);
    for (std::size_t t = 0; t < nt; ++t)
      if (top[t] >= 0)
        for (int k = top[t] / kBand; k <= bottom[t] / kBand; ++k) band_tris[fill[k]++] = int32_t(t);
  }

  auto raster_band = [&](int k, std::vector<int32_t>& owner) {
    const int row0 = k * kBand, row1 = std::min(n, row0 + kBand);
    owner.assign(std::size_t(row1 - row0) * n, INT32_MAX);
    for (std::size_t i = band_offs[k]; i < band_offs[k + 1]; ++i) {
      const int32_t t = band_tris[i];
      const Vec2 a = corner_uv[3 * std::size_t(t)] * n, b = corner_uv[3 * std::size_t(t) + 1] * n,
                 c = corner_uv[3 * std::size_t(t) + 2] * n;
      const double area2 = cross(b - a, c - a);
      // Inclusive edges with a little slack so that no texel centre on a
      // shared edge falls between two triangles.
      const double eps = -1e-9 * area2;
      const int x0 = std::max(0, int(std::ceil(std::min({a.x, b.x, c.x}) - 0.5)));
      const int x1 = std::min(n - 1, int(std::floor(std::max({a.x, b.x, c.x}) - 0.5)));
      for (int y = std::max(row0, top[t]); y <= std::min(row1 - 1, bottom[t]); ++y) {
        const double py = (n - 1 - y) + 0.5;
        int32_t* row = owner.data() + std::size_t(y - row0) * n;
        for (int x = x0; x <= x1; ++x) {
          if (row[x] != INT32_MAX) continue;
          const Vec2 p{x + 0.5, py};
          if (cross(c - b, p - b) >= eps && cross(a - c, p - c) >= eps && cross(b - a, p - a) >= eps) row[x] = t;
        }
      }
    }
    return row0;
  };

  // Band owner buffers are kept between the passes (a quarter of the size
  // of the output arrays; cheaper than rasterising twice).
  std::vector<std::vector<int32_t>> owners(bands);
  std::vector<std::size_t> count(std::size_t(bands) + 1, 0);
  parallel_for(std::size_t(bands), [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      raster_band(int(k), owners[k]);
      count[k + 1] = std::size_t(std::count_if(owners[k].begin(), owners[k].end(), [](int32_t t) { return t != INT32_MAX; }));
    }
  }, 1);
  for (int k = 0; k < bands; ++k) count[k + 1] += count[k];
  TexelMap map;
  const std::size_t total = count[bands];
  // The four arrays are first touched by different tasks (page faults of
  // hundreds of megabytes at 4096^2 are a large part of the cost).
  parallel_for(4, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      if (i == 0) map.texel.resize(total);
      if (i == 1) map.triangle.resize(total);
      if (i == 2) map.b1.resize(total);
      if (i == 3) map.b2.resize(total);
    }
  }, 1);
  parallel_for(std::size_t(bands), [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      std::vector<int32_t> owner = std::move(owners[k]);
      const int row0 = int(k) * kBand;
      std::size_t out = count[k];
      for (std::size_t i = 0; i < owner.size(); ++i) {
        const int32_t t = owner[i];
        if (t == INT32_MAX) continue;
        const std::size_t x = i % n, y = row0 + i / n;
        const Vec2 a = corner_uv[3 * std::size_t(t)] * n, bb = corner_uv[3 * std::size_t(t) + 1] * n,
                   c = corner_uv[3 * std::size_t(t) + 2] * n;
        const Vec2 p{x + 0.5, double(n - 1 - y) + 0.5};
        const double area2 = cross(bb - a, c - a);
        const double w1 = std::clamp(cross(a - c, p - c) / area2, 0.0, 1.0);
        const double w2 = std::clamp(cross(bb - a, p - a) / area2, 0.0, 1.0 - w1);
        map.texel[out] = uint32_t(y * n + x);
        map.triangle[out] = t;
        map.b1[out] = float(w1);
        map.b2[out] = float(w2);
        ++out;
      }
    }
  }, 1);
  return map;
}

}  // namespace lapflow::atlas_detail
