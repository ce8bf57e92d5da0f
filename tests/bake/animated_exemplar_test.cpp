// Animated exemplars (docs/layers.md, "Animated exemplars"): an image
// sequence plays on every patch from its birth with a phase of its own, at
// --exemplar-fps, looping, ping-ponging or holding; a texel shows exactly
// the exemplar frame its patch's birth and phase give.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <string>
#include <unordered_map>

#include "io_test_helpers.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/layers.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

constexpr int kFrames = 5;
constexpr int kSize = 32;

/// Frame k (0-based) of the test sequence: one colour over the whole image.
Vec3 frame_colour(int k) { return {0.1 + 0.15 * k, 0.5, 0.9 - 0.1 * k}; }

/// boil.color.0001.exr ... and a feature map for each frame, in `dir`.
void write_sequence(const fs::path& dir, int frames, int size = kSize) {
  fs::create_directories(dir);
  const ExrOptions exact{ExrPixelType::Float};
  for (int k = 0; k < frames; ++k) {
    Image color(size, size, 3), feature(size, size, 1);
    const Vec3 c = frame_colour(k);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x) {
        color.at(x, y, 0) = float(c.x), color.at(x, y, 1) = float(c.y), color.at(x, y, 2) = float(c.z);
        // A ramp that moves with the frame: the erosion reads each frame's own.
        feature.at(x, y, 0) = float(((x + 3 * k) % size) / double(size));
      }
    write_exr((dir / fmt::format("boil.color.{:04d}.exr", k + 1)).string(), color, {"R", "G", "B"}, exact);
    write_exr((dir / fmt::format("boil.feature.{:04d}.exr", k + 1)).string(), feature, {"Y"}, exact);
  }
}

/// The InputError load_exemplar_frames throws for the `boil` frames in
/// `dir` (feature maps beside them), or "" when it loads.
std::string load_error(const std::string& dir) {
  try {
    load_exemplar_frames(dir + "/boil.color.%04d.exr", dir + "/boil.feature.%04d.exr");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

Patch patch_born(int frame, uint32_t id) {
  Patch p;
  p.birth_frame = frame;
  p.id = id;
  return p;
}

}  // namespace

TEST(ExemplarClock, LoopPlaysOneFrameABakeFrameFromTheBirthPhase) {
  ExemplarClock clock;
  clock.seed = 7;
  const Patch p = patch_born(3, 42);
  clock.frame = 3;
  const int first = clock.frame_of(p, kFrames);
  ASSERT_GE(first, 0);
  ASSERT_LT(first, kFrames);
  for (int f = 3; f < 20; ++f) {
    clock.frame = f;
    EXPECT_EQ(clock.frame_of(p, kFrames), (first + f - 3) % kFrames) << "frame " << f;
  }
}

TEST(ExemplarClock, AHalfRateAdvancesEveryOtherFrame) {
  ExemplarClock clock;
  clock.rate = 0.5;
  const Patch p = patch_born(1, 5);
  std::vector<int> shown;
  for (int f = 1; f <= 21; ++f) {
    clock.frame = f;
    shown.push_back(clock.frame_of(p, kFrames));
  }
  int changes = 0;
  for (std::size_t i = 1; i < shown.size(); ++i) {
    if (shown[i] == shown[i - 1]) continue;
    ++changes;
    EXPECT_EQ(shown[i], (shown[i - 1] + 1) % kFrames);
  }
  EXPECT_EQ(changes, 10);
}

TEST(ExemplarClock, PingPongTurnsAtBothEnds) {
  ExemplarClock clock;
  clock.loop = ExemplarLoop::PingPong;
  const Patch p = patch_born(0, 9);
  std::vector<int> shown;
  for (int f = 0; f < 24; ++f) {
    clock.frame = f;
    shown.push_back(clock.frame_of(p, 4));
  }
  // 0 1 2 3 2 1 0 1 ... from the phase: each step is +-1, and turns only at 0 and 3.
  for (std::size_t i = 1; i < shown.size(); ++i) {
    ASSERT_EQ(std::abs(shown[i] - shown[i - 1]), 1) << "frame " << i;
    if (i >= 2 && shown[i] == shown[i - 2]) {
      EXPECT_TRUE(shown[i - 1] == 0 || shown[i - 1] == 3) << "frame " << i;
    }
  }
  EXPECT_EQ(*std::min_element(shown.begin(), shown.end()), 0);
  EXPECT_EQ(*std::max_element(shown.begin(), shown.end()), 3);
}

TEST(ExemplarClock, HoldStartsAtTheFirstFrameAndStaysOnTheLast) {
  ExemplarClock clock;
  clock.loop = ExemplarLoop::Hold;
  for (uint32_t id : {1u, 2u, 3u}) {
    const Patch p = patch_born(10, id);
    for (int f = 10; f < 30; ++f) {
      clock.frame = f;
      EXPECT_EQ(clock.frame_of(p, kFrames), std::min(f - 10, kFrames - 1));
    }
  }
}

TEST(ExemplarClock, NeighboursBornTogetherDoNotPulseInStepAndTheSeedDecides) {
  ExemplarClock a, b;
  a.seed = 1, b.seed = 2;
  std::set<int> shown;
  int same_as_other_seed = 0;
  for (uint32_t id = 0; id < 64; ++id) {
    const Patch p = patch_born(1, id);
    shown.insert(a.frame_of(p, 8));
    EXPECT_EQ(a.frame_of(p, 8), a.frame_of(p, 8));
    same_as_other_seed += a.frame_of(p, 8) == b.frame_of(p, 8);
  }
  EXPECT_EQ(shown.size(), 8u) << "64 patches born on one frame cover all 8 phases";
  EXPECT_LT(same_as_other_seed, 24) << "another seed gives other phases";
  const Patch still = patch_born(1, 3);
  EXPECT_EQ(a.frame_of(still, 1), 0);
}

TEST(AnimatedExemplar, ATexelShowsExactlyTheFrameItsPatchsBirthAndPhaseGive) {
  TempDir tmp("animated_texel");
  const fs::path dir(tmp.str());
  fs::create_directories(dir / "in");
  write_sequence(dir / "boil", kFrames);
  test::write_heat_plane((dir / "in").string(), 8, [](double x, int) { return x; });
  BakeOptions o = default_bake_options();
  o.mesh_pattern = (dir / "in").string() + "/m.%04d.ply";
  o.out_dir = (dir / "out").string();
  o.name = "t";
  o.patch.radius = 0.08;
  o.atlas.resolution = 192;
  o.aov = true;
  o.usd = false;
  o.exr.type = ExrPixelType::Float;
  o.exemplar_color = (dir / "boil").string() + "/boil.color.%04d.exr";
  o.exemplar_feature = (dir / "boil").string() + "/boil.feature.%04d.exr";
  o.fps = 24;
  o.exemplar_fps = 12;  // a new exemplar frame every other bake frame
  resolve_bake_options(o);
  const BakeExemplars exemplars = load_bake_exemplars(o);
  ASSERT_EQ(exemplars.raster.size(), 1u);
  ASSERT_EQ(exemplars.raster[0].frame_count(), std::size_t(kFrames));
  EXPECT_NE(exemplars.feature_digest().find("/5"), std::string::npos) << exemplars.feature_digest();

  const FrameSource source = frame_source(o);
  PatchSet patches;
  std::shared_ptr<Frame> prev;
  std::set<int> frames_seen;
  std::set<int> births;
  for (int f = 1; f <= 8; ++f) {
    SCOPED_TRACE(fmt::format("bake frame {}", f));
    std::shared_ptr<Frame> cur = load_frame(source, f);
    build_frame_atlases(*cur, o);
    track_frame(*cur, prev.get(), patches, exemplars.layers(), o);
    render_frame(*cur, patches, exemplars.layers(), o);
    std::unordered_map<uint32_t, const Patch*> by_id;
    for (const Patch& p : patches.patches) by_id[p.id] = &p;
    ExemplarClock clock = o.raster.clock;
    clock.frame = f;
    const Image& aov = cur->textures.aov;
    const Image& color = cur->textures.color;
    ASSERT_EQ(aov.channels, 4);
    const TexelMap& tm = cur->atlas.texels;
    std::size_t checked = 0;
    for (std::size_t i = 0; i < tm.size(); ++i) {
      const std::size_t pix = tm.texel[i];
      const float id = aov.pixels[pix * 4];
      if (id < 0) continue;
      const auto at = by_id.find(uint32_t(id));
      ASSERT_NE(at, by_id.end()) << "texel " << pix << ": patch " << id;
      const int k = clock.frame_of(*at->second, kFrames);
      frames_seen.insert(k);
      births.insert(at->second->birth_frame);
      const Vec3 want = frame_colour(k);
      const float* got = &color.pixels[pix * color.channels];
      // The frames differ by 0.1 or more in red and blue: a texel of another
      // frame, or a mix of two, is off by far more than the float rounding
      // of the mip filter's weights (1e-6).
      ASSERT_NEAR(got[0], want.x, 1e-6) << "texel " << pix << ", patch " << id << ", exemplar frame " << k;
      ASSERT_NEAR(got[1], want.y, 1e-6) << "texel " << pix;
      ASSERT_NEAR(got[2], want.z, 1e-6) << "texel " << pix;
      ++checked;
    }
    EXPECT_GT(checked, tm.size() * 9 / 10);
    prev = cur;
  }
  EXPECT_EQ(frames_seen.size(), std::size_t(kFrames)) << "the phases spread the patches over the sequence";
  EXPECT_GT(births.size(), 1u) << "patches born on later frames are checked too";
}

TEST(AnimatedExemplar, AGapOrAFrameOfAnotherSizeIsAnErrorNamingTheFile) {
  TempDir tmp("animated_bad");
  const fs::path dir(tmp.str());
  write_sequence(dir / "gap", 4);
  fs::remove(dir / "gap" / "boil.color.0003.exr");
  const std::string gap = load_error((dir / "gap").string());
  EXPECT_NE(gap.find("boil.color.0003.exr"), std::string::npos) << "a gap in the sequence: " << gap;
  write_sequence(dir / "sizes", 3);
  write_sequence(dir / "big", 1, kSize * 2);
  fs::copy_file(dir / "big" / "boil.color.0001.exr", dir / "sizes" / "boil.color.0002.exr",
                fs::copy_options::overwrite_existing);
  const std::string size = load_error((dir / "sizes").string());
  EXPECT_NE(size.find("boil.color.0002.exr"), std::string::npos) << "a frame of another size: " << size;
  EXPECT_NE(size.find("64x64"), std::string::npos) << size;
  fs::remove(dir / "sizes" / "boil.feature.0003.exr");
  fs::copy_file(dir / "gap" / "boil.color.0001.exr", dir / "sizes" / "boil.color.0002.exr",
                fs::copy_options::overwrite_existing);
  const std::string feature = load_error((dir / "sizes").string());
  EXPECT_NE(feature.find("boil.feature.0003.exr"), std::string::npos) << "a feature frame missing: " << feature;
}

TEST(AnimatedExemplar, AStillFeatureMapServesEveryFrame) {
  TempDir tmp("animated_still_feature");
  const fs::path dir(tmp.str());
  write_sequence(dir / "s", 3);
  const std::string s = (dir / "s").string();
  const std::vector<Exemplar> frames = load_exemplar_frames(s + "/boil.color.%04d.exr", s + "/boil.feature.0001.exr");
  ASSERT_EQ(frames.size(), 3u);
  for (const Exemplar& f : frames) EXPECT_EQ(f.feature.pixels, frames[0].feature.pixels);
  EXPECT_EQ(frames[2].color.at(0, 0, 0), float(frame_colour(2).x));
}
