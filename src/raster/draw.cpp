// Lapped rasterization (ALGORITHM.md step 7) without a per-texel patch search:
// every patch triangle is drawn in atlas space and each chart texel keeps the
// smallest key (patch index << 32 | triangle) whose erosion test passes, by an
// atomic min, so the winner is the oldest non-eroded patch whatever the
// drawing order or thread count. The set-up is in setup.cpp, hole filling
// (step 8) in holes.cpp, the resolve in resolve.cpp, retirement (step 9) in
// retire.cpp, gutter dilation in dilate.cpp, and the two passes that run
// these steps in order in passes.cpp.
#include <algorithm>
#include <array>
#include <atomic>
#include <climits>
#include <cstdint>
#include <memory>
#include <cmath>
#include <stdexcept>

#include "lapflow/core/parallel.hpp"
#include "lapflow/core/stamp_set.hpp"
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"
#include "raster/sampling.hpp"
#include "raster/tiles.hpp"

namespace lapflow {
namespace detail {
namespace {

// Atlas pixel coordinates of 3D point p through fluid triangle `tri`'s affine
// map (p projected on the triangle's plane, barycentrics unclamped so points
// just off the triangle extrapolate smoothly). Texel centres are integers:
// X = u N - 0.5, Y = (1 - v) N - 0.5 (atlas.hpp's convention).
bool to_pixels(const RasterContext& ctx, int tri, const Vec3& p, Vec2& out) {
  const TrianglePixelMap& m = ctx.pixel_map[std::size_t(tri)];
  if (!m.ok) return false;
  const Vec3 e2 = p - m.a;
  const double d20 = dot(e2, m.e0), d21 = dot(e2, m.e1);
  const double b1 = (m.d11 * d20 - m.d01 * d21) / m.den, b2 = (m.d00 * d21 - m.d01 * d20) / m.den;
  const Vec2 uv = m.uv0 + m.du1 * b1 + m.du2 * b2;
  out = {uv.x * ctx.N - 0.5, (1.0 - uv.y) * ctx.N - 0.5};
  return std::isfinite(out.x) && std::isfinite(out.y);
}

int vertex_triangle(const RasterContext& ctx, const Patch& patch, int v) {
  int s = v < int(patch.surface_triangle.size()) ? patch.surface_triangle[v] : -1;
  if (s >= int(ctx.mesh.triangles.size())) s = -1;
  if (s < 0 && ctx.locate && *ctx.locate) s = (*ctx.locate)(patch.positions[v]);
  return s;
}

// The cells where the patch of index p may win a texel when it is bound
// (RasterOptions::rest_bound), or nullptr: wherever its test passes.
inline const uint64_t* rest_ground(const RasterContext& ctx, std::size_t p) {
  if (p >= ctx.rest_ground_slot.size() || ctx.rest_ground_slot[p] < 0) return nullptr;
  return &ctx.rest_ground[std::size_t(ctx.rest_ground_slot[p]) * kHeldWords];
}

}  // namespace

// Which of the erosion tests (keeps, keeps_held) every texel of a patch
// triangle passes, told from bounds over the triangle alone: the feature map's
// minimum under the bilinear taps of its uv box (MinPyramid), D's minimum at
// the box's corner farthest from the centre, w's at a vertex. Each texel's
// test computes f >= that minimum, D and w no lower than theirs, and every
// step of the test is monotone in them, so when the bound passes, so does
// every texel: the same decisions, without a feature-map lookup per texel.
// The slack covers the texels' barycentrics (kInsideTol outside the
// triangle) and the bilinear weights' rounding.
uint8_t sure_passes(const RasterContext& ctx, const LayerMaps& layer, const Vec2 uv[3], const float w[3], double slope) {
  if (ctx.mode != RasterMode::Erosion || !layer.erosion_min) return 0;
  constexpr double kUvSlack = 1e-7, kWSlack = 1e-6, kFScale = 1 - 1e-5;
  const double ua = std::min({uv[0].x, uv[1].x, uv[2].x}) - kUvSlack, ub = std::max({uv[0].x, uv[1].x, uv[2].x}) + kUvSlack;
  const double va = std::min({uv[0].y, uv[1].y, uv[2].y}) - kUvSlack, vb = std::max({uv[0].y, uv[1].y, uv[2].y}) + kUvSlack;
  if (!(ua >= 0 && ub <= 1 && va >= 0 && vb <= 1)) return 0;  // keeps rejects (u, v) off the square
  const double w_min = double(std::min({w[0], w[1], w[2]})) - kWSlack;
  const double dx = std::max(std::abs(ua - 0.5), std::abs(ub - 0.5)), dy = std::max(std::abs(va - 0.5), std::abs(vb - 0.5));
  const double d_max = std::sqrt(dx * dx + dy * dy) * (1 + 1e-12) + 1e-12;
  const double D_min = std::max(0.0, 1.0 - d_max / 0.5) - 1e-9;
  // The pixels bilinear() reads for u in [ua, ub], v in [va, vb].
  auto f_min = [&](const MinPyramid& m, const Image& img) {
    const int W = img.width, H = img.height;
    const int x0 = int(std::clamp(ua * W - 0.5, 0.0, double(W - 1)));
    const int x1 = std::min(int(std::clamp(ub * W - 0.5, 0.0, double(W - 1))) + 1, W - 1);
    const int y0 = int(std::clamp((1.0 - vb) * H - 0.5, 0.0, double(H - 1)));
    const int y1 = std::min(int(std::clamp((1.0 - va) * H - 0.5, 0.0, double(H - 1))) + 1, H - 1);
    return double(m.min_over(x0, y0, x1, y1)) * kFScale;
  };
  uint8_t sure = 0;
  {
    const ErosionMap& map = layer.erosion();
    const double f = f_min(*layer.erosion_min, map.feature);
    if (f >= 0 && std::sqrt(f + std::max(0.0, D_min)) * map.inv_max - map.epsilon >= 1.0 - w_min) sure |= kSureKeeps;
  }
  if (ctx.hold && layer.held) {
    const ErosionMap& held = layer.held_erosion();
    const double r = ctx.held_reach;
    const double f = f_min(layer.held->min, held.feature);
    const double D = std::min(1.0, std::max(0.0, D_min) + 2 * r);
    if (f >= 0 && std::sqrt(f + D) * held.inv_max - held.epsilon >= 1.0 - std::min(1.0, w_min + slope * r) - ctx.options.hold_margin)
      sure |= kSureHeld;
  }
  return sure;
}

// Chart texel i at pixel (x, y) has its 3x3 neighbourhood in its own chart.
// Only such texels mark held cells (resolve_texels), so the cells of a won
// region stop about a texel short of its chart's border.
bool interior_texel(const RasterContext& ctx, std::size_t i, int x, int y) {
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  const int chart = ctx.atlas.chart_of_triangle[tm.triangle[i]];
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int xx = x + dx, yy = y + dy;
      const int32_t n = xx < 0 || yy < 0 || xx >= N || yy >= N ? -1 : ctx.index[std::size_t(yy) * N + xx];
      if (n < 0 || ctx.atlas.chart_of_triangle[tm.triangle[n]] != chart) return false;
    }
  return true;
}

namespace {

// The erosion test of texel idx at pixel (x, y), with the hold where the
// patch won texels before (RasterOptions::hold), and for a bound patch,
// nothing beyond them (`ground`: rest_ground, or nullptr) but next to a
// chart's border, where no texel marks a cell.
// w is linear on the patch triangle: `slope` is its gradient's length in
// uv, so w + slope x reach bounds w within the reach (weight_slope).
// `sure` (sure_passes) says where the answer is known for the whole triangle.
// `layer` is the patch's (RasterContext::layer_of), looked up once per patch.
inline bool passes(const RasterContext& ctx, const Patch& patch, const LayerMaps& layer, const ErosionMap& erosion,
                   const uint64_t* ground, int32_t idx, int x, int y, double u, double v, double w, double slope,
                   uint8_t sure = 0) {
  if (ctx.hold && held_at(patch.held, u, v)) {
    if (sure & kSureHeld) return true;
    const double r = ctx.held_reach;
    return keeps_held(layer.held_erosion(), r, ctx.options.hold_margin, u, v, std::min(1.0, w + slope * r));
  }
  if (!(sure & kSureKeeps) && !keeps(erosion, u, v, w, ctx.mode)) return false;
  return !ground || held_at(ground, u, v) || !interior_texel(ctx, std::size_t(idx), x, y);
}

// `held` (kHeldWords words) grown by `reach` cells along u and v into `out`:
// a cell is set when one within a square of side 2 reach + 1 around it is.
// A row of kHeldCells = 128 cells is two words, bit u of the row.
void grow_cells(const uint64_t* held, int reach, uint64_t* out) {
  static_assert(kHeldCells == 128, "a row is two words");
  std::array<uint64_t, 2 * kHeldCells> rows;
  for (int y = 0; y < kHeldCells; ++y) {
    const uint64_t lo = held[2 * y], hi = held[2 * y + 1];
    uint64_t glo = lo, ghi = hi;
    for (int k = 1; k <= reach; ++k) {
      glo |= lo << k | lo >> k | hi << (64 - k);  // cell u - k and u + k; row bits 64.. shift into the low word
      ghi |= hi << k | hi >> k | lo >> (64 - k);
    }
    rows[2 * y] = glo, rows[2 * y + 1] = ghi;
  }
  for (int y = 0; y < kHeldCells; ++y) {
    uint64_t lo = 0, hi = 0;
    for (int z = std::max(0, y - reach); z <= std::min(kHeldCells - 1, y + reach); ++z)
      lo |= rows[2 * z], hi |= rows[2 * z + 1];
    out[2 * y] = lo, out[2 * y + 1] = hi;
  }
}

// RasterOptions::rest_bound: the cells of every patch at rest (in a render:
// every patch) that held some, grown by rest_reach_cells.
void bind_rest_ground(RasterContext& ctx, const PatchSet& patches) {
  ctx.rest_ground_slot.clear();
  ctx.rest_ground.clear();
  if (!ctx.hold || !ctx.options.rest_bound) return;
  const std::size_t np = patches.patches.size();
  std::vector<int32_t> slot(np, -1);
  int32_t bound = 0;
  for (std::size_t p = 0; p < np; ++p)
    if ((patches.patches[p].at_rest || !ctx.options.mark_held) && patches.patches[p].held.size() == kHeldWords)
      slot[p] = bound++;
  if (bound == 0) return;
  ctx.rest_ground.resize(std::size_t(bound) * kHeldWords);
  const double texel_uv = ctx.options.held_texel > 0 ? 0.5 * ctx.options.held_texel : ctx.held_reach;
  const int reach = rest_reach_cells(texel_uv);
  parallel_for(np, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p)
      if (slot[p] >= 0)
        grow_cells(patches.patches[p].held.data(), reach, &ctx.rest_ground[std::size_t(slot[p]) * kHeldWords]);
  }, 64);
  ctx.rest_ground_slot = std::move(slot);
}

}  // namespace

// The draw's test with the hold at (u, v, w) of patch triangle t, as if
// (u, v) were held (passes).
bool held_test_keeps(const RasterContext& ctx, const LayerMaps& layer, const Patch& patch, const Tri& t, double u,
                     double v, double w) {
  const Vec2 uv[3] = {patch.rest_uv[t[0]], patch.rest_uv[t[1]], patch.rest_uv[t[2]]};
  const float wv[3] = {vertex_weight(patch, t[0]), vertex_weight(patch, t[1]), vertex_weight(patch, t[2])};
  const double r = ctx.held_reach;
  return keeps_held(layer.held_erosion(), r, ctx.options.hold_margin, u, v,
                    std::min(1.0, w + weight_slope(uv, wv) * r));
}

namespace {

// Tolerance on barycentrics so that texel centres on a shared edge are never
// lost to round-off (a duplicate is harmless: the atomic min picks one).
constexpr double kInsideTol = 1e-9;

// Draws one patch triangle (pixel positions P) into the texels accepted by
// `accept(texel index)`, inside the clip box; erosion is the discard.
template <class Sink, class Accept>
void draw_triangle(RasterContext& ctx, Sink& sink, const Patch& patch, const Vec2 P[3], const Vec2 uv[3],
                   const float w[3], uint64_t key, int cx0, int cy0, int cx1, int cy1, Accept&& accept) {
  Bary b;
  if (!b.init(P)) return;
  const double slope = ctx.hold ? weight_slope(uv, w) : 0;
  const uint64_t* ground = rest_ground(ctx, std::size_t(key >> 32));
  const LayerMaps& layer = ctx.layer_of(patch);
  const ErosionMap& erosion = layer.erosion();
  const int x0 = std::max(cx0, int(std::ceil(std::min({P[0].x, P[1].x, P[2].x}) - 1e-7)));
  const int x1 = std::min(cx1, int(std::floor(std::max({P[0].x, P[1].x, P[2].x}) + 1e-7)));
  const int y0 = std::max(cy0, int(std::ceil(std::min({P[0].y, P[1].y, P[2].y}) - 1e-7)));
  const int y1 = std::min(cy1, int(std::floor(std::max({P[0].y, P[1].y, P[2].y}) + 1e-7)));
  const std::size_t N = std::size_t(ctx.N);
  for (int y = y0; y <= y1; ++y) {
    const int32_t* row = &ctx.index[std::size_t(y) * N];
    for (int x = x0; x <= x1; ++x) {
      const int32_t idx = row[x];
      if (idx < 0) continue;
      double l0, l1, l2;
      b.at(x, y, l0, l1, l2);
      if (l0 < -kInsideTol || l1 < -kInsideTol || l2 < -kInsideTol) continue;
      if (sink.taken(idx, key)) continue;  // an older patch (or this one) already keeps it
      if (!accept(idx)) continue;
      const double u = l0 * uv[0].x + l1 * uv[1].x + l2 * uv[2].x;
      const double v = l0 * uv[0].y + l1 * uv[1].y + l2 * uv[2].y;
      const double wt = l0 * w[0] + l1 * w[1] + l2 * w[2];
      if (!passes(ctx, patch, layer, erosion, ground, idx, x, y, u, v, wt, slope)) continue;
      sink.put(idx, x, y, key, u, v, wt);
    }
  }
}

// Pixel positions of a patch triangle's vertices for texels of fluid
// triangle F: a vertex on F's chart keeps its own position (the one in-chart
// triangles use, so shared edges match and no texel falls in a crack); the
// others go through F's affine map.
bool pixels_through(const RasterContext& ctx, const Patch& patch, const Tri& t, int F, Vec2 P[3]) {
  const int chart = ctx.atlas.chart_of_triangle[F];
  for (int k = 0; k < 3; ++k) {
    const int vt = vertex_triangle(ctx, patch, t[k]);
    if (vt >= 0 && ctx.atlas.chart_of_triangle[vt] == chart && to_pixels(ctx, vt, patch.positions[t[k]], P[k]))
      continue;
    if (!to_pixels(ctx, F, patch.positions[t[k]], P[k])) return false;
  }
  return true;
}

// The atlas pixels fluid triangle F's texels can lie in: the box of its
// corners, widened to whole pixels and clamped to the atlas; false when empty.
bool fluid_triangle_box(const RasterContext& ctx, int F, int& x0, int& y0, int& x1, int& y1) {
  const Vec2* cu = &ctx.atlas.corner_uv[std::size_t(F) * 3];
  double fx0 = 1e300, fx1 = -1e300, fy0 = 1e300, fy1 = -1e300;
  for (int k = 0; k < 3; ++k) {
    const double X = cu[k].x * ctx.N - 0.5, Y = (1.0 - cu[k].y) * ctx.N - 0.5;
    fx0 = std::min(fx0, X), fx1 = std::max(fx1, X), fy0 = std::min(fy0, Y), fy1 = std::max(fy1, Y);
  }
  x0 = std::max(0, int(std::floor(fx0))), x1 = std::min(ctx.N - 1, int(std::ceil(fx1)));
  y0 = std::max(0, int(std::floor(fy0))), y1 = std::min(ctx.N - 1, int(std::ceil(fy1)));
  return x0 <= x1 && y0 <= y1;
}

struct PatchTriGeometry {
  Vec3 centre, normal;
  double radius = 0, margin = 0;
};

PatchTriGeometry patch_tri_geometry(const Patch& patch, const Tri& t) {
  const Vec3 &a = patch.positions[t[0]], &b = patch.positions[t[1]], &c = patch.positions[t[2]];
  PatchTriGeometry g;
  g.centre = (a + b + c) / 3.0;
  g.normal = normalized(cross(b - a, c - a));
  g.radius = std::sqrt(std::max({norm2(a - g.centre), norm2(b - g.centre), norm2(c - g.centre)}));
  // The patch triangle is a chord of the curved surface: allow texels up to
  // half its longest edge off its plane.
  g.margin = 0.5 * std::sqrt(std::max({norm2(b - a), norm2(c - b), norm2(a - c)})) + 1e-12;
  return g;
}

// The seam fallback's buffers, one set per thread (the thread-local is looked
// up once per patch, not at every step of the walk).
struct SeamWalk {
  std::vector<int32_t> found;
  StampSet looked;
};

// Seam fallback: the fluid triangles near the patch triangle (walk over shared
// vertices from its vertices' triangles, bounded by its bounding sphere plus a
// margin), each drawn through its own affine map into its own texels.
template <class Sink>
void draw_seam_triangle(RasterContext& ctx, Sink& sink, const Patch& patch, int ti, const int vtri[3], uint64_t key,
                        SeamWalk& walk, int exclude_chart = -1, const TileMask* clip = nullptr) {
  const Tri& t = patch.triangles[ti];
  const PatchTriGeometry g = patch_tri_geometry(patch, t);
  if (norm2(g.normal) == 0) return;
  if (clip && !clip->walk_may_write(ctx, vtri, g.centre, g.radius, g.margin)) return;
  // Triangles looked at, found or not, in a per-thread set: a linear search
  // of `found` would make the walk quadratic, and a patch stretched over the
  // whole liquid (--mode advect) walks the 4096 triangles of the guard for
  // each of its triangles. The distance test does not depend on where the
  // walk came from, so each triangle is tested once.
  StampSet& looked = walk.looked;
  std::vector<int32_t>& found = walk.found;
  looked.clear(ctx.mesh.triangles.size());
  found.clear();
  for (int k = 0; k < 3; ++k)
    if (vtri[k] >= 0 && looked.insert(std::size_t(vtri[k]))) found.push_back(vtri[k]);
  constexpr std::size_t kMaxWalk = 4096;  // guard against pathological meshes
  for (std::size_t q = 0; q < found.size() && found.size() < kMaxWalk; ++q) {
    const int32_t* nb = ctx.tt_list.data() + ctx.tt_offset[found[q]];
    const int32_t* end = ctx.tt_list.data() + ctx.tt_offset[found[q] + 1];
    for (; nb != end; ++nb) {
      const int32_t g2 = *nb;
      if (!looked.insert(std::size_t(g2))) continue;
      const RasterContext::Sphere& s = ctx.tri_sphere[g2];
      if (norm(s.centre - g.centre) > g.radius + s.radius + g.margin) continue;
      found.push_back(g2);
    }
  }
  const auto& tm = ctx.atlas.texels;
  for (const int32_t F : found) {
    if (dot(ctx.tri_normal[F], g.normal) <= 0) continue;  // the other side of a thin sheet
    if (ctx.atlas.chart_of_triangle[F] == exclude_chart) continue;  // drawn in-chart already
    Vec2 P[3];
    if (!pixels_through(ctx, patch, t, F, P)) continue;
    int cx0, cy0, cx1, cy1;
    if (!fluid_triangle_box(ctx, F, cx0, cy0, cx1, cy1)) continue;
    if (clip && !clip->any(cx0, cy0, cx1, cy1)) continue;  // every write lands in F's box
    const Vec2 uv[3] = {patch.rest_uv[t[0]], patch.rest_uv[t[1]], patch.rest_uv[t[2]]};
    const float w[3] = {vertex_weight(patch, t[0]), vertex_weight(patch, t[1]), vertex_weight(patch, t[2])};
    draw_triangle(ctx, sink, patch, P, uv, w, key, cx0, cy0, cx1, cy1, [&](int32_t idx) {
      if (tm.triangle[idx] != F) return false;
      return std::abs(dot(texel_position(ctx, std::size_t(idx)) - g.centre, g.normal)) <= g.margin;
    });
  }
}

bool skip_distorted(const RasterContext& ctx, const Patch& patch, int t) {
  if (ctx.mode == RasterMode::NoErosion) return false;
  if (patch.triangle_delta.size() != patch.triangles.size()) return false;
  return !(patch.triangle_delta[t] <= ctx.delta_max);
}

}  // namespace

static bool seam_vertex_near(const RasterContext& ctx, const Vec3& c, double radius) {
  if (ctx.seam_grid.empty()) return false;
  const double h = ctx.seam_cell;
  const int64_t x0 = int64_t(std::floor((c.x - radius) / h)), x1 = int64_t(std::floor((c.x + radius) / h));
  const int64_t y0 = int64_t(std::floor((c.y - radius) / h)), y1 = int64_t(std::floor((c.y + radius) / h));
  const int64_t z0 = int64_t(std::floor((c.z - radius) / h)), z1 = int64_t(std::floor((c.z + radius) / h));
  if ((x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > 4096) return true;  // huge triangle: assume it crosses
  for (int64_t z = z0; z <= z1; ++z)
    for (int64_t y = y0; y <= y1; ++y)
      for (int64_t x = x0; x <= x1; ++x) {
        const uint64_t key = hash64(uint64_t(x), uint64_t(y), uint64_t(z));
        auto it = std::lower_bound(ctx.seam_grid.begin(), ctx.seam_grid.end(), std::make_pair(key, int32_t(-1)));
        for (; it != ctx.seam_grid.end() && it->first == key; ++it)
          if (norm2(ctx.mesh.positions[it->second] - c) <= radius * radius) return true;
      }
  return false;
}

namespace {

// Grid cells of side h that box [c - r, c + r] touches, as (x, y, z)
// ranges; false when they are more than `limit`.
bool cell_range(const Vec3& c, double r, double h, int64_t lo[3], int64_t hi[3], int64_t limit) {
  const double p[3] = {c.x, c.y, c.z};
  int64_t count = 1;
  for (int a = 0; a < 3; ++a) {
    const double l = std::floor((p[a] - r) / h), u = std::floor((p[a] + r) / h);
    if (!(u - l < double(limit))) return false;
    lo[a] = int64_t(l), hi[a] = int64_t(u);
    count *= hi[a] - lo[a] + 1;
    if (count > limit) return false;
  }
  return true;
}

// Room for rounding in the cell ranges (they only need to overlap).
inline double widened(double r) { return r * (1 + 1e-9) + 1e-12; }

}  // namespace

void TileMask::set_writable(const RasterContext& ctx, std::vector<uint8_t> writable) {
  writable_ = std::move(writable);
  cell_ = ctx.seam_cell;
  spheres_.clear();
  everywhere_ = false;
  constexpr int64_t kMaxCells = 512;
  for (std::size_t F = 0; F < writable_.size() && !everywhere_; ++F) {
    if (!writable_[F]) continue;
    const RasterContext::Sphere& s = ctx.tri_sphere[F];
    int64_t lo[3], hi[3];
    if (!cell_range(s.centre, widened(s.radius), cell_, lo, hi, kMaxCells)) {
      everywhere_ = true;
      break;
    }
    for (int64_t z = lo[2]; z <= hi[2]; ++z)
      for (int64_t y = lo[1]; y <= hi[1]; ++y)
        for (int64_t x = lo[0]; x <= hi[0]; ++x)
          spheres_.push_back({hash64(uint64_t(x), uint64_t(y), uint64_t(z)), int32_t(F)});
  }
  std::sort(spheres_.begin(), spheres_.end());
}

bool TileMask::walk_may_write(const RasterContext& ctx, const int start[3], const Vec3& centre, double radius,
                              double margin) const {
  if (everywhere_ || writable_.empty()) return true;  // not told: walk
  for (int k = 0; k < 3; ++k)
    if (start[k] >= 0 && writable_[std::size_t(start[k])]) return true;
  if (spheres_.empty()) return false;
  int64_t lo[3], hi[3];
  if (!cell_range(centre, widened(radius + margin), cell_, lo, hi, 4096)) return true;
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y)
      for (int64_t x = lo[0]; x <= hi[0]; ++x) {
        const uint64_t key = hash64(uint64_t(x), uint64_t(y), uint64_t(z));
        for (auto it = std::lower_bound(spheres_.begin(), spheres_.end(), std::make_pair(key, int32_t(-1)));
             it != spheres_.end() && it->first == key; ++it) {
          const RasterContext::Sphere& s = ctx.tri_sphere[std::size_t(it->second)];
          // The walk's own test, to the bit.
          if (!(norm(s.centre - centre) > radius + s.radius + margin)) return true;
        }
      }
  return false;
}

namespace {

// One patch triangle drawn in its chart: pixel-space barycentrics, rest uv, w.
struct ChartTriangle {
  int32_t index;  // in the patch
  int32_t chart;
  Bary bary;
  Vec2 uv[3];
  float w[3];
  float slope = 0;  // weight_slope (hold only)
  // sure_passes, worked out at the first texel that needs the test (many
  // triangles have none: older patches keep all their texels).
  mutable uint8_t sure = kSureUnknown;
  int x0, y0, x1, y1;  // pixel bbox, clamped to the atlas
  bool ring = false;   // test the pixels around it for a seam (see rasterize_patch)
};

// Pixel box [x0, x1] x [y0, y1]; empty when x0 > x1 or y0 > y1.
struct PixelBox {
  int x0 = INT32_MAX, y0 = INT32_MAX, x1 = INT32_MIN, y1 = INT32_MIN;
  bool empty() const { return x0 > x1 || y0 > y1; }
  std::size_t width() const { return std::size_t(x1 - x0 + 1); }
  std::size_t height() const { return std::size_t(y1 - y0 + 1); }
};

// The joint pixel box of the triangles not marked in `skip` (of all without it).
PixelBox joint_box(const ChartTriangle* tris, std::size_t count, const uint8_t* skip = nullptr) {
  PixelBox b;
  for (std::size_t k = 0; k < count; ++k) {
    if (skip && skip[k]) continue;
    b.x0 = std::min(b.x0, tris[k].x0), b.y0 = std::min(b.y0, tris[k].y0);
    b.x1 = std::max(b.x1, tris[k].x1), b.y1 = std::max(b.y1, tris[k].y1);
  }
  return b;
}

// The in-chart triangles of one patch and chart: first each pixel of their
// joint bounding box learns the lowest-index triangle covering it (a small
// buffer in cache), then one row-ordered sweep does the erosion test and the
// atomic min. Row order keeps the index, key and texel arrays streaming
// instead of hopping N texels at every triangle row.
// Sets leaky[k] when triangle k covers a pixel centre outside its chart: its
// vertices are in one chart but part of it lies across a seam or boundary.
template <class Sink>
void draw_chart_group(RasterContext& ctx, Sink& sink, const Patch& patch, std::size_t patch_index, const ChartTriangle* tris,
                      std::size_t count, std::vector<int32_t>& local, uint8_t* leaky, RasterCounters& counters) {
  PixelBox box = joint_box(tris, count);
  if (box.empty()) return;
  const uint64_t* ground = rest_ground(ctx, patch_index);
  const int chart = tris[0].chart;
  const auto& tri_of = ctx.atlas.texels.triangle;
  const auto& chart_of = ctx.atlas.chart_of_triangle;
  // A patch whose pieces lie far apart in one chart would make the joint box
  // huge: draw its triangles one by one instead.
  std::size_t area = 0;
  for (std::size_t k = 0; k < count; ++k)
    area += std::size_t(tris[k].x1 - tris[k].x0 + 1) * std::size_t(tris[k].y1 - tris[k].y0 + 1);
  if (box.width() * box.height() > 16 * area + 4096) {
    for (std::size_t k = 0; k < count; ++k) {
      const ChartTriangle& t = tris[k];
      const Vec2 P[3] = {t.bary.p0, t.bary.p0 + t.bary.e1, t.bary.p0 + t.bary.e2};
      draw_triangle(ctx, sink, patch, P, t.uv, t.w, make_key(patch_index, std::size_t(t.index)), t.x0, t.y0, t.x1, t.y1,
                    [&](int32_t idx) { return chart_of[tri_of[idx]] == chart; });
      leaky[k] = 1;  // not checked on this rare path: let the seam fallback look
    }
    return;
  }
  const int Nm1 = ctx.N - 1;
  // Triangles wholly in tiles older patches keep (the ring pixels included):
  // no texel to win and no seam to find. A triangle already known to cross
  // one (leaky) goes through the fallback as before. The buffer then spans
  // the others' box only.
  const OwnedTiles* owned = sink.owned_tiles();
  thread_local std::vector<uint8_t> skip;
  if (owned) {
    const uint64_t first_key = make_key(patch_index, 0);
    skip.assign(count, 0);
    for (std::size_t k = 0; k < count; ++k) {
      const ChartTriangle& t = tris[k];
      if (!leaky[k] && owned->kept_below(t.x0 - 1, t.y0 - 1, t.x1 + 1, t.y1 + 1, chart, first_key)) {
        skip[k] = 1;
        ++counters.skipped_triangles;
      }
    }
    box = joint_box(tris, count, skip.data());
    if (box.empty()) return;
  }
  const int bx0 = box.x0, by0 = box.y0, bx1 = box.x1, by1 = box.y1;
  const std::size_t W = box.width(), H = box.height();
  const LayerMaps& layer = ctx.layer_of(patch);
  const ErosionMap& erosion = layer.erosion();
  // Pixel (x, y), texel idx, is a texel of this chart: a whole tile of it
  // says so without the texel's triangle (a load from arrays of a texel's
  // size, the draw's main cost).
  auto in_chart = [&](int x, int y, int32_t idx) {
    const int32_t c = owned ? owned->tile_chart(x, y) : -1;
    return c >= 0 ? c == chart : chart_of[tri_of[idx]] == chart;
  };
  local.assign(W * H, -1);
  // Per row of the box, the columns some triangle covers (the sweep's span).
  thread_local std::vector<int> span_lo, span_hi;
  span_lo.assign(H, INT32_MAX);
  span_hi.assign(H, INT32_MIN);
  for (std::size_t k = 0; k < count; ++k) {
    if (owned && skip[k]) continue;
    const ChartTriangle& t = tris[k];
    // Barycentric slack of one pixel per edge: pixel centres within 1 px
    // outside the triangle only serve the leak test (a seam cutting a sliver
    // off the triangle between pixel centres still shows up there).
    const Vec2 e[3] = {t.bary.e2 - t.bary.e1, t.bary.e2, t.bary.e1};  // edges opposite vertices 0, 1, 2
    const double area2 = 1.0 / std::abs(t.bary.inv_area);
    double ring[3];
    for (int i = 0; i < 3; ++i) ring[i] = -norm(e[i]) / area2;
    bool leak = leaky[k] || !t.ring;  // no ring test: nothing to look for
    // The ring around the box only matters while a leak is still looked for.
    const int pad = leak ? 0 : 1;
    const int ry0 = std::max(0, t.y0 - pad), ry1 = std::min(Nm1, t.y1 + pad);
    const int rx0 = std::max(0, t.x0 - pad), rx1 = std::min(Nm1, t.x1 + pad);
    for (int y = ry0; y <= ry1; ++y) {
      const bool in_rows = y >= t.y0 && y <= t.y1;
      int32_t* row = in_rows ? &local[std::size_t(y - by0) * W] - bx0 : nullptr;
      int lo = INT32_MAX, hi = INT32_MIN;
      for (int x = rx0; x <= rx1; ++x) {
        double l0, l1, l2;
        t.bary.at(x, y, l0, l1, l2);
        if (in_rows && x >= t.x0 && x <= t.x1 && l0 >= -kInsideTol && l1 >= -kInsideTol && l2 >= -kInsideTol) {
          if (row[x] < 0) row[x] = int32_t(k);
          lo = std::min(lo, x), hi = std::max(hi, x);
        } else if (!leak && l0 >= ring[0] && l1 >= ring[1] && l2 >= ring[2]) {
          const int32_t idx = ctx.index[std::size_t(y) * ctx.N + x];
          leak = idx < 0 || !in_chart(x, y, idx);
        }
      }
      if (lo <= hi) {
        span_lo[std::size_t(y - by0)] = std::min(span_lo[std::size_t(y - by0)], lo);
        span_hi[std::size_t(y - by0)] = std::max(span_hi[std::size_t(y - by0)], hi);
      }
    }
    leaky[k] = leak && t.ring ? 1 : leaky[k];
  }
  const std::size_t N = std::size_t(ctx.N);
  // Consecutive rows of the box are N texels apart in the index, and their
  // chart texels far apart in the key and triangle arrays: too far for the
  // hardware prefetcher, so every row would start with cache misses in all
  // three. Ask for the index row two ahead and for the keys and triangles of
  // the next row (whose index row is in cache by then).
  auto prefetch_rows = [&](int y) {
    if (y + 2 <= by1)
      for (int x = bx0; x <= bx1 + 15; x += 16) __builtin_prefetch(&ctx.index[std::size_t(y + 2) * N + std::min(x, bx1)]);
    if (y + 1 > by1) return;
    const int32_t* next = &ctx.index[std::size_t(y + 1) * N];
    int a = bx0, b = bx1;
    while (a <= b && next[a] < 0) ++a;
    while (b >= a && next[b] < 0) --b;
    if (a > b) return;
    // Pixels in row order are texels in index order: [next[a], next[b]] is
    // one contiguous run of each array.
    for (int32_t i = next[a]; i <= next[b] + 7; i += 8) sink.prefetch(std::min(i, next[b]));
    for (int32_t i = next[a]; i <= next[b] + 15; i += 16) __builtin_prefetch(&tri_of[std::min(i, next[b])]);
  };
  sink.open_box(bx0, by0, bx1, by1);
  for (int y = by0; y <= by1; ++y) {
    prefetch_rows(y);
    const int32_t* lrow = &local[std::size_t(y - by0) * W] - bx0;
    const int32_t* irow = &ctx.index[std::size_t(y) * N];
    const int x_end = span_hi[std::size_t(y - by0)];
    for (int x = span_lo[std::size_t(y - by0)]; x <= x_end; ++x) {
      const int32_t k = lrow[x];
      if (k < 0) continue;
      const int32_t idx = irow[x];
      if (idx < 0 || !in_chart(x, y, idx)) {
        leaky[k] = 1;
        continue;
      }
      const ChartTriangle& t = tris[k];
      const uint64_t key = make_key(patch_index, std::size_t(t.index));
      if (sink.taken(idx, key)) continue;
      double l0, l1, l2;
      t.bary.at(x, y, l0, l1, l2);
      const double u = l0 * t.uv[0].x + l1 * t.uv[1].x + l2 * t.uv[2].x;
      const double v = l0 * t.uv[0].y + l1 * t.uv[1].y + l2 * t.uv[2].y;
      const double wt = l0 * t.w[0] + l1 * t.w[1] + l2 * t.w[2];
      if (t.sure == kSureUnknown) t.sure = sure_passes(ctx, layer, t.uv, t.w, t.slope);
      if (!passes(ctx, patch, layer, erosion, ground, idx, x, y, u, v, wt, t.slope, t.sure)) continue;
      sink.put(idx, x, y, key, u, v, wt);
    }
  }
  sink.close_box();
}

// Erosion and Advect: each texel keeps the smallest key by atomic min.
// With `owned` (draw_patches), first writes keep OwnedTiles up to date.
struct KeySink {
  std::vector<uint64_t>& keys;
  OwnedTiles* owned = nullptr;
  // First writes within the box of open_box, per tile: handed to `owned` at
  // close_box, one atomic update per tile instead of one per texel. A tile
  // then looks open a little longer, which only skips less.
  struct Tally {
    uint32_t writes = 0;
    uint64_t key = 0;  // the largest key written
  };
  std::vector<Tally>* tally = nullptr;
  int tx0 = 0, ty0 = 0, tw = 0;
  const OwnedTiles* owned_tiles() const { return owned; }
  void prefetch(int32_t idx) const { __builtin_prefetch(&keys[idx]); }
  bool taken(int32_t idx, uint64_t key) const {
    return std::atomic_ref<uint64_t>(keys[idx]).load(std::memory_order_relaxed) <= key;
  }
  void put(int32_t idx, int x, int y, uint64_t key, double, double, double) {
    std::atomic_ref<uint64_t> slot(keys[idx]);
    uint64_t cur = slot.load(std::memory_order_relaxed);
    while (cur > key && !slot.compare_exchange_weak(cur, key, std::memory_order_relaxed)) {
    }
    if (!owned || cur != kNoKey) return;
    if (!tally) {
      owned->first_write(x, y, key);
      return;
    }
    Tally& e = (*tally)[std::size_t((y >> TileGrid::kShift) - ty0) * std::size_t(tw) + std::size_t((x >> TileGrid::kShift) - tx0)];
    ++e.writes;
    e.key = std::max(e.key, key);
  }
  // Pixel box [x0, x1] x [y0, y1] (inside the atlas): put's pixels until close_box.
  void open_box(int x0, int y0, int x1, int y1) {
    if (!owned) return;
    thread_local std::vector<Tally> buffer;
    tx0 = x0 >> TileGrid::kShift, ty0 = y0 >> TileGrid::kShift, tw = (x1 >> TileGrid::kShift) - tx0 + 1;
    const int th = (y1 >> TileGrid::kShift) - ty0 + 1;
    buffer.assign(std::size_t(tw) * std::size_t(th), Tally{});
    tally = &buffer;
  }
  void close_box() {
    if (!tally) return;
    for (std::size_t i = 0; i < tally->size(); ++i) {
      const Tally& e = (*tally)[i];
      if (e.writes == 0) continue;
      const int x = (tx0 + int(i % std::size_t(tw))) << TileGrid::kShift, y = (ty0 + int(i / std::size_t(tw))) << TileGrid::kShift;
      owned->first_write(x, y, e.key, e.writes);
    }
    tally = nullptr;
  }
};

// Blend: every texel the patch covers is collected (raster_blend.cpp sums them).
struct SampleSink {
  std::vector<BlendSample>& out;
  const OwnedTiles* owned_tiles() const { return nullptr; }
  void open_box(int, int, int, int) {}
  void close_box() {}
  void prefetch(int32_t) const {}
  bool taken(int32_t, uint64_t) const { return false; }
  void put(int32_t idx, int, int, uint64_t key, double u, double v, double w) {
    out.push_back({idx, uint32_t(key & 0xffffffffu), u, v, w});
  }
};

// `clip` (optional): only texels in its marked tiles matter to the caller.
// Triangles drawn in their chart whose pixels (and the ring around them) lie
// in unmarked tiles are left out, but those that look for a seam (`ring`):
// a seam could send them through the fallback into another chart's marked
// texels. The fallback skips fluid triangles whose boxes are unmarked.
template <class Sink>
void rasterize_patch_into(RasterContext& ctx, Sink& sink, const Patch& patch, std::size_t patch_index,
                          RasterCounters& counters, const TileMask* clip = nullptr) {
  const std::size_t nv = patch.positions.size();
  if (patch.rest_uv.size() != nv) return;
  // Per vertex: its fluid triangle and, through it, its atlas pixel position.
  std::vector<int> vtri(nv);
  std::vector<Vec2> vpix(nv);
  std::vector<uint8_t> vok(nv);
  for (std::size_t v = 0; v < nv; ++v) {
    vtri[v] = vertex_triangle(ctx, patch, int(v));
    vok[v] = vtri[v] >= 0 && to_pixels(ctx, vtri[v], patch.positions[v], vpix[v]);
  }
  std::vector<int32_t> scratch;
  thread_local SeamWalk walk_here;
  SeamWalk& walk = walk_here;
  std::vector<ChartTriangle> in_chart;
  std::vector<uint8_t> crossing;
  in_chart.reserve(patch.triangles.size());
  const int Nm1 = ctx.N - 1;
  for (std::size_t ti = 0; ti < patch.triangles.size(); ++ti) {
    const Tri& t = patch.triangles[ti];
    if (skip_distorted(ctx, patch, int(ti))) {
      ++counters.distorted_triangles;
      continue;
    }
    const int c0 = vok[t[0]] ? ctx.atlas.chart_of_triangle[vtri[t[0]]] : -1;
    const bool same_chart = c0 >= 0 && vok[t[1]] && vok[t[2]] && ctx.atlas.chart_of_triangle[vtri[t[1]]] == c0 &&
                            ctx.atlas.chart_of_triangle[vtri[t[2]]] == c0;
    if (same_chart) {
      ChartTriangle ct;
      ct.index = int32_t(ti);
      ct.chart = c0;
      const Vec2 P[3] = {vpix[t[0]], vpix[t[1]], vpix[t[2]]};
      if (!ct.bary.init(P)) continue;
      for (int k = 0; k < 3; ++k) ct.uv[k] = patch.rest_uv[t[k]], ct.w[k] = vertex_weight(patch, t[k]);
      if (ctx.hold) ct.slope = float(weight_slope(ct.uv, ct.w));
      ct.x0 = std::max(0, int(std::ceil(std::min({P[0].x, P[1].x, P[2].x}) - 1e-7)));
      ct.x1 = std::min(Nm1, int(std::floor(std::max({P[0].x, P[1].x, P[2].x}) + 1e-7)));
      ct.y0 = std::max(0, int(std::ceil(std::min({P[0].y, P[1].y, P[2].y}) - 1e-7)));
      ct.y1 = std::min(Nm1, int(std::floor(std::max({P[0].y, P[1].y, P[2].y}) + 1e-7)));
      // Vertices in one chart do not keep the triangle's middle out of
      // another one: near a seam, the parts beyond the chart go through the
      // fallback too (pixel centres alone miss slivers under small triangles).
      // Only for triangles of a few pixels: larger ones are tested on the
      // pixels in and around them (draw_chart_group), much cheaper.
      const double area2 = std::abs(cross(P[1] - P[0], P[2] - P[0]));
      const bool tiny = area2 < 32;
      const bool near = ctx.near_seam[vtri[t[0]]] || ctx.near_seam[vtri[t[1]]] || ctx.near_seam[vtri[t[2]]];
      // The pixel ring test is needed where a seam may pass: next to one, or
      // when the triangle is large against its vertices' fluid triangles (a
      // seam could then cross it away from them).
      ct.ring = near || area2 > 4 * std::min({ctx.tri_area2_px[vtri[t[0]]], ctx.tri_area2_px[vtri[t[1]]],
                                              ctx.tri_area2_px[vtri[t[2]]]});
      if (clip && !clip->any(ct.x0 - 1, ct.y0 - 1, ct.x1 + 1, ct.y1 + 1)) {
        if (!ct.ring) continue;
        // Its pixels miss every marked tile: only the fallback could write,
        // and not when its walk cannot find a writable triangle.
        const PatchTriGeometry g = patch_tri_geometry(patch, t);
        const int vt[3] = {vtri[t[0]], vtri[t[1]], vtri[t[2]]};
        if (!clip->walk_may_write(ctx, vt, g.centre, g.radius, g.margin)) continue;
      }
      bool crosses = false;
      if (tiny && near) {
        const PatchTriGeometry g = patch_tri_geometry(patch, t);
        crosses = seam_vertex_near(ctx, g.centre, g.radius + g.margin);
      }
      if (ct.x0 <= ct.x1 && ct.y0 <= ct.y1) {
        in_chart.push_back(ct);
        crossing.push_back(crosses);
      } else if (crosses) {
        const int vt[3] = {vtri[t[0]], vtri[t[1]], vtri[t[2]]};
        ++counters.seam_triangles;
        draw_seam_triangle(ctx, sink, patch, int(ti), vt, make_key(patch_index, ti), walk, c0, clip);
      }
    } else {
      ++counters.seam_triangles;
      const int vt[3] = {vtri[t[0]], vtri[t[1]], vtri[t[2]]};
      draw_seam_triangle(ctx, sink, patch, int(ti), vt, make_key(patch_index, ti), walk, -1, clip);
    }
  }
  // Group by chart (stable: triangle order kept inside a chart).
  std::vector<uint32_t> order(in_chart.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = uint32_t(k);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return in_chart[a].chart < in_chart[b].chart; });
  std::vector<ChartTriangle> sorted(in_chart.size());
  std::vector<uint8_t> leaky(in_chart.size(), 0);
  for (std::size_t k = 0; k < order.size(); ++k) sorted[k] = in_chart[order[k]], leaky[k] = crossing[order[k]];
  in_chart.swap(sorted);
  for (std::size_t b = 0; b < in_chart.size();) {
    std::size_t e = b;
    while (e < in_chart.size() && in_chart[e].chart == in_chart[b].chart) ++e;
    draw_chart_group(ctx, sink, patch, patch_index, &in_chart[b], e - b, scratch, &leaky[b], counters);
    b = e;
  }
  // The parts of leaky triangles beyond their chart, through the fallback.
  for (std::size_t k = 0; k < in_chart.size(); ++k) {
    if (!leaky[k]) continue;
    ++counters.seam_triangles;
    const Tri& t = patch.triangles[in_chart[k].index];
    const int vt[3] = {vtri[t[0]], vtri[t[1]], vtri[t[2]]};
    draw_seam_triangle(ctx, sink, patch, in_chart[k].index, vt,
                       make_key(patch_index, std::size_t(in_chart[k].index)), walk, in_chart[k].chart, clip);
  }
}

}  // namespace

void rasterize_patch(RasterContext& ctx, const Patch& patch, std::size_t patch_index, RasterCounters& counters,
                     OwnedTiles* owned) {
  if (ctx.mode != RasterMode::Blend) {
    KeySink sink{ctx.keys, owned};
    rasterize_patch_into(ctx, sink, patch, patch_index, counters);
    return;
  }
  thread_local std::vector<BlendSample> samples;
  samples.clear();
  SampleSink sink{samples};
  rasterize_patch_into(ctx, sink, patch, patch_index, counters);
  blend_patch(ctx, patch_index, ctx.layer_of(patch), samples);
}

bool winner_pixels(const RasterContext& ctx, const Patch& patch, int ti, int texel_tri, Vec2 out[3],
                   bool* same_chart) {
  const Tri& t = patch.triangles[ti];
  if (same_chart) *same_chart = false;
  int vt[3];
  for (int k = 0; k < 3; ++k) vt[k] = vertex_triangle(ctx, patch, t[k]);
  bool ok = vt[0] >= 0 && vt[1] >= 0 && vt[2] >= 0;
  if (ok) {
    const int c0 = ctx.atlas.chart_of_triangle[vt[0]];
    ok = ctx.atlas.chart_of_triangle[vt[1]] == c0 && ctx.atlas.chart_of_triangle[vt[2]] == c0 &&
         ctx.atlas.chart_of_triangle[texel_tri] == c0;
    for (int k = 0; ok && k < 3; ++k) ok = to_pixels(ctx, vt[k], patch.positions[t[k]], out[k]);
    if (ok) {
      if (same_chart) *same_chart = true;
      return true;
    }
  }
  return pixels_through(ctx, patch, t, texel_tri, out);
}

void draw_patch_keys(RasterContext& ctx, std::vector<uint64_t>& keys, const Patch& patch, std::size_t patch_index,
                     const TileMask& clip) {
  KeySink sink{keys};
  RasterCounters unused;
  rasterize_patch_into(ctx, sink, patch, patch_index, unused, &clip);
}

}  // namespace detail

using namespace detail;

void draw_patches(RasterBuffers& r, const PatchSet& patches) {
  RasterContext& ctx = *r.context;
  RasterStats& st = r.stats;
  const std::size_t np = patches.patches.size();
  if (np >= (std::size_t(1) << 32) - 1) throw std::invalid_argument("rasterize: too many patches");
  for (const Patch& patch : patches.patches)
    if (patch.layer >= ctx.layer_first.size())
      throw std::invalid_argument("rasterize: patch " + std::to_string(patch.id) + " has layer " +
                                  std::to_string(patch.layer) + " of " + std::to_string(ctx.layer_first.size()));
  if (ctx.mode == RasterMode::Blend) ctx.blend.contributed.assign(np, 0);
  bind_rest_ground(ctx, patches);
  // Every patch triangle, any order (the atomic min decides).
  std::vector<RasterCounters> counters(np);
  // All threads go through the patches from the oldest to the youngest, a
  // few at a time, so a texel's keeper is usually drawn before the younger
  // patches that cover it, which then stop at the key test instead of
  // eroding and writing. (Splitting the range in halves had one thread draw
  // the youngest patches first.) The result does not depend on the order.
  constexpr std::size_t kBatch = 8;
  std::atomic<std::size_t> next_batch{0};
  // Blend sums every patch: nothing to skip.
  const std::unique_ptr<OwnedTiles> owned = ctx.mode == RasterMode::Blend ? nullptr : std::make_unique<OwnedTiles>(ctx);
  const std::size_t workers = std::size_t(std::max(1, thread_count()));
  parallel_for(workers, [&](std::size_t, std::size_t) {
    for (;;) {
      const std::size_t b = next_batch.fetch_add(1, std::memory_order_relaxed) * kBatch;
      if (b >= np) break;
      for (std::size_t p = b; p < std::min(np, b + kBatch); ++p)
        rasterize_patch(ctx, patches.patches[p], p, counters[p], owned.get());
    }
  }, 1);
  for (const auto& c : counters) {
    st.seam_triangles += c.seam_triangles;
    st.skipped_triangles += c.skipped_triangles;
    st.distorted_triangles += c.distorted_triangles;
  }
}
}  // namespace lapflow
