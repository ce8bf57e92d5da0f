// `lapflow eval`: quality metrics of a bake, from its files and the input
// velocities (docs/eval.md says what each metric measures and how).
//
// Shape: each frame is loaded once into a FrameData (UV mesh, texel map with
// one 3D position per chart texel, the AOV per texel, velocities); single-
// frame metrics read one FrameData, pair metrics (flow, popping, drift) read
// the previous frame's and this one's. Every reduction runs over fixed chunks
// of texels summed in chunk order, so results do not depend on the thread
// count.
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
#include "lapflow/bake/render_record.hpp"
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

// ---- the exemplar at the atlas texel scale ----------------------------------

struct ExemplarStats {
  int width = 0, height = 0;
  double luminance_std = kNoValue;
  std::array<std::vector<double>, 3> histogram;  ///< R, G, B, kBins each
  std::vector<float> lum;                        ///< width * height
};

ExemplarStats exemplar_stats(const Image& img) {
  ExemplarStats s;
  s.width = img.width;
  s.height = img.height;
  const std::size_t n = std::size_t(img.width) * img.height;
  s.lum.resize(n);
  for (auto& h : s.histogram) h.assign(kBins, 0);
  double sum = 0;
  for (std::size_t p = 0; p < n; ++p) {
    const float* px = &img.pixels[p * img.channels];
    const float r = px[0], g = img.channels >= 3 ? px[1] : px[0], b = img.channels >= 3 ? px[2] : px[0];
    s.lum[p] = float(luminance(r, g, b));
    sum += s.lum[p];
    s.histogram[0][bin_of(r)] += 1;
    s.histogram[1][bin_of(g)] += 1;
    s.histogram[2][bin_of(b)] += 1;
  }
  const double mean = sum / double(n);
  double var = 0;
  for (float l : s.lum) var += (l - mean) * (l - mean);
  s.luminance_std = std::sqrt(var / double(n));
  return s;
}

/// The exemplar resampled so that one pixel covers one atlas texel, cached
/// by target size (the texel size changes little between frames).
class ExemplarAtScale {
 public:
  explicit ExemplarAtScale(Image exemplar) : exemplar_(std::move(exemplar)) {}
  const Image& original() const { return exemplar_; }
  /// `scale` = exemplar pixels per atlas texel.
  const ExemplarStats& at(double scale) {
    const double s = std::isfinite(scale) && scale > 0 ? scale : 1.0;
    // Cap the upsampled size: past 4096 pixels the windows say nothing new.
    const int w = std::clamp(int(std::lround(exemplar_.width / s)), 1, 4096);
    const int h = std::clamp(int(std::lround(exemplar_.height * double(w) / exemplar_.width)), 1, 4096);
    auto it = cache_.find({w, h});
    if (it == cache_.end()) {
      const Image resized = w == exemplar_.width && h == exemplar_.height ? exemplar_ : resize_image(exemplar_, w, h);
      it = cache_.emplace(std::make_pair(w, h), exemplar_stats(resized)).first;
    }
    return it->second;
  }

 private:
  Image exemplar_;
  std::map<std::pair<int, int>, ExemplarStats> cache_;
};

// ---- single-frame metrics ---------------------------------------------------

/// Unit directions in R^25 from the seed (Gaussian by Box-Muller, normalised).
std::vector<std::array<double, kWindowDim>> projections(int count, uint64_t seed) {
  std::vector<std::array<double, kWindowDim>> dirs(std::size_t(std::max(count, 0)));
  for (std::size_t p = 0; p < dirs.size(); ++p) {
    double len2 = 0;
    for (int k = 0; k < kWindowDim; ++k) {
      const double u1 = 1 - hash_to_unit(hash64(seed, p, uint64_t(k), 1)), u2 = hash_to_unit(hash64(seed, p, uint64_t(k), 2));
      dirs[p][k] = std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
      len2 += dirs[p][k] * dirs[p][k];
    }
    for (double& d : dirs[p]) d /= std::sqrt(len2);
  }
  return dirs;
}

/// `count` evenly strided picks from `n` candidates (all when n <= count).
std::vector<std::size_t> strided(std::size_t n, std::size_t count) {
  std::vector<std::size_t> out;
  if (n <= count) {
    out.resize(n);
    std::iota(out.begin(), out.end(), 0);
  } else {
    out.resize(count);
    for (std::size_t k = 0; k < count; ++k) out[k] = std::size_t((unsigned __int128)k * n / count);
  }
  return out;
}

/// True when chart texel i is covered and, for `layer` >= 0, shows that
/// exemplar layer (FrameData::layer).
bool shows(const FrameData& f, std::size_t i, int layer) {
  return f.covered[i] && (layer < 0 || f.layer[i] == layer);
}

/// Sliced W1 between 5x5 luminance windows of the surface (every texel of
/// the window a covered texel of the centre's chart, showing `layer` when it
/// is >= 0) and of the exemplar at the atlas texel scale. Returns {distance,
/// surface windows used}.
std::pair<double, std::size_t> sliced_wasserstein(const FrameData& f, const ExemplarStats& ex, const EvalOptions& o,
                                                  int layer) {
  constexpr int h = kWindow / 2;
  const std::size_t count = f.texels.size();
  std::vector<uint8_t> ok(count, 0);
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      if (!shows(f, i, layer)) continue;
      const int x = f.x_of(i), y = f.y_of(i), chart = f.chart_of_slot(i);
      bool good = true;
      for (int dy = -h; dy <= h && good; ++dy)
        for (int dx = -h; dx <= h && good; ++dx) {
          const int32_t j = f.slot_at(x + dx, y + dy);
          good = j >= 0 && shows(f, std::size_t(j), layer) && f.chart_of_slot(std::size_t(j)) == chart;
        }
      ok[i] = good;
    }
  }, 4096);
  std::vector<std::size_t> centres;
  for (std::size_t i = 0; i < count; ++i)
    if (ok[i]) centres.push_back(i);
  const std::size_t ex_w = std::size_t(std::max(0, ex.width - 2 * h)), ex_h = std::size_t(std::max(0, ex.height - 2 * h));
  if (centres.empty() || ex_w == 0 || ex_h == 0) return {kNoValue, centres.size()};
  const std::size_t want = std::size_t(std::max(1, o.windows));
  const std::vector<std::size_t> pick_s = strided(centres.size(), want), pick_e = strided(ex_w * ex_h, want);

  auto surface_lum = [&](std::size_t j) {
    return luminance(f.rgb[3 * j], f.rgb[3 * j + 1], f.rgb[3 * j + 2]);
  };
  std::vector<double> ws(pick_s.size() * kWindowDim), we(pick_e.size() * kWindowDim);
  for (std::size_t k = 0; k < pick_s.size(); ++k) {
    const std::size_t i = centres[pick_s[k]];
    const int x = f.x_of(i), y = f.y_of(i);
    for (int dy = -h, d = 0; dy <= h; ++dy)
      for (int dx = -h; dx <= h; ++dx, ++d) ws[k * kWindowDim + d] = surface_lum(std::size_t(f.slot_at(x + dx, y + dy)));
  }
  for (std::size_t k = 0; k < pick_e.size(); ++k) {
    const int x = int(pick_e[k] % ex_w) + h, y = int(pick_e[k] / ex_w) + h;
    for (int dy = -h, d = 0; dy <= h; ++dy)
      for (int dx = -h; dx <= h; ++dx, ++d) we[k * kWindowDim + d] = ex.lum[std::size_t(y + dy) * ex.width + (x + dx)];
  }
  const auto dirs = projections(o.projections, o.seed);
  std::vector<double> per_dir(dirs.size());
  parallel_for(dirs.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p) {
      auto project = [&](const std::vector<double>& w) {
        std::vector<double> out(w.size() / kWindowDim);
        for (std::size_t k = 0; k < out.size(); ++k) {
          double s = 0;
          for (int d = 0; d < kWindowDim; ++d) s += dirs[p][d] * w[k * kWindowDim + d];
          out[k] = s;
        }
        return out;
      };
      std::vector<double> a = project(ws), c = project(we);
      per_dir[p] = wasserstein1(a, c);
    }
  }, 1);
  const double mean = per_dir.empty() ? kNoValue : std::accumulate(per_dir.begin(), per_dir.end(), 0.0) / double(per_dir.size());
  return {mean, centres.size()};
}

/// Contrast and fidelity of the covered texels that show `layer` (every
/// covered texel when it is -1) against `exemplar`: the fields of
/// LayerMetrics up to surface_windows (`texels`: the texels compared).
LayerMetrics compare_with_exemplar(const FrameData& f, ExemplarAtScale& exemplar, double radius, const EvalOptions& o,
                                   int layer) {
  LayerMetrics c;
  const std::size_t count = f.texels.size();
  c.exemplar_scale = exemplar.original().width * f.texel_world / (2 * radius);
  const ExemplarStats& ex = exemplar.at(c.exemplar_scale);
  c.exemplar_luminance_std = ex.luminance_std;

  // Area-weighted luminance moments and colour histograms.
  struct Part {
    std::size_t covered = 0;
    double w = 0, wl = 0;
    std::array<std::vector<double>, 3> hist;
  };
  auto weight_of = [&](std::size_t i) { return f.area_per_texel[f.texels.triangle[i]]; };
  auto lum_of = [&](std::size_t i) { return luminance(f.rgb[3 * i], f.rgb[3 * i + 1], f.rgb[3 * i + 2]); };
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
    for (auto& h : p.hist) h.assign(kBins, 0);
    for (std::size_t i = b; i < e; ++i) {
      if (!shows(f, i, layer)) continue;
      const double w = weight_of(i);
      ++p.covered;
      p.w += w;
      p.wl += w * lum_of(i);
      for (int c = 0; c < 3; ++c) p.hist[c][bin_of(f.rgb[3 * i + c])] += w;
    }
  });
  Part total;
  for (auto& h : total.hist) h.assign(kBins, 0);
  for (const Part& p : parts) {
    total.covered += p.covered;
    total.w += p.w;
    total.wl += p.wl;
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < kBins; ++k) total.hist[c][k] += p.hist[c][k];
  }
  c.texels = total.covered;
  if (total.w > 0) {
    const double mean = total.wl / total.w;
    const auto var_parts = chunked<double>(count, [&](std::size_t b, std::size_t e, double& s) {
      for (std::size_t i = b; i < e; ++i)
        if (shows(f, i, layer)) s += weight_of(i) * (lum_of(i) - mean) * (lum_of(i) - mean);
    });
    c.luminance_std = std::sqrt(std::accumulate(var_parts.begin(), var_parts.end(), 0.0) / total.w);
    c.contrast = ex.luminance_std > 0 ? c.luminance_std / ex.luminance_std : kNoValue;
    double sum = 0;
    for (int k = 0; k < 3; ++k) sum += c.histogram_w1[k] = histogram_w1(total.hist[k], ex.histogram[k]);
    c.histogram_distance = sum / 3;
  }
  std::tie(c.sliced_wasserstein, c.surface_windows) = sliced_wasserstein(f, ex, o, layer);
  return c;
}

/// The mean of `get` over the layers with a value, weighted by their texels.
template <typename Get>
double texel_weighted(const std::vector<LayerMetrics>& layers, Get get) {
  double sum = 0, weight = 0;
  for (const LayerMetrics& l : layers)
    if (const double v = get(l); std::isfinite(v) && l.texels > 0) sum += double(l.texels) * v, weight += double(l.texels);
  return weight > 0 ? sum / weight : kNoValue;
}

/// A bake with exemplar layers: each layer's texels compared with its own
/// exemplar, the frame's figures their texel-weighted means, each layer's
/// share, and the agreement of the shown layer with the rules.
void layered_frame_metrics(const FrameData& f, std::vector<ExemplarAtScale>& exemplars, double radius,
                           const EvalOptions& o, FrameMetrics& m) {
  const std::size_t count = f.texels.size();
  struct Part {
    std::size_t covered = 0, with_layer = 0, agree = 0, interior = 0, interior_agree = 0;
  };
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
    for (std::size_t i = b; i < e; ++i) {
      if (!f.covered[i]) continue;
      ++p.covered;
      if (f.layer[i] < 0) continue;
      const bool agree = f.layer[i] == f.rule_layer[i];
      ++p.with_layer;
      p.agree += agree;
      if (f.rule_interior[i]) ++p.interior, p.interior_agree += agree;
    }
  });
  Part t;
  for (const Part& p : parts) {
    t.covered += p.covered, t.with_layer += p.with_layer, t.agree += p.agree;
    t.interior += p.interior, t.interior_agree += p.interior_agree;
  }
  m.covered_texels = t.covered;
  m.layer_agreement_texels = t.with_layer;
  m.layer_agreement = t.with_layer ? double(t.agree) / double(t.with_layer) : kNoValue;
  m.layer_agreement_interior_texels = t.interior;
  m.layer_agreement_interior = t.interior ? double(t.interior_agree) / double(t.interior) : kNoValue;

  m.layers.clear();
  for (std::size_t l = 0; l < exemplars.size(); ++l) {
    m.layers.push_back(compare_with_exemplar(f, exemplars[l], radius, o, int(l)));
    m.layers.back().share = t.with_layer ? double(m.layers.back().texels) / double(t.with_layer) : kNoValue;
  }
  const auto& L = m.layers;
  m.exemplar_scale = texel_weighted(L, [](const LayerMetrics& l) { return l.exemplar_scale; });
  m.luminance_std = texel_weighted(L, [](const LayerMetrics& l) { return l.luminance_std; });
  m.exemplar_luminance_std = texel_weighted(L, [](const LayerMetrics& l) { return l.exemplar_luminance_std; });
  m.contrast = texel_weighted(L, [](const LayerMetrics& l) { return l.contrast; });
  for (int c = 0; c < 3; ++c) m.histogram_w1[c] = texel_weighted(L, [c](const LayerMetrics& l) { return l.histogram_w1[c]; });
  m.histogram_distance = texel_weighted(L, [](const LayerMetrics& l) { return l.histogram_distance; });
  m.sliced_wasserstein = texel_weighted(L, [](const LayerMetrics& l) { return l.sliced_wasserstein; });
  m.surface_windows = 0;
  for (const LayerMetrics& l : L) m.surface_windows += l.surface_windows;
}

/// The single-frame metrics; `exemplars` holds one exemplar, or one per
/// layer of a bake with exemplar layers (FrameData::layer set).
void frame_metrics(const FrameData& f, std::vector<ExemplarAtScale>& exemplars, double radius, const EvalOptions& o,
                   FrameMetrics& m) {
  const std::size_t count = f.texels.size();
  m.chart_texels = count;
  m.texel_world_size = f.texel_world;
  if (f.layer.empty()) {
    const LayerMetrics c = compare_with_exemplar(f, exemplars.front(), radius, o, -1);
    m.covered_texels = c.texels;
    m.exemplar_scale = c.exemplar_scale;
    m.exemplar_luminance_std = c.exemplar_luminance_std;
    m.luminance_std = c.luminance_std;
    m.contrast = c.contrast;
    m.histogram_w1 = c.histogram_w1;
    m.histogram_distance = c.histogram_distance;
    m.sliced_wasserstein = c.sliced_wasserstein;
    m.surface_windows = c.surface_windows;
  } else {
    layered_frame_metrics(f, exemplars, radius, o, m);
  }
  m.coverage = count ? double(m.covered_texels) / double(count) : kNoValue;

  // Distortion over visible (covered, patch-named) texels.
  std::vector<float> delta(count, NAN);
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    Vec3 J[2];
    for (std::size_t i = b; i < e; ++i)
      if (f.patch[i] >= 0 && patch_jacobian(f, i, 2 * radius, J)) delta[i] = float(sorkine_delta(J));
  }, 4096);
  std::vector<float> d = finite_values(delta);
  m.distortion_texels = d.size();
  if (!d.empty()) {
    m.distortion_max = *std::max_element(d.begin(), d.end());
    m.distortion_p99 = quantile(d, 0.99);
    m.distortion_p90 = quantile(d, 0.9);
    m.distortion_median = quantile(d, 0.5);
  }
}

// ---- metrics between the previous frame and this one ------------------------

/// Frame t's texels bucketed by patch id and sorted by uv cell, for the
/// nearest (u,v) of a patch.
class PatchUvIndex {
 public:
  PatchUvIndex(const FrameData& f, double cell) : f_(f), cell_(cell) {
    int32_t max_id = -1;
    for (int32_t p : f.patch) max_id = std::max(max_id, p);
    offsets_.assign(std::size_t(max_id) + 2, 0);
    for (int32_t p : f.patch)
      if (p >= 0) ++offsets_[std::size_t(p) + 1];
    for (std::size_t k = 1; k < offsets_.size(); ++k) offsets_[k] += offsets_[k - 1];
    entries_.resize(offsets_.back());
    std::vector<std::size_t> fill(offsets_.begin(), offsets_.end() - 1);
    for (std::size_t i = 0; i < f.patch.size(); ++i)
      if (f.patch[i] >= 0) entries_[fill[f.patch[i]]++] = {cell_of(f.pv[i]), cell_of(f.pu[i]), uint32_t(i)};
    parallel_for(offsets_.size() - 1, [&](std::size_t b, std::size_t e) {
      for (std::size_t p = b; p < e; ++p)
        std::sort(entries_.begin() + std::ptrdiff_t(offsets_[p]), entries_.begin() + std::ptrdiff_t(offsets_[p + 1]));
    }, 64);
  }

  /// Chart texel of patch `id` with the nearest (u,v) within `cell`, -1 if none.
  int64_t nearest(int32_t id, float u, float v) const {
    if (id < 0 || std::size_t(id) + 1 >= offsets_.size()) return -1;
    const auto first = entries_.begin() + std::ptrdiff_t(offsets_[id]), last = entries_.begin() + std::ptrdiff_t(offsets_[id + 1]);
    const int32_t cx = cell_of(u), cy = cell_of(v);
    int64_t best = -1;
    double best_d2 = cell_ * cell_;
    for (int32_t y = cy - 1; y <= cy + 1; ++y) {
      for (auto it = std::lower_bound(first, last, Entry{y, cx - 1, 0}); it != last && it->cy == y && it->cx <= cx + 1; ++it) {
        const double du = f_.pu[it->slot] - u, dv = f_.pv[it->slot] - v, d2 = du * du + dv * dv;
        if (d2 < best_d2 || (d2 == best_d2 && (best < 0 || int64_t(it->slot) < best))) best_d2 = d2, best = it->slot;
      }
    }
    return best;
  }

 private:
  struct Entry {
    int32_t cy, cx;
    uint32_t slot;
    bool operator<(const Entry& o) const { return std::tie(cy, cx, slot) < std::tie(o.cy, o.cx, o.slot); }
  };
  int32_t cell_of(float x) const { return int32_t(std::floor(double(x) / cell_)); }
  const FrameData& f_;
  double cell_;
  std::vector<std::size_t> offsets_;
  std::vector<Entry> entries_;
};

/// Chart texel of `prev` under a point on its surface (closest-point hit):
/// the texel containing its atlas uv, else the nearest chart texel of the
/// same chart among its 8 neighbours; -1 when none.
int32_t texel_under(const FrameData& prev, const ClosestHit& hit) {
  const std::size_t t = std::size_t(hit.triangle);
  const Vec2 uv = prev.uv.corner_uv[3 * t] * (1 - hit.b1 - hit.b2) + prev.uv.corner_uv[3 * t + 1] * hit.b1 +
                  prev.uv.corner_uv[3 * t + 2] * hit.b2;
  const double px = uv.x * prev.n, py = (1 - uv.y) * prev.n;
  const int x = std::clamp(int(std::floor(px)), 0, prev.n - 1), y = std::clamp(int(std::floor(py)), 0, prev.n - 1);
  const int chart = prev.chart_of_triangle[t];
  int32_t best = -1;
  double best_d2 = INFINITY;
  for (int dy = 0; dy <= 2; ++dy)
    for (int dx = 0; dx <= 2; ++dx) {
      // The centre texel first, so that it wins ties.
      const int xx = x + (dx == 2 ? -1 : dx), yy = y + (dy == 2 ? -1 : dy);
      const int32_t j = prev.slot_at(xx, yy);
      if (j < 0 || prev.chart_of_slot(std::size_t(j)) != chart) continue;
      const double ex = xx + 0.5 - px, ey = yy + 0.5 - py, d2 = ex * ex + ey * ey;
      if (d2 < best_d2) best_d2 = d2, best = j;
    }
  return best;
}

struct PairSettings {
  double dt = 0, radius = 0, bake_min_speed = 0, rest_speed = 0;
};

/// True when chart texel (x, y) and its 8 neighbours are all chart texels of
/// `chart` covered by `patch`: the texel is more than a texel from a patch
/// border, a chart border and any uncovered texel.
bool inside_patch(const FrameData& f, int x, int y, int chart, int32_t patch) {
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int32_t j = f.slot_at(x + dx, y + dy);
      if (j < 0 || f.patch[j] != patch || !f.covered[j] || f.chart_of_slot(std::size_t(j)) != chart) return false;
    }
  return true;
}

/// Drift at rest at fixed surface points (issue 12's definition). The points
/// are this frame's covered chart texels at rest (|v| <= rest speed); each is
/// located on the previous frame's surface by closest point, whose
/// barycentrics give the previous atlas uv and the texel holding it. A point
/// within a texel of a patch border in either frame (its 3x3 texels not all
/// one patch of one chart, covered) is left out: there only where each
/// frame's atlas happens to sample the surface decides which side it falls
/// on. A point farther from the previous surface than a texel, or than
/// rest_speed * dt when that is more, is left out too (the surface changed
/// there). The others changed when the patch
/// differs or (u, v) moved by more than one texel.
void rest_point_drift(const FrameData& prev, const FrameData& cur, const PairSettings& s, FrameMetrics& m) {
  const std::size_t count = cur.texels.size();
  const double two_r = 2 * s.radius;
  const double uv_texel = prev.texel_world / two_r;  // one texel of the previous frame in patch (u,v) units
  // A point at rest moves at most rest_speed * dt a frame (2 mm at 5 cm/s
  // and 24 fps, more than a texel at 1024^2 on viscous_drop); a texel when
  // that is less. Farther, the surface changed there.
  const double reach = std::max(prev.texel_world, s.rest_speed * s.dt);
  struct Part {
    std::size_t compared = 0, border = 0, far = 0, changed = 0;
  };
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
    for (std::size_t i = b; i < e; ++i) {
      if (cur.patch[i] < 0 || !(norm(velocity_at(cur, i, cur.position[i])) <= s.rest_speed)) continue;
      if (!inside_patch(cur, cur.x_of(i), cur.y_of(i), cur.chart_of_slot(i), cur.patch[i])) {
        ++p.border;
        continue;
      }
      const ClosestHit hit = prev.query->closest(cur.position[i], reach);
      if (!hit.found) {
        ++p.far;
        continue;
      }
      const std::size_t t = std::size_t(hit.triangle);
      const Vec2 uv = prev.uv.corner_uv[3 * t] * (1 - hit.b1 - hit.b2) + prev.uv.corner_uv[3 * t + 1] * hit.b1 +
                      prev.uv.corner_uv[3 * t + 2] * hit.b2;
      const int x = int(std::floor(uv.x * prev.n)), y = int(std::floor((1 - uv.y) * prev.n));
      const int32_t j = prev.slot_at(x, y);
      if (j < 0 || prev.chart_of_slot(std::size_t(j)) != prev.chart_of_triangle[t] ||
          !inside_patch(prev, x, y, prev.chart_of_triangle[t], prev.patch[j])) {
        ++p.border;
        continue;
      }
      ++p.compared;
      bool changed = prev.patch[j] != cur.patch[i];
      if (!changed) {
        // The previous frame's (u,v) at the located point (its texel's
        // neighbours are all of this patch).
        const Vec2 uv = patch_uv_at(prev, std::size_t(j), hit.point, two_r);
        changed = std::hypot(cur.pu[i] - uv.x, cur.pv[i] - uv.y) > uv_texel;
      }
      p.changed += changed;
    }
  });
  Part t;
  for (const Part& p : parts) {
    t.compared += p.compared;
    t.border += p.border;
    t.far += p.far;
    t.changed += p.changed;
  }
  m.drift_points = t.compared;
  m.drift_border_points = t.border;
  m.drift_far_points = t.far;
  m.drift = t.compared ? double(t.changed) / double(t.compared) : kNoValue;
}

// What a chart texel of the current frame was in the popping count
// (pair_metrics), as a popping map shows it.
enum class PopKind : uint8_t { NotCompared, Kept, PoppedToExisting, PoppedToNewborn };

/// Rest change at fixed surface points as shared/tools/check_bake.py
/// `change` measures it (FrameMetrics::rest_change).
void rest_point_change(const FrameData& prev, const FrameData& cur, const PairSettings& s, FrameMetrics& m) {
  const std::size_t count = cur.texels.size();
  // The texel as the checker sizes it: the surface's area over the chart
  // texels (whole texels, a little smaller than texel_world).
  const double uv_texel = cur.texel_world_count / (2 * s.radius);
  const double reach = 4 * cur.texel_world_count;
  const int n = prev.n;
  struct Part {
    std::size_t compared = 0, changed = 0;
  };
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
    for (std::size_t i = b; i < e; ++i) {
      if (cur.patch[i] < 0 || !(norm(velocity_at(cur, i, cur.position[i])) <= s.rest_speed)) continue;
      const ClosestHit hit = prev.query->closest(cur.position[i], reach);
      if (!hit.found) continue;
      const std::size_t t = std::size_t(hit.triangle);
      const Vec2 uv = prev.uv.corner_uv[3 * t] * (1 - hit.b1 - hit.b2) + prev.uv.corner_uv[3 * t + 1] * hit.b1 +
                      prev.uv.corner_uv[3 * t + 2] * hit.b2;
      // A point at a texel's very centre (a tie between two 2x2 blocks that
      // rounding would settle either way) takes the block that starts there.
      constexpr double kTie = 1e-9;
      const double x = uv.x * n - 0.5 + kTie, y = (1 - uv.y) * n - 0.5 + kTie;
      const int x0 = std::clamp(int(std::floor(x)), 0, n - 2), y0 = std::clamp(int(std::floor(y)), 0, n - 2);
      const double fx = std::clamp(x - x0, 0.0, 1.0), fy = std::clamp(y - y0, 0.0, 1.0);
      const int32_t j[4] = {prev.slot_at(x0, y0), prev.slot_at(x0 + 1, y0), prev.slot_at(x0, y0 + 1),
                            prev.slot_at(x0 + 1, y0 + 1)};
      bool same = true;
      for (int k = 0; k < 4 && same; ++k) same = j[k] >= 0 && prev.patch[j[k]] >= 0 && prev.patch[j[k]] == prev.patch[j[0]];
      if (!same) continue;
      ++p.compared;
      if (prev.patch[j[0]] != cur.patch[i]) {
        ++p.changed;
        continue;
      }
      const double w[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
      double u0 = 0, v0 = 0;
      for (int k = 0; k < 4; ++k) u0 += w[k] * prev.pu[j[k]], v0 += w[k] * prev.pv[j[k]];
      p.changed += std::hypot(cur.pu[i] - u0, cur.pv[i] - v0) > uv_texel;
    }
  });
  Part total;
  for (const Part& p : parts) total.compared += p.compared, total.changed += p.changed;
  m.rest_change_points = total.compared;
  m.rest_change = total.compared ? double(total.changed) / double(total.compared) : kNoValue;
}

void pair_metrics(const FrameData& prev, const FrameData& cur, const PairSettings& s, FrameMetrics& m,
                  std::vector<PopKind>* kinds = nullptr) {
  const std::size_t count = cur.texels.size();
  const double two_r = 2 * s.radius;
  // One texel of the previous frame in patch (u,v) units; matches are
  // accepted within 1.5 of them.
  const double uv_texel = prev.texel_world / two_r;
  const PatchUvIndex index(prev, 1.5 * uv_texel);
  const double floor_distance = prev.texel_world;  // |v| dt below one texel: no ratio
  auto bake_velocity = [&](const Vec3& v) { return norm(v) < s.bake_min_speed ? Vec3{} : v; };

  // Flow agreement: the texel's patch point on the previous frame, x_t, and
  // the trapezoid velocity between the two frames (the bake integrates with
  // both frames' fields; v_t alone would count one frame of acceleration,
  // e.g. gravity's, as error).
  std::vector<float> ratio(count, NAN);
  std::vector<uint8_t> matched(count, 0);
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    Vec3 J[2];
    for (std::size_t i = b; i < e; ++i) {
      if (cur.patch[i] < 0) continue;
      const int64_t j = index.nearest(cur.patch[i], cur.pu[i], cur.pv[i]);
      if (j < 0) continue;
      matched[i] = 1;
      Vec3 x_prev = prev.position[std::size_t(j)];
      if (patch_jacobian(prev, std::size_t(j), two_r, J)) {
        const double du = (cur.pu[i] - prev.pu[j]) * two_r, dv = (cur.pv[i] - prev.pv[j]) * two_r;
        x_prev += J[0] * du + J[1] * dv;
      }
      const Vec3 v = (bake_velocity(velocity_at(prev, std::size_t(j), x_prev)) +
                      bake_velocity(velocity_at(cur, i, cur.position[i]))) * 0.5;
      const double step = norm(v) * s.dt;
      if (!(step >= floor_distance)) continue;
      ratio[i] = float(norm(cur.position[i] - x_prev - v * s.dt) / step);
    }
  }, 1024);
  std::vector<float> r = finite_values(ratio);
  m.flow_texels = r.size();
  m.flow_p90 = quantile(r, 0.9);
  m.flow_median = quantile(r, 0.5);

  // Popping and per-texel drift at rest (drift_texel; it counts patch
  // borders, which rest_point_drift leaves out): each covered texel goes back
  // along its velocity to the previous frame's surface. A texel whose patch
  // point was visible on the previous frame (matched above) has not popped,
  // whatever the back-advected point says: first-order back-advection misses
  // by |a| dt^2 / 2 under acceleration, which would count patch borders as
  // pops.
  struct Part {
    std::size_t compared = 0, rest = 0, drifted = 0;
    double w = 0, w_popped = 0, w_popped_born = 0;
    // With exemplar layers, by the texel's layer on this frame.
    std::vector<std::size_t> layer_compared;
    std::vector<double> layer_w, layer_w_popped;
  };
  const std::size_t layers = cur.layer.empty() ? 0 : m.layers.size();
  // Ids grow with birth: a patch newer than every patch of the previous
  // frame's atlas was born on this frame.
  int32_t newest_prev = -1;
  for (const int32_t id : prev.patch) newest_prev = std::max(newest_prev, id);
  if (kinds) kinds->assign(count, PopKind::NotCompared);
  const double reach = 2 * s.radius;
  const double drift_tolerance = 0.5 * uv_texel;
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
    p.layer_compared.assign(layers, 0);
    p.layer_w.assign(layers, 0);
    p.layer_w_popped.assign(layers, 0);
    for (std::size_t i = b; i < e; ++i) {
      if (cur.patch[i] < 0) continue;
      const Vec3 v = velocity_at(cur, i, cur.position[i]);
      const ClosestHit hit = prev.query->closest(cur.position[i] - v * s.dt, reach);
      if (!hit.found) continue;
      const int32_t j = texel_under(prev, hit);
      if (j < 0 || prev.patch[j] < 0) continue;
      const double w = cur.area_per_texel[cur.texels.triangle[i]];
      const bool other_patch = prev.patch[j] != cur.patch[i], popped = other_patch && !matched[i];
      ++p.compared;
      p.w += w;
      const bool born = cur.patch[i] > newest_prev;
      if (popped) {
        p.w_popped += w;
        if (born) p.w_popped_born += w;
      }
      if (layers && cur.layer[i] >= 0) {
        const std::size_t l = std::size_t(cur.layer[i]);
        ++p.layer_compared[l];
        p.layer_w[l] += w;
        if (popped) p.layer_w_popped[l] += w;
      }
      if (kinds) (*kinds)[i] = !popped ? PopKind::Kept : born ? PopKind::PoppedToNewborn : PopKind::PoppedToExisting;
      if (norm(v) <= s.rest_speed) {
        ++p.rest;
        bool changed = other_patch;
        if (!changed) {
          // The previous frame's (u,v) at the hit point.
          const Vec2 uv = patch_uv_at(prev, std::size_t(j), hit.point, two_r);
          changed = std::hypot(cur.pu[i] - uv.x, cur.pv[i] - uv.y) > drift_tolerance;
        }
        p.drifted += changed;
      }
    }
  });
  Part t;
  for (const Part& p : parts) {
    t.compared += p.compared;
    t.rest += p.rest;
    t.drifted += p.drifted;
    t.w += p.w;
    t.w_popped += p.w_popped;
    t.w_popped_born += p.w_popped_born;
  }
  m.popping_texels = t.compared;
  m.popping = t.w > 0 ? t.w_popped / t.w : kNoValue;
  m.popping_births = t.w_popped > 0 ? t.w_popped_born / t.w_popped : kNoValue;
  m.rest_texels = t.rest;
  m.drift_texel = t.rest ? double(t.drifted) / double(t.rest) : kNoValue;
  for (std::size_t l = 0; l < layers; ++l) {
    std::size_t compared = 0;
    double w = 0, w_popped = 0;
    for (const Part& p : parts) compared += p.layer_compared[l], w += p.layer_w[l], w_popped += p.layer_w_popped[l];
    m.layers[l].popping_texels = compared;
    m.layers[l].popping = w > 0 ? w_popped / w : kNoValue;
  }

  rest_point_drift(prev, cur, s, m);
  rest_point_change(prev, cur, s, m);
}

/// The population of one frame as NAME.stats.jsonl gives it.
struct Population {
  std::size_t born = 0, died = 0;
  std::optional<std::size_t> alive, fresh_seeding, died_projection, died_eroded, died_hidden, died_merged;
};

/// The population per frame from NAME.stats.jsonl (absent file: none; fields
/// older bakes did not write stay empty).
std::map<int, Population> read_population(const BakeManifest& m) {
  std::map<int, Population> out;
  const std::string path = (fs::path(m.dir) / (m.name + ".stats.jsonl")).string();
  std::ifstream in(path);
  if (!in) return out;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    try {
      const auto j = nlohmann::json::parse(line);
      const auto& p = j.at("patches");
      Population& pop = out[j.at("frame").get<int>()];
      pop.born = p.at("born").get<std::size_t>();
      pop.died = p.at("retired").get<std::size_t>() + p.at("lost").get<std::size_t>();
      auto optional = [](const nlohmann::json& o, const char* key, std::optional<std::size_t>& to) {
        if (o.contains(key)) to = o.at(key).get<std::size_t>();
      };
      optional(p, "alive", pop.alive);
      optional(p, "fresh_seeding", pop.fresh_seeding);
      if (j.contains("deaths")) {
        const auto& d = j.at("deaths");
        optional(d, "lost_to_projection", pop.died_projection);
        optional(d, "eroded_away", pop.died_eroded);
        optional(d, "hidden", pop.died_hidden);
        optional(d, "merged", pop.died_merged);
      }
    } catch (const nlohmann::json::exception& e) {
      throw InputError(path, fmt::format("line {}: {}", number, e.what()));
    }
  }
  return out;
}

/// The popping map of `cur` (EvalOptions::maps_dir): RGBA half in the
/// frame's atlas layout, written atomically.
std::string write_popping_map(const BakeManifest& m, const FrameData& cur, const std::vector<PopKind>& kinds,
                              const std::string& dir) {
  Image img(cur.n, cur.n, 4);
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    if (kinds[i] == PopKind::NotCompared) continue;
    float* px = &img.pixels[std::size_t(cur.texels.texel[i]) * 4];
    px[0] = kinds[i] == PopKind::PoppedToNewborn;
    px[1] = kinds[i] == PopKind::PoppedToExisting;
    px[2] = kinds[i] == PopKind::Kept;
    px[3] = 1;
  }
  const std::string path = (fs::path(dir) / fs::path(m.frame_file("popping", cur.frame)).filename()).string();
  write_exr(path, img, {"R", "G", "B", "A"});
  return path;
}

}  // namespace

EvalReport evaluate_bake(const std::string& dir, const EvalOptions& o,
                         const std::function<void(const FrameMetrics&)>& on_frame) {
  const BakeManifest m = read_bake_manifest(dir);
  const std::string folder = m.dir.empty() ? dir : m.dir;
  // What the frames on disk were made with: the first frame's record (a
  // tracked folder rendered anew), else the manifest.
  std::optional<RenderRecord> rendered;
  if (!m.frames.empty()) {
    const int first = o.frames ? std::max(o.frames->first, m.frames.front()) : m.frames.front();
    try {
      if (std::error_code ec; fs::exists(m.frame_file("render", first), ec))
        rendered = read_render_record(m.frame_file("render", first));
    } catch (const InputError&) {
      rendered.reset();  // damaged: the manifest says
    }
  }
  const auto recorded = [&](const char* option) -> std::optional<std::string> {
    if (!rendered || !rendered->options.contains(option)) return std::nullopt;
    return rendered->options.at(option);
  };
  const bool aov = recorded("aov") ? *recorded("aov") == "true" : m.options.aov;
  if (!aov)
    throw InputError(folder, "the bake has no AOVs (NAME.aov.N.exr): bake (or render) again with --aov to evaluate it");
  if (!(m.options.patch.radius > 0)) throw InputError(bake_manifest_path(folder, m.name), "radius must be positive");
  if (!(m.options.fps > 0)) throw InputError(bake_manifest_path(folder, m.name), "fps must be positive");
  std::vector<int> frames;
  for (int f : m.frames)
    if (!o.frames || (f >= o.frames->first && f <= o.frames->last)) frames.push_back(f);
  if (frames.empty())
    throw UsageError(o.frames ? fmt::format("--frames {}-{}: the bake in {} has none of these frames", o.frames->first,
                                            o.frames->last, folder)
                              : "the bake in " + folder + " lists no frames");

  // The layers' rules, to read the layer they choose at each texel.
  LayerRules rules;
  try {
    rules = layer_rules(m.options);
  } catch (const UsageError& e) {
    throw InputError(bake_manifest_path(folder, m.name), e.what());
  }
  const bool layered = rules.size() > 1;
  if (layered && !o.exemplar.empty())
    throw UsageError(fmt::format("--exemplar: the bake in {} has exemplar layers ({}); eval compares each layer with "
                                 "its own exemplar", folder, fmt::join(rules.names, ", ")));

  EvalReport report;
  report.dir = folder;
  report.name = m.name;
  report.mode = raster_mode_name(m.options.raster.mode);
  // One --layer alone is a bake of that exemplar.
  const std::string bake_exemplar = m.options.layers.size() == 1 ? m.options.layers.front().color : m.options.exemplar_color;
  report.exemplar = !o.exemplar.empty()                              ? o.exemplar
                    : rendered && !rendered->exemplar_color.empty() ? rendered->exemplar_color
                                                                    : bake_exemplar;
  report.resolution = m.options.atlas.resolution;
  if (const auto res = recorded("resolution")) report.resolution = std::atoi(res->c_str());
  report.radius = m.options.patch.radius;
  report.fps = m.options.fps;
  report.rest_speed = o.min_speed ? *o.min_speed : m.options.min_speed;
  if (report.rest_speed < 0) throw UsageError("--min-speed must not be negative");
  std::vector<ExemplarAtScale> exemplars;
  if (layered) {
    report.exemplar.clear();
    for (const ExemplarLayer& layer : m.options.layers) {
      exemplars.emplace_back(read_image(exemplar_frame_files(layer.color).front()));
      report.layers.push_back({layer.name, layer.color, exemplar_stats(exemplars.back().original()).luminance_std});
      report.exemplar += (report.exemplar.empty() ? "" : ",") + layer.name + "=" + layer.color;
    }
    report.exemplar_luminance_std = kNoValue;
  } else {
    exemplars.emplace_back(read_image(exemplar_frame_files(report.exemplar).front()));
    report.exemplar_luminance_std = exemplar_stats(exemplars.front().original()).luminance_std;
  }
  const auto population = read_population(m);
  if (!o.maps_dir.empty()) {
    std::error_code ec;
    fs::create_directories(o.maps_dir, ec);
    if (ec) throw OutputError(o.maps_dir + ": cannot create the map folder: " + ec.message());
  }
  std::vector<PopKind> kinds;

  std::unique_ptr<FrameData> prev;
  for (const int frame : frames) {
    const auto t0 = std::chrono::steady_clock::now();
    auto cur = std::make_unique<FrameData>(load_baked_frame(m, frame, rules));
    FrameMetrics fm;
    fm.frame = frame;
    frame_metrics(*cur, exemplars, m.options.patch.radius, o, fm);
    if (const auto it = population.find(frame); it != population.end()) {
      const Population& pop = it->second;
      fm.born = pop.born, fm.died = pop.died;
      fm.alive = pop.alive, fm.fresh_seeding = pop.fresh_seeding;
      fm.died_projection = pop.died_projection, fm.died_eroded = pop.died_eroded, fm.died_hidden = pop.died_hidden;
      fm.died_merged = pop.died_merged;
    }
    if (prev && std::isfinite(prev->texel_world) && !prev->uv.mesh.empty()) {
      prev->query = std::make_unique<SurfaceQuery>(prev->uv.mesh);
      PairSettings s;
      s.dt = double(frame - prev->frame) / m.options.fps;
      s.radius = m.options.patch.radius;
      s.bake_min_speed = m.options.min_speed;
      s.rest_speed = report.rest_speed;
      pair_metrics(*prev, *cur, s, fm, o.maps_dir.empty() ? nullptr : &kinds);
      if (!o.maps_dir.empty()) report.maps.push_back(write_popping_map(m, *cur, kinds, o.maps_dir));
    }
    fm.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (fm.born) report.born += *fm.born;
    if (fm.died) report.died += *fm.died;
    report.frames.push_back(fm);
    if (on_frame) on_frame(fm);
    // The previous frame's images and arrays go before the next frame loads.
    prev = std::move(cur);
  }
  report.summary = summarize_metrics(report.frames);
  return report;
}

}  // namespace lapflow
