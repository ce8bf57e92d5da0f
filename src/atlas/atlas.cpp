// The surface atlas of one frame (ALGORITHM.md step 6): charts, LSCM,
// packing, texel map, each stage timed for the report.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "atlas/internal.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace {

/// No chart may exceed this share of the surface: a handful of huge charts
/// leaves large empty corners in the square however they are packed.
constexpr double kMinChartsForPacking = 32;
/// Nor may a chart be longer (its minimum-area rectangle's long side, uv
/// metres) than this share of the square root of the surface area: one
/// long strip (a stream, a wave's crest) would set the one scale of every
/// chart alone and leave most of the atlas empty. Shorter limits pack a
/// little denser but cut ordinary charts too: more seams, where the raster's
/// hold is weaker (docs/atlas.md).
constexpr double kMaxChartLength = 0.5;

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point& t) {
  const Clock::time_point now = Clock::now();
  const double s = std::chrono::duration<double>(now - t).count();
  t = now;
  return s;
}

/// Density figures of the final atlas: sqrt(area3D / areaUV) per triangle,
/// normalised by its area-weighted mean, weighted by 3D area.
void measure_density(const TriMesh& mesh, const atlas_detail::TriangleInfo& info, const std::vector<Vec2>& uv,
                     AtlasReport& report) {
  std::vector<std::pair<double, double>> dens;  // (density, area)
  dens.reserve(mesh.triangle_count());
  double sum_a = 0, sum_ad = 0;
  report.flipped_triangles = 0;
  for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
    if (info.degenerate[t]) continue;
    const double auv = 0.5 * cross(uv[3 * t + 1] - uv[3 * t], uv[3 * t + 2] - uv[3 * t]);
    if (!(auv > 0)) {
      ++report.flipped_triangles;
      continue;
    }
    const double d = std::sqrt(info.area[t] / auv);
    dens.emplace_back(d, info.area[t]);
    sum_a += info.area[t];
    sum_ad += info.area[t] * d;
  }
  if (dens.empty() || !(sum_a > 0)) {
    report.density_p95_low = report.density_p95_high = report.area_in_density_bounds = 1;
    return;
  }
  const double mean = sum_ad / sum_a;
  double inside = 0;
  for (auto& [d, a] : dens) {
    d /= mean;
    if (d >= 0.8 && d <= 1.25) inside += a;
  }
  report.area_in_density_bounds = inside / sum_a;
  std::sort(dens.begin(), dens.end());
  double acc = 0;
  report.density_p95_low = dens.front().first;
  report.density_p95_high = dens.back().first;
  bool low_set = false;
  for (const auto& [d, a] : dens) {
    acc += a;
    if (!low_set && acc >= 0.025 * sum_a) report.density_p95_low = d, low_set = true;
    if (acc >= 0.975 * sum_a) {
      report.density_p95_high = d;
      break;
    }
  }
}

}  // namespace

namespace {

void check_options(const AtlasOptions& options) {
  if (options.resolution < 1 || options.resolution > 65536)
    throw UsageError("atlas resolution must be between 1 and 65536 texels, got " + std::to_string(options.resolution));
  if (options.gutter < 0) throw UsageError("atlas gutter must be >= 0 texels, got " + std::to_string(options.gutter));
  if (!(options.max_stretch > 1)) throw UsageError("atlas max_stretch must be > 1");
}

}  // namespace

std::vector<SurfaceAtlas> build_surface_atlases(const TriMesh& mesh, const std::vector<AtlasOptions>& options) {
  for (const AtlasOptions& o : options) {
    check_options(o);
    if (o.max_stretch != options.front().max_stretch)
      throw UsageError("atlases built together share one max_stretch (one flattening)");
  }
  std::vector<SurfaceAtlas> atlases(options.size());
  if (options.empty()) return atlases;
  Clock::time_point clock = Clock::now();

  // Charts and LSCM do not depend on the resolution or the gutter: done
  // once, timed into the first atlas's report.
  const atlas_detail::TriangleInfo info = atlas_detail::analyze_triangles(mesh);
  atlas_detail::Charts charts = atlas_detail::segment_charts(mesh, info, atlas_detail::ChartOptions{});
  atlases.front().report.seconds_charts = seconds_since(clock);

  double total_area = 0;
  for (double a : info.area) total_area += a;
  const double max_chart_area = total_area / kMinChartsForPacking;
  const double max_chart_length = kMaxChartLength * std::sqrt(total_area);
  const std::vector<Vec2> local =
      atlas_detail::flatten_charts(mesh, info, charts, options.front().max_stretch, max_chart_area, max_chart_length);
  atlases.front().report.seconds_lscm = seconds_since(clock);

  for (std::size_t k = 0; k < options.size(); ++k) {
    const AtlasOptions& o = options[k];
    SurfaceAtlas& atlas = atlases[k];
    atlas.resolution = o.resolution;
    atlas.corner_uv = local;
    const atlas_detail::PackResult packed = atlas_detail::pack_charts(charts, o.resolution, o.gutter, atlas.corner_uv);
    atlas.report.texels_per_metre = packed.texels_per_metre;
    atlas.report.packing_overflow = packed.overflow;
    atlas.report.seconds_pack = seconds_since(clock);

    atlas.texels = atlas_detail::build_texel_map(atlas.corner_uv, o.resolution);
    atlas.report.seconds_texels = seconds_since(clock);

    // The last atlas takes the segmentation's array; the others copy it.
    if (k + 1 == options.size()) atlas.chart_of_triangle = std::move(charts.chart_of_triangle);
    else atlas.chart_of_triangle = charts.chart_of_triangle;
    atlas.chart_count = charts.count;
    atlas.report.charts = charts.count;
    const double texels = double(o.resolution) * o.resolution;
    atlas.report.utilization = double(atlas.texels.size()) / texels;
    const double claimed = double(std::max(packed.claimed_texels, atlas.texels.size()));
    atlas.report.lost_to_gutters = (claimed - double(atlas.texels.size())) / texels;
    atlas.report.lost_to_packing = 1 - claimed / texels;
    measure_density(mesh, info, atlas.corner_uv, atlas.report);
    seconds_since(clock);  // the density figures are not a stage of the report
  }
  return atlases;
}

SurfaceAtlas build_surface_atlas(const TriMesh& mesh, const AtlasOptions& options) {
  return std::move(build_surface_atlases(mesh, {options}).front());
}

}  // namespace lapflow
