#pragma once
/// \file parallel.hpp The one parallel-for of lapflow (TBB behind it).
#include <cstddef>
#include <cstdint>
#include <functional>

namespace lapflow {

/// Sets the number of worker threads for the rest of the process (0 = all
/// cores). Results never depend on it.
void set_thread_count(int threads);
int thread_count();

/// Calls body(begin, end) over disjoint ranges covering [0, n). Bodies must
/// write by index only (no shared accumulation) so results do not depend on
/// the thread count. `grain` is the smallest range handed to one task.
void parallel_for(std::size_t n, const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain = 256);

/// Deterministic 64-bit hash of a few integers (splitmix64 chain): randomness
/// keyed by the work, not the thread.
uint64_t hash64(uint64_t a, uint64_t b = 0, uint64_t c = 0, uint64_t d = 0);
/// Uniform double in [0,1) from a hash.
inline double hash_to_unit(uint64_t h) { return double(h >> 11) * 0x1.0p-53; }

}  // namespace lapflow
