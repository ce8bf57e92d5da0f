#pragma once
/// \file large_blocks.hpp Large blocks (a frame's images, texel maps, keys)
/// kept mapped between frames without fragmenting the malloc heap.
///
/// A bake allocates and frees a few gigabytes of large arrays every frame, of
/// sizes that change with the frame's charts and texels. On one malloc heap
/// (keep_freed_memory_for_reuse) long-lived small blocks such as patches
/// settle between them, and a larger array of a later frame fits none of
/// the holes: the heap grows frame after frame while the data in use stays
/// level (docs/performance.md, "Memory and large blocks"). Unmapping each
/// large block instead costs the kernel's zeroing of fresh pages every
/// frame.
///
/// Here each large block is its own mapping, and a freed one is kept. A
/// later request takes the smallest kept block that fits (its head, when it
/// is much larger), or else a fresh address range onto which the kept blocks
/// move with mremap, pages and all, without a copy: pages are
/// interchangeable, and only what they do not cover is fresh. The cache
/// therefore never maps more than the most bytes ever alive at once (each
/// block rounded up to 2 MiB).
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>

namespace lapflow {

class LargeBlocks {
 public:
  /// Requests of at least this many bytes are large blocks.
  static constexpr std::size_t kThreshold = std::size_t(8) << 20;
  /// Blocks are returned aligned to at least this (a page; in fact to kGranule).
  static constexpr std::size_t kAlignment = 4096;
  /// Mappings are multiples of this.
  static constexpr std::size_t kGranule = std::size_t(2) << 20;
  /// Blocks alive, and blocks kept, at most (fixed tables: the cache itself
  /// allocates nothing).
  static constexpr int kMaxBlocks = 256;

  /// The process's cache (never destroyed: blocks may be freed at exit).
  static LargeBlocks& instance();

  /// A block of at least `bytes`, aligned to kAlignment; nullptr when the
  /// kernel gives no memory or the table of live blocks is full (the caller
  /// then falls back to malloc).
  void* allocate(std::size_t bytes);
  /// Gives a block back to the cache when it is one of its blocks and
  /// returns true; returns false for any other pointer, touching nothing.
  bool release(void* p);

  struct Stats {
    std::size_t live_bytes = 0;       ///< mapped bytes of blocks in use
    std::size_t kept_bytes = 0;       ///< mapped bytes of freed blocks kept
    std::size_t peak_live_bytes = 0;  ///< the most live_bytes ever
    std::size_t fresh_bytes = 0;      ///< bytes ever mapped fresh (mmap, or the growth of a kept block)
  };
  Stats stats() const;
  /// Unmaps every kept block.
  void drop_kept();

  LargeBlocks() = default;
  ~LargeBlocks();
  LargeBlocks(const LargeBlocks&) = delete;
  LargeBlocks& operator=(const LargeBlocks&) = delete;

 private:
  struct Block {
    char* base = nullptr;
    std::size_t size = 0;
  };
  void note_range(const char* base, std::size_t size);

  mutable std::mutex mutex_;
  Block live_[kMaxBlocks];
  Block kept_[kMaxBlocks];
  int live_count_ = 0, kept_count_ = 0;
  Stats stats_;
  // Every address this cache ever mapped lies in [lo_, hi_): any other
  // pointer is told apart without the lock.
  std::atomic<std::uintptr_t> lo_{UINTPTR_MAX}, hi_{0};
};

}  // namespace lapflow
