// Files written around the page cache (DirectFile): the same bytes as an
// ordinary write whatever the order of the writes, the exact size (no
// alignment padding left), failures reported with their errno, and EXRs and
// large text files byte-identical with direct writes on or off.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/direct_file.hpp"
#include "lapflow/io/image.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

std::string random_bytes(std::size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (char& c : s) c = char(rng() & 0xff);
  return s;
}

// Restores the process-wide switch however a test ends.
struct DirectIoSwitch {
  bool was = direct_io_enabled();
  ~DirectIoSwitch() { set_direct_io(was); }
};

}  // namespace

// Writes in the order OpenEXR makes them and worse: sequential blocks, a seek
// back into a block already on disk, a write past the end that leaves a gap,
// a last block that is not a multiple of the alignment.
TEST(DirectFile, AnyOrderOfWritesGivesTheBytesAndTheExactSize) {
  TempDir dir("direct");
  const std::size_t n = (std::size_t(9) << 20) + 12345;  // over two 4 MiB blocks
  const std::string data = random_bytes(n, 1), patch = random_bytes(5000, 2), tail = random_bytes(777, 3);
  for (const bool try_direct : {true, false}) {
    const std::string path = dir / (try_direct ? "direct.bin" : "cached.bin");
    std::string expected = data;
    {
      DirectFile f(path, try_direct);
      ASSERT_TRUE(f.ok()) << f.error();
      // In uneven pieces, as a stream writes them.
      for (std::size_t at = 0; at < n;) {
        const std::size_t k = std::min<std::size_t>(n - at, 100'000 + at % 7919);
        ASSERT_TRUE(f.write_at(data.data() + at, k, at));
        at += k;
      }
      // Back into the first block (on disk by now), across a block border.
      ASSERT_TRUE(f.write_at(patch.data(), patch.size(), 100));
      expected.replace(100, patch.size(), patch);
      const uint64_t border = uint64_t(4) << 20;
      ASSERT_TRUE(f.write_at(patch.data(), patch.size(), border - 2000));
      expected.replace(border - 2000, patch.size(), patch);
      // Past the end: the gap reads as zeros.
      ASSERT_TRUE(f.write_at(tail.data(), tail.size(), n + 3000));
      expected += std::string(3000, '\0') + tail;
      EXPECT_EQ(f.size(), expected.size());
      ASSERT_TRUE(f.close()) << f.error();
      EXPECT_TRUE(f.close()) << "close() again changes nothing";
    }
    EXPECT_EQ(fs::file_size(path), expected.size()) << path;
    EXPECT_TRUE(test::read_bytes(path) == expected) << path;
  }
}

TEST(DirectFile, AFailedWriteOrOpenGivesItsErrno) {
  TempDir dir("direct_fail");
  {
    DirectFile f(dir / "missing/x.bin");
    EXPECT_FALSE(f.ok());
    EXPECT_EQ(f.error(), ENOENT);
    EXPECT_FALSE(f.write_at("x", 1, 0));
    EXPECT_FALSE(f.close());
  }
  // /dev/full takes no byte: the first block written fails with ENOSPC, in
  // whichever mode it opened.
  if (::access("/dev/full", W_OK) == 0) {
    DirectFile f("/dev/full");
    const std::string data = random_bytes(std::size_t(5) << 20, 4);
    const bool wrote = f.write_at(data.data(), data.size(), 0);
    const bool closed = f.close();
    EXPECT_FALSE(wrote && closed);
    EXPECT_EQ(f.error(), ENOSPC);
  }
  // The same through write_text_atomically: the error names the file and
  // the reason, and nothing is left behind.
  EXPECT_THROW(
      {
        try {
          write_text_atomically(dir / "missing/state.bin", random_bytes(std::size_t(2) << 20, 5));
        } catch (const OutputError& e) {
          EXPECT_NE(std::string(e.what()).find(dir / "missing/state.bin"), std::string::npos) << e.what();
          EXPECT_NE(std::string(e.what()).find("No such file or directory"), std::string::npos) << e.what();
          throw;
        }
      },
      OutputError);
}

// A large EXR (incompressible noise over several 4 MiB blocks, so
// OpenEXR's seek back to its offset table lands in a block already written)
// and a large text file: the same bytes with direct writes on and off, and
// the pixels read back.
TEST(DirectFile, ExrsAndLargeFilesHaveTheSameBytesWithDirectWritesOnOrOff) {
  TempDir dir("direct_exr");
  DirectIoSwitch restore;
  Image img(1500, 1500, 4);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (float& v : img.pixels) v = u(rng);
  const std::string text = random_bytes((std::size_t(6) << 20) + 999, 8);
  for (const bool on : {true, false}) {
    set_direct_io(on);
    const std::string tag = on ? "on" : "off";
    write_exr(dir / ("c_" + tag + ".exr"), img, {"R", "G", "B", "A"});
    write_exr(dir / ("f_" + tag + ".exr"), img, {"R", "G", "B", "A"}, {ExrPixelType::Float, ExrCompression::Rle});
    write_text_atomically(dir / ("t_" + tag + ".bin"), text);
  }
  for (const char* kind : {"c", "f", "t"}) {
    const std::string a = test::read_bytes(dir / (std::string(kind) + "_on" + (kind[0] == 't' ? ".bin" : ".exr")));
    const std::string b = test::read_bytes(dir / (std::string(kind) + "_off" + (kind[0] == 't' ? ".bin" : ".exr")));
    EXPECT_GT(a.size(), std::size_t(6) << 20) << kind;
    EXPECT_TRUE(a == b) << kind << ": " << a.size() << " bytes against " << b.size();
  }
  EXPECT_TRUE(test::read_bytes(dir / "t_on.bin") == text);
  const Image back = read_image(dir / "f_on.exr", ColorSpace::Linear);
  ASSERT_EQ(back.pixels.size(), img.pixels.size());
  EXPECT_TRUE(back.pixels == img.pixels) << "float RLE is lossless";
  for (const std::string& name : test::names_in(dir.str())) EXPECT_NE(name[0], '.') << "temporary left: " << name;
}
