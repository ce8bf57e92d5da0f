// `lapflow eval`'s report: the summary of each metric over the frames, the
// JSON and the table it prints, and the plots (gnuplot).
#include "lapflow/addons/eval.hpp"
#include "lapflow/bake/frame.hpp"

#include <fmt/format.h>
#include <sys/wait.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>

#include "atlas/internal.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"
#include "addons/eval_internal.hpp"

namespace lapflow {
namespace fs = std::filesystem;
using namespace eval_detail;

namespace {

struct MetricDef {
  const char* key;
  double (*get)(const FrameMetrics&);
};
const std::vector<MetricDef>& metric_defs() {
  static const std::vector<MetricDef> defs{
      {"coverage", [](const FrameMetrics& m) { return m.coverage; }},
      {"contrast", [](const FrameMetrics& m) { return m.contrast; }},
      {"histogram_distance", [](const FrameMetrics& m) { return m.histogram_distance; }},
      {"sliced_wasserstein", [](const FrameMetrics& m) { return m.sliced_wasserstein; }},
      {"flow_median", [](const FrameMetrics& m) { return m.flow_median; }},
      {"flow_p90", [](const FrameMetrics& m) { return m.flow_p90; }},
      {"popping", [](const FrameMetrics& m) { return m.popping; }},
      {"born", [](const FrameMetrics& m) { return m.born ? double(*m.born) : kNoValue; }},
      {"died", [](const FrameMetrics& m) { return m.died ? double(*m.died) : kNoValue; }},
      {"popping_births", [](const FrameMetrics& m) { return m.popping_births; }},
      {"alive", [](const FrameMetrics& m) { return m.alive ? double(*m.alive) : kNoValue; }},
      {"fresh_seeding", [](const FrameMetrics& m) { return m.fresh_seeding ? double(*m.fresh_seeding) : kNoValue; }},
      {"drift", [](const FrameMetrics& m) { return m.drift; }},
      {"drift_texel", [](const FrameMetrics& m) { return m.drift_texel; }},
      {"rest_change", [](const FrameMetrics& m) { return m.rest_change; }},
      {"distortion_median", [](const FrameMetrics& m) { return m.distortion_median; }},
      {"distortion_p90", [](const FrameMetrics& m) { return m.distortion_p90; }},
      {"distortion_p99", [](const FrameMetrics& m) { return m.distortion_p99; }},
      {"distortion_max", [](const FrameMetrics& m) { return m.distortion_max; }},
  };
  return defs;
}

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// Layer l's name (its index when the report does not name it).
std::string layer_name(const EvalReport& r, int l) {
  return l >= 0 && std::size_t(l) < r.layers.size() ? r.layers[std::size_t(l)].name : std::to_string(l);
}

}  // namespace

namespace {

/// Frames, mean, median and max of `get` over the frames where it has a value.
template <typename Get>
MetricSummary summarize(const std::vector<FrameMetrics>& frames, std::string key, int layer, Get get) {
  MetricSummary s;
  s.key = std::move(key);
  s.layer = layer;
  std::vector<float> v;
  double sum = 0;
  for (const FrameMetrics& m : frames)
    if (const double x = get(m); std::isfinite(x)) v.push_back(float(x)), sum += x;
  s.frames = v.size();
  if (!v.empty()) {
    s.mean = sum / double(v.size());
    s.max = *std::max_element(v.begin(), v.end());
    s.median = quantile(v, 0.5);
  }
  return s;
}

/// The per-layer metrics summarized (and written per frame) for each layer.
constexpr std::pair<const char*, double LayerMetrics::*> kLayerMetrics[] = {
    {"share", &LayerMetrics::share},
    {"popping", &LayerMetrics::popping},
    {"contrast", &LayerMetrics::contrast},
    {"histogram_distance", &LayerMetrics::histogram_distance},
    {"sliced_wasserstein", &LayerMetrics::sliced_wasserstein},
};

}  // namespace

std::vector<MetricSummary> summarize_metrics(const std::vector<FrameMetrics>& frames) {
  std::vector<MetricSummary> out;
  for (const MetricDef& d : metric_defs()) out.push_back(summarize(frames, d.key, -1, d.get));
  std::size_t layers = 0;
  for (const FrameMetrics& m : frames) layers = std::max(layers, m.layers.size());
  if (layers == 0) return out;
  out.push_back(summarize(frames, "layer_agreement", -1, [](const FrameMetrics& m) { return m.layer_agreement; }));
  out.push_back(summarize(frames, "layer_agreement_interior", -1,
                          [](const FrameMetrics& m) { return m.layer_agreement_interior; }));
  for (std::size_t l = 0; l < layers; ++l)
    for (const auto& [key, field] : kLayerMetrics)
      out.push_back(summarize(frames, key, int(l), [l, field](const FrameMetrics& m) {
        return l < m.layers.size() ? m.layers[l].*field : kNoValue;
      }));
  return out;
}

std::string eval_report_json(const EvalReport& r) {
  nlohmann::json frames = nlohmann::json::array();
  for (const FrameMetrics& m : r.frames) {
    frames.push_back({
        {"frame", m.frame},
        {"chart_texels", m.chart_texels},
        {"covered_texels", m.covered_texels},
        {"coverage", number(m.coverage)},
        {"texel_world_size", number(m.texel_world_size)},
        {"exemplar_scale", number(m.exemplar_scale)},
        {"luminance_std", number(m.luminance_std)},
        {"exemplar_luminance_std", number(m.exemplar_luminance_std)},
        {"contrast", number(m.contrast)},
        {"histogram_w1", {number(m.histogram_w1[0]), number(m.histogram_w1[1]), number(m.histogram_w1[2])}},
        {"histogram_distance", number(m.histogram_distance)},
        {"sliced_wasserstein", number(m.sliced_wasserstein)},
        {"surface_windows", m.surface_windows},
        {"flow_texels", m.flow_texels},
        {"flow_median", number(m.flow_median)},
        {"flow_p90", number(m.flow_p90)},
        {"popping_texels", m.popping_texels},
        {"popping", number(m.popping)},
        {"born", m.born ? nlohmann::json(*m.born) : nlohmann::json(nullptr)},
        {"died", m.died ? nlohmann::json(*m.died) : nlohmann::json(nullptr)},
        {"popping_births", number(m.popping_births)},
        {"alive", m.alive ? nlohmann::json(*m.alive) : nlohmann::json(nullptr)},
        {"fresh_seeding", m.fresh_seeding ? nlohmann::json(*m.fresh_seeding) : nlohmann::json(nullptr)},
        {"deaths", {{"lost_to_projection", m.died_projection ? nlohmann::json(*m.died_projection) : nlohmann::json(nullptr)},
                    {"eroded_away", m.died_eroded ? nlohmann::json(*m.died_eroded) : nlohmann::json(nullptr)},
                    {"hidden", m.died_hidden ? nlohmann::json(*m.died_hidden) : nlohmann::json(nullptr)},
                    {"merged", m.died_merged ? nlohmann::json(*m.died_merged) : nlohmann::json(nullptr)}}},
        {"drift", number(m.drift)},
        {"drift_points", m.drift_points},
        {"drift_border_points", m.drift_border_points},
        {"drift_far_points", m.drift_far_points},
        {"rest_texels", m.rest_texels},
        {"drift_texel", number(m.drift_texel)},
        {"rest_change", number(m.rest_change)},
        {"rest_change_points", m.rest_change_points},
        {"distortion_texels", m.distortion_texels},
        {"distortion_median", number(m.distortion_median)},
        {"distortion_p90", number(m.distortion_p90)},
        {"distortion_p99", number(m.distortion_p99)},
        {"distortion_max", number(m.distortion_max)},
        {"seconds", m.seconds},
    });
    if (m.layers.empty()) continue;
    nlohmann::json& f = frames.back();
    f["layer_agreement"] = number(m.layer_agreement);
    f["layer_agreement_texels"] = m.layer_agreement_texels;
    f["layer_agreement_interior"] = number(m.layer_agreement_interior);
    f["layer_agreement_interior_texels"] = m.layer_agreement_interior_texels;
    nlohmann::json layers = nlohmann::json::object();
    for (std::size_t l = 0; l < m.layers.size(); ++l) {
      const LayerMetrics& x = m.layers[l];
      layers[layer_name(r, int(l))] = {
          {"texels", x.texels},
          {"share", number(x.share)},
          {"exemplar_scale", number(x.exemplar_scale)},
          {"luminance_std", number(x.luminance_std)},
          {"exemplar_luminance_std", number(x.exemplar_luminance_std)},
          {"contrast", number(x.contrast)},
          {"histogram_w1", {number(x.histogram_w1[0]), number(x.histogram_w1[1]), number(x.histogram_w1[2])}},
          {"histogram_distance", number(x.histogram_distance)},
          {"sliced_wasserstein", number(x.sliced_wasserstein)},
          {"surface_windows", x.surface_windows},
          {"popping_texels", x.popping_texels},
          {"popping", number(x.popping)},
      };
    }
    f["layers"] = layers;
  }
  nlohmann::json summary = nlohmann::json::object();
  for (const MetricSummary& s : r.summary) {
    const nlohmann::json value{
        {"frames", s.frames}, {"mean", number(s.mean)}, {"median", number(s.median)}, {"max", number(s.max)}};
    if (s.layer < 0)
      summary[s.key] = value;
    else
      summary["layers"][layer_name(r, s.layer)][s.key] = value;
  }
  nlohmann::json j{{"dir", r.dir},
                         {"name", r.name},
                         {"mode", r.mode},
                         {"exemplar", r.exemplar},
                         {"exemplar_luminance_std", number(r.exemplar_luminance_std)},
                         {"resolution", r.resolution},
                         {"radius", r.radius},
                         {"fps", r.fps},
                         {"rest_speed", r.rest_speed},
                         {"born", r.born},
                         {"died", r.died},
                         {"frames", frames},
                         {"summary", summary}};
  if (!r.layers.empty()) {
    nlohmann::json layers = nlohmann::json::array();
    for (const EvalLayer& l : r.layers)
      layers.push_back(
          {{"name", l.name}, {"exemplar", l.exemplar}, {"exemplar_luminance_std", number(l.exemplar_luminance_std)}});
    j["layers"] = layers;
  }
  return j.dump(2) + "\n";
}

namespace {

std::string cell(double v, const char* spec, int width) {
  if (!std::isfinite(v)) return fmt::format("{:>{}}", "-", width);
  return fmt::format(fmt::runtime(fmt::format("{{:>{}{}}}", width, spec)), v);
}

/// The exemplar layers' table: per frame the agreement with the rules (all
/// texels, interior texels) and each layer's share and popping, then the
/// summary, then each layer's fidelity (means over the frames).
std::string layer_table(const EvalReport& r) {
  std::map<std::pair<int, std::string>, const MetricSummary*> s;
  for (const MetricSummary& x : r.summary) s[{x.layer, x.key}] = &x;
  auto get = [&](int layer, const char* key, double MetricSummary::*field) {
    const auto it = s.find({layer, key});
    return it == s.end() ? kNoValue : it->second->*field;
  };
  auto pct = [](double v) { return std::isfinite(v) ? 100 * v : v; };
  const int n = int(r.layers.size());
  std::vector<int> width(static_cast<std::size_t>(n));  // of each layer's share column (the name above both of its columns)
  std::string names = fmt::format("\n{:>24}", ""), header = fmt::format("{:>6} {:>8} {:>8}", "frame", "agree%", "inner%");
  for (int l = 0; l < n; ++l) {
    const std::string& name = r.layers[std::size_t(l)].name;
    width[std::size_t(l)] = std::max(8, int(name.size()) - 9);
    names += fmt::format(" {:>{}}", name, width[std::size_t(l)] + 9);
    header += fmt::format(" {:>{}} {:>8}", "share%", width[std::size_t(l)], "pop%");
  }
  std::string out = "\nexemplar layers: agree% = texels showing the layer the rules choose there (inner%: away from "
                    "the rules' boundaries)" + names + "\n" + header + "\n";
  auto row = [&](const std::string& label, double agree, double inner, const std::function<double(int, bool)>& layer) {
    std::string line = fmt::format("{:>6} {} {}", label, cell(pct(agree), ".2f", 8), cell(pct(inner), ".2f", 8));
    for (int l = 0; l < n; ++l)
      line += fmt::format(" {} {}", cell(pct(layer(l, false)), ".2f", width[std::size_t(l)]),
                          cell(pct(layer(l, true)), ".2f", 8));
    return line + "\n";
  };
  for (const FrameMetrics& m : r.frames)
    out += row(std::to_string(m.frame), m.layer_agreement, m.layer_agreement_interior, [&](int l, bool popping) {
      if (std::size_t(l) >= m.layers.size()) return kNoValue;
      return popping ? m.layers[std::size_t(l)].popping : m.layers[std::size_t(l)].share;
    });
  out += "\n";
  for (const auto& [label, field] : {std::pair{"mean", &MetricSummary::mean}, std::pair{"median", &MetricSummary::median},
                                     std::pair{"max", &MetricSummary::max}})
    out += row(label, get(-1, "layer_agreement", field), get(-1, "layer_agreement_interior", field),
               [&](int l, bool popping) { return get(l, popping ? "popping" : "share", field); });
  for (int l = 0; l < n; ++l)
    out += fmt::format("{}: contrast {}, hist W1 {}, SW {} against {} (means over the frames)\n",
                       r.layers[std::size_t(l)].name, cell(get(l, "contrast", &MetricSummary::mean), ".3f", 1),
                       cell(get(l, "histogram_distance", &MetricSummary::mean), ".4f", 1),
                       cell(get(l, "sliced_wasserstein", &MetricSummary::mean), ".4f", 1),
                       fs::path(r.layers[std::size_t(l)].exemplar).filename().string());
  return out;
}

}  // namespace

std::string eval_report_table(const EvalReport& r) {
  std::string exemplar = "exemplar " + r.exemplar;
  if (!r.layers.empty()) {
    exemplar = "layers";
    for (const EvalLayer& l : r.layers)
      exemplar += fmt::format("{} {} ({})", &l == &r.layers.front() ? "" : ",", l.name,
                              fs::path(l.exemplar).filename().string());
  }
  std::string out = fmt::format("{} ({} mode) in {}\n{} | atlas {} | r = {:.4g} m | {} fps | rest below {:.4g} m/s\n\n",
                                r.name, r.mode, r.dir, exemplar, r.resolution, r.radius, r.fps, r.rest_speed);
  out += fmt::format("{:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6} {:>6} {:>8} {:>8} {:>7} {:>7} {:>7}\n",
                     "frame", "cover%", "contrast", "hist W1", "SW", "flow50", "flow90", "pop%", "born", "died",
                     "drift%", "drtex%", "delta50", "delta90", "delta99");
  auto pct = [](double v) { return std::isfinite(v) ? 100 * v : v; };
  auto row = [&](const std::string& label, double cov, double con, double hist, double sw, double f50, double f90,
                 double pop, double born, double died, double drift, double drift_texel, double d50, double d90,
                 double dmx) {
    return fmt::format("{:>6} {} {} {} {} {} {} {} {} {} {} {} {} {} {}\n", label, cell(pct(cov), ".2f", 8),
                       cell(con, ".3f", 8), cell(hist, ".4f", 8), cell(sw, ".4f", 8), cell(f50, ".3f", 8),
                       cell(f90, ".3f", 8), cell(pct(pop), ".2f", 8), cell(born, ".0f", 6), cell(died, ".0f", 6),
                       cell(pct(drift), ".2f", 8), cell(pct(drift_texel), ".2f", 8), cell(d50, ".2f", 7),
                       cell(d90, ".2f", 7), cell(dmx, ".2f", 7));
  };
  for (const FrameMetrics& m : r.frames)
    out += row(std::to_string(m.frame), m.coverage, m.contrast, m.histogram_distance, m.sliced_wasserstein,
               m.flow_median, m.flow_p90, m.popping, m.born ? double(*m.born) : kNoValue,
               m.died ? double(*m.died) : kNoValue, m.drift, m.drift_texel, m.distortion_median, m.distortion_p90,
               m.distortion_p99);
  std::map<std::string, const MetricSummary*> s;
  for (const MetricSummary& x : r.summary)
    if (x.layer < 0) s[x.key] = &x;
  auto get = [&](const char* key, double MetricSummary::*field) { return s.count(key) ? s[key]->*field : kNoValue; };
  out += "\n";
  for (const auto& [label, field] : {std::pair{"mean", &MetricSummary::mean}, std::pair{"median", &MetricSummary::median},
                                     std::pair{"max", &MetricSummary::max}})
    out += row(label, get("coverage", field), get("contrast", field), get("histogram_distance", field),
               get("sliced_wasserstein", field), get("flow_median", field), get("flow_p90", field),
               get("popping", field), get("born", field), get("died", field), get("drift", field),
               get("drift_texel", field), get("distortion_median", field), get("distortion_p90", field), get("distortion_p99", field));
  // The population, when the bake's stats hold it.
  const double births = get("popping_births", &MetricSummary::mean), alive = get("alive", &MetricSummary::max),
               fresh = get("fresh_seeding", &MetricSummary::mean);
  const double change = get("rest_change", &MetricSummary::mean), change_max = get("rest_change", &MetricSummary::max);
  if (std::isfinite(change))
    out += fmt::format("\nrest change at fixed points (check_bake.py's definition): {:.2f}% a frame, at most {:.2f}%",
                       100 * change, 100 * change_max);
  if (std::isfinite(births)) out += fmt::format("\npopping caused by births: {:.1f}% of the popped surface (mean over frames)\n", 100 * births);
  if (std::isfinite(alive) && std::isfinite(fresh)) {
    double ratio = 0;
    for (const FrameMetrics& m : r.frames)
      if (m.alive && m.fresh_seeding && *m.fresh_seeding > 0)
        ratio = std::max(ratio, double(*m.alive) / double(*m.fresh_seeding));
    out += fmt::format("patches alive: at most {:.0f}, at most {:.2f}x a fresh seeding of the same frame\n", alive, ratio);
  }
  if (!r.layers.empty()) out += layer_table(r);
  return out;
}

std::vector<std::string> write_eval_plots(const EvalReport& r, const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw OutputError(dir + ": cannot create the plot folder: " + ec.message());
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0)
    throw OutputError("--plots needs gnuplot on the PATH (Debian package gnuplot-nox)");

  // One data file (a column per value, NaN as "NaN", which gnuplot skips)
  // and one script that draws every plot to a temporary name; the PNGs are
  // renamed into place when gnuplot succeeded.
  const fs::path folder(dir);
  const std::string tag = fmt::format(".eval_plot_{}", ::getpid());
  const fs::path data = folder / (tag + ".dat"), script = folder / (tag + ".gp");
  std::string text =
      "# frame coverage contrast histR histG histB hist sw flow50 flow90 popping born died drift d50 d90 dmax d99 "
      "drift_texel alive fresh_seeding died_projection died_eroded died_hidden died_merged\n";
  auto v = [](double x) { return std::isfinite(x) ? fmt::format("{:.9g}", x) : std::string("NaN"); };
  auto n = [&](const std::optional<std::size_t>& x) { return v(x ? double(*x) : kNoValue); };
  for (const FrameMetrics& m : r.frames)
    text += fmt::format("{} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {}\n", m.frame, v(m.coverage), v(m.contrast),
                        v(m.histogram_w1[0]), v(m.histogram_w1[1]), v(m.histogram_w1[2]), v(m.histogram_distance),
                        v(m.sliced_wasserstein), v(m.flow_median), v(m.flow_p90), v(m.popping),
                        v(m.born ? double(*m.born) : kNoValue), v(m.died ? double(*m.died) : kNoValue), v(m.drift),
                        v(m.distortion_median), v(m.distortion_p90), v(m.distortion_max), v(m.distortion_p99),
                        v(m.drift_texel), n(m.alive), n(m.fresh_seeding), n(m.died_projection), n(m.died_eroded),
                        n(m.died_hidden), n(m.died_merged));
  write_text_atomically(data.string(), text);

  struct Plot {
    std::string file, title, ylabel, plot;
    double (*main)(const FrameMetrics&);  ///< gnuplot cannot draw a curve with no value: a note instead
  };
  const std::string d = "'" + data.string() + "'";
  auto lines = [&](std::initializer_list<std::pair<int, const char*>> cols) {
    std::string s;
    for (const auto& [col, title] : cols)
      s += fmt::format("{}{} using 1:{} with linespoints title \"{}\"", s.empty() ? "" : ", ", d, col, title);
    return s;
  };
  const std::vector<Plot> plots{
      {"coverage.png", "Coverage", "chart texels with a patch (%)", fmt::format("{} using 1:($2*100) with linespoints title 'coverage'", d),
       [](const FrameMetrics& m) { return m.coverage; }},
      {"contrast.png", "Contrast (ghosting lowers it)", "luminance std / exemplar's", lines({{3, "contrast"}}), [](const FrameMetrics& m) { return m.contrast; }},
      {"fidelity.png", "Fidelity: colour histogram W1 to the exemplar", "W1 (linear colour)",
       lines({{4, "R"}, {5, "G"}, {6, "B"}, {7, "mean"}}),
       [](const FrameMetrics& m) { return m.histogram_distance; }},
      {"sliced_wasserstein.png", "Fidelity: sliced W1 of 5x5 luminance windows", "sliced W1 (linear luminance)",
       lines({{8, "sliced W1"}}), [](const FrameMetrics& m) { return m.sliced_wasserstein; }},
      {"flow.png", "Flow agreement: |d - v dt| / (|v| dt)", "relative error", lines({{9, "median"}, {10, "p90"}}),
       [](const FrameMetrics& m) { return m.flow_median; }},
      {"popping.png", "Popping", "surface whose patch changed (%)",
       fmt::format("{0} using 1:($11*100) with linespoints title 'popping %', {0} using 1:12 axes x1y2 with "
                   "linespoints title 'born', {0} using 1:13 axes x1y2 with linespoints title 'died'", d),
       [](const FrameMetrics& m) { return m.popping; }},
      {"drift.png", "Drift at rest", "rest points whose texture changed (%)",
       fmt::format("{0} using 1:($14*100) with linespoints title 'drift (fixed points)', {0} using "
                   "1:($19*100) with linespoints title 'drift_texel (per texel)'", d),
       [](const FrameMetrics& m) { return std::isfinite(m.drift) ? m.drift : m.drift_texel; }},
      {"population.png", "Patch population", "patches alive",
       fmt::format("{0} using 1:20 with linespoints title 'alive', {0} using 1:21 with lines dashtype 2 title "
                   "'fresh seeding', {0} using 1:($21*1.5) with lines dashtype 3 title '1.5 x fresh seeding', {0} "
                   "using 1:12 axes x1y2 with linespoints title 'born', {0} using 1:22 axes x1y2 with linespoints "
                   "title 'died: projection', {0} using 1:23 axes x1y2 with linespoints title 'died: eroded', {0} "
                   "using 1:24 axes x1y2 with linespoints title 'died: hidden', {0} using 1:25 axes x1y2 with "
                   "linespoints title 'died: merged'",
                   d),
       [](const FrameMetrics& m) { return m.alive ? double(*m.alive) : kNoValue; }},
      {"distortion.png", "Distortion delta = max(s1, 1/s2)", "delta",
       lines({{15, "median"}, {16, "p90"}, {18, "p99"}}),
       [](const FrameMetrics& m) { return m.distortion_median; }},
  };
  std::string gp = "set terminal pngcairo size 960,540 noenhanced font 'sans,11'\nset grid\nset key outside right top\n"
                   "set xlabel 'frame'\nset datafile missing 'NaN'\n";
  // An explicit x range: one frame, or a metric with no value, leaves gnuplot none.
  const int first = r.frames.empty() ? 0 : r.frames.front().frame, last = r.frames.empty() ? 1 : r.frames.back().frame;
  gp += first < last ? fmt::format("set xrange [{}:{}]\n", first, last)
                     : fmt::format("set xrange [{}:{}]\n", first - 1, last + 1);
  gp += fmt::format("set xtics {}\n", std::max(1, int(std::lround((last - first) / 10.0))));
  std::vector<std::string> written;
  for (const Plot& p : plots) {
    const std::string tmp = (folder / (tag + "." + p.file)).string();
    gp += fmt::format("set output '{}'\nset title \"{}: {}\"\nset ylabel \"{}\"\n", tmp, p.title, r.name + " (" + r.mode + ")",
                      p.ylabel);
    gp += p.file == "popping.png" || p.file == "population.png" ? "set y2label 'patches per frame'\nset y2tics\n"
                                                                : "unset y2label\nunset y2tics\n";
    const bool any = std::any_of(r.frames.begin(), r.frames.end(), [&](const FrameMetrics& m) { return std::isfinite(p.main(m)); });
    if (any) {
      gp += "unset label\nset autoscale y\nplot " + p.plot + "\n";
    } else {
      gp += "set label 1 'no value on any frame' at graph 0.5, 0.5 center\nset yrange [0:1]\nplot 1/0 notitle\n";
    }
  }
  gp += "unset output\n";
  write_text_atomically(script.string(), gp);
  const std::string cmd = fmt::format("gnuplot '{}' 2>'{}'", script.string(), (folder / (tag + ".err")).string());
  const int status = std::system(cmd.c_str());
  std::string err;
  {
    std::ifstream in(folder / (tag + ".err"));
    std::getline(in, err, '\0');
  }
  fs::remove(data, ec);
  fs::remove(script, ec);
  fs::remove(folder / (tag + ".err"), ec);
  if (status != 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    for (const Plot& p : plots) fs::remove(folder / (tag + "." + p.file), ec);
    throw OutputError("gnuplot failed: " + err);
  }
  for (const Plot& p : plots) {
    const fs::path tmp = folder / (tag + "." + p.file), final_path = folder / p.file;
    fs::rename(tmp, final_path, ec);
    if (ec) throw OutputError(final_path.string() + ": cannot write: " + ec.message());
    written.push_back(final_path.string());
  }
  return written;
}

}  // namespace lapflow
