// `lapflow track` + `lapflow render` (docs/farm.md): the patch dynamics are
// decided at the tracking resolution, so a bake's output is the same files
// as a track followed by renders, and two output resolutions show the same
// patches.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <thread>
#include <variant>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/file_lock.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
using lapflow::test::input_error_of;
namespace fs = std::filesystem;

namespace {

constexpr int kFrames = 4;

BakeOptions small_bake(const std::string& meshes, const std::string& out, int resolution) {
  BakeOptions o = test::small_pebbles_bake(meshes, out);
  o.atlas.resolution = resolution;
  o.keep_states = -1;
  resolve_bake_options(o);
  return o;
}

class TrackRender : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    meshes_ = new TempDir("track_in");
    DemoOptions demo;
    demo.voxel_size = 1.0 / 40;
    for (int f = 1; f <= kFrames; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", meshes_->str(), f), demo_frame(demo, f));
  }
  static void TearDownTestSuite() {
    delete meshes_;
    meshes_ = nullptr;
  }
  static TempDir* meshes_;
};
TempDir* TrackRender::meshes_ = nullptr;

/// The patch id of the AOV at surface point (triangle t, barycentric b) of
/// `mesh`, and whether the 3x3 texels around it all name that patch (away
/// from patch borders, where a new sampling alone decides the side).
struct PointPatch {
  float id = -1;
  bool interior = false;
};
PointPatch patch_at(const Image& aov, const SurfaceAtlas& atlas, int t, const double b[3]) {
  Vec2 uv{};
  for (int k = 0; k < 3; ++k) uv = uv + atlas.corner_uv[std::size_t(3 * t + k)] * b[k];
  const int n = aov.width;
  const int x = std::clamp(int(uv.x * n), 0, n - 1), y = std::clamp(int((1 - uv.y) * n), 0, n - 1);
  const auto id = [&](int xx, int yy) { return aov.pixels[(std::size_t(yy) * n + xx) * 4]; };
  PointPatch p{id(x, y), x > 0 && y > 0 && x < n - 1 && y < n - 1};
  for (int dy = -1; dy <= 1 && p.interior; ++dy)
    for (int dx = -1; dx <= 1 && p.interior; ++dx) p.interior = id(x + dx, y + dy) == p.id;
  return p;
}

}  // namespace

// The one-process bake writes the very bytes of a track followed by a
// render of every frame, and the same patch states.
TEST_F(TrackRender, BakeIsTrackThenRender) {
  TempDir baked("track_bake"), tracked("track_track");
  bake(small_bake(meshes_->str(), baked.str(), 128));
  BakeOptions t = small_bake(meshes_->str(), tracked.str(), 128);
  t.track_only = true;
  bake(t);
  for (int f = 1; f <= kFrames; ++f) {
    EXPECT_FALSE(fs::exists(fmt::format("{}/t.{:04d}.obj", tracked.str(), f))) << "track writes no UV mesh";
    ASSERT_TRUE(fs::exists(fmt::format("{}/t.state.{:04d}.bin", tracked.str(), f)));
  }
  RenderOptions r;
  r.dir = tracked.str();
  std::vector<int> rendered;
  render(r, [&](const RenderedFrame& f) {
    EXPECT_FALSE(f.skipped);
    EXPECT_EQ(f.stats.coverage, 1.0);
    rendered.push_back(f.frame);
  });
  EXPECT_EQ(rendered, (std::vector<int>{1, 2, 3, 4}));
  for (int f = 1; f <= kFrames; ++f) {
    for (const std::string kind : {"color", "disp", "aov"}) {
      const std::string file = fmt::format("t.{}.{:04d}.exr", kind, f);
      EXPECT_TRUE(test::read_bytes(baked / file) == test::read_bytes(tracked / file)) << file;
    }
    for (const std::string& file : {fmt::format("t.{:04d}.obj", f), fmt::format("t.{:04d}.mtl", f),
                                   fmt::format("t.render.{:04d}.json", f)}) {
      EXPECT_TRUE(test::read_bytes(baked / file) == test::read_bytes(tracked / file)) << file;
    }
    const std::string state = fmt::format("t.state.{:04d}.bin", f);
    test::expect_same_patches(read_bake_state(baked / state).patches, read_bake_state(tracked / state).patches);
  }
  // A re-submitted render skips what is there; without --skip-done it
  // renders again, to the same bytes.
  r.skip_done = true;
  std::size_t skipped = 0;
  render(r, [&](const RenderedFrame& f) { skipped += f.skipped; });
  EXPECT_EQ(skipped, std::size_t(kFrames));
}

// A 128^2 and a 256^2 bake of the same shot carry the same patches, and at
// fixed surface points away from patch borders their atlases name the same
// patch.
TEST_F(TrackRender, TheOutputResolutionDoesNotChangeThePatches) {
  TempDir coarse("track_128"), fine("track_256");
  bake(small_bake(meshes_->str(), coarse.str(), 128));
  bake(small_bake(meshes_->str(), fine.str(), 256));
  for (int f = 1; f <= kFrames; ++f) {
    const std::string state = fmt::format("t.state.{:04d}.bin", f);
    test::expect_same_patches(read_bake_state(coarse / state).patches, read_bake_state(fine / state).patches);
  }
  // Fixed points: three per triangle of the last frame.
  const TriMesh mesh = read_mesh(fmt::format("{}/m.{:04d}.ply", meshes_->str(), kFrames));
  AtlasOptions a128, a256;
  a128.resolution = 128;
  a256.resolution = 256;
  const SurfaceAtlas atlas128 = build_surface_atlas(mesh, a128), atlas256 = build_surface_atlas(mesh, a256);
  const Image aov128 = read_image(fmt::format("{}/t.aov.{:04d}.exr", coarse.str(), kFrames));
  const Image aov256 = read_image(fmt::format("{}/t.aov.{:04d}.exr", fine.str(), kFrames));
  const double points[3][3] = {{0.6, 0.2, 0.2}, {0.2, 0.6, 0.2}, {0.2, 0.2, 0.6}};
  std::size_t compared = 0, same = 0;
  for (int t = 0; t < int(mesh.triangle_count()); ++t)
    for (const auto& b : points) {
      const PointPatch p = patch_at(aov128, atlas128, t, b), q = patch_at(aov256, atlas256, t, b);
      if (!p.interior || !q.interior) continue;
      ++compared;
      same += p.id == q.id;
    }
  ASSERT_GT(compared, 1000u);
  EXPECT_GE(double(same), 0.99 * double(compared)) << same << " of " << compared << " points name the same patch";
}

// A render needs the frame's state and the tracked feature map; another
// colour over the same feature map renders, at another resolution too.
TEST_F(TrackRender, RenderChecksItsInputs) {
  TempDir tracked("track_checks"), other("track_other");
  BakeOptions t = small_bake(meshes_->str(), tracked.str(), 128);
  t.track_only = true;
  t.until_frame = 2;
  bake(t);
  EXPECT_TRUE(fs::exists(tracked / "t.state.0002.bin"));
  EXPECT_FALSE(fs::exists(tracked / "t.state.0003.bin")) << "--until stops after its frame";

  RenderOptions r;
  r.dir = tracked.str();
  r.out_dir = other.str();
  r.frames = FrameRange{1, 3};
  std::vector<int> rendered;
  const std::string missing = input_error_of([&] { render(r, [&](const RenderedFrame& f) { rendered.push_back(f.frame); }); });
  EXPECT_NE(missing.find("t.state.0003.bin"), std::string::npos) << missing;
  EXPECT_EQ(rendered, (std::vector<int>{1, 2})) << "the frames with a state are rendered first";

  const std::string ex = std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/";
  r.frames = FrameRange{2, 2};
  r.resolution = 64;
  r.exemplar_color = ex + "lava.color.png";
  r.exemplar_feature = ex + "pebbles.feature.png";
  r.exemplar_displacement = ex + "lava.disp.png";
  EXPECT_EQ(input_error_of([&] { render(r); }), "") << "another colour over the tracked feature map renders";
  EXPECT_EQ(read_image_header(other / "t.color.0002.exr").width, 64);
  EXPECT_EQ(read_render_record(other / "t.render.0002.json").options.at("resolution"), "64");
  EXPECT_EQ(read_bake_manifest(other.str()).options.atlas.resolution, 128)
      << "the folder's manifest, of this tracking, is not rewritten: each frame's record says what it is";

  r.exemplar_feature = ex + "lava.feature.png";
  const std::string feature = input_error_of([&] { render(r); });
  EXPECT_NE(feature.find("lava.feature.png"), std::string::npos) << feature;
  EXPECT_NE(feature.find("feature map"), std::string::npos) << feature;

  // The rest of the tracking, resumed: the states are those of one run.
  t.until_frame.reset();
  t.resume = true;
  bake(t);
  TempDir whole("track_whole");
  BakeOptions w = small_bake(meshes_->str(), whole.str(), 256);  // another output resolution: same states
  w.track_only = true;
  bake(w);
  for (int f = 1; f <= kFrames; ++f) {
    const std::string state = fmt::format("t.state.{:04d}.bin", f);
    test::expect_same_patches(read_bake_state(tracked / state).patches, read_bake_state(whole / state).patches);
  }
}

namespace {

/// Frame `f`'s colour atlas width in `dir` (bake "t").
int color_width(const TempDir& dir, int f) {
  return read_image_header(dir / fmt::format("t.color.{:04d}.exr", f)).width;
}

}  // namespace

// A tracked folder rendered at two resolutions: --skip-done trusts each
// frame's record, not the manifest, renders again (saying why) what was made
// otherwise or is not whole, and never rewrites the tracked manifest.
TEST_F(TrackRender, SkipDoneTrustsEachFramesRecordNotTheManifest) {
  TempDir tracked("track_records");
  BakeOptions t = small_bake(meshes_->str(), tracked.str(), 128);
  t.track_only = true;
  bake(t);
  const std::string manifest = test::read_bytes(tracked / "t.bake.json");
  RenderOptions r;
  r.dir = tracked.str();
  render(r);
  r.frames = FrameRange{2, 2};
  r.resolution = 256;
  render(r);
  EXPECT_EQ(color_width(tracked, 1), 128);
  EXPECT_EQ(color_width(tracked, 2), 256);

  r.frames.reset();
  r.skip_done = true;
  std::vector<int> skipped, again;
  std::map<int, std::string> reasons;
  render(r, [&](const RenderedFrame& f) {
    (f.skipped ? skipped : again).push_back(f.frame);
    reasons[f.frame] = f.reason;
  });
  EXPECT_EQ(skipped, (std::vector<int>{2}));
  EXPECT_EQ(again, (std::vector<int>{1, 3, 4}));
  for (int f : {1, 3, 4}) {
    EXPECT_EQ(reasons[f], "made with other options: resolution: 128 on disk, 256 asked") << f;
    EXPECT_EQ(color_width(tracked, f), 256) << f;
  }
  EXPECT_EQ(test::read_bytes(tracked / "t.bake.json"), manifest) << "the tracking's manifest is never rewritten";
  EXPECT_EQ(read_render_record(tracked / "t.render.0003.json").options.at("resolution"), "256");

  // With --no-rerender, a frame made otherwise is an error naming its record; nothing is rewritten.
  r.resolution = 128;
  r.refuse_other_options = true;
  const std::string refused = input_error_of([&] { render(r); });
  EXPECT_NE(refused.find("t.render.0001.json: frame 1 is already there, made with other options: resolution: 256 on "
                         "disk, 128 asked (--no-rerender) (and 3 more frames refused)"),
            std::string::npos)
      << refused;
  for (int f = 1; f <= kFrames; ++f) EXPECT_EQ(color_width(tracked, f), 256) << f;

  // A file cut short: that frame alone is rendered again.
  const std::string color3 = tracked / "t.color.0003.exr";
  const std::string bytes = test::read_bytes(color3);
  test::write_bytes(color3, bytes.substr(0, bytes.size() / 2));
  r.resolution = 256;
  r.refuse_other_options = false;
  skipped.clear(), again.clear(), reasons.clear();
  render(r, [&](const RenderedFrame& f) {
    (f.skipped ? skipped : again).push_back(f.frame);
    reasons[f.frame] = f.reason;
  });
  EXPECT_EQ(again, (std::vector<int>{3}));
  EXPECT_EQ(reasons[3], fmt::format("t.color.0003.exr has {} bytes, {} recorded", bytes.size() / 2, bytes.size()));
  EXPECT_TRUE(test::read_bytes(color3) == bytes) << "the same options give the same bytes";
}

// Each frame is written under its lock: a render of the same options waits
// for the frame another holds (and does it last), one of other options is
// refused naming the lock, and a lock file its owner left behind is no lock.
TEST_F(TrackRender, FramesAreWrittenUnderTheirLocks) {
  TempDir tracked("track_locks");
  BakeOptions t = small_bake(meshes_->str(), tracked.str(), 128);
  t.track_only = true;
  bake(t);
  RenderOptions r;
  r.dir = tracked.str();
  r.frames = FrameRange{2, 2};
  render(r);
  const std::string purpose = render_lock_purpose(read_render_record(tracked / "t.render.0002.json"));
  const std::string lock2 = tracked / ".t.0002.lock";

  // Another render of the same options holds frame 2 for a while.
  r.frames = FrameRange{1, 3};
  std::vector<int> order;
  {
    auto held = FileLock::try_take(lock2, purpose);
    ASSERT_TRUE(std::holds_alternative<FileLock>(held));
    // It lets go once this render has written frame 3 (or after a minute,
    // should this render wait for it at once: then the order is wrong).
    std::atomic<bool> third_written = false, released = false;
    std::thread other([&] {
      for (int i = 0; i < 6000 && !third_written; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      released = true;
      std::get<FileLock>(held).release();
    });
    render(r, [&](const RenderedFrame& f) {
      order.push_back(f.frame);
      if (f.frame == 3) third_written = true;
      if (f.frame == 2) {
        EXPECT_TRUE(released) << "frame 2 waited for its lock";
      }
    });
    other.join();
  }
  EXPECT_EQ(order, (std::vector<int>{1, 3, 2}));
  EXPECT_FALSE(fs::exists(lock2)) << "a lock goes with its frame's files";

  // A process with other options holds frame 2: refused, naming the lock and its owner.
  {
    auto held = FileLock::try_take(lock2, "render 0badf00d, resolution 64");
    ASSERT_TRUE(std::holds_alternative<FileLock>(held));
    order.clear();
    const std::string refused = input_error_of([&] { render(r, [&](const RenderedFrame& f) { order.push_back(f.frame); }); });
    EXPECT_NE(refused.find(lock2 + ": frame 2 is being written by pid " + std::to_string(::getpid())), std::string::npos)
        << refused;
    EXPECT_NE(refused.find("(render 0badf00d, resolution 64), with other options"), std::string::npos) << refused;
    EXPECT_EQ(order, (std::vector<int>{1, 3})) << "the other frames are rendered";
  }

  // A lock file whose owner died (no process holds it): taken over.
  test::write_bytes(lock2, "{\"pid\": 4194305, \"host\": \"gone\", \"purpose\": \"render 0badf00d\"}\n");
  order.clear();
  render(r, [&](const RenderedFrame& f) { order.push_back(f.frame); });
  EXPECT_EQ(order, (std::vector<int>{1, 2, 3}));
  EXPECT_FALSE(fs::exists(lock2));
}

// A render clears the temporary files killed runs left in its folder (not a
// running process's), and refuses a frame whose mesh changed since it was
// tracked unless told otherwise; a manifest edited into options that do not
// hold is an input error naming it.
TEST_F(TrackRender, RenderClearsStaleTemporariesAndRefusesAChangedMesh) {
  TempDir meshes("track_changed_in"), tracked("track_changed");
  for (int f = 1; f <= 3; ++f) {
    const std::string name = fmt::format("m.{:04d}.ply", f);
    test::write_bytes(meshes / name, test::read_bytes(*meshes_ / name));
  }
  BakeOptions t = small_bake(meshes.str(), tracked.str(), 64);
  t.track_only = true;
  t.frames = FrameRange{1, 3};
  bake(t);
  const std::string dead = tracked / fmt::format(".t.color.0001.tmp{}-4194305_0.exr", temporary_host_tag());
  const std::string live = tracked / fmt::format(".t.color.0001.tmp{}-{}_9.exr", temporary_host_tag(), ::getpid());
  test::write_bytes(dead, "half a file");
  test::write_bytes(live, "being written");
  test::write_bytes(meshes / "m.0003.ply", test::read_bytes(*meshes_ / "m.0002.ply"));
  RenderOptions r;
  r.dir = tracked.str();
  std::vector<int> rendered;
  const std::string changed = input_error_of([&] { render(r, [&](const RenderedFrame& f) { rendered.push_back(f.frame); }); });
  EXPECT_FALSE(fs::exists(dead)) << "a dead process's temporary file is removed";
  EXPECT_TRUE(fs::exists(live)) << "a running process's is not";
  EXPECT_NE(changed.find(meshes / "m.0003.ply" + " (frame 3): changed since frame 3 was tracked"), std::string::npos)
      << changed;
  EXPECT_NE(changed.find("--allow-changed-input"), std::string::npos) << changed;
  EXPECT_EQ(rendered, (std::vector<int>{1, 2}));
  EXPECT_FALSE(fs::exists(tracked / "t.0003.obj"));
  r.allow_changed_input = true;
  EXPECT_EQ(input_error_of([&] { render(r); }), "");
  EXPECT_TRUE(fs::exists(tracked / "t.0003.obj"));

  // A tracking option edited in the manifest (a radius the options cannot keep).
  std::string text = test::read_bytes(tracked / "t.bake.json");
  const std::size_t at = text.find("\"radius\": ");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find(',', at) - at, "\"radius\": 0.0");
  test::write_bytes(tracked / "t.bake.json", text);
  const std::string edited = input_error_of([&] { render(r); });
  EXPECT_NE(edited.find(tracked / "t.bake.json: its tracking options do not hold as written (radius"), std::string::npos)
      << edited;
}
