// Checkpoints and --resume: NAME.state.N.bin holds every bit the next frame
// reads; a bake stopped after any frame and resumed writes the same bytes in
// every file as an uninterrupted one; a damaged state or other options are
// an InputError (exit 2) naming the file.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include <zlib.h>

#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/io/mesh_io.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
using lapflow::test::input_error_of;
namespace fs = std::filesystem;

namespace {

constexpr int kFrames = 5;

BakeOptions small_bake(const std::string& meshes, const std::string& out) {
  BakeOptions o = test::small_pebbles_bake(meshes, out);
  o.atlas.resolution = 128;
  o.dump_patches = true;  // every kind of frame file
  o.keep_states = -1;     // every state, to compare them all
  resolve_bake_options(o);
  return o;
}

using test::names_in;
using test::stats_without_timings;

/// Every file of `a` is in `b` with the same bytes, and `b` has no other;
/// NAME.stats.jsonl the same but for timings and memory.
void expect_same_files(const std::string& a, const std::string& b) {
  const std::vector<std::string> files = names_in(a);
  ASSERT_EQ(files, names_in(b));
  for (const std::string& f : files) {
    if (f == "t.stats.jsonl") {
      EXPECT_EQ(stats_without_timings(fs::path(a) / f), stats_without_timings(fs::path(b) / f));
      continue;
    }
    EXPECT_TRUE(test::read_bytes(fs::path(a) / f) == test::read_bytes(fs::path(b) / f))
        << f << " differs from an uninterrupted bake's";
  }
}

/// Bakes until frame `k` is written, then stops as a SIGTERM would. Returns
/// the last complete frame: k, or k + 1 with background writes (frame k is
/// reported once k + 1 is computed, and a stop finishes the frame in flight).
int bake_until(const BakeOptions& o, int k) {
  try {
    bake(o, [&](const FrameStats& s) {
      if (s.frame == k) request_stop(SIGTERM);
    });
  } catch (const Interrupted& e) {
    request_stop(0);
    EXPECT_EQ(e.last_complete_frame().value_or(-1), o.background_write ? k + 1 : k);
    return e.last_complete_frame().value_or(-1);
  }
  request_stop(0);
  ADD_FAILURE() << "the bake must stop after frame " << k;
  return -1;
}

/// The frames a bake computes and writes.
std::vector<int> bake_frames(const BakeOptions& o) {
  std::vector<int> written;
  bake(o, [&](const FrameStats& s) { written.push_back(s.frame); });
  return written;
}

std::vector<int> frames_from(int first) {
  std::vector<int> f;
  for (int i = first; i <= kFrames; ++i) f.push_back(i);
  return f;
}

class BakeResume : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    meshes_ = new TempDir("resume_in");
    ref_ = new TempDir("resume_ref");
    DemoOptions demo;
    demo.voxel_size = 1.0 / 40;
    for (int f = 1; f <= kFrames; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", meshes_->str(), f), demo_frame(demo, f));
    bake(small_bake(meshes_->str(), ref_->str()));
  }
  static void TearDownTestSuite() {
    delete meshes_;
    delete ref_;
    meshes_ = ref_ = nullptr;
  }
  static TempDir* meshes_;
  static TempDir* ref_;
};
TempDir* BakeResume::meshes_ = nullptr;
TempDir* BakeResume::ref_ = nullptr;

}  // namespace

// The state file gives back every field of every patch bit for bit (NaN,
// infinities, -0, held bits, at_rest), next_id, and the header.
TEST(BakeState, RoundTripsEveryFieldBitForBit) {
  TempDir dir("state_round_trip");
  PatchSet set;
  set.next_id = 4242;
  for (uint32_t k = 0; k < 3; ++k) {
    Patch& p = set.patches.emplace_back();
    p.id = 7 * k + 1;
    p.birth_frame = -3 + int(k);
    p.center = {0.1 * k, -0.0, 1e-300};
    p.center_normal = {0, std::numeric_limits<double>::infinity(), 1};
    p.center_uv = {0.5, std::nextafter(0.5, 1.0)};
    p.at_rest = k == 1;
    if (k == 2) continue;  // a patch with nothing: no triangle, no held bit
    p.positions = {{1, 2, 3}, {4, 5, 6}, {7, 8, std::numeric_limits<double>::quiet_NaN()}};
    p.rest_uv = {{0, 0}, {1, 0}, {0, 1}};
    p.surface_triangle = {-1, 5, 123456};
    p.quality = {0.25f, 1.0f, 0.0f};
    p.border = {0, 1, 1};
    p.weight = {0.0f, std::numeric_limits<float>::denorm_min(), 1.0f};
    p.triangles = {Tri{0, 1, 2}};
    p.triangle_quality = {0.75f};
    p.triangle_delta = {std::numeric_limits<float>::infinity()};
    if (k == 0) {
      p.held.assign(kHeldWords, 0);
      p.held[3] = 0x8000000000000001ull;
      p.held.back() = ~0ull;
    }
  }
  BakeStateHeader header;
  header.name = "t";
  header.frame = 12;
  header.options_checksum = 0xdeadbeef;
  header.stats_line = R"({"frame":12,"patches":{"alive":3}})";
  const std::string bytes = encode_bake_state(header, set);
  write_bake_state(dir / "t.state.0012.bin", bytes);
  const BakeState back = read_bake_state(dir / "t.state.0012.bin");
  EXPECT_EQ(back.header.name, "t");
  EXPECT_EQ(back.header.frame, 12);
  EXPECT_EQ(back.header.options_checksum, 0xdeadbeefu);
  EXPECT_EQ(nlohmann::json::parse(back.header.stats_line), nlohmann::json::parse(header.stats_line));
  EXPECT_EQ(back.patches.next_id, 4242u);
  ASSERT_EQ(back.patches.patches.size(), 3u);
  // An empty vector's data() may be null, which memcmp must not get
  // (UndefinedBehaviorSanitizer's finding: `held` is empty for patches 1-2).
  const auto same_bits = [](const auto& a, const auto& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0);
  };
  for (std::size_t k = 0; k < 3; ++k) {
    const Patch &p = set.patches[k], &q = back.patches.patches[k];
    EXPECT_EQ(q.id, p.id);
    EXPECT_EQ(q.birth_frame, p.birth_frame);
    EXPECT_EQ(std::memcmp(&q.center, &p.center, sizeof p.center), 0);
    EXPECT_EQ(std::memcmp(&q.center_normal, &p.center_normal, sizeof p.center_normal), 0);
    EXPECT_EQ(std::memcmp(&q.center_uv, &p.center_uv, sizeof p.center_uv), 0);
    EXPECT_EQ(q.at_rest, p.at_rest);
    EXPECT_TRUE(same_bits(q.positions, p.positions)) << k;
    EXPECT_TRUE(same_bits(q.rest_uv, p.rest_uv)) << k;
    EXPECT_TRUE(same_bits(q.surface_triangle, p.surface_triangle)) << k;
    EXPECT_TRUE(same_bits(q.quality, p.quality)) << k;
    EXPECT_TRUE(same_bits(q.border, p.border)) << k;
    EXPECT_TRUE(same_bits(q.weight, p.weight)) << k;
    EXPECT_TRUE(same_bits(q.triangles, p.triangles)) << k;
    EXPECT_TRUE(same_bits(q.triangle_quality, p.triangle_quality)) << k;
    EXPECT_TRUE(same_bits(q.triangle_delta, p.triangle_delta)) << k;
    EXPECT_TRUE(same_bits(q.held, p.held)) << k;
  }
  EXPECT_EQ(encode_bake_state(back.header, back.patches), bytes);  // and back to the same bytes
}

// Every byte of the file counts: truncated anywhere, or one bit changed
// anywhere, it is an InputError naming the file.
TEST(BakeState, HeaderNumbersOutOfRangeAreAnErrorBehindAValidChecksum) {
  // A header rewritten with a matching CRC (as a tool that edits the file
  // would leave it): a frame of 1e30 or 2.5, or counts that are not whole
  // numbers, are an InputError naming the file, never an out-of-range
  // conversion (found by tests/fuzz/fuzz_state.cpp).
  PatchSet set;
  BakeStateHeader header;
  header.name = "t";
  header.frame = 3;
  const std::string bytes = encode_bake_state(header, set);
  const std::size_t newline = bytes.find('\n');
  ASSERT_NE(newline, std::string::npos);
  const std::string head = bytes.substr(0, newline), rest = bytes.substr(newline, bytes.size() - newline - 4);
  for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
           {"\"frame\":3", "\"frame\":1e30"}, {"\"frame\":3", "\"frame\":2.5"},
           {"\"patches\":0", "\"patches\":-1"}, {"\"next_id\":0", "\"next_id\":\"x\""}}) {
    std::string edited = head;
    const std::size_t at = edited.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    edited.replace(at, from.size(), to);
    edited += rest;
    const uint32_t crc = uint32_t(crc32(0, reinterpret_cast<const Bytef*>(edited.data()), uInt(edited.size())));
    edited.append(reinterpret_cast<const char*>(&crc), sizeof crc);
    EXPECT_NE(input_error_of([&] { parse_bake_state(edited, "t.state.0003.bin"); }).find("t.state.0003.bin"),
              std::string::npos)
        << to;
  }
}

TEST(BakeState, ADamagedFileIsAnErrorNamingIt) {
  TempDir dir("state_damaged");
  PatchSet set;
  set.next_id = 2;
  Patch& p = set.patches.emplace_back();
  p.positions = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  p.rest_uv.resize(3);
  p.surface_triangle = {0, 0, 0};
  p.quality = p.weight = {1, 1, 1};
  p.border = {1, 1, 1};
  p.triangles = {Tri{0, 1, 2}};
  p.triangle_quality = p.triangle_delta = {1};
  BakeStateHeader header;
  header.name = "t";
  header.frame = 3;
  const std::string bytes = encode_bake_state(header, set);
  const std::string path = dir / "t.state.0003.bin";
  for (std::size_t at = 0; at < bytes.size(); at += 7) {
    test::write_bytes(path, bytes.substr(0, at));
    EXPECT_NE(input_error_of([&] { read_bake_state(path); }).find(path), std::string::npos) << "truncated at " << at;
    std::string flipped = bytes;
    flipped[at] = char(flipped[at] ^ 0x10);
    test::write_bytes(path, flipped);
    EXPECT_NE(input_error_of([&] { read_bake_state(path); }).find(path), std::string::npos) << "flipped at " << at;
  }
  test::write_bytes(path, bytes);
  EXPECT_EQ(read_bake_state(path).patches.patches.size(), 1u);
  EXPECT_NE(input_error_of([&] { read_bake_state(dir / "t.state.0004.bin"); }).find("t.state.0004.bin"),
            std::string::npos);  // missing
}

// Stopped after frame 1, 2 or 4 and resumed, in the foreground or with the
// files written in the background: the resumed bake computes only the
// frames after, and every file (EXRs, OBJs, MTLs, patch dumps, AOVs, every
// state, the manifest) has an uninterrupted bake's bytes; the stats lines
// differ only in timings.
TEST_F(BakeResume, StoppedAfterAnyFrameAndResumedGivesTheSameBytes) {
  for (const int k : {1, 2, 4}) {
    for (const bool background : {false, true}) {
      if (background && k != 2) continue;
      SCOPED_TRACE(fmt::format("stopped after frame {}{}", k, background ? ", background writes" : ""));
      TempDir out("resume_out");
      BakeOptions o = small_bake(meshes_->str(), out.str());
      o.background_write = background;
      const int last = bake_until(o, k);
      EXPECT_TRUE(fs::exists(out / fmt::format("t.state.{:04d}.bin", last)));
      o.resume = true;
      EXPECT_EQ(bake_frames(o), frames_from(last + 1));
      expect_same_files(ref_->str(), out.str());
    }
  }
}

// A kill between a frame's files and its stats line (the line is written
// after the OBJ): the resumed bake puts the line back from the state.
TEST_F(BakeResume, AMissingStatsLineComesBackFromTheState) {
  TempDir out("resume_stats");
  BakeOptions o = small_bake(meshes_->str(), out.str());
  bake_until(o, 3);
  const std::string stats = test::read_bytes(out / "t.stats.jsonl");
  std::string two_lines = stats.substr(0, stats.find('\n', stats.find('\n') + 1) + 1);
  test::write_bytes(out / "t.stats.jsonl", two_lines);
  o.resume = true;
  EXPECT_EQ(bake_frames(o), frames_from(4));
  expect_same_files(ref_->str(), out.str());
}

// By default only the last two states stay; none with keep_states 0, and
// then --resume has nothing to continue from and bakes every frame.
TEST_F(BakeResume, KeepsTheLastStatesOnly) {
  TempDir out("resume_keep");
  BakeOptions o = small_bake(meshes_->str(), out.str());
  o.keep_states = 2;
  bake_until(o, 3);
  EXPECT_FALSE(fs::exists(out / "t.state.0001.bin"));
  EXPECT_TRUE(fs::exists(out / "t.state.0002.bin"));
  EXPECT_TRUE(fs::exists(out / "t.state.0003.bin"));
  o.resume = true;
  EXPECT_EQ(bake_frames(o), frames_from(4));
  for (int f = 1; f <= kFrames; ++f)
    EXPECT_EQ(fs::exists(out / fmt::format("t.state.{:04d}.bin", f)), f >= 4) << f;
  for (int f = 4; f <= kFrames; ++f) {
    const std::string state = fmt::format("t.state.{:04d}.bin", f);
    EXPECT_TRUE(test::read_bytes(out / state) == test::read_bytes(*ref_ / state)) << state;
  }

  TempDir none("resume_none");
  BakeOptions n = small_bake(meshes_->str(), none.str());
  n.keep_states = 0;
  bake_until(n, 2);
  for (const std::string& f : names_in(none.str())) EXPECT_EQ(f.find(".state."), std::string::npos) << f;
  n.resume = true;
  EXPECT_EQ(bake_frames(n), frames_from(1));
}

// Without resume a bake starts over, and first removes the states of the
// earlier run; resume on an empty folder bakes every frame; resume of a
// finished bake has nothing left to do.
TEST_F(BakeResume, WithoutResumeABakeStartsOver) {
  TempDir out("resume_plain");
  BakeOptions o = small_bake(meshes_->str(), out.str());
  bake_until(o, 2);
  o.keep_states = 2;
  EXPECT_EQ(bake_frames(o), frames_from(1));
  EXPECT_FALSE(fs::exists(out / "t.state.0002.bin"));
  EXPECT_TRUE(fs::exists(out / "t.state.0005.bin"));
  o.resume = true;
  EXPECT_EQ(bake_frames(o), std::vector<int>{});

  TempDir empty("resume_empty");
  BakeOptions e = small_bake(meshes_->str(), empty.str());
  e.resume = true;
  EXPECT_EQ(bake_frames(e), frames_from(1));
  expect_same_files(ref_->str(), empty.str());
}

// Other options than the manifest's: an InputError naming NAME.bake.json
// and each option that differs, and no frame is written. A damaged last
// state: an InputError naming it.
TEST_F(BakeResume, OtherOptionsOrADamagedStateAreErrorsNamingTheFile) {
  TempDir out("resume_bad");
  BakeOptions o = small_bake(meshes_->str(), out.str());
  bake_until(o, 2);
  const std::string obj3 = out / "t.0003.obj";

  BakeOptions other = o;
  other.resume = true;
  other.seed = 99;
  other.patch.seed = 99;
  other.atlas.gutter = 3;
  std::string error = input_error_of([&] { bake(other); });
  EXPECT_NE(error.find(out / "t.bake.json"), std::string::npos) << error;
  EXPECT_NE(error.find("seed: 1 in the manifest, 99 now"), std::string::npos) << error;
  EXPECT_NE(error.find("settings/gutter: \"4\" in the manifest, \"3\" now"), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(obj3));

  const std::string state = out / "t.state.0002.bin";
  const std::string good = test::read_bytes(state);
  o.resume = true;
  test::write_bytes(state, good.substr(0, good.size() / 2));
  error = input_error_of([&] { bake(o); });
  EXPECT_NE(error.find(state), std::string::npos) << error;
  std::string flipped = good;
  flipped[flipped.size() * 2 / 3] = char(flipped[flipped.size() * 2 / 3] ^ 1);
  test::write_bytes(state, flipped);
  error = input_error_of([&] { bake(o); });
  EXPECT_NE(error.find(state), std::string::npos) << error;
  EXPECT_NE(error.find("checksum"), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(obj3));

  // Put back, it resumes to the uninterrupted bytes.
  test::write_bytes(state, good);
  EXPECT_EQ(bake_frames(o), frames_from(3));
  expect_same_files(ref_->str(), out.str());
}
