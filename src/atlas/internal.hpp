#pragma once
// Internal pieces of the surface atlas (atlas.cpp orchestrates them):
// segmentation (charts.cpp), LSCM (flatten.cpp), packing and texel map
// (pack.cpp). Not a public header.
#include <cstdint>
#include <vector>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/surface/mesh.hpp"

namespace lapflow::atlas_detail {

/// Per-triangle geometry the stages share.
struct TriangleInfo {
  std::vector<Vec3> normal;        ///< unit normal; zero for degenerate triangles
  std::vector<double> area;        ///< square metres
  std::vector<uint8_t> degenerate; ///< repeated index, area below 1e-12 bbox diagonal^2, or a needle
  /// Neighbour across edge (k, k+1) of each triangle, 3 per triangle; -1 on a
  /// boundary, a non-manifold edge (more than two triangles), an edge whose two
  /// triangles disagree on orientation, or next to a degenerate triangle.
  std::vector<int32_t> across;
};
TriangleInfo analyze_triangles(const TriMesh& mesh);

/// A partition of the triangles into charts.
struct Charts {
  int count = 0;
  std::vector<int32_t> chart_of_triangle;
  /// CSR: triangles of chart c are triangles[offsets[c] .. offsets[c+1]), increasing.
  std::vector<int32_t> offsets, triangles;
  void rebuild_csr(std::size_t triangle_count);
};

struct ChartOptions {
  double cone_degrees = 60;  ///< largest angle between a triangle normal and its chart's mean normal
};

/// Region growing from seeds with a normal-cone criterion; degenerate
/// triangles join the chart of a triangle sharing a vertex (or get their own
/// chart when no such triangle exists). Deterministic, sequential, O(n).
Charts segment_charts(const TriMesh& mesh, const TriangleInfo& info, const ChartOptions& options);

/// Flattens every chart with LSCM into chart-local uv (metres: each chart's
/// area-weighted mean of sqrt(area3D / areaUV) is 1). A chart with a flipped
/// triangle or with more than 2% of its area outside the density band
/// [1/max_stretch, max_stretch] is split in two across the long side of its
/// minimum-area rectangle (then into connected parts) and redone until it
/// passes; so is a chart larger than `max_chart_area` (square metres: few
/// huge charts pack badly) or longer than `max_chart_length` (the long side
/// of its uv's minimum-area rectangle, metres: one long strip sets the scale
/// of all). Updates `charts`.
/// Returns corner uv, 3 per triangle. Degenerate triangles get a point (all
/// three corners at the uv of one of their vertices in the chart).
std::vector<Vec2> flatten_charts(const TriMesh& mesh, const TriangleInfo& info, Charts& charts,
                                 double max_stretch, double max_chart_area, double max_chart_length);

/// Convex hull of points, counter-clockwise, without repeated or collinear
/// points (fewer than three points: the distinct ones).
std::vector<Vec2> convex_hull(std::vector<Vec2> pts);

struct PackResult {
  double texels_per_metre = 0;
  bool overflow = false;  ///< charts could not be separated by the gutter at this resolution
  /// Texels within ceil(gutter / 2) (a square) of a chart's conservative
  /// footprint: the charts' texels, their partly covered edge texels and
  /// their half of the gutters.
  std::size_t claimed_texels = 0;
};
/// Rotates each chart to its minimum-area bounding rectangle, scales all by one
/// density (the largest that packs) and packs their footprints (every texel
/// their triangles touch) into the N x N square, bottom-left with quarter
/// turns, so that `gutter` empty texels separate any two charts (shared
/// gutters) and ceil(gutter / 2) separate a chart from the square's edges.
/// Rewrites corner_uv into atlas uv in [0,1].
PackResult pack_charts(const Charts& charts, int resolution, int gutter, std::vector<Vec2>& corner_uv);

/// Texels whose centre lies inside a chart triangle (ties on shared edges go to
/// the lowest triangle index), sorted by texel index.
TexelMap build_texel_map(const std::vector<Vec2>& corner_uv, int resolution);

}  // namespace lapflow::atlas_detail
