#pragma once
/// \file atlas.hpp The surface atlas of one fluid frame (ALGORITHM.md step 6,
/// Lévy et al. 2002): charts, LSCM, packing at one texel density, texel map.
///
/// UV convention: atlas uv (0,0) is the bottom-left corner of the image (OBJ
/// and renderers' convention). Texel (x, y), with image row y counted from the
/// top, has its centre at u = (x + 0.5) / N, v = 1 - (y + 0.5) / N.
#include <cstdint>
#include <vector>

#include "lapflow/mesh.hpp"

namespace lapflow {

struct AtlasOptions {
  int resolution = 2048;    ///< atlas width = height in texels
  int gutter = 4;           ///< empty texels kept around every chart
  double max_stretch = 1.25;  ///< chart is split when its texel-density spread exceeds this
};

/// Every chart texel (centre inside a chart triangle), sorted by texel index
/// y * N + x. The rasterizer streams these.
struct TexelMap {
  std::vector<uint32_t> texel;      ///< y * N + x
  std::vector<int32_t> triangle;    ///< fluid triangle under the texel centre
  std::vector<float> b1, b2;        ///< barycentric of triangle vertices 1 and 2
  std::size_t size() const { return texel.size(); }
};

struct AtlasReport {
  int charts = 0;
  double utilization = 0;       ///< chart texels / all texels
  double density_p95_low = 0;   ///< texel-density quantiles (normalised by the area-weighted mean)
  double density_p95_high = 0;  ///<   that bound 95% of the surface area
  double area_in_density_bounds = 0;  ///< share of surface area with density in [0.8, 1.25]
  std::size_t flipped_triangles = 0;
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
SurfaceAtlas build_surface_atlas(const TriMesh& mesh, const AtlasOptions& options);

}  // namespace lapflow
