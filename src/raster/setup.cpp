// Set-up of one frame's raster (begin_raster): the texel index, the
// per-texel keys, the fluid-triangle tables and seam cells (setup_context),
// the exemplar's level of detail and the hold's filtered feature map.
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"

namespace lapflow {
namespace detail {

static uint64_t cell_hash(const RasterContext& ctx, const Vec3& p) {
  const double h = ctx.seam_cell;
  return hash64(uint64_t(int64_t(std::floor(p.x / h))), uint64_t(int64_t(std::floor(p.y / h))),
                uint64_t(int64_t(std::floor(p.z / h))));
}

void setup_context(RasterContext& ctx) {
  const SurfaceAtlas& atlas = ctx.atlas;
  const TriMesh& mesh = ctx.mesh;
  ctx.N = atlas.resolution;
  const std::size_t nt = mesh.triangles.size();
  if (atlas.corner_uv.size() != nt * 3 || atlas.chart_of_triangle.size() != nt)
    throw std::invalid_argument("rasterize: the atlas does not belong to this mesh");
  const std::size_t NN = std::size_t(ctx.N) * ctx.N;
  if (NN >= (std::size_t(1) << 31)) throw std::invalid_argument("rasterize: atlas resolution above 46340");
  const TexelMap& tm = atlas.texels;
  ctx.index.assign(NN, -1);
  parallel_for(tm.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) ctx.index[tm.texel[i]] = int32_t(i);
  }, 1 << 14);
  ctx.keys.assign(tm.size(), kNoKey);

  ctx.pixel_map.resize(nt);
  ctx.tri_normal.resize(nt);
  ctx.tri_sphere.resize(nt);
  ctx.tri_area2_px.resize(nt);
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      const Tri& T = mesh.triangles[t];
      const Vec3 &a = mesh.positions[T[0]], &bb = mesh.positions[T[1]], &c = mesh.positions[T[2]];
      ctx.tri_normal[t] = normalized(cross(bb - a, c - a));
      const Vec3 m = (a + bb + c) / 3.0;
      ctx.tri_sphere[t] = {m, std::sqrt(std::max({norm2(a - m), norm2(bb - m), norm2(c - m)}))};
      const Vec2* cu = &atlas.corner_uv[t * 3];
      ctx.tri_area2_px[t] = std::abs(cross(cu[1] - cu[0], cu[2] - cu[0])) * double(ctx.N) * ctx.N;
      TrianglePixelMap& pm = ctx.pixel_map[t];
      pm.a = a;
      pm.e0 = bb - a, pm.e1 = c - a;
      pm.d00 = dot(pm.e0, pm.e0), pm.d01 = dot(pm.e0, pm.e1), pm.d11 = dot(pm.e1, pm.e1);
      pm.den = pm.d00 * pm.d11 - pm.d01 * pm.d01;
      pm.ok = pm.den > 1e-14 * pm.d00 * pm.d11;
      pm.uv0 = cu[0], pm.du1 = cu[1] - cu[0], pm.du2 = cu[2] - cu[0];
    }
  }, 4096);
  // Vertex -> triangles in triangle order (deterministic walk order).
  ctx.vt_offset.assign(mesh.positions.size() + 1, 0);
  for (const Tri& T : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++ctx.vt_offset[T[k] + 1];
  for (std::size_t v = 0; v < mesh.positions.size(); ++v) ctx.vt_offset[v + 1] += ctx.vt_offset[v];
  ctx.vt_list.resize(nt * 3);
  std::vector<int32_t> fill(ctx.vt_offset.begin(), ctx.vt_offset.end() - 1);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) ctx.vt_list[fill[mesh.triangles[t][k]]++] = int32_t(t);

  // Triangle -> triangles sharing a vertex: a count, then a fill.
  auto neighbours = [&](std::size_t t, auto&& emit) {
    int32_t seen[64];
    int count = 0;
    for (int k = 0; k < 3; ++k)
      for (int32_t j = ctx.vt_offset[mesh.triangles[t][k]]; j < ctx.vt_offset[mesh.triangles[t][k] + 1]; ++j) {
        const int32_t g = ctx.vt_list[j];
        if (g == int32_t(t) || std::find(seen, seen + count, g) != seen + count) continue;
        if (count < 64) seen[count++] = g;  // past 64 a repeat stays: the walk's set skips it
        emit(g);
      }
  };
  ctx.tt_offset.assign(nt + 1, 0);
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) neighbours(t, [&](int32_t) { ++ctx.tt_offset[t + 1]; });
  }, 4096);
  for (std::size_t t = 0; t < nt; ++t) ctx.tt_offset[t + 1] += ctx.tt_offset[t];
  ctx.tt_list.resize(std::size_t(ctx.tt_offset[nt]));
  parallel_for(nt, [&](std::size_t b, std::size_t e) {
    for (std::size_t t = b; t < e; ++t) {
      int32_t at = ctx.tt_offset[t];
      neighbours(t, [&](int32_t g) { ctx.tt_list[std::size_t(at++)] = g; });
    }
  }, 4096);

  // Seams: vertices whose triangles lie in more than one chart.
  std::vector<uint8_t> seam_vertex(mesh.positions.size(), 0);
  double edge_sum = 0;
  for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
    const int32_t b = ctx.vt_offset[v], e = ctx.vt_offset[v + 1];
    for (int32_t j = b + 1; j < e && !seam_vertex[v]; ++j)
      seam_vertex[v] = atlas.chart_of_triangle[ctx.vt_list[j]] != atlas.chart_of_triangle[ctx.vt_list[b]];
  }
  ctx.near_seam.assign(nt, 0);
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& T = mesh.triangles[t];
    ctx.near_seam[t] = seam_vertex[T[0]] | seam_vertex[T[1]] | seam_vertex[T[2]];
    edge_sum += norm(mesh.positions[T[1]] - mesh.positions[T[0]]);
  }
  // Cells about a patch triangle's size (r / 6 by default) or a fluid edge.
  ctx.seam_cell = std::max({nt > 0 ? edge_sum / double(nt) : 1.0, ctx.radius / 4, 1e-9});
  ctx.seam_grid.clear();
  for (std::size_t v = 0; v < mesh.positions.size(); ++v)
    if (seam_vertex[v]) ctx.seam_grid.push_back({cell_hash(ctx, mesh.positions[v]), int32_t(v)});
  std::sort(ctx.seam_grid.begin(), ctx.seam_grid.end());
}

}  // namespace detail

using namespace detail;

RasterBuffers begin_raster(const TriMesh& mesh, const SurfaceAtlas& atlas, const RasterExemplar& exemplar,
                           const RasterOptions& options, const WeightOptions& weights, TriangleLocator locate) {
  return begin_raster(mesh, atlas, ExemplarLayers{&exemplar, 1}, options, weights, std::move(locate));
}

RasterBuffers begin_raster(const TriMesh& mesh, const SurfaceAtlas& atlas, ExemplarLayers exemplars,
                           const RasterOptions& options, const WeightOptions& weights, TriangleLocator locate) {
  if (!(options.radius > 0)) throw std::invalid_argument("rasterize: radius must be positive");
  if (exemplars.empty() || exemplars.size() > kMaxLayers)
    throw std::invalid_argument("rasterize: from 1 to " + std::to_string(kMaxLayers) + " exemplar layers");
  for (const RasterExemplar& exemplar : exemplars)
    if (exemplar.mips.levels.empty()) throw std::invalid_argument("rasterize: exemplar not prepared");
  RasterBuffers r;
  r.context = std::make_shared<RasterContext>(mesh, atlas, options.mode, weights.delta_max);
  RasterContext& ctx = *r.context;
  ctx.options = options;
  for (const RasterExemplar& exemplar : exemplars) {
    ctx.layer_first.push_back(uint32_t(ctx.layers.size()));
    ctx.layer_frames.push_back(uint32_t(exemplar.frame_count()));
    for (std::size_t k = 0; k < exemplar.frame_count(); ++k) ctx.layers.emplace_back().exemplar = &exemplar.frame(k);
  }
  ctx.locate_fn = std::move(locate);
  ctx.locate = ctx.locate_fn ? &ctx.locate_fn : nullptr;
  ctx.radius = options.radius;
  setup_context(ctx);
  const int N = ctx.N;
  RasterStats& st = r.stats;
  st.chart_texels = atlas.texels.size();

  // Exemplar level of detail: one atlas texel spans texel_world_size / (2r)
  // of the patch's uv square.
  double wsum = 0, asum = 0;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const double a3 = triangle_area(mesh, int(t));
    const Vec2* cu = &atlas.corner_uv[t * 3];
    const double auv = 0.5 * std::abs(cross(cu[1] - cu[0], cu[2] - cu[0])) * double(N) * N;
    if (a3 > 0 && auv > 0 && std::isfinite(a3) && std::isfinite(auv)) {
      wsum += a3 * std::sqrt(a3 / auv);
      asum += a3;
    }
  }
  st.texel_world_size = asum > 0 ? wsum / asum : 0;
  ctx.texel_world_size = st.texel_world_size;
  ctx.hold = options.hold && options.mode == RasterMode::Erosion;
  // One atlas texel in uv.
  if (ctx.hold) ctx.held_reach = st.texel_world_size / (2 * options.radius);
  for (LayerMaps& layer : ctx.layers) {
    const RasterExemplar& exemplar = *layer.exemplar;
    const Image& base = exemplar.mips.levels[0];
    const double px_per_texel = st.texel_world_size / (2 * options.radius) * std::max(base.width, base.height);
    ExemplarTables own;
    ExemplarTables& tables = exemplar.tables ? *exemplar.tables : own;
    std::lock_guard lock(tables.mutex);
    if (ctx.hold) {
      // The window reaches a pixel further than the held reach so that the
      // bilinear lookup of the maximum bounds every lookup within the reach.
      const Image& F = exemplar.erosion.feature;
      const int kx = std::min(F.width, int(std::ceil(ctx.held_reach * F.width)) + 1);
      const int ky = std::min(F.height, int(std::ceil(ctx.held_reach * F.height)) + 1);
      const auto fits = [&](int k) { return tables.held[k] && tables.held[k]->kx == kx && tables.held[k]->ky == ky; };
      int slot = fits(0) ? 0 : fits(1) ? 1 : -1;
      if (slot < 0) {
        slot = 1 - tables.last_used;  // the one asked for longer ago
        auto held = std::make_shared<HeldTables>();
        held->kx = kx, held->ky = ky;
        held->erosion = exemplar.erosion;
        held->erosion.feature = max_filter(F, kx, ky);
        held->min.build(held->erosion.feature);
        tables.held[slot] = std::move(held);
      }
      tables.last_used = slot;
      layer.held = tables.held[slot];
    }
    if (options.mode == RasterMode::Erosion) {
      if (!tables.erosion_min) {
        auto min = std::make_shared<MinPyramid>();
        min->build(exemplar.erosion.feature);
        tables.erosion_min = std::move(min);
      }
      layer.erosion_min = tables.erosion_min;
    }
    layer.lod = options.mipmap && px_per_texel > 1 ? std::log2(px_per_texel) : 0;
  }
  st.lod = ctx.layers[0].lod;
  if (options.mode == RasterMode::Blend) {
    ctx.blend.trilinear = options.trilinear;
    ctx.blend.sums.assign(atlas.texels.size() * 5, 0);
    ctx.blend.best.assign(atlas.texels.size(), 0);
  }
  return r;
}

}  // namespace lapflow
