// `lapflow track` and `lapflow render` as processes: a scene file and options
// as for bake; a render of a frame without a state, of a folder without a
// manifest, or with another feature map is exit 2 naming the file.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/io/mesh_io.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

TEST(RenderCli, TrackThenRenderAndTheirErrors) {
  TempDir meshes("render_cli_in"), out("render_cli_out"), scratch("render_cli_scratch");
  DemoOptions demo;
  demo.voxel_size = 1.0 / 32;
  for (int f = 1; f <= 3; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", meshes.str(), f), demo_frame(demo, f));
  // A scene file, as bake takes it.
  const std::string scene = meshes / "shot.toml";
  test::write_bytes(scene, fmt::format("mesh = \"m.%04d.ply\"\nexemplar = \"{}/exemplars/pebbles.color.png\"\n"
                                       "resolution = 96\nradius = 0.05\nname = \"t\"\n",
                                       LAPFLOW_SOURCE_DIR));
  const std::string lapflow = LAPFLOW_BINARY;
  std::string err;
  ASSERT_EQ(test::run_command(fmt::format("'{}' track '{}' --out '{}' --until 2 --quiet", lapflow, scene, out.str()),
                              nullptr, &err, scratch),
            0)
      << err;
  EXPECT_TRUE(fs::exists(out / "t.state.0002.bin"));
  EXPECT_FALSE(fs::exists(out / "t.state.0003.bin"));
  EXPECT_FALSE(fs::exists(out / "t.0001.obj"));

  // Frame 3 has no state: frames 1-2 are rendered, then exit 2 naming it.
  EXPECT_EQ(test::run_command(fmt::format("'{}' render '{}' --frames 1-3 --quiet", lapflow, out.str()), nullptr, &err,
                              scratch),
            2);
  EXPECT_NE(err.find("t.state.0003.bin"), std::string::npos) << err;
  EXPECT_TRUE(fs::exists(out / "t.0002.obj"));
  EXPECT_FALSE(fs::exists(out / "t.0003.obj"));

  // Another feature map: exit 2 naming it; nothing of frame 1 is touched.
  const std::string before = test::read_bytes(out / "t.color.0001.exr");
  EXPECT_EQ(test::run_command(fmt::format("'{}' render '{}' --frames 1 --exemplar lava --quiet", lapflow, out.str()),
                              nullptr, &err, scratch),
            2);
  EXPECT_NE(err.find("lava.feature.png"), std::string::npos) << err;
  EXPECT_TRUE(test::read_bytes(out / "t.color.0001.exr") == before);

  // A folder with no manifest.
  EXPECT_EQ(test::run_command(fmt::format("'{}' render '{}' --quiet", lapflow, scratch.str()), nullptr, &err, scratch),
            2);
  EXPECT_NE(err.find(scratch.str()), std::string::npos) << err;
}

// A farm's tracking chunk starts (`lapflow track --resume`, which first
// removes the temporary files killed runs left) while the previous chunk's
// render jobs write into the same folder. It must leave a running render's
// temporary files alone: a track that removed them would make the render
// fail with "cannot move the finished file into place" (docs/bake.md,
// "When a frame is there").
TEST(RenderCli, ATrackStartingBesideARunningRenderLeavesItsFilesAlone) {
  TempDir meshes("render_race_in"), out("render_race_out"), scratch("render_race_scratch");
  DemoOptions demo;
  demo.voxel_size = 1.0 / 64;
  const int frames = 30;
  for (int f = 1; f <= frames; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", meshes.str(), f), demo_frame(demo, f));
  const std::string scene = meshes / "shot.toml";
  test::write_bytes(scene, fmt::format("mesh = \"m.%04d.ply\"\nexemplar = \"{}/exemplars/pebbles.color.png\"\n"
                                       "resolution = 256\nradius = 0.05\nname = \"t\"\naov = true\n",
                                       LAPFLOW_SOURCE_DIR));
  const std::string lapflow = LAPFLOW_BINARY;
  std::string out_text, err;
  ASSERT_EQ(test::run_command(fmt::format("'{}' track '{}' --out '{}' --threads 1 --quiet", lapflow, scene, out.str()),
                              nullptr, &err, scratch),
            0)
      << err;
  // The render in the background; track starts one after another while it runs.
  const std::string script = fmt::format(
      "'{0}' render '{2}' --threads 1 --quiet 2>'{3}' & r=$!\n"
      "n=0\n"
      "while kill -0 $r 2>/dev/null; do '{0}' track '{1}' --out '{2}' --resume --threads 1 --quiet || exit 9; "
      "n=$((n+1)); done\n"
      "wait $r; rc=$?\n"
      "echo \"$rc $n\"\n",
      lapflow, scene, out.str(), scratch / "render.err");
  test::write_bytes(scratch / "race.sh", script);
  ASSERT_EQ(test::run_command("bash '" + (scratch / "race.sh") + "'", &out_text, &err, scratch), 0) << err;
  int render_rc = -1, track_starts = 0;
  ASSERT_EQ(std::sscanf(out_text.c_str(), "%d %d", &render_rc, &track_starts), 2) << out_text;
  EXPECT_EQ(render_rc, 0) << test::read_bytes(scratch / "render.err");
  EXPECT_GE(track_starts, 1) << "the render ended before a track started beside it";
  for (int f = 1; f <= frames; ++f) {
    EXPECT_TRUE(fs::exists(out / fmt::format("t.{:04d}.obj", f))) << f;
    EXPECT_TRUE(fs::exists(out / fmt::format("t.aov.{:04d}.exr", f))) << f;
  }
  EXPECT_TRUE(test::temporaries_in(out.str()).empty());
}
