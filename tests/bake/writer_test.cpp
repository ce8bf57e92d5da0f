// Writing baked frames: the same inputs give the same bytes in every file;
// a frame's files appear together; a stop between frames leaves whole frames
// only; a bake's start removes the temporary files killed runs left.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

/// The demo's vortex, coarse, frames 1..n, as dir/m.%04d.ply.
void write_demo_sequence(const std::string& dir, int n) {
  DemoOptions demo;
  demo.voxel_size = 1.0 / 40;
  for (int f = 1; f <= n; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", dir, f), demo_frame(demo, f));
}

BakeOptions small_bake(const std::string& meshes, const std::string& out) {
  BakeOptions o = test::small_pebbles_bake(meshes, out);
  o.atlas.resolution = 128;
  o.dump_patches = true;  // every kind of frame file
  resolve_bake_options(o);
  return o;
}

using test::names_in;
using test::stats_without_timings;
using test::temporaries_in;

const char* const kFrameFiles[] = {"t.{:04d}.obj", "t.{:04d}.mtl", "t.color.{:04d}.exr", "t.disp.{:04d}.exr",
                                   "t.aov.{:04d}.exr", "t.patches.{:04d}.ply", "t.render.{:04d}.json",
                                   "t.usd.{:04d}.usda"};

}  // namespace

// Two bakes of the same inputs (one on one thread reading each frame when
// it is needed and writing in the foreground, one on two threads reading
// ahead and writing in the background) give the same bytes in every file,
// EXRs included: no date in their headers.
TEST(BakeWriter, SameInputsGiveByteIdenticalFiles) {
  TempDir meshes("bytes_in"), a("bytes_a"), b("bytes_b");
  write_demo_sequence(meshes.str(), 3);
  set_thread_count(1);
  BakeOptions serial = small_bake(meshes.str(), a.str());
  serial.prefetch_read = false;
  bake(serial);
  set_thread_count(2);
  BakeOptions background = small_bake(meshes.str(), b.str());
  background.background_write = true;
  bake(background);
  set_thread_count(0);

  const std::vector<std::string> files = names_in(a.str());
  ASSERT_EQ(files, names_in(b.str()));
  // + bake.json, stats.jsonl, states 2 and 3, the USD stage and its clip manifest
  ASSERT_EQ(files.size(), 3 * std::size(kFrameFiles) + 6);
  for (const std::string& f : files) {
    if (f == "t.stats.jsonl") continue;
    const std::string bytes = test::read_bytes(a / f);
    ASSERT_GT(bytes.size(), 0u) << f;
    EXPECT_TRUE(bytes == test::read_bytes(b / f)) << f << " differs between two bakes of the same inputs";
    if (f.ends_with(".exr")) {
      EXPECT_EQ(bytes.find("capDate"), std::string::npos) << f << " carries a date";
    }
  }
  // The stats differ only in the seconds and the memory.
  EXPECT_EQ(stats_without_timings(a / "t.stats.jsonl"), stats_without_timings(b / "t.stats.jsonl"));
}

// `--exr-type float` keeps the resolve's float images (a half bake makes
// its images in half directly, RasterOptions::half_images): the float
// files hold values a half cannot, and round to the half bake's pixels.
TEST(BakeWriter, AFloatBakeWritesTheHalfBakesPixelsUnrounded) {
  TempDir meshes("float_in"), half("float_half"), full("float_full");
  write_demo_sequence(meshes.str(), 2);
  bake(small_bake(meshes.str(), half.str()));
  BakeOptions o = small_bake(meshes.str(), full.str());
  o.exr.type = ExrPixelType::Float;
  bake(o);
  for (const char* kind : {"color", "disp"}) {
    const std::string name = fmt::format("t.{}.0002.exr", kind);
    const Image h = read_image(half / name, ColorSpace::Linear);
    const Image f = read_image(full / name, ColorSpace::Linear);
    ASSERT_EQ(h.pixels.size(), f.pixels.size()) << name;
    EXPECT_TRUE(to_half_image(f).bits == to_half_image(h).bits) << name << ": not the half bake's pixels";
    EXPECT_FALSE(f.pixels == h.pixels) << name << ": the float bake's pixels are all halves";
  }
}

// A stop asked for while frame 3 computes (as SIGTERM does) abandons it:
// frames 1-2 whole, no file of frame 3, no temporary file, the stop says
// which frame was the last complete one.
TEST(BakeWriter, AStopBetweenFramesLeavesOnlyWholeFrames) {
  TempDir meshes("stop_in"), out("stop_out");
  write_demo_sequence(meshes.str(), 4);
  std::vector<int> written;
  try {
    bake(small_bake(meshes.str(), out.str()), [&](const FrameStats& s) {
      written.push_back(s.frame);
      if (s.frame == 2) request_stop(SIGTERM);
    });
    request_stop(0);
    FAIL() << "the bake must stop";
  } catch (const Interrupted& e) {
    request_stop(0);
    EXPECT_EQ(e.signal(), SIGTERM);
    EXPECT_EQ(e.last_complete_frame(), 2);
    EXPECT_NE(std::string(e.what()).find("the last complete frame is 2"), std::string::npos) << e.what();
  }
  EXPECT_EQ(written, (std::vector<int>{1, 2}));
  for (int f = 1; f <= 4; ++f)
    for (const char* kind : kFrameFiles)
      EXPECT_EQ(fs::exists(out / fmt::format(fmt::runtime(kind), f)), f <= 2) << fmt::format(fmt::runtime(kind), f);
  EXPECT_TRUE(temporaries_in(out.str()).empty());
  EXPECT_EQ(stats_without_timings(out / "t.stats.jsonl").size(), 2u);
}

// A bake's start removes the temporary files a killed run of the same bake
// left (a SIGKILL cannot be caught), and only those: not another bake's, and
// not those a running process is writing (a farm's render job beside it).
TEST(BakeWriter, ABakeRemovesTheStaleTemporaryFilesOfItsOwnName) {
  TempDir meshes("stale_in"), out("stale_out");
  write_demo_sequence(meshes.str(), 1);
  const std::string& host = temporary_host_tag();
  const long gone = test::ended_process_id();
  for (const auto& [name, ext] : {std::pair{"t.color.0002", ".exr"}, {"t.0001", ".obj"}, {"t.stats", ".jsonl"}})
    test::write_bytes(out / test::temporary_name(name, ext, host, gone, 9), std::string(1000, 'x'));
  const std::string other = test::temporary_name("other.color.0001", ".exr", host, gone, 7);
  const std::string rendering = test::temporary_name("t.aov.0003", ".exr", host, long(::getppid()), 7);
  test::write_bytes(out / other, "another bake's");
  test::write_bytes(out / rendering, "a running render's");
  bake(small_bake(meshes.str(), out.str()));
  std::vector<std::string> left = {other, rendering};
  std::sort(left.begin(), left.end());
  EXPECT_EQ(temporaries_in(out.str()), left);
  EXPECT_EQ(test::read_bytes(out / rendering), "a running render's");
  for (const char* kind : kFrameFiles) EXPECT_TRUE(fs::exists(out / fmt::format(fmt::runtime(kind), 1))) << kind;
}
