// Hole filling (ALGORITHM.md step 8), texel by texel as in the paper but
// without re-searching: a new patch is drawn only into the still-open texels
// (its key is larger than every older patch's, so the atomic min never lets
// it take a texel an older patch keeps).
#include <algorithm>
#include <unordered_set>

#include "lapflow/parallel.hpp"
#include "raster_internal.hpp"

namespace lapflow::detail {

std::size_t fill_holes(RasterContext& ctx, PatchSet& patches, int frame, const PatchMaker& make_patch,
                       std::size_t max_patches) {
  const TexelMap& tm = ctx.atlas.texels;
  std::size_t born = 0;
  // A fluid triangle where create_patch failed once is not retried for each
  // of its texels (it would fail again: the maker only sees the surface).
  std::unordered_set<int32_t> failed;
  RasterCounters counters;
  for (std::size_t i = 0; i < tm.size() && born < max_patches; ++i) {
    if (ctx.keys[i] != kNoKey) continue;
    const int32_t F = tm.triangle[i];
    if (failed.count(F)) continue;
    const Tri& T = ctx.mesh.triangles[F];
    const double b1 = tm.b1[i], b2 = tm.b2[i];
    SurfacePoint at;
    at.position = ctx.mesh.positions[T[0]] * (1 - b1 - b2) + ctx.mesh.positions[T[1]] * b1 +
                  ctx.mesh.positions[T[2]] * b2;
    at.normal = ctx.tri_normal[F];
    at.triangle = F;
    std::optional<Patch> patch;
    if (norm2(at.normal) > 0) patch = make_patch(at, patches.next_id);
    if (!patch || !patch->alive()) {
      failed.insert(F);
      continue;
    }
    patch->id = patches.next_id++;
    patch->birth_frame = frame;
    patches.patches.push_back(std::move(*patch));
    ++born;
    rasterize_patch(ctx, patches.patches.back(), patches.patches.size() - 1, counters);
    // A newborn that does not keep its own seed texel (a maker that breaks
    // B_V = 1 near the centre) would be followed by one more per texel of the
    // hole: leave that triangle's texels to propagate_keys instead.
    if (ctx.keys[i] == kNoKey) failed.insert(F);
  }
  return born;
}

std::size_t propagate_keys(RasterContext& ctx) {
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  std::vector<uint32_t> open;
  for (std::size_t i = 0; i < tm.size(); ++i)
    if (ctx.keys[i] == kNoKey) open.push_back(uint32_t(i));
  std::size_t filled = 0;
  std::vector<uint64_t> next(open.size());
  while (!open.empty()) {
    next.resize(open.size());
    // Jacobi sweep: read the keys of the previous sweep only.
    parallel_for(open.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t j = b; j < e; ++j) {
        const uint32_t i = open[j];
        const int chart = ctx.atlas.chart_of_triangle[tm.triangle[i]];
        const int x = int(tm.texel[i] % uint32_t(N)), y = int(tm.texel[i] / uint32_t(N));
        uint64_t best = kNoKey;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if ((dx == 0 && dy == 0) || xx < 0 || yy < 0 || xx >= N || yy >= N) continue;
            const int32_t n = ctx.index[std::size_t(yy) * N + xx];
            if (n < 0 || ctx.atlas.chart_of_triangle[tm.triangle[n]] != chart) continue;
            best = std::min(best, ctx.keys[n]);
          }
        next[j] = best;
      }
    }, 1024);
    std::vector<uint32_t> still;
    std::size_t changed = 0;
    for (std::size_t j = 0; j < open.size(); ++j) {
      if (next[j] == kNoKey) {
        still.push_back(open[j]);
      } else {
        ctx.keys[open[j]] = next[j];
        ++changed;
      }
    }
    filled += changed;
    if (changed == 0) break;  // charts no patch reaches at all
    open.swap(still);
  }
  return filled;
}

}  // namespace lapflow::detail
