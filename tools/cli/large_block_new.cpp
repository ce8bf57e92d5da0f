// The executables' operator new and delete: requests of
// LargeBlocks::kThreshold bytes and more come from the large-block cache
// (lapflow/core/large_blocks.hpp), the rest from malloc. Linked into the
// lapflow CLI and lapflow_bench only: a program embedding the library keeps
// its own allocator. Not under sanitizers, which replace these themselves.
#include <cstdlib>
#include <new>

#include "lapflow/core/large_blocks.hpp"

#if !defined(LAPFLOW_SANITIZED)

namespace {

using lapflow::LargeBlocks;

void* try_allocate(std::size_t n, std::size_t align) {
  if (n >= LargeBlocks::kThreshold && align <= LargeBlocks::kAlignment)
    if (void* p = LargeBlocks::instance().allocate(n)) return p;
  if (align <= alignof(std::max_align_t)) return std::malloc(n ? n : 1);
  void* p = nullptr;
  return ::posix_memalign(&p, align, n ? n : 1) == 0 ? p : nullptr;
}

void* allocate(std::size_t n, std::size_t align) {
  for (;;) {
    if (void* p = try_allocate(n, align)) return p;
    std::new_handler handler = std::get_new_handler();
    if (!handler) throw std::bad_alloc();
    handler();
  }
}

void* allocate_nothrow(std::size_t n, std::size_t align) noexcept {
  try {
    return allocate(n, align);
  } catch (...) {
    return nullptr;
  }
}

void release(void* p) noexcept {
  if (p && !LargeBlocks::instance().release(p)) std::free(p);
}

constexpr std::size_t kDefault = alignof(std::max_align_t);

}  // namespace

void* operator new(std::size_t n) { return allocate(n, kDefault); }
void* operator new[](std::size_t n) { return allocate(n, kDefault); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocate_nothrow(n, kDefault); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocate_nothrow(n, kDefault); }
void* operator new(std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a)); }
void* operator new[](std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a)); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate_nothrow(n, std::size_t(a));
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate_nothrow(n, std::size_t(a));
}

void operator delete(void* p) noexcept { release(p); }
void operator delete[](void* p) noexcept { release(p); }
void operator delete(void* p, std::size_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t) noexcept { release(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { release(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { release(p); }
void operator delete(void* p, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::align_val_t) noexcept { release(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { release(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { release(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { release(p); }

#endif
