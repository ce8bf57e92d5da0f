#pragma once
// The state behind RasterBuffers: one frame's lapped rasterization, carried
// through the steps of raster.hpp (setup.cpp: set-up; draw.cpp: draw;
// holes.cpp: hole filling; resolve.cpp: resolve; retire.cpp: retirement;
// blend.cpp: Blend mode; dilate.cpp: the gutter).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <vector>

#include "lapflow/raster/raster.hpp"

namespace lapflow::detail {

inline constexpr uint64_t kNoKey = std::numeric_limits<uint64_t>::max();

inline uint64_t make_key(std::size_t patch_index, std::size_t triangle) {
  return (uint64_t(patch_index) << 32) | uint64_t(uint32_t(triangle));
}

/// The feature map's maximum over a window of 2 kx + 1 by 2 ky + 1 pixels.
Image max_filter(const Image& img, int kx, int ky);

/// The minimum of a one-channel image over pixel rectangles: a pyramid of
/// 2 x 2 minima, so a rectangle of side up to 2^k costs at most four lookups
/// at level k (the minimum over a rectangle up to twice as large: never
/// above the true minimum).
struct MinPyramid {
  std::vector<std::vector<float>> levels;  ///< level 0: the image
  std::vector<int> widths, heights;
  void build(const Image& img);
  bool empty() const { return levels.empty(); }
  /// A lower bound of the pixels in [x0, x1] x [y0, y1] (inclusive, inside the image).
  float min_over(int x0, int y0, int x1, int y1) const;
};

/// One texel a patch triangle covers (Blend mode): chart texel, patch
/// triangle, and the patch's (u, v, w) there.
struct BlendSample {
  int32_t texel;
  uint32_t triangle;
  double u, v, w;
};

/// Blend mode accumulators (docs/raster.md, "Blend mode"). Weights and
/// weighted values are summed in 2^-32 fixed point with 64-bit integer atomic
/// adds: exact, so the sums do not depend on the order or the thread count.
inline constexpr double kBlendScale = 4294967296.0;  // 2^32
/// A texel is covered in Blend mode when its summed weight exceeds this.
inline constexpr double kBlendMinWeight = 1e-3;
inline constexpr int64_t kBlendMinFixed = int64_t(kBlendMinWeight * kBlendScale);
struct BlendState {
  bool trilinear = true;
  /// 1: sample and sum every covering patch; 2: write ctx.keys of the texels'
  /// largest-weight patches (the AOV winners).
  int phase = 1;
  /// Per chart texel, 5 values: sum W, sum W R, sum W G, sum W B, sum W H.
  std::vector<int64_t> sums;
  /// Per chart texel: float bits of the largest w << 32 | ~patch index (atomic
  /// max: the largest weight, ties to the oldest patch).
  std::vector<uint64_t> best;
  /// Per patch index: chart texels it gave weight to (for retirement).
  std::vector<uint64_t> contributed;
  bool covered(std::size_t i) const { return sums[i * 5] > kBlendMinFixed; }
};

/// A fluid triangle's map from 3D points to atlas uv: p is projected on the
/// triangle's plane (barycentrics b1, b2 from the dot products with its edges,
/// unclamped) and carried by the corner uv (draw.cpp, to_pixels). Computed
/// once per frame instead of once per patch vertex.
struct TrianglePixelMap {
  Vec3 a, e0, e1;                // corner 0 and the edges to corners 1 and 2
  double d00 = 0, d01 = 0, d11 = 0, den = 0;
  Vec2 uv0, du1, du2;            // corner 0's uv and the edges' uv
  bool ok = false;               // not degenerate
};

/// The held test's feature map for one window (RasterContext::held_reach
/// in exemplar pixels) and its minima.
struct HeldTables {
  int kx = -1, ky = -1;
  ErosionMap erosion;
  MinPyramid min;
};

/// What the raster derives from one exemplar frame's feature map, built on
/// first use and kept with the RasterExemplar: the bake's frames, and its
/// two passes, share them. The held tables of the last two windows asked
/// for are kept, one for each pass's atlas (a window changes only when that
/// atlas's texel size crosses a pixel of the exemplar).
}  // namespace lapflow::detail

struct lapflow::ExemplarTables {
  std::mutex mutex;
  std::shared_ptr<const detail::MinPyramid> erosion_min;
  std::shared_ptr<const detail::HeldTables> held[2];
  int last_used = 0;  ///< which of `held` was asked for last
};

namespace lapflow::detail {

/// What the raster reads of one exemplar layer (Patch::layer) and, for an
/// animated one, one of its frames: its mips and erosion map, and the
/// tables built from them for this atlas.
struct LayerMaps {
  const RasterExemplar* exemplar = nullptr;
  /// RasterOptions::hold (Erosion mode): the held test's feature map (the
  /// maximum within RasterContext::held_reach in uv: one atlas texel) and
  /// its minima.
  std::shared_ptr<const HeldTables> held;
  /// Minima of exemplar->erosion.feature (Erosion mode): a patch triangle
  /// whose every texel passes the test is known before its pixels are
  /// visited (draw.cpp, sure_passes).
  std::shared_ptr<const MinPyramid> erosion_min;
  double lod = 0;  ///< the exemplar's level of detail on this atlas
  const ErosionMap& erosion() const { return exemplar->erosion; }
  const ErosionMap& held_erosion() const { return held->erosion; }
};

struct RasterContext {
  const TriMesh& mesh;
  const SurfaceAtlas& atlas;
  RasterMode mode;
  double delta_max;
  RasterOptions options;
  /// One per exemplar layer and frame: layer l's frames from
  /// layer_first[l] (one in a bake of one still exemplar).
  std::vector<LayerMaps> layers;
  std::vector<uint32_t> layer_first, layer_frames;
  /// The maps of the patch's layer at the exemplar frame it shows.
  const LayerMaps& layer_of(const Patch& patch) const {
    const uint32_t n = layer_frames[patch.layer];
    return layers[layer_first[patch.layer] + (n > 1 ? uint32_t(options.clock.frame_of(patch, int(n))) : 0u)];
  }
  TriangleLocator locate_fn;                ///< owned copy of the caller's locator (may be empty)
  const TriangleLocator* locate = nullptr;  ///< &locate_fn when it is set
  double radius = 0.1;  ///< r (metres)
  double texel_world_size = 0;  ///< metres per atlas texel (RasterStats::texel_world_size)
  int N = 0;
  /// Texel-map index of every atlas pixel y * N + x, -1 outside charts.
  std::vector<int32_t> index;
  /// Per chart texel: the smallest key of a patch that keeps it (kNoKey: none).
  std::vector<uint64_t> keys;
  /// Per chart texel, set by fill_holes: its key was taken from a neighbour
  /// or the nearest patch (closed or forced), not won by the erosion test.
  std::vector<uint8_t> extrapolated;
  /// Per chart texel, set by fill_holes: in a small hole closed by its
  /// neighbours (RasterOptions::small_hole). Empty when none was.
  std::vector<uint8_t> closed;
  /// Per patch index, kHeldWords words: the cells of Patch::held for the
  /// next frame, marked by resolve_texels and moved into the patches by
  /// retire_patches (empty when RasterOptions::hold is off).
  std::vector<uint64_t> held_next;
  /// RasterOptions::hold is on (Erosion mode), and the held test's reach in
  /// uv (one atlas texel).
  bool hold = false;
  /// Patches from this index on were born in this frame's hole filling.
  std::size_t newborn_from = std::numeric_limits<std::size_t>::max();
  double held_reach = 0;
  /// RasterOptions::rest_bound: per patch index, the slot of its cells in
  /// `rest_ground` (-1: not bound: outside a render a patch that moves, or
  /// one with no held cell), and there kHeldWords words per bound patch: its
  /// held cells grown by rest_reach_cells, where alone it may win a texel.
  std::vector<int32_t> rest_ground_slot;
  std::vector<uint64_t> rest_ground;
  /// Per fluid triangle: the map of to_pixels.
  std::vector<TrianglePixelMap> pixel_map;
  /// Fluid triangles: unit normal (seam fallback).
  std::vector<Vec3> tri_normal;
  /// A fluid triangle's centroid and bounding radius, side by side: the seam
  /// fallback's walk reads both for every triangle it meets.
  struct Sphere {
    Vec3 centre;
    double radius;
  };
  std::vector<Sphere> tri_sphere;
  /// Twice each fluid triangle's area in atlas pixels.
  std::vector<double> tri_area2_px;
  /// Vertex -> incident fluid triangles (CSR), in triangle order.
  std::vector<int32_t> vt_offset, vt_list;
  /// Fluid triangle -> the other triangles sharing a vertex with it (CSR):
  /// its vertices' lists of vt_list in vertex order, each triangle where it
  /// first appears. The seam fallback's walk meets its triangles in the
  /// order the three vertex lists give, without their repeats.
  std::vector<int32_t> tt_offset, tt_list;
  /// Fluid triangles with a vertex shared with another chart.
  std::vector<uint8_t> near_seam;
  /// Seam vertices (shared by two charts) bucketed on a grid of `seam_cell`
  /// metres: sorted (cell hash, vertex) pairs.
  double seam_cell = 0;
  std::vector<std::pair<uint64_t, int32_t>> seam_grid;
  /// Blend mode only.
  BlendState blend;

  RasterContext(const TriMesh& m, const SurfaceAtlas& a, RasterMode mo, double dm)
      : mesh(m), atlas(a), mode(mo), delta_max(dm) {}
};

/// The surface point under chart texel i's centre (its fluid triangle at
/// texel_barycentrics).
inline Vec3 texel_position(const RasterContext& ctx, std::size_t i) {
  const TexelMap& tm = ctx.atlas.texels;
  const Tri& T = ctx.mesh.triangles[tm.triangle[i]];
  float fb1, fb2;
  texel_barycentrics(ctx.atlas.corner_uv, ctx.N, tm.texel[i], tm.triangle[i], fb1, fb2);
  const double b1 = fb1, b2 = fb2;
  return ctx.mesh.positions[T[0]] * (1 - b1 - b2) + ctx.mesh.positions[T[1]] * b1 + ctx.mesh.positions[T[2]] * b2;
}

/// Counters of one raster call (summed per chunk, integers only).
struct RasterCounters {
  std::size_t seam_triangles = 0, distorted_triangles = 0, skipped_triangles = 0;
};

/// Builds index, keys and the fluid-triangle tables.
void setup_context(RasterContext& ctx);

/// Tiles that older patches keep (tiles.hpp), used by draw_patches to skip
/// drawing that cannot win a texel.
struct OwnedTiles;

/// Rasterizes every triangle of `patch` (PatchSet index `patch_index`) into
/// ctx.keys by atomic min. Safe to call concurrently for different patches.
/// `owned`: see OwnedTiles (draw_patches only; it must see every write).
void rasterize_patch(RasterContext& ctx, const Patch& patch, std::size_t patch_index, RasterCounters& counters,
                     OwnedTiles* owned = nullptr);

/// Tiles the merge test's second draw looks at (tiles.hpp).
struct TileMask;

/// Rasterizes `patch` into `keys` (one per chart texel) by atomic min,
/// leaving out triangles that reach no tile `clip` marks: the merge test's
/// second draw (retire.cpp). Safe to call concurrently for different patches.
void draw_patch_keys(RasterContext& ctx, std::vector<uint64_t>& keys, const Patch& patch, std::size_t patch_index,
                     const TileMask& clip);

/// sure_passes: every texel of a patch triangle passes the erosion test
/// (keeps, kSureKeeps) or the held test (keeps_held, kSureHeld).
inline constexpr uint8_t kSureKeeps = 1, kSureHeld = 2, kSureUnknown = 255;
/// Which erosion tests every texel of the patch triangle with rest uv `uv`,
/// weights `w` and weight slope `slope` (the held test's) passes, from bounds
/// over the triangle alone: the same decisions as the texels' own tests
/// wherever it says so, and 0 outside RasterMode::Erosion.
uint8_t sure_passes(const RasterContext& ctx, const LayerMaps& layer, const Vec2 uv[3], const float w[3], double slope);

/// Blend mode: the samples of one patch (any order, duplicates allowed; the
/// lowest patch triangle of each texel counts) added to ctx.blend (phase 1)
/// or written as AOV winner keys (phase 2). Sorts `samples`.
void blend_patch(RasterContext& ctx, std::size_t patch_index, const LayerMaps& layer, std::vector<BlendSample>& samples);
/// Blend mode: ctx.keys set to 0 on chart texels whose summed weight covers
/// them, kNoKey elsewhere (what hole filling reads).
void blend_mark_coverage(RasterContext& ctx);

/// Atlas pixel coordinates (texel centres at integers) of the three vertices
/// of patch triangle t as seen from the texel's fluid triangle `texel_tri`:
/// the same numbers rasterize_patch used when the key was written.
/// `same_chart` (optional) tells whether they do not depend on `texel_tri`.
bool winner_pixels(const RasterContext& ctx, const Patch& patch, int t, int texel_tri, Vec2 out[3],
                   bool* same_chart = nullptr);

/// Step 8: new patches at the centres of the holes (open chart texels,
/// 8-connected within a chart), in rounds of seeds 2r apart created in
/// parallel, each drawn into the still-open texels. Returns patches born.
/// Holes no wider than RasterOptions::small_hole x r (and not a whole chart)
/// get no patch: they are left open for propagate_keys, and `closed` counts
/// their texels. `make_patch` must be set: a render of a tracked state has
/// no birth to make and does not call this (fill_holes).
std::size_t create_hole_patches(RasterContext& ctx, PatchSet& patches, int frame, const PatchMaker& make_patch,
                                std::size_t max_patches, std::size_t& closed);
/// Gives every open chart texel the key of a covered 8-neighbour in the same
/// chart, repeatedly (Jacobi sweeps: deterministic). Returns texels so filled;
/// the texels it could not reach (in texel order) go to `left` when given.
std::size_t propagate_keys(RasterContext& ctx, std::vector<uint32_t>* left = nullptr);

/// Before hole filling (RasterOptions::hold): hole texels up to two layers
/// (any depth for a patch at rest, Patch::at_rest)
/// deep take a neighbour's patch where that patch's map, extended to them,
/// lands in a cell it holds. Returns the texels so closed.
std::size_t close_held_texels(RasterContext& ctx, const PatchSet& patches);

/// Last resort after propagate_keys, for chart texels with no covered texel
/// in their chart (a tiny chart whose newborn failed): each takes the key of
/// the patch triangle nearest to its surface point in 3D (ties: lowest key)
/// among those whose map extends to it; the resolve extrapolates that map.
/// `open`: the open chart texels in texel order (propagate_keys's `left`).
/// Returns texels so filled.
std::size_t cover_from_nearest_patch(RasterContext& ctx, const PatchSet& patches, const std::vector<uint32_t>& open);

/// Fills texels outside charts from the nearest chart texel: `gutter`
/// 8-neighbour dilation passes, then a row-nearest and a row-copy fill.
/// `source` holds, per pixel, its own index on chart texels and -1 elsewhere;
/// on return it names a chart pixel for every pixel (when any exists).
void dilate_sources(std::vector<int32_t>& source, int N, int gutter);

/// Patch vertex v's weight (1 when the patch has none).
inline float vertex_weight(const Patch& patch, int v) {
  return patch.weight.size() == patch.positions.size() ? patch.weight[v] : 1.f;
}

/// The length of the gradient in uv of w interpolated over a patch triangle.
inline double weight_slope(const Vec2 uv[3], const float w[3]) {
  const Vec2 d1 = uv[1] - uv[0], d2 = uv[2] - uv[0];
  const double det = cross(d1, d2);
  if (!(std::abs(det) > 1e-14)) return 0;
  const double dw1 = double(w[1]) - w[0], dw2 = double(w[2]) - w[0];
  const double gx = (dw1 * d2.y - dw2 * d1.y) / det, gy = (dw2 * d1.x - dw1 * d2.x) / det;
  return std::sqrt(gx * gx + gy * gy);
}

/// Barycentric coordinates of pixel centre (x, y) in pixel-space triangle P.
struct Bary {
  Vec2 p0, e1, e2;
  double inv_area = 0;
  bool init(const Vec2 P[3]) {
    p0 = P[0];
    e1 = P[1] - P[0];
    e2 = P[2] - P[0];
    const double a = cross(e1, e2);
    if (!(std::abs(a) > 1e-12)) return false;
    inv_area = 1.0 / a;
    return true;
  }
  void at(double x, double y, double& l0, double& l1, double& l2) const {
    const Vec2 d{x - p0.x, y - p0.y};
    l1 = cross(d, e2) * inv_area;
    l2 = cross(e1, d) * inv_area;
    l0 = 1.0 - l1 - l2;
  }
};

/// Chart texel i at pixel (x, y) has its 3x3 neighbourhood in its own chart.
/// Only such texels mark held cells (resolve_texels).
bool interior_texel(const RasterContext& ctx, std::size_t i, int x, int y);
/// The draw's test with the hold at (u, v, w) of patch triangle t, as if
/// (u, v) were held; `layer` is the patch's (RasterContext::layer_of).
bool held_test_keeps(const RasterContext& ctx, const LayerMaps& layer, const Patch& patch, const Tri& t, double u,
                     double v, double w);

}  // namespace lapflow::detail
