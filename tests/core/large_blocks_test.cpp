// The large-block cache: freed blocks are reused whole, split or grown, so
// that a bake's frames map no fresh memory once the largest frame was seen.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <vector>

#include "lapflow/core/large_blocks.hpp"

using lapflow::LargeBlocks;

namespace {
constexpr std::size_t MiB = std::size_t(1) << 20;
}

TEST(LargeBlocks, AFreedBlockServesTheNextRequestThatFits) {
  LargeBlocks cache;
  void* a = cache.allocate(20 * MiB);
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(a) % LargeBlocks::kGranule, 0u);  // huge-page boundaries
  std::memset(a, 1, 20 * MiB);
  EXPECT_TRUE(cache.release(a));
  EXPECT_EQ(cache.stats().kept_bytes, 20 * MiB);
  void* b = cache.allocate(19 * MiB);
  EXPECT_EQ(b, a);
  EXPECT_EQ(cache.stats().fresh_bytes, 20 * MiB);
  EXPECT_EQ(cache.stats().kept_bytes, 0u);
  EXPECT_TRUE(cache.release(b));
}

TEST(LargeBlocks, TellsForeignPointersApart) {
  LargeBlocks cache;
  int on_stack = 0;
  std::vector<char> heap(64);
  EXPECT_FALSE(cache.release(&on_stack));
  EXPECT_FALSE(cache.release(heap.data()));
  void* a = cache.allocate(10 * MiB);
  // Inside the block but not its start: not a block of the cache.
  EXPECT_FALSE(cache.release(static_cast<char*>(a) + 4096));
  EXPECT_TRUE(cache.release(a));
  EXPECT_FALSE(cache.release(a));  // already given back
}

TEST(LargeBlocks, AMuchLargerBlockIsSplitAndItsTailKept) {
  LargeBlocks cache;
  char* a = static_cast<char*>(cache.allocate(100 * MiB));
  ASSERT_NE(a, nullptr);
  ASSERT_TRUE(cache.release(a));
  void* b = cache.allocate(30 * MiB);
  EXPECT_EQ(b, a);
  EXPECT_EQ(cache.stats().kept_bytes, 70 * MiB);
  void* c = cache.allocate(60 * MiB);
  EXPECT_EQ(c, a + 30 * MiB);
  EXPECT_EQ(cache.stats().fresh_bytes, 100 * MiB);
  EXPECT_TRUE(cache.release(b));
  EXPECT_TRUE(cache.release(c));
}

TEST(LargeBlocks, GrowingAKeptBlockKeepsItsPages) {
  LargeBlocks cache;
  char* a = static_cast<char*>(cache.allocate(20 * MiB));
  ASSERT_NE(a, nullptr);
  for (std::size_t i = 0; i < 20 * MiB; i += 4096) a[i] = char(i / 4096 % 127 + 1);
  ASSERT_TRUE(cache.release(a));
  char* b = static_cast<char*>(cache.allocate(50 * MiB));
  ASSERT_NE(b, nullptr);
  // Only the growth is fresh; the old pages moved with the block (their
  // contents show it: not zeroed by the kernel again).
  EXPECT_EQ(cache.stats().fresh_bytes, 50 * MiB);
  bool kept = true;
  for (std::size_t i = 0; i < 20 * MiB; i += 4096) kept = kept && b[i] == char(i / 4096 % 127 + 1);
  EXPECT_TRUE(kept);
  std::memset(b, 0, 50 * MiB);
  EXPECT_TRUE(cache.release(b));
}

// A bake's pattern: each frame allocates blocks whose sizes change a little
// from frame to frame (charts and texels move), frees them in another order.
// After the first frames nothing more is mapped, and what stays mapped is
// close to the largest frame's demand.
TEST(LargeBlocks, FramesOfJitteredSizesStopMappingFreshMemory) {
  LargeBlocks cache;
  std::mt19937 rng(7);
  const std::vector<std::size_t> base = {604 * MiB, 151 * MiB, 151 * MiB, 124 * MiB, 62 * MiB,
                                         62 * MiB,  62 * MiB,  62 * MiB,  40 * MiB,  9 * MiB};
  std::uniform_real_distribution<double> jitter(0.9, 1.1);
  std::size_t largest_frame = 0, fresh_after_10 = 0;
  for (int frame = 0; frame < 60; ++frame) {
    std::vector<void*> live;
    std::size_t demand = 0;
    std::vector<std::size_t> sizes = base;
    std::shuffle(sizes.begin() + 3, sizes.end(), rng);
    for (std::size_t s : sizes) {
      const std::size_t bytes = std::size_t(double(s) * jitter(rng));
      demand += bytes;
      live.push_back(cache.allocate(bytes));  // not touched: only the mapping is measured
      ASSERT_NE(live.back(), nullptr);
    }
    largest_frame = std::max(largest_frame, demand);
    std::shuffle(live.begin(), live.end(), rng);
    for (void* p : live) ASSERT_TRUE(cache.release(p));
    if (frame == 9) fresh_after_10 = cache.stats().fresh_bytes;
  }
  const LargeBlocks::Stats s = cache.stats();
  EXPECT_EQ(s.live_bytes, 0u);
  EXPECT_LE(double(s.kept_bytes), 1.1 * double(largest_frame));
  // Frames 11-60 mapped at most a few percent more.
  EXPECT_LE(double(s.fresh_bytes), 1.05 * double(fresh_after_10));
}
