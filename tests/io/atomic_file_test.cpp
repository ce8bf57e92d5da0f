// Files that appear together (StagedFiles) and the removal of stale
// temporary files: nothing under a final name until commit, the commit file
// last, no temporary file left on any path.
#include <gtest/gtest.h>

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
  const std::vector<std::string> stale = {".t.color.0002.tmp4242_7.exr", ".t.disp.0002.tmp4242_8.exr",
                                          ".t.0002.tmp4242_9.obj",       ".t.0002.tmp4242_10.mtl",
                                          ".t.stats.tmp4242_11.jsonl",   ".t.bake.tmp4242_0.json",
                                          ".t.patches.0002.tmp1_2.ply",  ".t.aov.0013.tmp77_3.exr"};
  const std::vector<std::string> kept = {
      ".u.color.0002.tmp4242_7.exr",  // another bake's
      ".tx.0002.tmp4242_9.obj",       // another bake whose name starts with "t"
      ".t.notes.tmp1_1.txt",          // not a file a bake writes
      "t.color.0002.exr",             // a finished file
      ".t.color.0002.exr",            // hidden but not a temporary
      "t.0002.tmp4242_9.obj"};        // not hidden
  for (const auto& n : stale) test::write_bytes(dir / n, "x");
  for (const auto& n : kept) test::write_bytes(dir / n, "x");
  std::vector<std::string> expected = stale;
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(remove_stale_temporaries(dir.str(), bake_file_stem_patterns("t")), expected);
  std::vector<std::string> left = kept;
  std::sort(left.begin(), left.end());
  EXPECT_EQ(names_in(dir.str()), left);
  // A name with regex characters is taken literally.
  test::write_bytes(dir / ".a+b.0001.tmp1_1.obj", "x");
  test::write_bytes(dir / ".aab.0001.tmp1_1.obj", "x");
  EXPECT_EQ(remove_stale_temporaries(dir.str(), bake_file_stem_patterns("a+b")),
            std::vector<std::string>{".a+b.0001.tmp1_1.obj"});
  EXPECT_TRUE(fs::exists(dir / ".aab.0001.tmp1_1.obj"));
}
