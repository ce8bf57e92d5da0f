// Large blocks kept mapped between frames (large_blocks.hpp has the why).
#include "lapflow/core/large_blocks.hpp"

#include <sys/mman.h>

#include <algorithm>
#include <new>

namespace lapflow {
namespace {

std::size_t round_up(std::size_t bytes, std::size_t granule) { return (bytes + granule - 1) / granule * granule; }

// A fresh mapping of `bytes` (a multiple of the granule) starting on a
// granule boundary: blocks and the pieces split off them then stay on 2 MiB
// boundaries, so that the kernel can back them with transparent huge pages
// and mremap moves whole page-table levels instead of splitting huge pages.
char* map_aligned(std::size_t bytes) {
  const std::size_t g = LargeBlocks::kGranule;
  void* raw = ::mmap(nullptr, bytes + g, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) return nullptr;
  char* const start = static_cast<char*>(raw);
  char* const aligned = reinterpret_cast<char*>(round_up(reinterpret_cast<std::uintptr_t>(start), g));
  if (aligned > start) ::munmap(start, std::size_t(aligned - start));
  char* const end = start + bytes + g;
  if (end > aligned + bytes) ::munmap(aligned + bytes, std::size_t(end - (aligned + bytes)));
  return aligned;
}

}  // namespace

LargeBlocks& LargeBlocks::instance() {
  // Placement into static storage and never destroyed: operator delete may
  // hand a block back after static destructors ran.
  alignas(LargeBlocks) static unsigned char storage[sizeof(LargeBlocks)];
  static LargeBlocks* cache = new (storage) LargeBlocks;
  return *cache;
}

LargeBlocks::~LargeBlocks() {
  drop_kept();
  for (int i = 0; i < live_count_; ++i) ::munmap(live_[i].base, live_[i].size);
}

void LargeBlocks::note_range(const char* base, std::size_t size) {
  const auto lo = reinterpret_cast<std::uintptr_t>(base), hi = lo + size;
  std::uintptr_t seen = lo_.load();
  while (lo < seen && !lo_.compare_exchange_weak(seen, lo)) {
  }
  seen = hi_.load();
  while (hi > seen && !hi_.compare_exchange_weak(seen, hi)) {
  }
}

// Moves the `bytes` at `from` to `to` (pages and all, no copy) and returns
// how many moved. A range that spans several kernel mappings (a block
// assembled from pieces) moves one granule at a time: pieces always join at
// granule offsets. Stops at the first granule the kernel refuses.
static std::size_t move_pages(char* from, char* to, std::size_t bytes) {
  if (::mremap(from, bytes, bytes, MREMAP_MAYMOVE | MREMAP_FIXED, to) != MAP_FAILED) return bytes;
  std::size_t moved = 0;
  while (moved < bytes && ::mremap(from + moved, LargeBlocks::kGranule, LargeBlocks::kGranule,
                                   MREMAP_MAYMOVE | MREMAP_FIXED, to + moved) != MAP_FAILED)
    moved += LargeBlocks::kGranule;
  return moved;
}

void* LargeBlocks::allocate(std::size_t bytes) {
  if (bytes == 0 || bytes > (std::size_t(1) << 46)) return nullptr;
  const std::size_t need = round_up(bytes, kGranule);
  std::lock_guard lock(mutex_);
  if (live_count_ == kMaxBlocks) return nullptr;
  auto remove_kept = [&](int i) {
    stats_.kept_bytes -= kept_[i].size;
    kept_[i] = kept_[--kept_count_];
  };
  // The smallest kept block that fits: taken whole, or its head when it is
  // much larger (the tail stays kept).
  int fit = -1;
  for (int i = 0; i < kept_count_; ++i)
    if (kept_[i].size >= need && (fit < 0 || kept_[i].size < kept_[fit].size)) fit = i;
  Block block;
  if (fit >= 0) {
    block = kept_[fit];
    if (block.size - need >= kThreshold) {
      block.size = need;
      kept_[fit].base += need, kept_[fit].size -= need;
      stats_.kept_bytes -= need;
    } else {
      remove_kept(fit);
    }
  } else {
    // None fits alone: a fresh address range, onto which the kept blocks
    // move, largest first, with their pages; only what they do not cover is
    // fresh memory. Pages are interchangeable, so the cache never maps more
    // than the most bytes ever alive at once.
    char* range = map_aligned(need);
    if (!range) return nullptr;
    block = {range, need};
    std::size_t covered = 0;
    while (covered < need && kept_count_ > 0) {
      int largest = 0;
      for (int i = 1; i < kept_count_; ++i)
        if (kept_[i].size > kept_[largest].size) largest = i;
      Block& piece = kept_[largest];
      const std::size_t take = std::min(piece.size, need - covered);
      const std::size_t moved = move_pages(piece.base, block.base + covered, take);
      covered += moved;
      if (moved == piece.size) {
        remove_kept(largest);
      } else {
        piece.base += moved, piece.size -= moved;
        stats_.kept_bytes -= moved;
      }
      if (moved < take) break;  // the rest of the range stays fresh
    }
    stats_.fresh_bytes += need - covered;
  }
  note_range(block.base, block.size);
  live_[live_count_++] = block;
  stats_.live_bytes += block.size;
  stats_.peak_live_bytes = std::max(stats_.peak_live_bytes, stats_.live_bytes);
  return block.base;
}

bool LargeBlocks::release(void* p) {
  const auto at = reinterpret_cast<std::uintptr_t>(p);
  if (at < lo_.load(std::memory_order_relaxed) || at >= hi_.load(std::memory_order_relaxed)) return false;
  std::lock_guard lock(mutex_);
  for (int i = 0; i < live_count_; ++i) {
    if (live_[i].base != p) continue;
    const Block b = live_[i];
    live_[i] = live_[--live_count_];
    stats_.live_bytes -= b.size;
    if (kept_count_ < kMaxBlocks) {
      kept_[kept_count_++] = b;
      stats_.kept_bytes += b.size;
    } else {
      ::munmap(b.base, b.size);
    }
    return true;
  }
  return false;
}

LargeBlocks::Stats LargeBlocks::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

void LargeBlocks::drop_kept() {
  std::lock_guard lock(mutex_);
  for (int i = 0; i < kept_count_; ++i) ::munmap(kept_[i].base, kept_[i].size);
  kept_count_ = 0;
  stats_.kept_bytes = 0;
}

}  // namespace lapflow
