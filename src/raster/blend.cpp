// Blend mode (the 2019 baseline of Gagnon et al., deformable patches with
// alpha blending): every patch whose triangle covers a texel with (u, v) in
// [0,1]^2 and w > 0 contributes its exemplar sample weighted by w. The sums
// are kept in 2^-32 fixed point and added with 64-bit integer atomics, which
// are exact: the result is the same whatever the order or the thread count.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include "lapflow/core/parallel.hpp"
#include "raster/internal.hpp"
#include "raster/sampling.hpp"

namespace lapflow::detail {

void blend_patch(RasterContext& ctx, std::size_t patch_index, const LayerMaps& layer, std::vector<BlendSample>& samples) {
  // One sample per texel: the lowest patch triangle (shared edges and the
  // seam fallback may draw a texel twice; a folded patch covers it twice).
  std::sort(samples.begin(), samples.end(), [](const BlendSample& a, const BlendSample& b) {
    return a.texel != b.texel ? a.texel < b.texel : a.triangle < b.triangle;
  });
  BlendState& B = ctx.blend;
  const uint64_t tag = uint64_t(~uint32_t(patch_index));  // ties of the atomic max go to the oldest patch
  uint64_t contributed = 0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    if (k > 0 && samples[k].texel == samples[k - 1].texel) continue;
    const BlendSample& s = samples[k];
    const double w = std::clamp(s.w, 0.0, 1.0);
    const float wf = float(w);
    uint32_t bits;
    std::memcpy(&bits, &wf, 4);
    const uint64_t packed = (uint64_t(bits) << 32) | tag;
    if (B.phase == 2) {
      // Exactly one patch matches the texel's maximum (same arithmetic as phase 1).
      if (B.covered(std::size_t(s.texel)) && B.best[s.texel] == packed)
        ctx.keys[s.texel] = make_key(patch_index, s.triangle);
      continue;
    }
    float c[4];
    sample(layer.exemplar->mips, s.u, s.v, layer.lod, c, B.trilinear);
    int64_t* sum = &B.sums[std::size_t(s.texel) * 5];
    std::atomic_ref<int64_t>(sum[0]).fetch_add(std::llround(w * kBlendScale), std::memory_order_relaxed);
    for (int ch = 0; ch < 4; ++ch) {
      // |c| clamped to the half-float range keeps thousands of terms clear of overflow.
      const double q = w * std::clamp(double(c[ch]), -65504.0, 65504.0) * kBlendScale;
      std::atomic_ref<int64_t>(sum[1 + ch]).fetch_add(std::llround(q), std::memory_order_relaxed);
    }
    std::atomic_ref<uint64_t> best(B.best[s.texel]);
    uint64_t cur = best.load(std::memory_order_relaxed);
    while (cur < packed && !best.compare_exchange_weak(cur, packed, std::memory_order_relaxed)) {
    }
    ++contributed;
  }
  if (B.phase == 1) B.contributed[patch_index] += contributed;
}

void blend_mark_coverage(RasterContext& ctx) {
  parallel_for(ctx.keys.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) ctx.keys[i] = ctx.blend.covered(i) ? 0 : kNoKey;
  }, 1 << 14);
}

}  // namespace lapflow::detail
