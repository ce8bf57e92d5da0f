// lapflow_bench: speed and memory of the stages and of the whole bake, on
// generated scenes and on ../shared/data. Numbers go in docs/performance.md (headline rows in the README).
//
//   lapflow_bench                 every benchmark below, each bake in its own process (peak RSS per run)
//   lapflow_bench bake-demo N R   one bake of the ~100k-triangle demo at N x N, radius R (0 = ~5k patches)
//   lapflow_bench bake-data [N]   the headline real scene: ../shared/data/splash frames 1-48, foam, r = 0.028,
//                                 at N x N (default 6144); a row per frame, then means, worst and peak RSS
//   lapflow_bench bake-data PATTERN N  one bake of the mesh sequence PATTERN (e.g. .../dam_break.%04d.ply) at N x N
//   lapflow_bench raster [N...]   the rasterizer alone at the given resolutions
//   lapflow_bench atlas [DATA]    the surface atlas alone
//   lapflow_bench patches [DATA]  the patch stages alone
//   lapflow_bench seeding [DATA]  the per-frame fresh seeding on shared frames
//   lapflow_bench obj [DATA]      the UV-mesh OBJ and USD layer writers on shared splash frames
//   lapflow_bench replay DIR F [K] frame F of the bake in DIR computed again K times (default 5) from
//                                 the previous frame's state, each step timed (tools/bench/bench_replay.cpp)
//   lapflow_bench write DIR F [K] frame F's EXRs and state written again K times (default 5) each way,
//                                 direct and through the page cache, alternated (tools/bench/bench_write.cpp)
#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include <malloc.h>
#include <unistd.h>

#include "bench.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/large_blocks.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/core/stopwatch.hpp"

namespace fs = std::filesystem;
using namespace lapflow;

namespace {

std::string source_dir() { return LAPFLOW_SOURCE_DIR; }

/// Bakes and prints one table row: mean seconds per stage over the frames
/// after the first (the first frame seeds), and the peak RSS of the process.
void run_bake(const std::string& label, BakeOptions o) {
  resolve_bake_options(o);
  std::vector<FrameStats> stats;
  bake(o, [&](const FrameStats& s) { stats.push_back(s); });
  FrameStats mean;
  std::size_t n = 0, patches = 0, tris = 0;
  for (std::size_t i = stats.size() > 1 ? 1 : 0; i < stats.size(); ++i, ++n) {
    const FrameStats& s = stats[i];
    mean.seconds_read += s.seconds_read;
    mean.seconds_advect += s.seconds_advect;
    mean.seconds_atlas += s.seconds_atlas;
    mean.seconds_raster += s.seconds_raster;
    mean.seconds_write += s.seconds_write;
    mean.seconds_total += s.seconds_total;
    patches += s.patches_alive;
    tris += s.triangles;
  }
  const double k = n ? 1.0 / double(n) : 0;
  fmt::print("| {} | {} | {} | {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | **{:.2f}** | {:.0f} | {:.2f} |\n", label,
             o.atlas.resolution, tris / std::max<std::size_t>(n, 1), patches / std::max<std::size_t>(n, 1),
             mean.seconds_read * k, mean.seconds_advect * k, mean.seconds_atlas * k, mean.seconds_raster * k,
             mean.seconds_write * k, mean.seconds_total * k, peak_rss_mb(), stats.empty() ? 0.0 : stats[0].seconds_total);
  std::fflush(stdout);
}

BakeOptions base_options(const std::string& out) {
  BakeOptions o;
  o.exemplar_color = source_dir() + "/exemplars/pebbles.color.png";
  o.exemplar_feature = source_dir() + "/exemplars/pebbles.feature.png";
  o.exemplar_displacement = source_dir() + "/exemplars/pebbles.disp.png";
  o.out_dir = out;
  o.name = "bench";
  // LAPFLOW_BENCH_IO=serial|prefetch|overlap: read, compute and write one
  // after the other; read ahead (the default); read ahead and write behind.
  if (const char* io = std::getenv("LAPFLOW_BENCH_IO")) {
    o.prefetch_read = std::string(io) != "serial";
    o.background_write = std::string(io) == "overlap";
  }
  // LAPFLOW_BENCH_EXR=piz|zip|none: another EXR compression than the default (rle).
  if (const char* exr = std::getenv("LAPFLOW_BENCH_EXR")) {
    const std::string c = exr;
    o.exr.compression = c == "piz" ? ExrCompression::Piz : c == "zip" ? ExrCompression::Zip
                        : c == "none" ? ExrCompression::None : ExrCompression::Rle;
  }
  return o;
}

/// The demo's vortex at about 100k triangles per frame, written once.
std::string demo_frames(int frames) {
  const fs::path dir = fs::temp_directory_path() / "lapflow_bench_demo100k";
  DemoOptions d;
  d.frames = frames;
  d.voxel_size = demo_voxel_size_for(DemoCase::Vortex, 100000);
  if (!fs::exists(dir / fmt::format("demo.{:04d}.ply", frames))) {
    fs::create_directories(dir);
    for (int f = 1; f <= frames; ++f) write_ply((dir / fmt::format("demo.{:04d}.ply", f)).string(), demo_frame(d, f));
  }
  return (dir / "demo.%04d.ply").string();
}

void bake_demo(int resolution, double radius) {
  const std::string pattern = demo_frames(6);
  BakeOptions o = base_options((fs::temp_directory_path() / "lapflow_bench_out").string());
  o.mesh_pattern = pattern;
  o.frames = FrameRange{1, 6};
  o.atlas.resolution = resolution;
  if (radius <= 0) {
    // Poisson-disk samples at distance r cover about 0.8 A / r^2: aim at 5k.
    const double area = surface_area(read_mesh(FramePattern(pattern).path(1)));
    radius = std::sqrt(0.8 * area / 5000);
  }
  o.patch.radius = radius;
  run_bake(fmt::format("demo vortex ~100k tris, r={:.4f}", radius), o);
}

void bake_data(const std::string& pattern, int resolution, int first, int last) {
  BakeOptions o = base_options((fs::temp_directory_path() / "lapflow_bench_out").string());
  o.mesh_pattern = pattern;
  o.frames = FrameRange{first, last};
  o.atlas.resolution = resolution;
  o.patch.radius = 0.04;
  run_bake(fmt::format("{} {}-{}, r=0.04", fs::path(pattern).filename().string(), first, last), o);
}

/// Resident memory now (not the peak): /proc/self/statm's second field.
double current_rss_mb() {
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return double(resident) * double(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

/// The memory after a frame: what the allocators have in use (live data:
/// malloc's blocks and the large blocks, LargeBlocks) and what they hold
/// from the system (in use plus freed memory kept for reuse). RSS follows the
/// second; when it grows while the first does not, the growth is freed
/// memory kept, not data.
struct HeapUse {
  double in_use_mb = 0, held_mb = 0;
};
HeapUse heap_use() {
  const struct mallinfo2 m = mallinfo2();
  const LargeBlocks::Stats large = LargeBlocks::instance().stats();
  constexpr double mb = 1024.0 * 1024.0;
  return {double(m.uordblks + m.hblkhd + large.live_bytes) / mb,
          double(m.arena + m.hblkhd + large.live_bytes + large.kept_bytes) / mb};
}

/// The most memory in use within each frame: a thread samples heap_use()
/// every 5 ms and keeps the maximum until take() hands it over. mallinfo2
/// walks malloc's free lists under its lock, which slows the bake: only with
/// LAPFLOW_BENCH_HEAP_PEAK=1, for where memory goes, not for timings.
class HeapPeakSampler {
 public:
  HeapPeakSampler()
      : thread_([this] {
          while (!stop_.load()) {
            const double now = heap_use().in_use_mb;
            double seen = peak_.load();
            while (now > seen && !peak_.compare_exchange_weak(seen, now)) {
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
          }
        }) {}
  ~HeapPeakSampler() {
    stop_ = true;
    thread_.join();
  }
  double take() { return peak_.exchange(heap_use().in_use_mb); }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<double> peak_{0};
  std::thread thread_;
};

/// Issue 15's benchmark on real data: the shared splash (droplets, many
/// charts) with the foam exemplar at r = 0.028. "Per frame" is the wall time
/// between two frames' files landing on disk: every stage, the reading ahead
/// and the writing included, as a user waits for it.
int bake_splash(const std::string& data, int resolution) {
  const std::string pattern = data + "/splash/splash.%04d.ply";
  if (!fs::exists(FramePattern(pattern).path(48))) {
    fmt::print(stderr, "bake-data: {} frames 1-48 not found (the shared data sits beside the project)\n", pattern);
    return 2;
  }
  BakeOptions o = base_options((fs::temp_directory_path() / "lapflow_bench_splash").string());
  o.exemplar_color = source_dir() + "/exemplars/foam.color.png";
  o.exemplar_feature = source_dir() + "/exemplars/foam.feature.png";
  o.exemplar_displacement = source_dir() + "/exemplars/foam.disp.png";
  o.mesh_pattern = pattern;
  o.frames = FrameRange{1, 48};
  o.atlas.resolution = resolution;
  o.patch.radius = 0.028;
  resolve_bake_options(o);
  fmt::print("splash 1-48, foam, r = 0.028, {}^2, {} threads\n\n", resolution, thread_count());
  fmt::print("| frame | triangles | charts | patches | advect s | weights s | atlas s (ahead) | track s | draw s | holes s | "
             "resolve s | dilate s | write s | wall s | RSS MiB | heap peak MiB | heap in use MiB | heap held MiB |\n");
  fmt::print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  Stopwatch clock;
  std::vector<double> wall, rss;
  std::optional<HeapPeakSampler> heap_peak;
  if (std::getenv("LAPFLOW_BENCH_HEAP_PEAK")) heap_peak.emplace();
  bake(o, [&](const FrameStats& s) {
    wall.push_back(clock.lap());
    rss.push_back(current_rss_mb());
    const HeapUse heap = heap_use();
    const std::string frame_peak = heap_peak ? fmt::format("{:.0f}", heap_peak->take()) : "-";
    fmt::print("| {} | {} | {} | {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | "
               "{:.0f} | {} | {:.0f} | {:.0f} |\n",
               s.frame, s.triangles, s.charts, s.patches_alive, s.seconds_advect, s.seconds_weights, s.seconds_atlas,
               s.seconds_track, s.seconds_draw, s.seconds_holes, s.seconds_resolve, s.seconds_dilate, s.seconds_write,
               wall.back(), rss.back(), frame_peak, heap.in_use_mb, heap.held_mb);
    std::fflush(stdout);
  });
  double sum = 0, worst = 0;
  for (std::size_t i = 1; i < wall.size(); ++i) sum += wall[i], worst = std::max(worst, wall[i]);
  const double mean = wall.size() > 1 ? sum / double(wall.size() - 1) : 0;
  fmt::print("\nframes 2-48: mean {:.2f} s a frame, worst {:.2f} s; first frame {:.2f} s; peak RSS {:.0f} MiB; "
             "RSS at frame 5 {:.0f} MiB, at frame 48 {:.0f} MiB\n",
             mean, worst, wall.empty() ? 0.0 : wall[0], peak_rss_mb(), rss.size() > 4 ? rss[4] : 0.0,
             rss.empty() ? 0.0 : rss.back());
  const LargeBlocks::Stats large = LargeBlocks::instance().stats();
  fmt::print("large blocks (8 MiB and more): at most {:.0f} MiB alive at once, {:.0f} MiB mapped fresh over the bake\n",
             double(large.peak_live_bytes) / (1024.0 * 1024.0), double(large.fresh_bytes) / (1024.0 * 1024.0));
  return 0;
}

void header() {
  fmt::print("| scene | atlas | triangles | patches | read s | advect s | atlas s (ahead) | raster s | write s | total s/frame | peak RSS MiB | first frame s |\n");
  fmt::print("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

}  // namespace

int main(int argc, char** argv) {
  lapflow::keep_freed_memory_for_reuse();  // as the lapflow CLI does
  const std::vector<std::string> args(argv + 1, argv + argc);
  const std::string data = source_dir() + "/../shared/data";
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  if (args.size() >= 2 && args[0] == "bake-demo") {
    bake_demo(std::stoi(args[1]), args.size() > 2 ? std::stod(args[2]) : 0);
    return 0;
  }
  if (!args.empty() && args.size() <= 2 && args[0] == "bake-data")
    return bake_splash(data, args.size() == 2 ? std::stoi(args[1]) : 6144);
  if (args.size() >= 3 && args[0] == "bake-data") {
    bake_data(args[1], std::stoi(args[2]), 20, 26);
    return 0;
  }
  if (!args.empty() && args[0] == "raster") {
    std::vector<int> sizes;
    for (std::size_t i = 1; i < args.size(); ++i) sizes.push_back(std::stoi(args[i]));
    if (sizes.empty()) sizes = {2048, 4096, 6144};
    bench::bench_raster(sizes);
    return 0;
  }
  if (!args.empty() && args[0] == "atlas") {
    bench::bench_atlas(args.size() > 1 ? args[1] : data);
    return 0;
  }
  // replay and write: frame F of a finished bake, K repeats; an unreadable
  // bake is exit 2 naming it.
  for (const auto& [name, run] : {std::pair{"replay", &bench::bench_replay}, std::pair{"write", &bench::bench_write}}) {
    if (args.size() < 3 || args[0] != name) continue;
    try {
      run(args[1], std::stoi(args[2]), args.size() > 3 ? std::stoi(args[3]) : 5);
    } catch (const std::exception& e) {
      fmt::print(stderr, "lapflow_bench {}: {}\n", name, e.what());
      return 2;
    }
    return 0;
  }
  if (!args.empty() && args[0] == "obj") {
    bench::bench_obj(args.size() > 1 ? args[1] : data);
    return 0;
  }
  if (!args.empty() && args[0] == "seeding") {
    bench::bench_fresh_seeding(args.size() > 1 ? args[1] : data);
    return 0;
  }
  if (!args.empty() && args[0] == "patches") {
    bench::bench_patches(args.size() > 1 ? args[1] : data);
    return 0;
  }
  fmt::print("lapflow_bench on {} threads\n\n## Patches\n\n", thread_count());
  bench::bench_patches(data);
  fmt::print("\n## Surface atlas\n\n");
  bench::bench_atlas(data);
  fmt::print("\n## Rasterizer alone\n\n");
  bench::bench_raster({2048, 4096, 6144});
  fmt::print("\nBake, mean per frame over frames 2-6 (frame 1 seeds):\n\n");
  header();
  std::fflush(stdout);  // the bakes below print from child processes
  for (int n : {2048, 4096, 6144})
    if (std::system(fmt::format("'{}' bake-demo {}", self, n).c_str()) != 0) return 1;
  if (fs::exists(data + "/dam_break/dam_break.0020.ply"))
    if (std::system(fmt::format("'{}' bake-data '{}' 4096", self, data + "/dam_break/dam_break.%04d.ply").c_str()) != 0)
      return 1;
  return 0;
}
