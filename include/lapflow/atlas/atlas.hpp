#pragma once
/// \file atlas.hpp The surface atlas of one fluid frame (ALGORITHM.md step 6,
/// Lévy et al. 2002): charts, LSCM, packing at one texel density, texel map.
///
/// UV convention: atlas uv (0,0) is the bottom-left corner of the image (OBJ
/// and renderers' convention). Texel (x, y), with image row y counted from the
/// top, has its centre at u = (x + 0.5) / N, v = 1 - (y + 0.5) / N.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "lapflow/surface/mesh.hpp"

namespace lapflow {

struct AtlasOptions {
  int resolution = 2048;    ///< atlas width = height in texels
  /// Empty texels between any two charts, shared by the two: no texel
  /// within `gutter` (8-neighbour steps) of a chart's footprint (every texel
  /// its triangles touch) lies in another chart's footprint, and footprints
  /// keep ceil(gutter / 2) texels from the atlas's edges. Dilating every
  /// chart by `gutter` fills each gap from both sides: a texel within
  /// floor(gutter / 2) of a chart's texels takes that chart's colour
  /// (docs/atlas.md, "Gutter"). Dropped to 0 (report.packing_overflow) only
  /// when the charts cannot be separated at this resolution at all.
  int gutter = 4;
  /// A chart is split and redone when more than 2% of its surface area (or 5%
  /// of its uv area) has a texel density outside [1/max_stretch, max_stretch]
  /// of the chart's mean.
  double max_stretch = 1.25;
};

/// Every chart texel (centre inside a chart triangle), sorted by texel index
/// y * N + x. The rasterizer streams these. Where in its triangle a texel
/// lies is texel_barycentrics (8 bytes a texel fewer to build and keep: the
/// few steps that need a texel's surface point work it out).
struct TexelMap {
  std::vector<uint32_t> texel;      ///< y * N + x
  std::vector<int32_t> triangle;    ///< fluid triangle under the texel centre
  std::size_t size() const { return texel.size(); }
};

/// The barycentrics (of vertices 1 and 2, as floats) of texel `texel`'s
/// centre (y * N + x, N = `resolution`) in fluid triangle `triangle`, from
/// the triangle's corner uvs, clamped into the triangle, with the arithmetic
/// of the texel map's fill, so the floats are the fill's own. The map does
/// not store them (docs/atlas.md, "Texel map").
inline void texel_barycentrics(const std::vector<Vec2>& corner_uv, int resolution, uint32_t texel, int32_t triangle,
                               float& b1, float& b2) {
  const int n = resolution;
  const std::size_t t = std::size_t(triangle);
  const Vec2 a = corner_uv[3 * t] * n, bb = corner_uv[3 * t + 1] * n, c = corner_uv[3 * t + 2] * n;
  const double area2 = cross(bb - a, c - a);
  const std::size_t x = texel % uint32_t(n), y = texel / uint32_t(n);
  const Vec2 p{x + 0.5, double(n - 1 - y) + 0.5};
  const double w1 = std::clamp(cross(a - c, p - c) / area2, 0.0, 1.0);
  const double w2 = std::clamp(cross(bb - a, p - a) / area2, 0.0, 1.0 - w1);
  b1 = float(w1), b2 = float(w2);
}

struct AtlasReport {
  int charts = 0;
  double utilization = 0;       ///< chart texels / all texels
  /// Share of the atlas within ceil(gutter / 2) of a chart's footprint but
  /// not a chart texel: gutters and partly covered chart edges.
  double lost_to_gutters = 0;
  double lost_to_packing = 0;   ///< the rest: 1 - utilization - lost_to_gutters
  double density_p95_low = 0;   ///< texel-density quantiles (normalised by the area-weighted mean)
  double density_p95_high = 0;  ///<   that bound 95% of the surface area
  double area_in_density_bounds = 0;  ///< share of surface area with density in [0.8, 1.25]
  std::size_t flipped_triangles = 0;
  double texels_per_metre = 0;    ///< the one density of every chart (texels per metre on the surface)
  bool packing_overflow = false;  ///< true when the gutter had to be dropped to fit the charts
  double seconds_charts = 0, seconds_lscm = 0, seconds_pack = 0, seconds_texels = 0;
};

struct SurfaceAtlas {
  int resolution = 0;
  std::vector<Vec2> corner_uv;          ///< 3 per triangle, in [0,1]
  std::vector<int32_t> chart_of_triangle;
  int chart_count = 0;
  TexelMap texels;
  AtlasReport report;
};

/// Builds the atlas. Never fails on legal input (non-manifold, degenerate,
/// many components, empty): a chart that does not flatten well is split and
/// redone, never dropped. Deterministic at any thread count.
///
/// Charts grow across manifold, consistently oriented edges only (a
/// non-manifold edge or vertex is a chart boundary). Degenerate triangles
/// (repeated index, area below 1e-12 of the squared bounding-box diagonal, or
/// height below 1e-8 of their longest edge) join the chart of a proper
/// triangle sharing a vertex and collapse onto that vertex's uv (zero uv area:
/// they claim no texel); a degenerate triangle with no such neighbour gets a
/// chart of its own, a point. Throws UsageError for a resolution outside
/// [1, 65536], a negative gutter or max_stretch <= 1.
SurfaceAtlas build_surface_atlas(const TriMesh& mesh, const AtlasOptions& options);

/// build_surface_atlas once per entry of `options`, from one segmentation
/// and one flattening: only the packing and the texel map depend on the
/// resolution and the gutter, so each atlas is the one build_surface_atlas
/// gives for its options. They must share max_stretch (UsageError
/// otherwise). The first atlas's report holds the charts' and LSCM's
/// seconds, the others' zero.
std::vector<SurfaceAtlas> build_surface_atlases(const TriMesh& mesh, const std::vector<AtlasOptions>& options);

}  // namespace lapflow
