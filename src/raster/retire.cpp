// Step 9, retirement (retire_patches): a patch that won no texel leaves
// the set, and with RasterOptions::merge so does a small patch whose every
// texel another patch's erosion test also passes (covered_small_patches,
// which draws those others again into a second key buffer).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"
#include "raster/tiles.hpp"

namespace lapflow {

using namespace detail;

namespace {


// A patch that could keep no texel anywhere: the erosion test needs
// w >= 1 + epsilon - sqrt(F + D) / M >= epsilon, or no triangle is drawn.
bool eroded_away(const RasterContext& ctx, const Patch& patch) {
  float max_w = 0;
  for (float w : patch.weight) max_w = std::max(max_w, w);
  bool any_drawable = patch.triangle_delta.size() != patch.triangles.size();
  for (std::size_t t = 0; t < patch.triangle_delta.size() && !any_drawable; ++t)
    any_drawable = patch.triangle_delta[t] <= ctx.delta_max;
  return double(max_w) < ctx.layers[0].erosion().epsilon || !any_drawable;
}



// RasterOptions::merge: the patches (not born this frame) that won between 1
// and `limit` texels, every one of which another patch's erosion test also
// passes. Those others are drawn again into a second key buffer that only
// the candidates' texels accept (the rest start at key 0, "taken"); only
// patches near a candidate texel in 3D are drawn, and of those only the
// triangles that can reach a tile holding a candidate texel (TileMask).
// Deterministic: atomic minimum as in draw_patches.
std::vector<uint8_t> covered_small_patches(RasterContext& ctx, const PatchSet& patches,
                                           const std::vector<uint64_t>& won, double limit) {
  const std::size_t np = patches.patches.size();
  std::vector<uint8_t> candidate(np, 0), merged(np, 0);
  bool any = false;
  for (std::size_t p = 0; p < std::min(np, ctx.newborn_from); ++p)
    any |= (candidate[p] = won[p] > 0 && double(won[p]) < limit);
  if (!any) return merged;
  const TexelMap& tm = ctx.atlas.texels;
  std::vector<uint64_t> alt(tm.size(), 0);
  TileMask clip(ctx.N);
  const double cell = ctx.radius;
  auto cell_of = [&](const Vec3& x) {
    return std::array<int64_t, 3>{int64_t(std::floor(x.x / cell)), int64_t(std::floor(x.y / cell)),
                                  int64_t(std::floor(x.z / cell))};
  };
  std::vector<uint64_t> cells;
  // Only the candidates' texels take a key, through the fluid triangles that own them.
  std::vector<uint8_t> writable(ctx.mesh.triangles.size(), 0);
  for (std::size_t i = 0; i < tm.size(); ++i) {
    const uint64_t key = ctx.keys[i];
    if (key == kNoKey || !candidate[key >> 32]) continue;
    alt[i] = kNoKey;
    writable[std::size_t(tm.triangle[i])] = 1;
    clip.mark(int(tm.texel[i] % uint32_t(ctx.N)), int(tm.texel[i] / uint32_t(ctx.N)));
    const auto c = cell_of(texel_position(ctx, i));
    cells.push_back(hash64(uint64_t(c[0]), uint64_t(c[1]), uint64_t(c[2])));
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  clip.set_writable(ctx, std::move(writable));
  auto near = [&](const Patch& patch) {
    // Patch vertices lie within about r of its centre: look a cell around.
    // A patch stretched farther is not drawn, which can only keep a
    // candidate (never retire one wrongly).
    const auto c = cell_of(patch.center);
    for (int64_t dz = -1; dz <= 1; ++dz)
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dx = -1; dx <= 1; ++dx)
          if (std::binary_search(cells.begin(), cells.end(),
                                 hash64(uint64_t(c[0] + dx), uint64_t(c[1] + dy), uint64_t(c[2] + dz))))
            return true;
    return false;
  };
  parallel_for(np, [&](std::size_t b, std::size_t e) {
    for (std::size_t q = b; q < e; ++q)
      // Not a candidate, and not retiring for winning nothing.
      if (!candidate[q] && won[q] > 0 && near(patches.patches[q])) draw_patch_keys(ctx, alt, patches.patches[q], q, clip);
  }, 4);
  std::vector<uint64_t> open(np, 0);
  for (std::size_t i = 0; i < tm.size(); ++i)
    if (alt[i] == kNoKey) ++open[ctx.keys[i] >> 32];
  for (std::size_t p = 0; p < np; ++p) merged[p] = candidate[p] && open[p] == 0;
  return merged;
}


}  // namespace

void retire_patches(RasterBuffers& r, PatchSet& patches) {
  RasterContext& ctx = *r.context;
  RasterStats& st = r.stats;
  if (r.texels_won.size() != patches.patches.size())
    throw std::invalid_argument("retire_patches: resolve_texels first, on the same patches");
  const bool blend = ctx.options.mode == RasterMode::Blend;
  // After hole filling, so a newborn patch that covered nothing goes too.
  const bool retire = ctx.options.retire && ctx.options.mode != RasterMode::NoErosion;
  const double merge_limit = retire && ctx.mode == RasterMode::Erosion && ctx.options.merge > 0 &&
                                    ctx.texel_world_size > 0
                                ? ctx.options.merge * 3.14159265358979323846 * (ctx.radius / ctx.texel_world_size) *
                                      (ctx.radius / ctx.texel_world_size)
                                : 0;
  const std::vector<uint8_t> merged =
      merge_limit > 0 ? covered_small_patches(ctx, patches, r.texels_won, merge_limit) : std::vector<uint8_t>{};
  std::vector<Patch> kept;
  kept.reserve(patches.patches.size());
  st.texels_per_patch.clear();
  for (std::size_t p = 0; p < patches.patches.size(); ++p) {
    const uint64_t n = r.texels_won[p];
    if (!merged.empty() && merged[p]) {
      ++st.patches_retired;
      ++st.retired_merged;
      continue;
    }
    // Blend: a patch that gave weight to no texel retires, unless a forced
    // texel names it.
    if (retire && n == 0 && (!blend || ctx.blend.contributed[p] == 0)) {
      ++st.patches_retired;
      ++(eroded_away(ctx, patches.patches[p]) ? st.retired_eroded : st.retired_hidden);
      continue;
    }
    Patch& patch = patches.patches[p];
    if (ctx.held_next.empty()) {
      patch.held.clear();
    } else {
      // Held cells stay held (the union over the patch's life): where the
      // patch no longer passes even with the slack, the cell has no effect.
      const uint64_t* words = &ctx.held_next[p * kHeldWords];
      if (std::any_of(words, words + kHeldWords, [](uint64_t w) { return w != 0; })) {
        if (patch.held.empty()) patch.held.assign(kHeldWords, 0);
        for (std::size_t k = 0; k < kHeldWords; ++k) patch.held[k] |= words[k];
      }
    }
    kept.push_back(std::move(patch));
    st.texels_per_patch.push_back(n);
  }
  patches.patches = std::move(kept);
  r.texels_won = st.texels_per_patch;
}

}  // namespace lapflow
