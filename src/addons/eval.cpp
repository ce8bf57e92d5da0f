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
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {

constexpr std::size_t kChunk = 1 << 15;  // texels per reduction chunk (fixed: thread-count independent)
constexpr int kBins = 1024;               // histogram bins on [0,1]
constexpr int kWindow = 5;                // window side of the sliced Wasserstein distance
constexpr int kWindowDim = kWindow * kWindow;

double luminance(float r, float g, float b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

/// Runs body(begin, end, part) over fixed chunks of [0, n) in parallel and
/// returns the per-chunk partial results in chunk order.
template <typename Part, typename Body>
std::vector<Part> chunked(std::size_t n, Body body) {
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<Part> parts(chunks);
  parallel_for(chunks, [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c) body(c * kChunk, std::min(n, (c + 1) * kChunk), parts[c]);
  }, 1);
  return parts;
}

/// Nearest-rank quantile (q in [0,1]) of the finite values; NaN when none.
/// Reorders `values`.
double quantile(std::vector<float>& values, double q) {
  if (values.empty()) return kNoValue;
  const std::size_t k = std::min(values.size() - 1, std::size_t(std::max(0.0, std::ceil(q * double(values.size())) - 1)));
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
  return values[k];
}

/// The finite values of `v`, in order.
std::vector<float> finite_values(const std::vector<float>& v) {
  std::vector<float> out;
  out.reserve(v.size());
  for (float x : v)
    if (std::isfinite(x)) out.push_back(x);
  return out;
}

/// W1 = integral |F_a - F_b| between two empirical distributions with equal
/// weights per sample. Sorts its arguments.
double wasserstein1(std::vector<double>& a, std::vector<double>& b) {
  if (a.empty() || b.empty()) return kNoValue;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  const double na = double(a.size()), nb = double(b.size());
  std::size_t i = 0, j = 0;
  double prev = std::min(a[0], b[0]), sum = 0;
  while (i < a.size() || j < b.size()) {
    const double x = std::min(i < a.size() ? a[i] : INFINITY, j < b.size() ? b[j] : INFINITY);
    sum += std::abs(double(i) / na - double(j) / nb) * (x - prev);
    while (i < a.size() && a[i] == x) ++i;
    while (j < b.size() && b[j] == x) ++j;
    prev = x;
  }
  return sum;
}

/// W1 between two histograms on [0,1] with kBins bins (masses at the bin
/// centres): sum over bins of |CDF_a - CDF_b| * bin width.
double histogram_w1(const std::vector<double>& a, const std::vector<double>& b) {
  const double ta = std::accumulate(a.begin(), a.end(), 0.0), tb = std::accumulate(b.begin(), b.end(), 0.0);
  if (!(ta > 0) || !(tb > 0)) return kNoValue;
  double ca = 0, cb = 0, sum = 0;
  for (int k = 0; k + 1 < kBins; ++k) {
    ca += a[k] / ta;
    cb += b[k] / tb;
    sum += std::abs(ca - cb);
  }
  return sum / kBins;
}

int bin_of(float v) { return std::clamp(int(v * kBins), 0, kBins - 1); }

// ---- one frame of a bake ---------------------------------------------------

/// Everything the metrics read of one baked frame. Per chart texel arrays are
/// indexed like TexelMap (sorted by texel index y * N + x).
struct FrameData {
  int frame = 0, n = 0;
  UvMesh uv;
  std::vector<int32_t> chart_of_triangle;
  std::vector<double> area_per_texel;   ///< per triangle: square metres of surface per atlas texel
  TexelMap texels;
  std::vector<int32_t> slot;            ///< per atlas texel: index into the chart texel arrays, -1 outside charts
  std::vector<Vec3> position;           ///< per chart texel: surface point under the texel centre
  std::vector<int32_t> patch;           ///< per chart texel: AOV patch id, -1 where none
  std::vector<float> pu, pv;            ///< per chart texel: AOV patch coordinates
  std::vector<uint8_t> covered;         ///< patch >= 0 or alpha = 1
  std::vector<float> rgb;               ///< per chart texel: linear R, G, B
  double texel_world = 0;               ///< metres per texel: sqrt(surface area / chart uv area in texels)
  double texel_world_count = 0;         ///< metres per texel: sqrt(surface area / chart texel count)
  std::vector<Vec3> vertex_velocity;    ///< input per-vertex velocity (empty: grid or zero)
  std::unique_ptr<VelocityGrid> grid;
  std::unique_ptr<SurfaceQuery> query;  ///< built when the next frame looks back at this one

  int x_of(std::size_t i) const { return int(texels.texel[i] % uint32_t(n)); }
  int y_of(std::size_t i) const { return int(texels.texel[i] / uint32_t(n)); }
  int32_t slot_at(int x, int y) const {
    return x < 0 || y < 0 || x >= n || y >= n ? -1 : slot[std::size_t(y) * n + x];
  }
  int chart_of_slot(std::size_t i) const { return chart_of_triangle[texels.triangle[i]]; }
};

/// Charts of a UV mesh: triangles that share a corner with the same vertex
/// and the same uv (one OBJ `vt`) are in one chart.
std::vector<int32_t> uv_charts(const UvMesh& uv) {
  const std::size_t nt = uv.mesh.triangle_count();
  std::vector<int32_t> parent(nt);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  struct Corner {
    int32_t vertex;
    double u, v;
    int32_t tri;
  };
  std::vector<Corner> corners(3 * nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k)
      corners[3 * t + k] = {uv.mesh.triangles[t][k], uv.corner_uv[3 * t + k].x, uv.corner_uv[3 * t + k].y, int32_t(t)};
  std::sort(corners.begin(), corners.end(), [](const Corner& a, const Corner& b) {
    return std::tie(a.vertex, a.u, a.v, a.tri) < std::tie(b.vertex, b.u, b.v, b.tri);
  });
  for (std::size_t k = 1; k < corners.size(); ++k) {
    const Corner &a = corners[k - 1], &b = corners[k];
    if (a.vertex == b.vertex && a.u == b.u && a.v == b.v) {
      const int32_t ra = find(a.tri), rb = find(b.tri);
      if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
    }
  }
  std::vector<int32_t> chart(nt);
  for (std::size_t t = 0; t < nt; ++t) chart[t] = find(int32_t(t));
  return chart;
}

int channel_index(const std::vector<std::string>& names, const std::string& want, const std::string& path) {
  for (std::size_t c = 0; c < names.size(); ++c)
    if (names[c] == want) return int(c);
  throw InputError(path, "no channel '" + want + "'");
}

FrameData load_baked_frame(const BakeManifest& m, int frame) {
  FrameData f;
  f.frame = frame;
  const std::string obj = m.frame_file("obj", frame), color_path = m.frame_file("color", frame),
                    aov_path = m.frame_file("aov", frame);
  if (!fs::exists(obj))
    throw InputError(obj, "missing: the bake did not write this frame (pick the frames it has with --frames)", frame);
  if (!fs::exists(aov_path))
    throw InputError(m.dir, "the bake has no AOVs (" + fs::path(aov_path).filename().string() +
                                " is missing): bake again with --aov to evaluate it", frame);
  f.uv = read_uv_mesh(obj);
  if (f.uv.corner_uv.empty() && !f.uv.mesh.empty()) throw InputError(obj, "no texture coordinates (vt)", frame);
  const Image aov = read_image(aov_path, ColorSpace::Linear);
  const Image color = read_image(color_path, ColorSpace::Linear);
  if (aov.width != aov.height || color.width != aov.width || color.height != aov.height)
    throw InputError(aov_path, fmt::format("atlas sizes differ: aov {}x{}, colour {}x{} (both must be square and equal)",
                                           aov.width, aov.height, color.width, color.height), frame);
  const auto aov_names = image_channel_names(aov_path), color_names = image_channel_names(color_path);
  const int c_id = channel_index(aov_names, "patch_id", aov_path), c_u = channel_index(aov_names, "u", aov_path),
            c_v = channel_index(aov_names, "v", aov_path);
  const int c_r = channel_index(color_names, "R", color_path), c_g = channel_index(color_names, "G", color_path),
            c_b = channel_index(color_names, "B", color_path), c_a = channel_index(color_names, "A", color_path);
  f.n = aov.width;

  // Input velocities: the manifest's meshes (vertex i of the OBJ is vertex i
  // of the input mesh) or its VDB grids.
  const TriMesh& mesh = f.uv.mesh;
  FrameSource source;
  source.mesh_pattern = m.options.mesh_pattern;
  source.velocity_vdb_pattern = m.options.velocity_vdb_pattern;
  source.velocity_grid = m.options.velocity_grid;
  source.allow_zero_velocity = true;  // eval reads what the bake accepted; no velocity is zero velocity
  source.units_ok = true;             // the same: the bake decided (--units-ok)
  FrameInput in = read_frame_input(source, frame);
  if (in.grid) {
    f.grid = std::move(in.grid);
  } else {
    if (in.mesh.vertex_count() != mesh.vertex_count())
      throw InputError(in.path, fmt::format("has {} vertices but the baked {} has {}: the input changed since the bake",
                                            in.mesh.vertex_count(), fs::path(obj).filename().string(),
                                            mesh.vertex_count()),
                       frame);
    f.vertex_velocity = std::move(in.mesh.velocities);  // empty: zero velocity (--allow-zero-velocity)
  }

  // Chart texels exactly as the bake's atlas defines them, and per-triangle
  // surface area per texel.
  f.texels = atlas_detail::build_texel_map(f.uv.corner_uv, f.n);
  f.chart_of_triangle = uv_charts(f.uv);
  const std::size_t nt = mesh.triangle_count();
  f.area_per_texel.assign(nt, 0);
  double area3 = 0, area_uv = 0;
  for (std::size_t t = 0; t < nt; ++t) {
    const Vec2 a = f.uv.corner_uv[3 * t], b = f.uv.corner_uv[3 * t + 1], c = f.uv.corner_uv[3 * t + 2];
    const double uv_texels = 0.5 * std::abs(cross(b - a, c - a)) * double(f.n) * f.n;
    const double area = triangle_area(mesh, int(t));
    if (uv_texels > 0) {
      f.area_per_texel[t] = area / uv_texels;
      area3 += area;
      area_uv += uv_texels;
    }
  }
  f.texel_world = area_uv > 0 ? std::sqrt(area3 / area_uv) : kNoValue;
  f.texel_world_count = f.texels.size() ? std::sqrt(area3 / double(f.texels.size())) : kNoValue;

  const std::size_t count = f.texels.size();
  f.slot.assign(std::size_t(f.n) * f.n, -1);
  f.position.resize(count);
  f.patch.resize(count);
  f.pu.resize(count);
  f.pv.resize(count);
  f.covered.resize(count);
  f.rgb.resize(3 * count);
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const uint32_t texel = f.texels.texel[i];
      f.slot[texel] = int32_t(i);
      const Tri& t = mesh.triangles[f.texels.triangle[i]];
      float fb1, fb2;
      texel_barycentrics(f.uv.corner_uv, f.n, texel, f.texels.triangle[i], fb1, fb2);
      const double b1 = fb1, b2 = fb2;
      f.position[i] = mesh.positions[t[0]] * (1 - b1 - b2) + mesh.positions[t[1]] * b1 + mesh.positions[t[2]] * b2;
      const int x = int(texel % uint32_t(f.n)), y = int(texel / uint32_t(f.n));
      const float id = aov.at(x, y, c_id);
      f.patch[i] = id >= 0 ? int32_t(std::lround(id)) : -1;
      f.pu[i] = aov.at(x, y, c_u);
      f.pv[i] = aov.at(x, y, c_v);
      f.covered[i] = f.patch[i] >= 0 || color.at(x, y, c_a) >= 0.999f;
      f.rgb[3 * i] = color.at(x, y, c_r);
      f.rgb[3 * i + 1] = color.at(x, y, c_g);
      f.rgb[3 * i + 2] = color.at(x, y, c_b);
    }
  }, 4096);
  return f;
}

/// Input velocity at chart texel i (m/s): per-vertex velocities interpolated
/// at the texel's barycentrics, or the grid at `p`.
Vec3 velocity_at(const FrameData& f, std::size_t i, const Vec3& p) {
  if (f.grid) return f.grid->sample(p);
  if (f.vertex_velocity.empty()) return {};
  const Tri& t = f.uv.mesh.triangles[f.texels.triangle[i]];
  float fb1, fb2;
  texel_barycentrics(f.uv.corner_uv, f.n, f.texels.texel[i], f.texels.triangle[i], fb1, fb2);
  const double b1 = fb1, b2 = fb2;
  return f.vertex_velocity[t[0]] * (1 - b1 - b2) + f.vertex_velocity[t[1]] * b1 + f.vertex_velocity[t[2]] * b2;
}

/// The 3x2 Jacobian J of the map (u,v) * 2r -> surface at chart texel i,
/// from one horizontal and one vertical neighbour of the same patch and chart
/// (forward, else backward). Columns J[0], J[1]. False when no such pair.
bool patch_jacobian(const FrameData& f, std::size_t i, double two_r, Vec3 J[2]) {
  const int x = f.x_of(i), y = f.y_of(i), chart = f.chart_of_slot(i);
  auto neighbour = [&](int dx, int dy) -> int32_t {
    for (const int s : {1, -1}) {
      const int32_t j = f.slot_at(x + s * dx, y + s * dy);
      if (j >= 0 && f.patch[j] == f.patch[i] && f.chart_of_slot(std::size_t(j)) == chart) return j;
    }
    return -1;
  };
  const int32_t jx = neighbour(1, 0), jy = neighbour(0, 1);
  if (jx < 0 || jy < 0) return false;
  const Vec2 a{(f.pu[jx] - f.pu[i]) * two_r, (f.pv[jx] - f.pv[i]) * two_r};
  const Vec2 b{(f.pu[jy] - f.pu[i]) * two_r, (f.pv[jy] - f.pv[i]) * two_r};
  const Vec3 A = f.position[jx] - f.position[i], B = f.position[jy] - f.position[i];
  const double det = cross(a, b);
  // Both steps are about one texel in uv; a determinant far below their
  // product means the patch coordinates do not change across the texels.
  if (!(std::abs(det) > 1e-6 * norm(a) * norm(b)) || !(std::abs(det) > 0)) return false;
  J[0] = (A * b.y - B * a.y) / det;
  J[1] = (B * a.x - A * b.x) / det;
  return true;
}

/// Sorkine's delta = max(s1, 1/s2) of a 3x2 Jacobian.
double sorkine_delta(const Vec3 J[2]) {
  const double g00 = dot(J[0], J[0]), g01 = dot(J[0], J[1]), g11 = dot(J[1], J[1]);
  const double half_trace = 0.5 * (g00 + g11), det = g00 * g11 - g01 * g01;
  const double disc = std::sqrt(std::max(0.0, half_trace * half_trace - det));
  const double s1 = std::sqrt(half_trace + disc), s2 = std::sqrt(std::max(0.0, half_trace - disc));
  return s2 > 0 ? std::max(s1, 1 / s2) : INFINITY;
}

/// (u,v) * 2r offset that J maps closest to the 3D offset d (least squares).
Vec2 jacobian_solve(const Vec3 J[2], const Vec3& d) {
  const double g00 = dot(J[0], J[0]), g01 = dot(J[0], J[1]), g11 = dot(J[1], J[1]);
  const double det = g00 * g11 - g01 * g01;
  if (!(det > 0)) return {};
  const double r0 = dot(J[0], d), r1 = dot(J[1], d);
  return {(g11 * r0 - g01 * r1) / det, (g00 * r1 - g01 * r0) / det};
}

/// Frame f's patch (u, v) at surface point x near chart texel i: the
/// texel's, moved by the patch Jacobian to x (unmoved where it has none).
Vec2 patch_uv_at(const FrameData& f, std::size_t i, const Vec3& x, double two_r) {
  double u = f.pu[i], v = f.pv[i];
  Vec3 J[2];
  if (patch_jacobian(f, i, two_r, J)) {
    const Vec2 d = jacobian_solve(J, x - f.position[i]);
    u += d.x / two_r;
    v += d.y / two_r;
  }
  return {u, v};
}

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

/// Sliced W1 between 5x5 luminance windows of the surface (every texel of
/// the window a covered texel of the centre's chart) and of the exemplar at
/// the atlas texel scale. Returns {distance, surface windows used}.
std::pair<double, std::size_t> sliced_wasserstein(const FrameData& f, const ExemplarStats& ex,
                                                  const EvalOptions& o) {
  constexpr int h = kWindow / 2;
  const std::size_t count = f.texels.size();
  std::vector<uint8_t> ok(count, 0);
  parallel_for(count, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      if (!f.covered[i]) continue;
      const int x = f.x_of(i), y = f.y_of(i), chart = f.chart_of_slot(i);
      bool good = true;
      for (int dy = -h; dy <= h && good; ++dy)
        for (int dx = -h; dx <= h && good; ++dx) {
          const int32_t j = f.slot_at(x + dx, y + dy);
          good = j >= 0 && f.covered[j] && f.chart_of_slot(std::size_t(j)) == chart;
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

void frame_metrics(const FrameData& f, ExemplarAtScale& exemplar, double radius, const EvalOptions& o,
                   FrameMetrics& m) {
  const std::size_t count = f.texels.size();
  m.chart_texels = count;
  m.texel_world_size = f.texel_world;
  m.exemplar_scale = exemplar.original().width * f.texel_world / (2 * radius);
  const ExemplarStats& ex = exemplar.at(m.exemplar_scale);
  m.exemplar_luminance_std = ex.luminance_std;

  // Coverage, area-weighted luminance moments and colour histograms.
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
      if (!f.covered[i]) continue;
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
  m.covered_texels = total.covered;
  m.coverage = count ? double(total.covered) / double(count) : kNoValue;
  if (total.w > 0) {
    const double mean = total.wl / total.w;
    const auto var_parts = chunked<double>(count, [&](std::size_t b, std::size_t e, double& s) {
      for (std::size_t i = b; i < e; ++i)
        if (f.covered[i]) s += weight_of(i) * (lum_of(i) - mean) * (lum_of(i) - mean);
    });
    m.luminance_std = std::sqrt(std::accumulate(var_parts.begin(), var_parts.end(), 0.0) / total.w);
    m.contrast = ex.luminance_std > 0 ? m.luminance_std / ex.luminance_std : kNoValue;
    double sum = 0;
    for (int c = 0; c < 3; ++c) sum += m.histogram_w1[c] = histogram_w1(total.hist[c], ex.histogram[c]);
    m.histogram_distance = sum / 3;
  }
  std::tie(m.sliced_wasserstein, m.surface_windows) = sliced_wasserstein(f, ex, o);

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
  };
  // Ids grow with birth: a patch newer than every patch of the previous
  // frame's atlas was born on this frame.
  int32_t newest_prev = -1;
  for (const int32_t id : prev.patch) newest_prev = std::max(newest_prev, id);
  if (kinds) kinds->assign(count, PopKind::NotCompared);
  const double reach = 2 * s.radius;
  const double drift_tolerance = 0.5 * uv_texel;
  const auto parts = chunked<Part>(count, [&](std::size_t b, std::size_t e, Part& p) {
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

// ---- the metrics as a list, for the summary, JSON, table and plots ----------

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

}  // namespace

// ---- public entry points ----------------------------------------------------

std::vector<MetricSummary> summarize_metrics(const std::vector<FrameMetrics>& frames) {
  std::vector<MetricSummary> out;
  for (const MetricDef& d : metric_defs()) {
    MetricSummary s;
    s.key = d.key;
    std::vector<float> v;
    double sum = 0;
    for (const FrameMetrics& m : frames)
      if (const double x = d.get(m); std::isfinite(x)) v.push_back(float(x)), sum += x;
    s.frames = v.size();
    if (!v.empty()) {
      s.mean = sum / double(v.size());
      s.max = *std::max_element(v.begin(), v.end());
      s.median = quantile(v, 0.5);
    }
    out.push_back(s);
  }
  return out;
}

EvalReport evaluate_bake(const std::string& dir, const EvalOptions& o,
                         const std::function<void(const FrameMetrics&)>& on_frame) {
  const BakeManifest m = read_bake_manifest(dir);
  const std::string folder = m.dir.empty() ? dir : m.dir;
  if (!m.options.aov)
    throw InputError(folder, "the bake has no AOVs (NAME.aov.N.exr): bake again with --aov to evaluate it");
  if (!(m.options.patch.radius > 0)) throw InputError(bake_manifest_path(folder, m.name), "radius must be positive");
  if (!(m.options.fps > 0)) throw InputError(bake_manifest_path(folder, m.name), "fps must be positive");
  std::vector<int> frames;
  for (int f : m.frames)
    if (!o.frames || (f >= o.frames->first && f <= o.frames->last)) frames.push_back(f);
  if (frames.empty())
    throw UsageError(o.frames ? fmt::format("--frames {}-{}: the bake in {} has none of these frames", o.frames->first,
                                            o.frames->last, folder)
                              : "the bake in " + folder + " lists no frames");

  EvalReport report;
  report.dir = folder;
  report.name = m.name;
  report.mode = raster_mode_name(m.options.raster.mode);
  report.exemplar = o.exemplar.empty() ? m.options.exemplar_color : o.exemplar;
  report.resolution = m.options.atlas.resolution;
  report.radius = m.options.patch.radius;
  report.fps = m.options.fps;
  report.rest_speed = o.min_speed ? *o.min_speed : m.options.min_speed;
  if (report.rest_speed < 0) throw UsageError("--min-speed must not be negative");
  ExemplarAtScale exemplar(read_image(report.exemplar));
  report.exemplar_luminance_std = exemplar_stats(exemplar.original()).luminance_std;
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
    auto cur = std::make_unique<FrameData>(load_baked_frame(m, frame));
    FrameMetrics fm;
    fm.frame = frame;
    frame_metrics(*cur, exemplar, m.options.patch.radius, o, fm);
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
  }
  nlohmann::json summary = nlohmann::json::object();
  for (const MetricSummary& s : r.summary)
    summary[s.key] = {{"frames", s.frames}, {"mean", number(s.mean)}, {"median", number(s.median)}, {"max", number(s.max)}};
  const nlohmann::json j{{"dir", r.dir},
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
  return j.dump(2) + "\n";
}

namespace {

std::string cell(double v, const char* spec, int width) {
  if (!std::isfinite(v)) return fmt::format("{:>{}}", "-", width);
  return fmt::format(fmt::runtime(fmt::format("{{:>{}{}}}", width, spec)), v);
}

}  // namespace

std::string eval_report_table(const EvalReport& r) {
  std::string out = fmt::format("{} ({} mode) in {}\nexemplar {} | atlas {} | r = {:.4g} m | {} fps | rest below {:.4g} m/s\n\n",
                                r.name, r.mode, r.dir, r.exemplar, r.resolution, r.radius, r.fps, r.rest_speed);
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
  for (const MetricSummary& x : r.summary) s[x.key] = &x;
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
