// lapflow_bench: `lapflow_bench raster [N...]` times the rasterizer alone.
#include <cstdlib>
#include <cstring>
#include <vector>

#include "bench.hpp"

int main(int argc, char** argv) {
  if (argc >= 2 && std::strcmp(argv[1], "raster") == 0) {
    std::vector<int> sizes;
    for (int i = 2; i < argc; ++i) sizes.push_back(std::atoi(argv[i]));
    if (sizes.empty()) sizes = {2048, 4096, 6144};
    lapflow::bench::bench_raster(sizes);
  }
  return 0;
}
