// Gutter dilation: texels outside the charts take the values of a nearby chart
// texel so that bilinear and mip-mapped lookups in a renderer never pull in
// the background at chart borders. Works on a per-pixel "source pixel" image
// so each output channel is copied once at the end.
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "lapflow/core/parallel.hpp"
#include "lapflow/raster/raster.hpp"
#include "raster/internal.hpp"

namespace lapflow::detail {
namespace {

// Squared distance between pixel indices a and b of an N-wide image.
inline int64_t dist2(int64_t a, int64_t b, int64_t N) {
  const int64_t dx = a % N - b % N, dy = a / N - b / N;
  return dx * dx + dy * dy;
}

}  // namespace

void dilate_sources(std::vector<int32_t>& source, int N, int gutter) {
  const int64_t n = N;
  // 8-neighbour passes. A pixel filled in this pass is stored as -(s + 2) so
  // its neighbours still see it as empty (Jacobi: thread-count independent);
  // among the filled neighbours the one whose source is nearest wins, ties to
  // the lowest source index. Only pixels next to a filled one can change: a
  // bit image of the filled pixels, dilated a word (64 pixels) at a time,
  // finds them without visiting the whole atlas's 8 neighbourhoods per pass.
  const std::size_t words = (std::size_t(N) + 63) / 64;
  std::vector<uint64_t> filled(words * std::size_t(N), 0), front(words * std::size_t(N), 0);
  parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (int64_t x = 0; x < n; ++x)
        if (source[y * n + x] >= 0) filled[y * words + std::size_t(x >> 6)] |= uint64_t(1) << (x & 63);
  }, 8);
  const uint64_t last_mask = (N % 64) ? (uint64_t(1) << (N % 64)) - 1 : ~uint64_t(0);
  for (int pass = 0; pass < gutter; ++pass) {
    std::vector<uint8_t> row_changed(N, 0);
    parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
      for (int64_t y = int64_t(y0); y < int64_t(y1); ++y) {
        // Pixels of row y with a filled pixel among their 8 neighbours.
        uint64_t* out = &front[std::size_t(y) * words];
        bool any = false;
        for (std::size_t w = 0; w < words; ++w) {
          uint64_t d = 0;
          for (int64_t yy = std::max<int64_t>(0, y - 1); yy <= std::min<int64_t>(n - 1, y + 1); ++yy) {
            const uint64_t* f = &filled[std::size_t(yy) * words];
            d |= f[w] | (f[w] << 1) | (f[w] >> 1);
            if (w > 0) d |= f[w - 1] >> 63;
            if (w + 1 < words) d |= f[w + 1] << 63;
          }
          d &= ~filled[std::size_t(y) * words + w];
          if (w + 1 == words) d &= last_mask;
          out[w] = d;
          any |= d != 0;
        }
        if (!any) continue;
        for (std::size_t w = 0; w < words; ++w)
          for (uint64_t bits = out[w]; bits; bits &= bits - 1) {
            const int64_t x = int64_t(w * 64) + __builtin_ctzll(bits);
            const int64_t i = y * n + x;
            int32_t best = -1;
            int64_t best_d = INT64_MAX;
            for (int64_t dy = -1; dy <= 1; ++dy)
              for (int64_t dx = -1; dx <= 1; ++dx) {
                const int64_t xx = x + dx, yy = y + dy;
                if (xx < 0 || yy < 0 || xx >= n || yy >= n) continue;
                const int32_t s = std::atomic_ref<int32_t>(source[yy * n + xx]).load(std::memory_order_relaxed);
                if (s < 0) continue;
                const int64_t d = dist2(i, s, n);
                if (d < best_d || (d == best_d && s < best)) best = s, best_d = d;
              }
            std::atomic_ref<int32_t>(source[i]).store(-(best + 2), std::memory_order_relaxed);
          }
        row_changed[y] = 1;
      }
    }, 8);
    // Every frontier pixel had a filled neighbour, so each one was filled.
    bool any = false;
    for (int y = 0; y < N; ++y) any |= row_changed[y] != 0;
    if (!any) break;
    parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
      for (std::size_t y = y0; y < y1; ++y) {
        if (!row_changed[y]) continue;
        for (std::size_t w = 0; w < words; ++w)
          for (uint64_t bits = front[y * words + w]; bits; bits &= bits - 1) {
            const std::size_t i = y * std::size_t(n) + w * 64 + std::size_t(__builtin_ctzll(bits));
            source[i] = -(source[i] + 2);
          }
        for (std::size_t w = 0; w < words; ++w) filled[y * words + w] |= front[y * words + w];
      }
    }, 8);
  }
  // The rest: nearest filled pixel along the row (ties to the left), then
  // rows with nothing copy the nearest row that has something (ties upward).
  std::vector<uint8_t> row_has(N, 0);
  parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
    std::vector<int32_t> left(N), right(N);
    for (std::size_t y = y0; y < y1; ++y) {
      int32_t* row = &source[y * n];
      int32_t last = -1;
      for (int64_t x = 0; x < n; ++x) {
        if (row[x] >= 0) last = int32_t(x);
        left[x] = last;
      }
      if (last < 0) continue;
      row_has[y] = 1;
      last = -1;
      for (int64_t x = n - 1; x >= 0; --x) {
        if (row[x] >= 0) last = int32_t(x);
        right[x] = last;
      }
      // Only empty pixels change, and they copy filled ones: in place is safe.
      for (int64_t x = 0; x < n; ++x) {
        if (row[x] >= 0) continue;
        const int64_t l = left[x], r = right[x];
        const int64_t pick = l < 0 ? r : (r < 0 ? l : ((x - l) <= (r - x) ? l : r));
        row[x] = row[pick];
      }
    }
  }, 4);
  std::vector<int> nearest_row(N, -1);
  int last = -1;
  for (int y = 0; y < N; ++y) {
    if (row_has[y]) last = y;
    nearest_row[y] = last;
  }
  int next = -1;
  for (int y = N - 1; y >= 0; --y) {
    if (row_has[y]) {
      next = y;
      continue;
    }
    const int up = nearest_row[y];
    nearest_row[y] = up < 0 ? next : (next < 0 ? up : ((y - up) <= (next - y) ? up : next));
  }
  parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y) {
      if (row_has[y] || nearest_row[y] < 0) continue;
      const int32_t* from = &source[std::size_t(nearest_row[y]) * n];
      std::copy(from, from + n, &source[y * n]);
    }
  }, 4);
}

}  // namespace lapflow::detail

namespace lapflow {

using namespace detail;

void dilate_gutter(RasterBuffers& r, FrameTextures& out) {
  RasterContext& ctx = *r.context;
  const RasterOptions& options = ctx.options;
  const TexelMap& tm = ctx.atlas.texels;
  const int N = ctx.N;
  // Every pixel outside the charts copies its nearest chart pixel's colour
  // (alpha stays 0), displacement and AOV.
  const std::size_t ac = std::size_t(std::max(out.aov.channels, 1));  // patch_id u v w (layer)
  if (options.dilate && tm.size() > 0) {
    std::vector<int32_t>& source = ctx.index;  // reused: the raster steps are done with it
    parallel_for(source.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) source[i] = source[i] >= 0 ? int32_t(i) : -1;
    }, 1 << 16);
    dilate_sources(source, N, options.gutter);
    // Colour (RGB) and height from pixel s to pixel i, in half or in float.
    auto copy_images = [](auto& color, auto& height, std::size_t i, std::size_t s) {
      if (color.empty()) return;
      for (int k = 0; k < 3; ++k) color[i * 4 + k] = color[s * 4 + k];
      height[i] = height[s];
    };
    parallel_for(source.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        const int32_t s = source[i];
        if (s < 0 || std::size_t(s) == i) continue;
        copy_images(out.color_half.bits, out.displacement_half.bits, i, std::size_t(s));
        copy_images(out.color.pixels, out.displacement.pixels, i, std::size_t(s));
        if (options.aov)
          for (std::size_t k = 0; k < ac; ++k) out.aov.pixels[i * ac + k] = out.aov.pixels[std::size_t(s) * ac + k];
      }
    }, 1 << 14);
  } else if (options.aov) {
    // Outside charts the AOV says "no patch".
    for (std::size_t i = 0; i < ctx.index.size(); ++i)
      if (ctx.index[i] < 0) {
        out.aov.pixels[i * ac] = -1.f;
        if (ac == 5) out.aov.pixels[i * ac + 4] = -1.f;
      }
  }
  // Dilation reuses the pixel index: the buffers are spent.
  r.context.reset();
}

}  // namespace lapflow
