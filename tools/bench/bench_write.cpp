// lapflow_bench write: a finished bake's frame written again, with direct
// writes (around the page cache) and through the page cache, alternated, so
// that the two ways compare at the same moment on the same bytes. Each round
// writes the frame's colour and displacement EXRs and its patch state as the
// bake does (write_exr, write_text_atomically) and times it: wall, and this
// process's user and system CPU (getrusage), which include OpenEXR's threads.
#include <fmt/format.h>
#include <sys/resource.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/stopwatch.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/direct_file.hpp"
#include "lapflow/io/image.hpp"

namespace lapflow::bench {
namespace {

double cpu_seconds(const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); }

std::string read_all(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error(path + ": cannot read");
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

}  // namespace

void bench_write(const std::string& dir, int frame, int rounds) {
  namespace fs = std::filesystem;
  const BakeManifest manifest = read_bake_manifest(dir);
  struct Exr {
    std::string name;
    HalfImage pixels;
    std::vector<std::string> channels;
  };
  std::vector<Exr> exrs;
  for (const char* kind : {"color", "disp"}) {
    const std::string path = manifest.frame_file(kind, frame);
    exrs.push_back({fs::path(path).filename().string(), to_half_image(read_image(path, ColorSpace::Linear)),
                    image_channel_names(path)});
  }
  const std::string state_path = manifest.frame_file("state", frame);
  const std::string state = read_all(state_path);
  const fs::path out = fs::path(dir) / ".bench_write";
  fs::create_directories(out);
  fmt::print("write of {} frame {}: {} + {} + state {} MB, {} rounds, each way once a round\n", dir, frame,
             exrs[0].name, exrs[1].name, state.size() >> 20, rounds);
  fmt::print("| round | way | wall s | user s | system s | MB written |\n|---|---|---|---|---|---|\n");
  const bool was = direct_io_enabled();
  std::vector<double> best_wall[2], best_cpu[2];
  for (int r = 0; r < rounds; ++r)
    for (int way = 0; way < 2; ++way) {
      // Direct first on even rounds, second on odd ones.
      const bool direct = (way == 0) == (r % 2 == 0);
      set_direct_io(direct);
      rusage before{}, after{};
      getrusage(RUSAGE_SELF, &before);
      Stopwatch clock;
      for (const Exr& e : exrs) write_exr((out / e.name).string(), e.pixels, e.channels);
      write_text_atomically((out / fs::path(state_path).filename()).string(), state);
      const double wall = clock.lap();
      getrusage(RUSAGE_SELF, &after);
      std::uintmax_t bytes = 0;
      for (const auto& f : fs::directory_iterator(out)) bytes += f.file_size();
      const double user = cpu_seconds(after.ru_utime) - cpu_seconds(before.ru_utime);
      const double sys = cpu_seconds(after.ru_stime) - cpu_seconds(before.ru_stime);
      fmt::print("| {} | {} | {:.3f} | {:.3f} | {:.3f} | {:.0f} |\n", r + 1, direct ? "direct" : "page cache", wall, user,
                 sys, double(bytes) / 1e6);
      best_wall[direct].push_back(wall);
      best_cpu[direct].push_back(user + sys);
      for (const auto& f : fs::directory_iterator(out)) fs::remove(f.path());
    }
  set_direct_io(was);
  fs::remove_all(out);
  for (int direct : {1, 0}) {
    auto& w = best_wall[direct];
    auto& c = best_cpu[direct];
    std::sort(w.begin(), w.end());
    std::sort(c.begin(), c.end());
    fmt::print("{}: wall min {:.3f} median {:.3f} s; CPU (user + system) min {:.3f} median {:.3f} s\n",
               direct ? "direct" : "page cache", w.front(), w[w.size() / 2], c.front(), c[c.size() / 2]);
  }
}

}  // namespace lapflow::bench
