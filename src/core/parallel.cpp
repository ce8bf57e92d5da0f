#include "lapflow/core/parallel.hpp"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>

#include <memory>

namespace lapflow {
namespace {
std::unique_ptr<tbb::global_control> g_control;  // the --threads setting, set once by the CLI
int g_threads = 0;
}  // namespace

void set_thread_count(int threads) {
  g_control.reset();
  g_threads = threads > 0 ? threads : 0;
  if (g_threads > 0)
    g_control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, g_threads);
}

int thread_count() { return g_threads > 0 ? g_threads : int(tbb::info::default_concurrency()); }

void parallel_for(std::size_t n, const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain) {
  if (n == 0) return;
  if (thread_count() == 1 || n <= grain) {
    body(0, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain == 0 ? 1 : grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

uint64_t hash64(uint64_t a, uint64_t b, uint64_t c, uint64_t d) {
  auto mix = [](uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
  };
  uint64_t h = mix(a);
  h = mix(h ^ b);
  h = mix(h ^ c);
  h = mix(h ^ d);
  return h;
}

}  // namespace lapflow
