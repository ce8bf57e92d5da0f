#pragma once
// `lapflow eval`'s parts shared by its files: the reductions over fixed
// chunks (so results do not depend on the thread count), the distribution
// distances, and FrameData, one baked frame as the metrics read it
// (eval_frame.cpp loads it; eval.cpp measures; eval_report.cpp reports).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lapflow/addons/eval.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"

namespace lapflow::eval_detail {

constexpr std::size_t kChunk = 1 << 15;  // texels per reduction chunk (fixed: thread-count independent)
constexpr int kBins = 1024;               // histogram bins on [0,1]
constexpr int kWindow = 5;                // window side of the sliced Wasserstein distance
constexpr int kWindowDim = kWindow * kWindow;

inline double luminance(float r, float g, float b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

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
double quantile(std::vector<float>& values, double q);

/// The finite values of `v`, in order.
std::vector<float> finite_values(const std::vector<float>& v);

/// W1 = integral |F_a - F_b| between two empirical distributions with equal
/// weights per sample. Sorts its arguments.
double wasserstein1(std::vector<double>& a, std::vector<double>& b);

/// W1 between two histograms on [0,1] with kBins bins (masses at the bin
/// centres): sum over bins of |CDF_a - CDF_b| * bin width.
double histogram_w1(const std::vector<double>& a, const std::vector<double>& b);

inline int bin_of(float v) { return std::clamp(int(v * kBins), 0, kBins - 1); }

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
  // With exemplar layers (empty with one exemplar), per chart texel:
  std::vector<int16_t> layer;           ///< the AOV layer, -1 where none
  std::vector<int16_t> rule_layer;      ///< the layer the rules choose at the surface point
  std::vector<uint8_t> rule_interior;   ///< the fluid triangle's three vertices choose one layer
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

/// Frame `frame` of the bake `m`: its UV mesh, colour and AOV atlases and
/// input velocities; with `rules` of more than one layer (layer_rules of the
/// manifest's options) also the AOV's layer channel and the layer the rules
/// choose at each chart texel, from the input mesh's attributes. Throws
/// InputError naming a missing or damaged file.
FrameData load_baked_frame(const BakeManifest& m, int frame, const LayerRules& rules = {});

/// Input velocity at chart texel i (m/s): per-vertex velocities interpolated
/// at the texel's barycentrics, or the grid at `p`.
Vec3 velocity_at(const FrameData& f, std::size_t i, const Vec3& p);

/// The 3x2 Jacobian J of the map (u,v) * 2r -> surface at chart texel i,
/// from one horizontal and one vertical neighbour of the same patch and chart
/// (forward, else backward). Columns J[0], J[1]. False when no such pair.
bool patch_jacobian(const FrameData& f, std::size_t i, double two_r, Vec3 J[2]);

/// Sorkine's delta = max(s1, 1/s2) of a 3x2 Jacobian.
double sorkine_delta(const Vec3 J[2]);

/// (u,v) * 2r offset that J maps closest to the 3D offset d (least squares).
Vec2 jacobian_solve(const Vec3 J[2], const Vec3& d);

/// Frame f's patch (u, v) at surface point x near chart texel i: the
/// texel's, moved by the patch Jacobian to x (unmoved where it has none).
Vec2 patch_uv_at(const FrameData& f, std::size_t i, const Vec3& x, double two_r);

}  // namespace lapflow::eval_detail
