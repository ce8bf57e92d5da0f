#pragma once
/// \file eval.hpp Quality metrics of a bake (`lapflow eval`, docs/eval.md):
/// coverage, contrast (ghosting), fidelity to the exemplar, agreement of the
/// texture's motion with the input velocity, popping, drift at rest (at fixed
/// surface points, and the former per-texel figure) and distortion, per frame
/// and over the sequence. Everything is measured from the files of a bake
/// folder (NAME.bake.json, UV meshes, colour atlases, the AOVs of
/// `bake --aov`, NAME.stats.jsonl) and the input meshes the manifest names.
/// Deterministic at any thread count.
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "lapflow/io/mesh_io.hpp"

namespace lapflow {

struct EvalOptions {
  std::string exemplar;               ///< colour exemplar; empty = the one the bake used (manifest)
  std::optional<FrameRange> frames;   ///< default: every frame of the bake
  std::optional<double> min_speed;    ///< m/s: rest threshold of the drift metric (default: the bake's --min-speed)
  int windows = 16384;                ///< 5x5 windows per side sampled for the sliced Wasserstein distance
  int projections = 64;               ///< random unit directions of the sliced Wasserstein distance
  uint64_t seed = 1;                  ///< seed of those directions
  /// When set, a popping map per frame after the first goes into this folder
  /// (created): NAME.popping.NNNN.exr in that frame's atlas layout, R = the
  /// texel popped to a patch born on the frame, G = popped to a patch that already existed,
  /// B = compared and kept, A = compared (docs/eval.md, "Popping maps").
  std::string maps_dir;
};

constexpr double kNoValue = std::numeric_limits<double>::quiet_NaN();

/// Metrics of one frame. Values that need a previous frame (flow, popping,
/// drift) or samples that a frame does not have are NaN ("no value").
struct FrameMetrics {
  int frame = 0;
  // Coverage: chart texels (centre inside a UV-mesh triangle) with a patch.
  std::size_t chart_texels = 0, covered_texels = 0;
  double coverage = kNoValue;
  // Scale: metres per atlas texel (sqrt(surface area / chart texel area)) and
  // exemplar pixels per atlas texel (exemplar width * texel / 2r).
  double texel_world_size = kNoValue, exemplar_scale = kNoValue;
  // Contrast: area-weighted std of linear luminance over covered texels /
  // the std of the exemplar seen at the atlas texel scale.
  double luminance_std = kNoValue, exemplar_luminance_std = kNoValue, contrast = kNoValue;
  // Fidelity: W1 between the area-weighted R, G, B distributions of the
  // surface and the exemplar's (1024 bins on [0,1]), their mean, and the
  // sliced W1 between 5x5 luminance windows of the surface and the exemplar.
  std::array<double, 3> histogram_w1{kNoValue, kNoValue, kNoValue};
  double histogram_distance = kNoValue;
  double sliced_wasserstein = kNoValue;
  std::size_t surface_windows = 0;
  // Flow agreement: |d - v dt| / (|v| dt) over texels matched to the previous
  // frame through (patch_id, u, v) where |v| dt >= one texel; v is the mean
  // of the input velocity at both ends of the displacement d.
  std::size_t flow_texels = 0;
  double flow_median = kNoValue, flow_p90 = kNoValue;
  // Popping: area share of compared texels whose patch point was not visible
  // on the previous frame and whose patch differs from the one found at the
  // back-advected point there.
  std::size_t popping_texels = 0;
  double popping = kNoValue;
  /// Share of the popped area whose new patch was born on this frame (its
  /// id above every id on the previous frame's atlas): popping caused by births.
  double popping_births = kNoValue;
  std::optional<std::size_t> born, died;  ///< from NAME.stats.jsonl (died = retired + lost)
  /// The population, from NAME.stats.jsonl when the bake wrote it: patches
  /// alive, a fresh seeding's count, and deaths by cause.
  std::optional<std::size_t> alive, fresh_seeding, died_projection, died_eroded, died_hidden, died_merged;
  // Drift at rest, at fixed surface points: this frame's covered chart
  // texels with |v| <= min_speed, each located on the previous frame's mesh
  // by closest point (then barycentrics, atlas uv, the texel there). Points
  // within a texel of a patch border in either frame (3x3 texels not all one
  // covered patch of one chart) are left out, and so are points farther from
  // the previous surface than max(one texel, min_speed * dt). drift = share
  // of the compared points whose patch differs or whose (u,v) moved by more
  // than one texel. drift_points + drift_border_points + drift_far_points =
  // the texels with a patch at rest.
  std::size_t drift_points = 0, drift_border_points = 0, drift_far_points = 0;
  double drift = kNoValue;
  // Rest change, the definition of the independent checker
  // (shared/tools/check_bake.py change): every covered texel with |v| <=
  // min_speed, located on the previous frame's mesh by closest point (within
  // four texels); its previous patch is the nearest of the 2x2 texels around
  // that atlas point, which must all hold one patch (else it is left out),
  // and its previous (u,v) their bilinear blend. Changed: another patch, or
  // (u,v) moved by more than one texel. Unlike drift, it counts points next
  // to a patch border on this frame, so a patch that gains or loses texels
  // at its border counts here and not in drift. rest_change_points: the
  // points compared.
  std::size_t rest_change_points = 0;
  double rest_change = kNoValue;
  // The former per-texel drift, kept for comparison: share of the rest
  // texels whose back-advected point on the previous frame has another
  // patch, or (u,v) off by more than half a texel. It counts patch borders,
  // where only each frame's atlas sampling decides the side a point is on,
  // and goes back along input velocities below the bake's --min-speed,
  // which the bake treated as zero.
  std::size_t rest_texels = 0;
  double drift_texel = kNoValue;
  // Distortion: delta = max(s1, 1/s2) of the map (u,v)*2r -> surface,
  // estimated from neighbouring texels of one patch and chart.
  std::size_t distortion_texels = 0;
  double distortion_median = kNoValue, distortion_p90 = kNoValue, distortion_p99 = kNoValue, distortion_max = kNoValue;
  double seconds = 0;
};

/// One metric over the frames where it has a value.
struct MetricSummary {
  std::string key;  ///< as in the JSON (e.g. "contrast", "flow_median")
  std::size_t frames = 0;
  double mean = kNoValue, median = kNoValue, max = kNoValue;
};

struct EvalReport {
  std::string dir, name, mode, exemplar;
  int resolution = 0;
  double radius = 0, fps = 0, rest_speed = 0;
  double exemplar_luminance_std = 0;  ///< at the exemplar's own resolution
  std::vector<FrameMetrics> frames;
  std::vector<MetricSummary> summary;
  std::size_t born = 0, died = 0;  ///< over the evaluated frames
  std::vector<std::string> maps;   ///< popping maps written (EvalOptions::maps_dir)
};

/// Evaluates the bake in `dir` (a folder with one NAME.bake.json, or the
/// manifest itself). Throws InputError naming the folder when the bake has no
/// AOVs (bake with --aov), and naming the file for any missing or malformed
/// file. `on_frame` is called after each frame.
EvalReport evaluate_bake(const std::string& dir, const EvalOptions& options = {},
                         const std::function<void(const FrameMetrics&)>& on_frame = {});

/// Mean, median and max of every metric over the frames (fills report.summary).
std::vector<MetricSummary> summarize_metrics(const std::vector<FrameMetrics>& frames);

/// The report as JSON: settings, "frames" (one object per frame), "summary"
/// (per metric: frames, mean, median, max). NaN is written as null.
std::string eval_report_json(const EvalReport& report);
/// A table for a terminal: one row per frame, then the summary.
std::string eval_report_table(const EvalReport& report);

/// Writes one PNG per metric over the frames into `dir` (created) with
/// gnuplot (Debian package gnuplot-nox): coverage.png, contrast.png,
/// fidelity.png, sliced_wasserstein.png, flow.png, popping.png, drift.png,
/// distortion.png. Returns the paths written. Throws OutputError when gnuplot
/// is missing or fails.
std::vector<std::string> write_eval_plots(const EvalReport& report, const std::string& dir);

}  // namespace lapflow
