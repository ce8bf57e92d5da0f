// Gutter dilation: texels outside the charts take the values of a nearby chart
// texel so that bilinear and mip-mapped lookups in a renderer never pull in
// the background at chart borders. Works on a per-pixel "source pixel" image
// so each output channel is copied once at the end.
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "lapflow/parallel.hpp"
#include "raster_internal.hpp"

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
  // the lowest source index.
  for (int pass = 0; pass < gutter; ++pass) {
    parallel_for(std::size_t(N), [&](std::size_t y0, std::size_t y1) {
      for (int64_t y = int64_t(y0); y < int64_t(y1); ++y)
        for (int64_t x = 0; x < n; ++x) {
          const int64_t i = y * n + x;
          if (std::atomic_ref<int32_t>(source[i]).load(std::memory_order_relaxed) != -1) continue;
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
          if (best >= 0) std::atomic_ref<int32_t>(source[i]).store(-(best + 2), std::memory_order_relaxed);
        }
    }, 8);
    std::atomic<bool> any{false};
    parallel_for(source.size(), [&](std::size_t b, std::size_t e) {
      bool local = false;
      for (std::size_t i = b; i < e; ++i)
        if (source[i] <= -2) source[i] = -(source[i] + 2), local = true;
      if (local) any.store(true, std::memory_order_relaxed);
    }, 1 << 16);
    if (!any.load()) break;
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
