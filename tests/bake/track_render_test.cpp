// `lapflow track` + `lapflow render` (docs/farm.md): the patch dynamics are
// decided at the tracking resolution, so a bake's output is the same files
// as a track followed by renders, and two output resolutions show the same
// patches.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/atlas/atlas.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
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
    for (const std::string ext : {"obj", "mtl"}) {
      const std::string file = fmt::format("t.{:04d}.{}", f, ext);
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
  EXPECT_EQ(read_bake_manifest(other.str()).options.atlas.resolution, 64);

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
