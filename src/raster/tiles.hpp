#pragma once
// Tiles of 8 x 8 atlas pixels that let the draw skip work: TileGrid (the
// tiling), TileMask (tiles the merge test's second draw looks at) and
// OwnedTiles (tiles older patches already keep, which draw_patches skips).
#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "lapflow/core/parallel.hpp"
#include "raster/internal.hpp"

namespace lapflow::detail {

// Square tiles of 8 x 8 atlas pixels, `width` a side, tile (tx, ty) at
// ty * width + tx. Two widths: covering(N) gives every pixel a tile
// (TileMask); inside(N) keeps only the tiles wholly inside the atlas
// (OwnedTiles: an edge tile partly outside it is never pure), so the last
// pixels of a row or column may have none.
struct TileGrid {
  static constexpr int kShift = 3;
  int width = 0;
  static TileGrid covering(int N) { return {((N - 1) >> kShift) + 1}; }
  static TileGrid inside(int N) { return {N >> kShift}; }
  std::size_t size() const { return std::size_t(width) * width; }
  // Pixel (x, y) has a tile (x, y >= 0).
  bool has(int x, int y) const { return (x >> kShift) < width && (y >> kShift) < width; }
  // The tile of pixel (x, y), which has one.
  std::size_t at(int x, int y) const { return std::size_t(y >> kShift) * width + std::size_t(x >> kShift); }
  // pred(tile) holds for some tile under pixel box [x0, x1] x [y0, y1]
  // (clamped to the grid); tried row by row, stopping at the first.
  template <class Pred>
  bool any_tile(int x0, int y0, int x1, int y1, Pred&& pred) const {
    const int tx0 = std::max(0, x0) >> kShift, tx1 = std::min(width - 1, std::max(0, x1) >> kShift);
    const int ty0 = std::max(0, y0) >> kShift, ty1 = std::min(width - 1, std::max(0, y1) >> kShift);
    for (int ty = ty0; ty <= ty1; ++ty)
      for (int tx = tx0; tx <= tx1; ++tx)
        if (pred(std::size_t(ty) * width + std::size_t(tx))) return true;
    return false;
  }
};

// Tiles marked where a draw may matter: the merge test's second draw only
// looks at its candidates' texels, so a patch triangle whose pixels all lie
// in unmarked tiles can be left out.
struct TileMask {
  TileGrid grid;
  std::vector<uint8_t> marked;
  explicit TileMask(int N) : grid(TileGrid::covering(N)), marked(grid.size(), 0) {}
  void mark(int x, int y) { marked[grid.at(x, y)] = 1; }
  // Any marked tile under pixel box [x0, x1] x [y0, y1] (clamped to the atlas).
  bool any(int x0, int y0, int x1, int y1) const {
    return grid.any_tile(x0, y0, x1, y1, [&](std::size_t t) { return marked[t] != 0; });
  }

  // The seam fallback writes a texel only through the fluid triangle that
  // owns it, and its walk finds only its start triangles and triangles whose
  // bounding spheres pass its distance test. Given the fluid triangles that
  // own a texel the draw can write (`writable`, per triangle),
  // walk_may_write() tells whether the walk can find any of them: when not,
  // the walk is skipped, with the same writes.
  void set_writable(const RasterContext& ctx, std::vector<uint8_t> writable);
  bool walk_may_write(const RasterContext& ctx, const int start[3], const Vec3& centre, double radius,
                      double margin) const;

 private:
  std::vector<uint8_t> writable_;                        // per fluid triangle
  std::vector<std::pair<uint64_t, int32_t>> spheres_;    // those triangles by the grid cells their spheres touch
  double cell_ = 1;
  bool everywhere_ = false;                              // a sphere too large to bucket: always walk
};

// Tiles of 8 x 8 atlas pixels that older patches already keep, so that a
// younger patch's triangle lying wholly in them is not drawn at all (its every
// texel would stop at the key test). Only "pure" tiles count: every pixel a
// texel of one chart, so that a triangle of that chart inside them cannot
// leak across a seam either; the skip then changes nothing but the time, at
// any thread count or timing. Per tile: the texels still at kNoKey, and an
// upper bound of the keys written (every first write raises it before it
// counts the texel as kept). Built on fresh keys, all kNoKey: draw_patches
// is the first step after begin_raster.
struct OwnedTiles {
  TileGrid grid;               // whole tiles only (TileGrid::inside)
  std::vector<int32_t> chart;  // every pixel's chart, or -1 (mixed, outside the charts or the atlas)
  std::unique_ptr<std::atomic<uint32_t>[]> open;
  std::unique_ptr<std::atomic<uint64_t>[]> max_key;

  explicit OwnedTiles(const RasterContext& ctx) : grid(TileGrid::inside(ctx.N)) {
    constexpr int s = TileGrid::kShift;
    const std::size_t n = grid.size(), width = std::size_t(grid.width);
    chart.assign(n, -1);
    open = std::make_unique<std::atomic<uint32_t>[]>(n);
    max_key = std::make_unique<std::atomic<uint64_t>[]>(n);
    const auto& tri_of = ctx.atlas.texels.triangle;
    const auto& chart_of = ctx.atlas.chart_of_triangle;
    const std::size_t N = std::size_t(ctx.N);
    parallel_for(width, [&](std::size_t b, std::size_t e) {
      for (std::size_t ty = b; ty < e; ++ty)
        for (std::size_t tx = 0; tx < width; ++tx) {
          const std::size_t t = ty * width + tx;
          open[t].store(1u << (2 * s), std::memory_order_relaxed);
          max_key[t].store(0, std::memory_order_relaxed);
          int32_t c = -2;
          for (std::size_t y = ty << s; y < (ty + 1) << s && c != -1; ++y)
            for (std::size_t x = tx << s; x < (tx + 1) << s; ++x) {
              const int32_t idx = ctx.index[y * N + x];
              const int32_t ci = idx < 0 ? -1 : chart_of[tri_of[idx]];
              if (c == -2) c = ci;
              if (ci != c) c = -1;
              if (c == -1) break;
            }
          chart[t] = c < 0 ? -1 : c;
        }
    }, 8);
  }
  // `n` texels of the tile of pixel (x, y) got their first keys, the largest `key`.
  void first_write(int x, int y, uint64_t key, uint32_t n = 1) {
    if (!grid.has(x, y)) return;
    const std::size_t t = grid.at(x, y);
    if (chart[t] < 0) return;
    uint64_t cur = max_key[t].load(std::memory_order_relaxed);
    while (cur < key && !max_key[t].compare_exchange_weak(cur, key, std::memory_order_relaxed)) {
    }
    open[t].fetch_sub(n, std::memory_order_release);
  }
  // The chart whose texels fill the tile of pixel (x, y), or -1 (mixed, or
  // no whole tile there).
  int32_t tile_chart(int x, int y) const { return grid.has(x, y) ? chart[grid.at(x, y)] : -1; }
  // Every pixel of box [x0, x1] x [y0, y1] (clamped to the atlas) is a texel of
  // `c` whose key is below `key`.
  bool kept_below(int x0, int y0, int x1, int y1, int c, uint64_t key) const {
    if (!grid.has(x1, y1)) return false;  // the box reaches past the whole tiles
    return !grid.any_tile(x0, y0, x1, y1, [&](std::size_t t) {
      return chart[t] != c || open[t].load(std::memory_order_acquire) != 0 ||
             max_key[t].load(std::memory_order_relaxed) >= key;
    });
  }
};

}  // namespace lapflow::detail
