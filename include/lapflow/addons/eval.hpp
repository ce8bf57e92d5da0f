#pragma once
/// \file eval.hpp Quality metrics of a bake (`lapflow eval`, docs/eval.md):
/// coverage, contrast (ghosting), fidelity to the exemplar, agreement of the
/// texture's motion with the input velocity, popping, drift at rest (at fixed
/// surface points, and the former per-texel figure) and distortion, per frame
/// and over the sequence. Everything is measured from the files of a bake
/// folder (NAME.bake.json, UV meshes, colour atlases, the AOVs of
/// `bake --aov`, NAME.stats.jsonl) and the input meshes the manifest names.
/// A bake with exemplar layers is compared layer by layer with each layer's
/// exemplar, and gains per-layer coverage and popping and the agreement of
/// the shown layer with the rules (docs/eval.md, "Exemplar layers").
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
  /// Colour exemplar; empty = the one the bake used (manifest). Not with a
  /// bake of exemplar layers (each layer is compared with its own).
  std::string exemplar;
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

/// One exemplar layer's figures on one frame (a bake with layers only).
struct LayerMetrics {
  /// Covered chart texels whose AOV layer is this one, and their share of
  /// the covered texels that have a layer (the shares of a frame sum to 1).
  std::size_t texels = 0;
  double share = kNoValue;
  /// The exemplar comparison over those texels against this layer's
  /// exemplar, as FrameMetrics defines it for the whole surface.
  double exemplar_scale = kNoValue, luminance_std = kNoValue, exemplar_luminance_std = kNoValue, contrast = kNoValue;
  std::array<double, 3> histogram_w1{kNoValue, kNoValue, kNoValue};
  double histogram_distance = kNoValue, sliced_wasserstein = kNoValue;
  std::size_t surface_windows = 0;
  /// Popping of the compared texels whose layer (on this frame) is this one.
  std::size_t popping_texels = 0;
  double popping = kNoValue;
};

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
  // the std of the exemplar seen at the atlas texel scale. With exemplar
  // layers, this and the fidelity figures below (and exemplar_scale) are
  // the means over the layers of each layer's figure (LayerMetrics)
  // weighted by its texels.
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
  /// With exemplar layers: one per layer, in the AOV's order (empty with one exemplar).
  std::vector<LayerMetrics> layers;
  /// With exemplar layers: of the covered chart texels with a layer, the
  /// share whose AOV layer is the one the rules choose at the texel's surface
  /// point; and the same over the interior texels, whose fluid triangle's
  /// three vertices all choose one layer (away from the rules' boundaries,
  /// which a patch keeping its birth layer may overlap).
  std::size_t layer_agreement_texels = 0, layer_agreement_interior_texels = 0;
  double layer_agreement = kNoValue, layer_agreement_interior = kNoValue;
  double seconds = 0;
};

/// One metric over the frames where it has a value.
struct MetricSummary {
  std::string key;  ///< as in the JSON (e.g. "contrast", "flow_median"; per layer "share", "popping", ...)
  int layer = -1;   ///< the layer (index into EvalReport::layers) of a per-layer metric; -1: the whole surface
  std::size_t frames = 0;
  double mean = kNoValue, median = kNoValue, max = kNoValue;
};

/// One exemplar layer of the bake evaluated.
struct EvalLayer {
  std::string name, exemplar;                 ///< the layer's name and its colour exemplar
  double exemplar_luminance_std = kNoValue;   ///< at the exemplar's own resolution
};

struct EvalReport {
  std::string dir, name, mode;
  std::string exemplar;  ///< the colour exemplar; with layers "NAME=COLOR,..." of every layer
  int resolution = 0;
  double radius = 0, fps = 0, rest_speed = 0;
  double exemplar_luminance_std = 0;  ///< at the exemplar's own resolution (NaN with layers: see `layers`)
  std::vector<EvalLayer> layers;      ///< with exemplar layers, in the AOV's order; empty with one exemplar
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

/// Mean, median and max of every metric over the frames (fills
/// report.summary); with exemplar layers also layer_agreement,
/// layer_agreement_interior and, per layer, share, popping, contrast,
/// histogram_distance and sliced_wasserstein.
std::vector<MetricSummary> summarize_metrics(const std::vector<FrameMetrics>& frames);

/// The report as JSON: settings, "frames" (one object per frame), "summary"
/// (per metric: frames, mean, median, max). NaN is written as null. With
/// exemplar layers: "layers" (name, exemplar, exemplar_luminance_std per
/// layer), and per frame and in the summary "layer_agreement",
/// "layer_agreement_interior" and "layers" (an object per layer name).
std::string eval_report_json(const EvalReport& report);
/// A table for a terminal: one row per frame, then the summary; with
/// exemplar layers a second table of the layers' shares, popping and agreement.
std::string eval_report_table(const EvalReport& report);

/// Writes one PNG per metric over the frames into `dir` (created) with
/// gnuplot (Debian package gnuplot-nox): coverage.png, contrast.png,
/// fidelity.png, sliced_wasserstein.png, flow.png, popping.png, drift.png,
/// distortion.png. Returns the paths written. Throws OutputError when gnuplot
/// is missing or fails.
std::vector<std::string> write_eval_plots(const EvalReport& report, const std::string& dir);

}  // namespace lapflow
