// Files that appear together (StagedFiles) and the removal of stale
// temporary files: nothing under a final name until commit, the commit file
// last, no temporary file left on any path.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <stdexcept>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/atomic_file.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

/// Names in `dir`, sorted.
using test::names_in;

std::size_t hidden_temporaries(const std::string& dir) {
  std::size_t n = 0;
  for (const std::string& name : names_in(dir)) n += name[0] == '.' && name.find(".tmp") != std::string::npos;
  return n;
}

}  // namespace

TEST(StagedFiles, NothingUnderAFinalNameBeforeCommitThenEverything) {
  TempDir dir("staged");
  test::write_bytes(dir / "f.0001.obj", "old obj");
  test::write_bytes(dir / "f.color.0001.exr", "old color");
  {
    StagedFiles staged;
    write_text_atomically(dir / "f.color.0001.exr", "new color", &staged);
    write_text_atomically(dir / "f.0001.mtl", "new mtl", &staged);
    write_text_atomically(dir / "f.0001.obj", "new obj", &staged);
    // Written, but only under hidden temporary names.
    EXPECT_EQ(hidden_temporaries(dir.str()), 3u);
    EXPECT_EQ(test::read_bytes(dir / "f.0001.obj"), "old obj");
    EXPECT_EQ(test::read_bytes(dir / "f.color.0001.exr"), "old color");
    EXPECT_FALSE(fs::exists(dir / "f.0001.mtl"));
    staged.commit(dir / "f.0001.obj");
  }
  EXPECT_EQ(names_in(dir.str()), (std::vector<std::string>{"f.0001.mtl", "f.0001.obj", "f.color.0001.exr"}));
  EXPECT_EQ(test::read_bytes(dir / "f.0001.obj"), "new obj");
  EXPECT_EQ(test::read_bytes(dir / "f.color.0001.exr"), "new color");
  EXPECT_EQ(test::read_bytes(dir / "f.0001.mtl"), "new mtl");
}

TEST(StagedFiles, AnAbandonedGroupLeavesNoFile) {
  TempDir dir("staged");
  {
    StagedFiles staged;
    write_text_atomically(dir / "g.0001.mtl", "mtl", &staged);
    write_text_atomically(dir / "g.0001.obj", "obj", &staged);
    EXPECT_EQ(hidden_temporaries(dir.str()), 2u);
  }  // a write error or a stop: no commit
  EXPECT_TRUE(names_in(dir.str()).empty());
}

TEST(StagedFiles, AFailedWriteRemovesItsTemporaryFile) {
  TempDir dir("staged");
  StagedFiles staged;
  EXPECT_THROW(staged.write(dir / "h.0001.obj",
                            [](const std::string& tmp) {
                              test::write_bytes(tmp, "half a file");
                              throw OutputError("h.0001.obj: write failed: No space left on device");
                            }),
               OutputError);
  EXPECT_TRUE(names_in(dir.str()).empty());
}

TEST(StagedFiles, AFailedCommitNeverLeavesAnOldCommitFileBesideNewFiles) {
  // f.color.0001.exr cannot be replaced (a non-empty folder has its name):
  // the old OBJ is gone, so the frame reads as absent, not as a mix of the
  // old OBJ and the new files; no temporary file stays.
  TempDir dir("staged");
  test::write_bytes(dir / "f.0001.obj", "old obj");
  fs::create_directories(dir / "f.color.0001.exr");
  test::write_bytes(dir / "f.color.0001.exr/x", "x");
  StagedFiles staged;
  write_text_atomically(dir / "f.0001.mtl", "new mtl", &staged);
  write_text_atomically(dir / "f.color.0001.exr", "new color", &staged);
  write_text_atomically(dir / "f.0001.obj", "new obj", &staged);
  try {
    staged.commit(dir / "f.0001.obj");
    FAIL() << "the commit must fail";
  } catch (const OutputError& e) {
    EXPECT_NE(std::string(e.what()).find(dir / "f.color.0001.exr"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir / "f.0001.obj"));
  EXPECT_EQ(hidden_temporaries(dir.str()), 0u);
}

TEST(StaleTemporaries, OnlyThisBakesTemporaryFilesAreRemoved) {
  TempDir dir("stale");
  const std::string& host = temporary_host_tag();
  const long gone = test::ended_process_id();
  const auto tmp = [&](const std::string& name, const std::string& ext) {
    return test::temporary_name(name, ext, host, gone, 7);
  };
  const std::vector<std::string> stale = {tmp("t.color.0002", ".exr"), tmp("t.disp.0002", ".exr"),
                                          tmp("t.0002", ".obj"),       tmp("t.0002", ".mtl"),
                                          tmp("t.stats", ".jsonl"),    tmp("t.bake", ".json"),
                                          tmp("t.patches.0002", ".ply"), tmp("t.aov.0013", ".exr"),
                                          tmp("t.state.0013", ".bin"), tmp("t.usd.0002", ".usda"),
                                          tmp("t", ".usda"), tmp("t.manifest", ".usda"),
                                          // OpenImageIO's texture maker's temporary beside ours (--texture tiled)
                                          tmp("t.color.0002", ".0a1b2c3d.temp.exr")};
  const std::vector<std::string> kept = {
      tmp("u.color.0002", ".exr"),  // another bake's
      tmp("tx.0002", ".obj"),       // another bake whose name starts with "t"
      tmp("t.notes", ".txt"),       // not a file a bake writes
      "t.color.0002.exr",           // a finished file
      ".t.color.0002.exr",          // hidden but not a temporary
      "t.0002" + tmp("", ".obj").substr(1)};  // not hidden
  for (const auto& n : stale) test::write_bytes(dir / n, "x");
  for (const auto& n : kept) test::write_bytes(dir / n, "x");
  std::vector<std::string> expected = stale;
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(remove_stale_temporaries(dir.str(), bake_file_stem_patterns("t")), expected);
  std::vector<std::string> left = kept;
  std::sort(left.begin(), left.end());
  EXPECT_EQ(names_in(dir.str()), left);
  // A name with regex characters is taken literally.
  test::write_bytes(dir / tmp("a+b.0001", ".obj"), "x");
  test::write_bytes(dir / tmp("aab.0001", ".obj"), "x");
  EXPECT_EQ(remove_stale_temporaries(dir.str(), bake_file_stem_patterns("a+b")),
            std::vector<std::string>{tmp("a+b.0001", ".obj")});
  EXPECT_TRUE(fs::exists(dir / tmp("aab.0001", ".obj")));
}

// A farm runs a tracking chunk and render jobs in one --out folder at once,
// each starting with remove_stale_temporaries(): the files a running process
// is writing stay. Another host's process cannot be asked: its files go only
// once old, as do those named before the host tag.
TEST(StaleTemporaries, ARunningProcesssFilesStayAnotherHostsGoWhenOld) {
  TempDir dir("stale_live");
  const std::string& host = temporary_host_tag();
  std::string other = host;
  other[0] = other[0] == '0' ? '1' : '0';
  const long running = long(::getppid());  // the test runner
  const std::string writing = test::temporary_name("t.aov.0003", ".exr", host, running, 4);
  const std::string mine = test::temporary_name("t.0003", ".obj", host, long(::getpid()), 5);
  const std::string elsewhere = test::temporary_name("t.color.0003", ".exr", other, test::ended_process_id(), 6);
  const std::string elsewhere_old = test::temporary_name("t.color.0002", ".exr", other, 77, 6);
  const std::string untagged = ".t.disp.0003.tmp4242_7.exr";
  const std::string untagged_old = ".t.disp.0002.tmp4242_7.exr";
  for (const std::string& n : {writing, mine, elsewhere, elsewhere_old, untagged, untagged_old})
    test::write_bytes(dir / n, "x");
  const auto two_hours_ago = fs::file_time_type::clock::now() - std::chrono::hours(2);
  fs::last_write_time(dir / elsewhere_old, two_hours_ago);
  fs::last_write_time(dir / untagged_old, two_hours_ago);
  std::vector<std::string> expected = {elsewhere_old, untagged_old};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(remove_stale_temporaries(dir.str(), bake_file_stem_patterns("t")), expected);
  std::vector<std::string> left = {writing, mine, elsewhere, untagged};
  std::sort(left.begin(), left.end());
  EXPECT_EQ(names_in(dir.str()), left);
}

// The name a write uses carries this host's tag and this process's id.
TEST(StaleTemporaries, AWritesTemporaryNameCarriesHostAndProcess) {
  TempDir dir("stale_name");
  std::string seen;
  write_atomically(dir / "t.0001.obj", [&](const std::string& tmp) {
    seen = fs::path(tmp).filename().string();
    test::write_bytes(tmp, "x");
  });
  const std::string prefix = ".t.0001.tmp" + temporary_host_tag() + "-" + std::to_string(::getpid()) + "_";
  EXPECT_EQ(seen.substr(0, prefix.size()), prefix) << seen;
  EXPECT_TRUE(seen.ends_with(".obj")) << seen;
  EXPECT_EQ(temporary_host_tag().size(), 8u);
}
