// End-to-end properties of the bake (ALGORITHM.md "Properties the result must
// have"): coverage, stillness, determinism across thread counts, rigid motion,
// bad input that never damages earlier frames.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <system_error>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/bake/bake.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
namespace fs = std::filesystem;

namespace {

/// The folders this test process made (fresh_dir). When every test of the
/// process passed they are removed at its end: otherwise a clone tested
/// once and deleted (as CI does) leaves gigabytes in the temp dir for good. A
/// failed test keeps its folders to look into. ctest runs each test in a
/// process of its own, so no other test's folder is in the list.
class MadeFolders : public ::testing::Environment {
 public:
  void add(const fs::path& d) { made_.push_back(d); }
  void TearDown() override {
    if (!::testing::UnitTest::GetInstance()->Passed()) return;
    for (const fs::path& d : made_) {
      std::error_code ec;
      fs::remove_all(d, ec);
    }
  }

 private:
  std::vector<fs::path> made_;
};

// Registered before main, as gtest asks of a program using gtest_main;
// gtest owns it.
MadeFolders* const made_folders =
    static_cast<MadeFolders*>(::testing::AddGlobalTestEnvironment(new MadeFolders));

/// A folder of its own per test name and per build folder (a hash of its
/// lapflow binary's path): two test runs on one machine (two worktrees, or
/// two build folders of one tree) must not bake into, and delete, each
/// other's folders. A build folder's next run reuses and clears its own,
/// and a passing test removes its folders at the end (MadeFolders), so runs
/// do not pile up in the temp dir (the every-frame bakes are large).
fs::path fresh_dir(const std::string& name) {
  const std::string build = fmt::format("{:08x}", std::hash<std::string>{}(LAPFLOW_BINARY) & 0xffffffffu);
  const fs::path d = fs::temp_directory_path() / ("lapflow_bake_test_" + build + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  made_folders->add(d);
  return d;
}

BakeOptions small_bake(const fs::path& meshes, const fs::path& out) {
  return test::small_pebbles_bake(meshes.string(), out.string());
}

/// The demo's vortex, coarse, frames 1..n.
fs::path demo_sequence(const std::string& name, int n) {
  const fs::path d = fresh_dir(name);
  DemoOptions demo;
  demo.voxel_size = 1.0 / 40;
  for (int f = 1; f <= n; ++f) write_ply((d / fmt::format("m.{:04d}.ply", f)).string(), demo_frame(demo, f));
  return d;
}

Image frame_image(const fs::path& out, const std::string& kind, int frame) {
  return read_image((out / fmt::format("t.{}.{:04d}.exr", kind, frame)).string(), ColorSpace::Linear);
}

std::vector<FrameStats> run(const BakeOptions& o) {
  BakeOptions copy = o;
  resolve_bake_options(copy);
  std::vector<FrameStats> stats;
  bake(copy, [&](const FrameStats& s) { stats.push_back(s); });
  return stats;
}

}  // namespace

TEST(Bake, EveryChartTexelIsCoveredOnEveryFrame) {
  const fs::path meshes = demo_sequence("coverage_in", 4), out = fresh_dir("coverage_out");
  const auto stats = run(small_bake(meshes, out));
  ASSERT_EQ(stats.size(), 4u);
  for (const FrameStats& s : stats) {
    EXPECT_GT(s.chart_texels, 1000u);
    EXPECT_EQ(s.coverage, 1.0) << "frame " << s.frame;
    // Alpha marks chart texels; the AOV names a patch on each of them and none elsewhere.
    const Image color = frame_image(out, "color", s.frame), aov = frame_image(out, "aov", s.frame);
    std::size_t alpha = 0;
    for (int y = 0; y < color.height; ++y)
      for (int x = 0; x < color.width; ++x) {
        const bool inside = color.at(x, y, 3) == 1.f;
        alpha += inside;
        if (inside) {
          EXPECT_GE(aov.at(x, y, 0), 0.f);
        }
      }
    EXPECT_EQ(alpha, s.chart_texels);
    // Every retired patch has one cause, and the population has its yardstick.
    EXPECT_EQ(s.retired_eroded + s.retired_hidden + s.retired_merged, s.patches_retired);
    EXPECT_GT(s.fresh_seeding, 0u);
  }
  // The first frame is seeded: every sample of a fresh seeding became a patch
  // (the demo's ball has no spot where creation fails), and hole filling may add more.
  EXPECT_LE(stats[0].fresh_seeding, stats[0].patches_born);
}

TEST(Bake, IdenticalForOneAndTwoThreads) {
  const fs::path meshes = demo_sequence("threads_in", 3);
  const fs::path out1 = fresh_dir("threads_1"), out2 = fresh_dir("threads_2");
  set_thread_count(1);
  const auto s1 = run(small_bake(meshes, out1));
  set_thread_count(2);
  const auto s2 = run(small_bake(meshes, out2));
  set_thread_count(0);
  ASSERT_EQ(s1.size(), s2.size());
  for (std::size_t i = 0; i < s1.size(); ++i) {
    EXPECT_EQ(s1[i].patches_alive, s2[i].patches_alive);
    EXPECT_EQ(s1[i].patches_born, s2[i].patches_born);
    for (const char* kind : {"color", "disp", "aov"}) {
      const Image a = frame_image(out1, kind, s1[i].frame), b = frame_image(out2, kind, s1[i].frame);
      EXPECT_TRUE(a.pixels == b.pixels) << kind << " differs at frame " << s1[i].frame;
    }
  }
}

// The AOV is float data and never lossy. RLE finds no runs in it (every
// texel holds a patch's (u, v), the gutters too once dilated), so under RLE,
// the default, it is written uncompressed; ZIP and PIZ are kept, DWAA (lossy)
// becomes ZIP. Colour and displacement keep the compression asked for.
TEST(Bake, AovIsLosslessAndUncompressedUnderRle) {
  const fs::path meshes = demo_sequence("aov_compression_in", 2);
  const std::pair<ExrCompression, std::pair<int, int>> cases[] = {
      {ExrCompression::Rle, {1, 0}}, {ExrCompression::Zip, {3, 3}}, {ExrCompression::Piz, {4, 4}},
      {ExrCompression::Dwaa, {8, 3}}, {ExrCompression::None, {0, 0}}};
  Image rle_aov;
  for (const auto& [compression, codes] : cases) {
    const fs::path out = fresh_dir("aov_compression");
    BakeOptions o = small_bake(meshes, out);
    o.aov = true;
    o.exr.compression = compression;
    run(o);
    for (int frame : {1, 2}) {
      const auto file = [&](const char* kind) { return (out / fmt::format("t.{}.{:04d}.exr", kind, frame)).string(); };
      EXPECT_EQ(test::exr_header_compression(file("color")), codes.first) << codes.first;
      EXPECT_EQ(test::exr_header_compression(file("aov")), codes.second) << codes.first;
    }
    // Whatever the compression, the AOV holds the same floats.
    const Image aov = frame_image(out, "aov", 2);
    if (compression == ExrCompression::Rle) rle_aov = aov;
    else EXPECT_TRUE(aov.pixels == rle_aov.pixels) << codes.first;
  }
}

// The temporal options of docs/temporal.md together (hold, small holes
// closed by neighbours, merge): coverage stays exactly 1, every retired
// patch has one cause, and 1 and 2 threads give the same images.
TEST(Bake, TemporalOptionsKeepCoverageAndAreIdenticalForOneAndTwoThreads) {
  const fs::path meshes = demo_sequence("temporal_in", 4);
  const fs::path out1 = fresh_dir("temporal_1"), out2 = fresh_dir("temporal_2");
  auto options = [&](const fs::path& out) {
    BakeOptions o = small_bake(meshes, out);
    o.raster.hold = true;
    o.raster.small_hole = 0.25;
    o.raster.merge = 0.1;
    return o;
  };
  set_thread_count(1);
  const auto s1 = run(options(out1));
  set_thread_count(2);
  const auto s2 = run(options(out2));
  set_thread_count(0);
  ASSERT_EQ(s1.size(), 4u);
  ASSERT_EQ(s2.size(), 4u);
  for (std::size_t i = 0; i < s1.size(); ++i) {
    EXPECT_EQ(s1[i].coverage, 1.0) << "frame " << s1[i].frame;
    EXPECT_EQ(s1[i].retired_eroded + s1[i].retired_hidden + s1[i].retired_merged, s1[i].patches_retired);
    EXPECT_EQ(s1[i].patches_alive, s2[i].patches_alive);
    EXPECT_EQ(s1[i].retired_merged, s2[i].retired_merged);
    for (const char* kind : {"color", "disp", "aov"}) {
      const Image a = frame_image(out1, kind, s1[i].frame), b = frame_image(out2, kind, s1[i].frame);
      EXPECT_TRUE(a.pixels == b.pixels) << kind << " differs at frame " << s1[i].frame;
    }
  }
}

TEST(Bake, StillSceneDoesNotChangeBetweenFrames) {
  const fs::path meshes = fresh_dir("still_in"), out = fresh_dir("still_out");
  TriMesh sphere = test::icosphere(4, 0.5);
  sphere.velocities.assign(sphere.positions.size(), Vec3{});
  for (int f = 1; f <= 3; ++f) write_ply((meshes / fmt::format("m.{:04d}.ply", f)).string(), sphere);
  const auto stats = run(small_bake(meshes, out));
  ASSERT_EQ(stats.size(), 3u);
  EXPECT_EQ(stats[1].patches_born, 0u);
  EXPECT_EQ(stats[2].patches_born, 0u);
  for (const char* kind : {"color", "disp", "aov"}) {
    const Image f1 = frame_image(out, kind, 1), f2 = frame_image(out, kind, 2), f3 = frame_image(out, kind, 3);
    EXPECT_TRUE(f2.pixels == f3.pixels) << kind;
    EXPECT_TRUE(f1.pixels == f2.pixels) << kind;
  }
}

TEST(Bake, TextureMovesWithARigidlyTranslatingSurface) {
  // The same sphere translated by d per frame with the exact velocity: the
  // atlas (a function of the shape) is the same, so every texel must keep
  // its patch and its exemplar coordinates.
  const fs::path meshes = fresh_dir("rigid_in"), out = fresh_dir("rigid_out");
  const Vec3 velocity{0.3, -0.2, 0.1};
  for (int f = 1; f <= 4; ++f) {
    TriMesh m = test::icosphere(4, 0.5);
    for (Vec3& p : m.positions) p += velocity * (double(f - 1) / 24.0);
    m.velocities.assign(m.positions.size(), velocity);
    write_ply((meshes / fmt::format("m.{:04d}.ply", f)).string(), m);
  }
  const auto stats = run(small_bake(meshes, out));
  const Image a = frame_image(out, "aov", 1), b = frame_image(out, "aov", 4);
  const Image ca = frame_image(out, "color", 1);
  std::size_t chart = 0, same = 0;
  double max_duv = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      if (ca.at(x, y, 3) != 1.f) continue;
      ++chart;
      if (a.at(x, y, 0) != b.at(x, y, 0)) continue;
      ++same;
      max_duv = std::max({max_duv, double(std::abs(a.at(x, y, 1) - b.at(x, y, 1))),
                          double(std::abs(a.at(x, y, 2) - b.at(x, y, 2)))});
    }
  ASSERT_GT(chart, 1000u);
  EXPECT_GT(double(same) / double(chart), 0.995);
  EXPECT_LT(max_duv, 2e-3);
  EXPECT_EQ(stats.back().patches_born, 0u);
}

TEST(Bake, ACorruptFrameStopsWithItsNameAndLeavesEarlierFramesIntact) {
  const fs::path meshes = demo_sequence("corrupt_in", 2), out = fresh_dir("corrupt_out");
  {
    // Frame 3: a binary PLY cut short in its vertex data.
    const std::string good = (meshes / "m.0002.ply").string();
    std::ifstream in(good, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    std::ofstream bad((meshes / "m.0003.ply").string(), std::ios::binary);
    bad.write(bytes.data(), std::streamsize(bytes.size() / 3));
  }
  BakeOptions o = small_bake(meshes, out);
  std::vector<FrameStats> stats;
  try {
    resolve_bake_options(o);
    bake(o, [&](const FrameStats& s) { stats.push_back(s); });
    FAIL() << "a truncated frame must stop the bake";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("m.0003.ply"), std::string::npos) << e.what();
    EXPECT_EQ(e.frame(), 3);
  }
  ASSERT_EQ(stats.size(), 2u);
  for (int f = 1; f <= 2; ++f) EXPECT_EQ(frame_image(out, "color", f).width, 256);
  for (const auto& entry : fs::directory_iterator(out))
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos) << entry.path();
  EXPECT_FALSE(fs::exists(out / "t.color.0003.exr"));
}

TEST(BakeCli, SceneFileOptionsAreOverriddenByTheCommandLine) {
  const fs::path meshes = demo_sequence("cli_in", 2), out = fresh_dir("cli_out");
  const fs::path scene = meshes / "scene.toml";
  {
    std::ofstream toml(scene);
    toml << "mesh = \"m.%04d.ply\"\nexemplar = \"" << LAPFLOW_SOURCE_DIR << "/exemplars/squares.color.png\"\n"
         << "out = \"" << out.string() << "\"\nresolution = 128\nframes = \"1-2\"\nname = \"scene\"\n";
  }
  const std::string cmd = fmt::format("'{}' bake '{}' --resolution 192 --frames 1-1 --quiet", LAPFLOW_BINARY, scene.string());
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const Image color = read_image((out / "scene.color.0001.exr").string(), ColorSpace::Linear);
  EXPECT_EQ(color.width, 192);
  EXPECT_FALSE(fs::exists(out / "scene.color.0002.exr"));
  EXPECT_TRUE(fs::exists(out / "scene.0001.obj"));
  EXPECT_TRUE(fs::exists(out / "scene.0001.mtl"));
  EXPECT_TRUE(fs::exists(out / "scene.stats.jsonl"));
}

TEST(BakeCli, MissingExemplarIsABadInputExit) {
  const fs::path meshes = demo_sequence("cli_bad_in", 1), out = fresh_dir("cli_bad_out");
  const std::string cmd = fmt::format("'{}' bake --mesh '{}' --exemplar /nonexistent/x.png --out '{}' --quiet 2>/dev/null",
                                      LAPFLOW_BINARY, (meshes / "m.%04d.ply").string(), out.string());
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
}

namespace {
/// Bakes every frame of a shared-data scene at a small atlas and checks the
/// coverage of every frame.
void expect_full_coverage_on_every_frame(const std::string& scene, double radius) {
  const fs::path data = fs::path(LAPFLOW_SOURCE_DIR) / ".." / "shared" / "data" / scene;
  LAPFLOW_NEED_SHARED((data / (scene + ".0001.ply")).string());
  const fs::path out = fresh_dir("every_frame_" + scene);
  BakeOptions o = small_bake(data, out);
  o.mesh_pattern = (data / (scene + ".%04d.ply")).string();
  o.patch.radius = radius;
  o.patch.remesh = false;  // keeps 170 frames affordable in the suite; remeshing is tested elsewhere
  const auto stats = run(o);
  ASSERT_GT(stats.size(), 50u);
  for (const FrameStats& s : stats) {
    const Image color = frame_image(out, "color", s.frame), aov = frame_image(out, "aov", s.frame);
    std::size_t chart = 0, without_patch = 0;
    for (int y = 0; y < color.height; ++y)
      for (int x = 0; x < color.width; ++x) {
        if (color.at(x, y, 3) != 1.f) continue;
        ++chart;
        without_patch += aov.at(x, y, 0) < 0.f;
      }
    // Every chart texel has alpha and names exactly one patch. Texels of tiny
    // droplet charts where hole filling fails are forced (a neighbour's or
    // the nearest patch, docs/raster.md): they must stay rare.
    EXPECT_EQ(without_patch, 0u) << "frame " << s.frame;
    EXPECT_EQ(chart, s.chart_texels) << "frame " << s.frame;
    EXPECT_EQ(s.coverage, 1.0) << "frame " << s.frame;
    EXPECT_LE(double(s.forced_texels), 0.001 * double(s.chart_texels)) << "frame " << s.frame;
    // Where hole filling decides, at the tracking resolution, too.
    EXPECT_LE(double(s.tracking.forced_texels), 0.001 * double(s.tracking.chart_texels)) << "frame " << s.frame;
  }
}
}  // namespace

TEST(BakeSharedData, DamBreakCoverageOnEveryFrame) {
  expect_full_coverage_on_every_frame("dam_break", 0.08);
}

TEST(BakeSharedData, ViscousDropSpreadingAtRestBreedsNoPatches) {
  // viscous_drop from frame 60: every vertex below 5 cm/s, yet the puddle
  // keeps spreading, and its rim uncovers a strip a texel or so wide each
  // frame. The patches around it close it while it is narrower than
  // --small-hole; it outgrows that rule within a few frames, after which
  // patches would pop in at the rim (docs/temporal.md, "At rest: the strip a
  // spreading rim uncovers"). --rest-hole lets the patches at rest that hold
  // its rim continue it: no birth, the same patches alive, every texel
  // covered.
  const fs::path data = fs::path(LAPFLOW_SOURCE_DIR) / ".." / "shared" / "data" / "viscous_drop";
  LAPFLOW_NEED_SHARED((data / "viscous_drop.0060.ply").string());
  BakeOptions o = small_bake(data, fresh_dir("rest_hole_default"));
  o.mesh_pattern = (data / "viscous_drop.%04d.ply").string();
  o.frames = FrameRange{60, 70};
  o.min_speed = 0.05;
  o.aov = false;
  const auto held = run(o);
  o.out_dir = fresh_dir("rest_hole_off").string();
  o.raster.rest_hole = 0;
  const auto off = run(o);
  ASSERT_EQ(held.size(), 11u);
  ASSERT_EQ(off.size(), 11u);
  std::size_t off_born = 0;
  for (std::size_t k = 1; k < held.size(); ++k) {
    EXPECT_EQ(held[k].patches_born, 0u) << "frame " << held[k].frame;
    EXPECT_EQ(held[k].patches_alive, held[0].patches_alive) << "frame " << held[k].frame;
    EXPECT_EQ(held[k].coverage, 1.0) << "frame " << held[k].frame;
    off_born += off[k].patches_born;
  }
  EXPECT_GT(off_born, 0u) << "without --rest-hole the spreading rim must breed patches, or this test shows nothing";
}

TEST(BakeSharedData, ViscousDropCoverageOnEveryFrame) {
  expect_full_coverage_on_every_frame("viscous_drop", 0.04);
}
