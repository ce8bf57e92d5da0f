// `lapflow eval`: one baked frame read back for the metrics (FrameData:
// the UV mesh, the chart texels' surface points, the AOV, the colour and the
// input velocity), the patch map's Jacobian at a texel, and the
// distribution helpers the metrics share.
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

namespace lapflow::eval_detail {
namespace fs = std::filesystem;

namespace {

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

}  // namespace

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

FrameData load_baked_frame(const BakeManifest& m, int frame, const LayerRules& rules) {
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
  const bool layered = rules.size() > 1;
  int c_layer = -1;
  if (layered) {
    const auto at = std::find(aov_names.begin(), aov_names.end(), "layer");
    if (at == aov_names.end())
      throw InputError(aov_path, fmt::format("no channel 'layer', yet the bake names {} exemplar layers", rules.size()),
                       frame);
    c_layer = int(at - aov_names.begin());
  }

  // Input velocities: the manifest's meshes (vertex i of the OBJ is vertex i
  // of the input mesh) or its VDB grids.
  const TriMesh& mesh = f.uv.mesh;
  FrameSource source;
  source.mesh_pattern = m.options.mesh_pattern;
  source.velocity_vdb_pattern = m.options.velocity_vdb_pattern;
  source.velocity_grid = m.options.velocity_grid;
  source.allow_zero_velocity = true;  // eval reads what the bake accepted; no velocity is zero velocity
  source.units_ok = true;             // the same: the bake decided (--units-ok)
  if (layered) source.attributes = rules.file_attributes();
  FrameInput in = read_frame_input(source, frame);
  if ((!in.grid || layered) && in.mesh.vertex_count() != mesh.vertex_count())
    throw InputError(in.path, fmt::format("has {} vertices but the baked {} has {}: the input changed since the bake",
                                          in.mesh.vertex_count(), fs::path(obj).filename().string(),
                                          mesh.vertex_count()),
                     frame);
  // The layer the rules choose: their attributes on the baked mesh (its
  // vertices and triangles are the input's) with the input's velocity and
  // PLY properties. LayerField reads the frame while it is built; later
  // only its mesh.
  Frame ruled;
  LayerField field;
  std::vector<uint8_t> vertex_layer;
  if (layered) {
    ruled.number = frame;
    ruled.path = in.path;
    ruled.mesh.positions = mesh.positions;
    ruled.mesh.triangles = mesh.triangles;
    ruled.mesh.velocities = in.mesh.velocities;
    ruled.velocity_grid = std::move(in.grid);
    ruled.attributes = std::move(in.attributes);
    field = LayerField(rules, ruled);
    vertex_layer = field.vertex_layers();
    in.grid = std::move(ruled.velocity_grid);
  }
  if (in.grid)
    f.grid = std::move(in.grid);
  else
    f.vertex_velocity = std::move(in.mesh.velocities);  // empty: zero velocity (--allow-zero-velocity)

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
  if (layered) {
    f.layer.resize(count);
    f.rule_layer.resize(count);
    f.rule_interior.resize(count);
  }
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
      if (layered) {
        const float layer = aov.at(x, y, c_layer);
        f.layer[i] = layer >= 0 ? int16_t(std::min(std::lround(layer), 32767L)) : int16_t(-1);
        f.rule_layer[i] = int16_t(field.layer_at(int(f.texels.triangle[i]), b1, b2));
        f.rule_interior[i] = vertex_layer[t[0]] == vertex_layer[t[1]] && vertex_layer[t[1]] == vertex_layer[t[2]];
      }
    }
  }, 4096);
  if (layered)
    for (std::size_t i = 0; i < count; ++i)
      if (f.layer[i] >= int(rules.size()))
        throw InputError(aov_path, fmt::format("layer {} at texel ({}, {}), but the bake names {} layers", f.layer[i],
                                               f.x_of(i), f.y_of(i), rules.size()),
                         frame);
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

}  // namespace lapflow::eval_detail
