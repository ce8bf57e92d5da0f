// Lapped rasterization's resolve pass (ALGORITHM.md step 7): each chart
// texel samples the exemplar at its winner's (u, v), marks the cells its
// patch held, and texels no patch triangle reached take their extended map.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"
#include "raster/sampling.hpp"

namespace lapflow {

using namespace detail;

FrameTextures resolve_texels(RasterBuffers& r, const PatchSet& patches) {
  RasterContext& ctx = *r.context;
  RasterStats& st = r.stats;
  const RasterOptions& options = ctx.options;
  const SurfaceAtlas& atlas = ctx.atlas;
  const TexelMap& tm = atlas.texels;
  const int N = ctx.N;
  const bool blend = options.mode == RasterMode::Blend;
  FrameTextures out;
  // The winner's (u, v, w) at the texel centre, then E and H.
  // The three images are allocated (zero-filled, page by page) on both
  // cores at once.
  const bool half = options.images && options.half_images;
  // patch_id, u, v, w, and with more than one exemplar layer the patch's layer.
  const int aov_channels = ctx.layer_first.size() > 1 ? 5 : 4;
  auto half_image = [&](int channels) {
    HalfImage h;
    h.width = N, h.height = N, h.channels = channels;
    h.bits.assign(std::size_t(N) * N * std::size_t(channels), 0);  // 0: +0 in half
    return h;
  };
  parallel_for(3, [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) {
      if (k == 0 && half) out.color_half = half_image(4);
      if (k == 0 && options.images && !half) out.color = Image(N, N, 4);
      if (k == 1 && half) out.displacement_half = half_image(1);
      if (k == 1 && options.images && !half) out.displacement = Image(N, N, 1);
      if (k == 2 && options.aov) out.aov = Image(N, N, aov_channels);
    }
  }, 1);
  float fallback[4];  // a texel no patch could reach (a chart hole filling failed on): the exemplar's mean
  sample(ctx.layers[0].exemplar->mips, 0.5, 0.5, 1e9, fallback);
  std::vector<std::atomic<uint64_t>> won(patches.patches.size());
  for (auto& a : won) a.store(0, std::memory_order_relaxed);
  // A winner's pixel-space triangle, for texels of one chart (same_chart)
  // or of one fluid triangle. Texels come in row order, so a patch triangle
  // returns on the next rows: a direct-mapped cache per thread, large enough
  // for a row's worth of triangles, saves most of the recomputation
  // (winner_pixels is a pure function of these, so hits cannot change a
  // result). The generation number empties it for each call.
  struct Winner {
    uint64_t key = kNoKey;
    int tri = -1, chart = -1;
    bool ok = false, same_chart = false;
    Bary bary;
    Vec2 ux, uy;  // the patch's uv per pixel step in x and y (Patch::held)
    const LayerMaps* layer = nullptr;  // RasterContext::layer_of the patch
  };
  // Patch::held for the next frame (below, per won texel). Bits are or-ed:
  // the result does not depend on the order.
  const bool hold = ctx.hold && options.mark_held;
  if (hold) ctx.held_next.assign(patches.patches.size() * kHeldWords, 0);
  else ctx.held_next.clear();
  // A texel won by the test marks the cells that lie wholly inside its
  // footprint (the texel square mapped into uv by the winner's affine map:
  // pixel steps ux, uy), and the cell under its centre. No other texel's
  // centre lies in its footprint, so on an unchanged sampling no texel that
  // lost finds its cell held (for cells smaller than a texel), and the frame
  // repeats; under a new sampling the footprints tile the won region but for
  // a band one cell wide along their borders, which the union over frames
  // fills.
  auto mark_held = [&](std::size_t p, double u, double v, Vec2 ux, Vec2 uy) {
    constexpr int R = kHeldCells;
    uint64_t* words = &ctx.held_next[p * kHeldWords];
    auto set = [&](int cu, int cv) {
      const std::size_t bit = std::size_t(cv) * R + std::size_t(cu);
      std::atomic_ref<uint64_t> slot(words[bit >> 6]);
      const uint64_t mask = uint64_t(1) << (bit & 63);
      if (!(slot.load(std::memory_order_relaxed) & mask)) slot.fetch_or(mask, std::memory_order_relaxed);
    };
    set(std::clamp(int(u * R), 0, R - 1), std::clamp(int(v * R), 0, R - 1));
    const double det = ux.x * uy.y - uy.x * ux.y;
    if (!(std::abs(det) > 1e-18)) return;
    // A cell fits in the footprint only if both its widths (area over the
    // other side's length) reach a cell: at fine atlas resolutions, never.
    if (std::abs(det) < std::max(norm(ux), norm(uy)) / R) return;
    const double hx = 0.5 * (std::abs(ux.x) + std::abs(uy.x)), hy = 0.5 * (std::abs(ux.y) + std::abs(uy.y));
    const int u0 = std::max(0, int(std::floor((u - hx) * R))), u1 = std::min(R - 1, int(std::floor((u + hx) * R)));
    const int v0 = std::max(0, int(std::floor((v - hy) * R))), v1 = std::min(R - 1, int(std::floor((v + hy) * R)));
    if (u0 > u1 || v0 > v1 || u1 - u0 > 16 || v1 - v0 > 16) return;  // off the square, or a degenerate map
    auto inside = [&](double cu, double cv) {  // uv point (cu, cv) in the footprint
      const double dx = cu - u, dy = cv - v;
      return std::abs(dx * uy.y - uy.x * dy) <= 0.5 * std::abs(det) && std::abs(ux.x * dy - dx * ux.y) <= 0.5 * std::abs(det);
    };
    // Only cells within the footprint's bounding box can lie in it (a
    // billionth of a cell of slack against round-off): most of [u0, u1] x
    // [v0, v1] is not, and each of those cells cost four tests.
    const int iu0 = std::max(u0, int(std::ceil((u - hx) * R - 1e-9))), iu1 = std::min(u1, int(std::floor((u + hx) * R + 1e-9)) - 1);
    const int iv0 = std::max(v0, int(std::ceil((v - hy) * R - 1e-9))), iv1 = std::min(v1, int(std::floor((v + hy) * R + 1e-9)) - 1);
    for (int cv = iv0; cv <= iv1; ++cv)
      for (int cu = iu0; cu <= iu1; ++cu)
        if (inside(double(cu) / R, double(cv) / R) && inside(double(cu + 1) / R, double(cv) / R) &&
            inside(double(cu) / R, double(cv + 1) / R) && inside(double(cu + 1) / R, double(cv + 1) / R))
          set(cu, cv);
  };
  constexpr int kWinnerCacheBits = 11;
  static std::atomic<uint64_t> generations{0};
  const uint64_t generation = ++generations;
  parallel_for(tm.size(), [&](std::size_t b, std::size_t e) {
    thread_local std::vector<Winner> cache;
    thread_local uint64_t cache_generation = 0;
    if (cache_generation != generation) {
      cache.assign(std::size_t(1) << kWinnerCacheBits, Winner{});
      cache_generation = generation;
    }
    const Winner* cur = nullptr;
    Vec2 P[3];
    std::size_t run_patch = 0;  // texels won, counted in runs: one atomic add per run
    uint64_t run = 0;
    // half_images: a block of texels' RGBA and H as floats, converted to
    // half together (to_half's vector instructions) and then stored.
    constexpr std::size_t kStage = 512;
    float stage[kStage * 5];
    uint16_t staged_bits[kStage * 5];
    std::size_t staged = 0, stage_from = b;
    auto flush = [&](std::size_t end) {
      to_half(stage, staged_bits, staged * 5);
      for (std::size_t k = 0; k < staged; ++k) {
        const std::size_t pix = tm.texel[stage_from + k];
        std::copy_n(&staged_bits[k * 5], 4, &out.color_half.bits[pix * 4]);
        out.displacement_half.bits[pix] = staged_bits[k * 5 + 4];
      }
      staged = 0, stage_from = end;
    };
    for (std::size_t i = b; i < e; ++i) {
      const uint32_t pix = tm.texel[i];
      const int x = int(pix % uint32_t(N)), y = int(pix / uint32_t(N));
      const uint64_t key = ctx.keys[i];
      float s[4] = {fallback[0], fallback[1], fallback[2], fallback[3]};
      float aov[5] = {-1.f, 0.f, 0.f, 0.f, -1.f};
      const bool blended = blend && ctx.blend.covered(i);  // else a forced texel: its key's patch extrapolated
      if (key != kNoKey) {
        const std::size_t p = std::size_t(key >> 32);
        const int ti = int(key & 0xffffffffu);
        const Patch& patch = patches.patches[p];
        // Same-chart winners do not depend on the texel's triangle: reuse.
        const int tri = tm.triangle[i];
        auto matches = [&](const Winner& w) {
          return w.key == key && (w.same_chart ? atlas.chart_of_triangle[tri] == w.chart : w.tri == tri);
        };
        if (!cur || !matches(*cur)) {
          Winner& slot = cache[(key * 0x9E3779B97F4A7C15ull) >> (64 - kWinnerCacheBits)];
          if (!matches(slot)) {
            slot.key = key;
            slot.tri = tri;
            slot.chart = atlas.chart_of_triangle[tri];
            slot.ok = winner_pixels(ctx, patch, ti, tri, P, &slot.same_chart) && slot.bary.init(P);
            slot.layer = &ctx.layer_of(patch);
            if (slot.ok && hold) {
              // The map is affine: uv changes by ux per pixel in x, uy in y.
              const Tri& t = patch.triangles[ti];
              const Vec2 d1 = patch.rest_uv[t[1]] - patch.rest_uv[t[0]], d2 = patch.rest_uv[t[2]] - patch.rest_uv[t[0]];
              const double ia = slot.bary.inv_area;
              slot.ux = (d1 * slot.bary.e2.y - d2 * slot.bary.e1.y) * ia;
              slot.uy = (d2 * slot.bary.e1.x - d1 * slot.bary.e2.x) * ia;
            }
          }
          cur = &slot;
        }
        if (cur->ok) {
          double l0, l1, l2;
          cur->bary.at(x, y, l0, l1, l2);
          const Tri& t = patch.triangles[ti];
          const double u = l0 * patch.rest_uv[t[0]].x + l1 * patch.rest_uv[t[1]].x + l2 * patch.rest_uv[t[2]].x;
          const double v = l0 * patch.rest_uv[t[0]].y + l1 * patch.rest_uv[t[1]].y + l2 * patch.rest_uv[t[2]].y;
          const double w = l0 * vertex_weight(patch, t[0]) + l1 * vertex_weight(patch, t[1]) +
                           l2 * vertex_weight(patch, t[2]);
          if (!blended && options.images) {
            const LayerMaps& layer = *cur->layer;
            sample(layer.exemplar->mips, u, v, layer.lod, s, options.trilinear);
          }
          // Only a texel whose 3x3 neighbourhood lies in its chart marks
          // (mark_held): near a seam the texels of two charts sample the same
          // surface at arbitrary offsets, and a cell marked from one chart
          // would let the patch take a texel of the other that it just lost.
          // A texel of a small hole closed by a patch at rest marks too: the
          // next frame gives the region back to it (close_held_texels)
          // instead of closing it anew from whichever neighbour comes first.
          // Not where the draw's held test (passes) would then keep it: that
          // would turn a closed texel into a won one on the next frame, a
          // change of a surface at rest.
          if (hold && (ctx.extrapolated.empty() || !ctx.extrapolated[i] ||
                       (patch.at_rest && !ctx.closed.empty() && ctx.closed[i] &&
                        !held_test_keeps(ctx, *cur->layer, patch, t, u, v, w))) &&
              interior_texel(ctx, i, x, y))
            mark_held(p, u, v, cur->ux, cur->uy);
          aov[0] = float(patch.id), aov[1] = float(u), aov[2] = float(v), aov[3] = float(w), aov[4] = float(patch.layer);
        }
        if (p != run_patch) {
          if (run > 0) won[run_patch].fetch_add(run, std::memory_order_relaxed);
          run_patch = p, run = 0;
        }
        ++run;
      }
      if (options.images) {
        if (blended) {
          const int64_t* sum = &ctx.blend.sums[i * 5];
          for (int c = 0; c < 4; ++c) s[c] = float(double(sum[1 + c]) / double(sum[0]));
        }
        float* c = half ? &stage[staged * 5] : &out.color.pixels[std::size_t(pix) * 4];
        c[0] = s[0], c[1] = s[1], c[2] = s[2], c[3] = key != kNoKey ? 1.f : 0.f;
        if (half) {
          c[4] = s[3];
          if (++staged == kStage) flush(i + 1);
        } else {
          out.displacement.pixels[pix] = s[3];
        }
      }
      if (options.aov)
        for (int k = 0; k < aov_channels; ++k) out.aov.pixels[std::size_t(pix) * aov_channels + k] = aov[k];
    }
    if (half) flush(e);
    if (run > 0) won[run_patch].fetch_add(run, std::memory_order_relaxed);
  }, 1 << 12);
  {
    constexpr std::size_t kChunk = std::size_t(1) << 16;
    std::vector<std::size_t> covered((ctx.keys.size() + kChunk - 1) / kChunk, 0);
    parallel_for(covered.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t c = b; c < e; ++c)
        for (std::size_t i = c * kChunk; i < std::min(ctx.keys.size(), (c + 1) * kChunk); ++i)
          covered[c] += ctx.keys[i] != kNoKey;
    }, 1);
    st.covered_texels = 0;
    for (std::size_t c : covered) st.covered_texels += c;
  }
  r.texels_won.resize(won.size());
  for (std::size_t p = 0; p < won.size(); ++p) r.texels_won[p] = won[p].load(std::memory_order_relaxed);
  return out;
}

}  // namespace lapflow
