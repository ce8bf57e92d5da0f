// Bounded resources, decided up front (issue 14 item 3): inputs and options
// whose memory would not fit are refused with exit 2 and one line naming the
// file or option, before anything large is allocated. The CLI runs under a
// `ulimit -v` of 3 GB: a refused input that allocated anyway would end in
// "out of memory" (exit 1) or a crash instead.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <cstdint>
#include <string>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/bake/budget.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"

using namespace lapflow;
using lapflow::test::TempDir;

namespace {

uint32_t crc32(const std::string& bytes) {
  uint32_t c = 0xffffffffu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return ~c;
}

void put_be32(std::string& s, uint32_t v) {
  for (int k = 3; k >= 0; --k) s += char((v >> (8 * k)) & 0xff);
}

std::string png_chunk(const std::string& type, const std::string& data) {
  std::string s;
  put_be32(s, uint32_t(data.size()));
  s += type + data;
  put_be32(s, crc32(type + data));
  return s;
}

/// A PNG of a few dozen bytes whose header claims width x height RGB pixels.
std::string huge_png(uint32_t width, uint32_t height) {
  std::string ihdr;
  put_be32(ihdr, width);
  put_be32(ihdr, height);
  ihdr += std::string("\x08\x02\x00\x00\x00", 5);  // 8 bit, RGB, deflate, no filter, no interlace
  // A valid zlib stream of a few zero bytes: far too little data for the size.
  const std::string idat("\x78\x9c\x63\x60\x00\x00\x00\x02\x00\x01", 10);
  return std::string("\x89PNG\r\n\x1a\n", 8) + png_chunk("IHDR", ihdr) + png_chunk("IDAT", idat) +
         png_chunk("IEND", "");
}

/// An ASCII PLY: a tetrahedron of edge `size` m with vertex 1 at x = `far`.
std::string tetra_ply(double size, double far = 0) {
  return fmt::format(
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n{} 0 0\n0 {} 0\n0 0 {}\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
      far != 0 ? far : size, size, size);
}

struct CliRun {
  int code = -1;
  std::string err;
  std::vector<std::string> new_files;  ///< files under the run's folder that it created
};

std::set<std::string> files_under(const TempDir& dir) {
  std::set<std::string> files;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir.str()))
    if (e.is_regular_file() && e.path().filename().string().rfind("cmd.", 0) != 0)  // not run_command's own
      files.insert(e.path().string());
  return files;
}

#ifdef LAPFLOW_SANITIZED
// AddressSanitizer reserves terabytes of address space for its shadow memory
// when the program starts: under ulimit -v it cannot start at all. Its
// allocator refuses any one allocation over 3 GB instead (bad_alloc, so
// "out of memory" as the ulimit would give).
constexpr const char* kAddressLimit =
    "export ASAN_OPTIONS=\"${ASAN_OPTIONS:-}:max_allocation_size_mb=3000:allocator_may_return_null=1\"; ";
#else
constexpr const char* kAddressLimit = "ulimit -v 3000000; ";
#endif

/// Runs `lapflow ARGS` with at most 3 GB of address space and 2 threads.
CliRun run_limited(const std::string& args, const TempDir& dir) {
  CliRun r;
  const std::set<std::string> before = files_under(dir);
  r.code = test::run_command(fmt::format("{}cd '{}' && '{}' {} --threads 2", kAddressLimit, dir.str(),
                                         LAPFLOW_BINARY, args),
                             nullptr, &r.err, dir);
  for (const std::string& f : files_under(dir))
    if (!before.count(f)) r.new_files.push_back(f);
  return r;
}

/// Exit 2, one error line containing every part, nothing that says memory
/// ran out.
void expect_refused(const CliRun& r, std::initializer_list<std::string> parts) {
  EXPECT_EQ(r.code, 2) << r.err;
  const auto line = r.err.find("error: ");
  ASSERT_NE(line, std::string::npos) << r.err;
  const std::string msg = r.err.substr(line, r.err.find('\n', line) - line);
  for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
  EXPECT_EQ(r.err.find("out of memory"), std::string::npos) << r.err;
  EXPECT_LT(msg.size(), 400u) << msg;
  // Refused from the headers and the first frame, before anything is
  // written (the address-space limit above stands for "no decoding").
  EXPECT_TRUE(r.new_files.empty()) << (r.new_files.empty() ? "" : r.new_files.front());
}

const std::string kPebbles = std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/pebbles";

}  // namespace

TEST(Budget, ParsesMemorySizes) {
  EXPECT_EQ(parse_memory_size("16G"), std::size_t(16) << 30);
  EXPECT_EQ(parse_memory_size("500M"), std::size_t(500) << 20);
  EXPECT_EQ(parse_memory_size("1.5GiB"), std::size_t(3) << 29);
  EXPECT_EQ(parse_memory_size("64kb"), std::size_t(64) << 10);
  EXPECT_EQ(parse_memory_size("123456"), 123456u);
  for (const char* bad : {"", "G", "10X", "0", "-5G", "1e30T", "nan"}) {
    try {
      parse_memory_size(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const UsageError& e) {
      EXPECT_NE(std::string(e.what()).find("--max-memory"), std::string::npos) << e.what();
    }
  }
  EXPECT_GT(default_memory_budget(), 0u);
  if (physical_memory() > 0) {
    EXPECT_LT(default_memory_budget(), physical_memory());
  }
}

TEST(Budget, ReadImageChecksTheHeaderBeforeDecoding) {
  TempDir dir("budget");
  const std::string png = dir / "huge.png";
  test::write_bytes(png, huge_png(100000, 100000));
  const ImageHeader h = read_image_header(png);
  EXPECT_EQ(h.width, 100000);
  EXPECT_EQ(h.height, 100000);
  EXPECT_EQ(h.channels, 3);
  // 1.2e11 bytes of float pixels: over any budget given, refused by name.
  try {
    read_image(png, ColorSpace::Auto, std::size_t(1) << 30);
    ADD_FAILURE() << "decoded a 100000x100000 header";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), png);
    EXPECT_NE(std::string(e.what()).find("100000x100000"), std::string::npos) << e.what();
  }
}

TEST(Budget, HugeImageHeadersAreRefusedNamingTheFile) {
  TempDir dir("budget");
  const std::string png = dir / "huge.png";
  test::write_bytes(png, huge_png(100000, 100000));
  ASSERT_LT(test::read_bytes(png).size(), 100u);
  test::write_bytes(dir / "m.0001.ply", tetra_ply(1.0));
  const std::string bake =
      fmt::format("bake --mesh m.%04d.ply --allow-zero-velocity --out out --resolution 256 --exemplar {}.color.png ",
                  kPebbles);
  expect_refused(run_limited("feature-map huge.png -o f.png", dir), {"huge.png", "100000x100000", "--max-memory"});
  expect_refused(run_limited(fmt::format("bake --mesh m.%04d.ply --allow-zero-velocity --out out --exemplar huge.png "
                                         "--feature {}.feature.png",
                                         kPebbles),
                             dir),
                 {"huge.png", "100000x100000"});
  expect_refused(run_limited(bake + "--feature huge.png", dir), {"huge.png", "100000x100000"});
  expect_refused(run_limited(bake + fmt::format("--feature {}.feature.png --displacement huge.png", kPebbles), dir),
                 {"huge.png", "100000x100000"});
  EXPECT_FALSE(std::filesystem::exists(dir / "out/m.0001.obj"));
}

TEST(Budget, AbsurdMeshBoundsAreAnInputErrorInTheBakeAndAWarningInInspect) {
  TempDir dir("budget");
  test::write_bytes(dir / "far.0001.ply", tetra_ply(1.0, 3e38));
  test::write_bytes(dir / "neg.0001.ply", tetra_ply(1.0, -5.8e24));
  for (const std::string name : {"far.0001.ply", "neg.0001.ply"}) {
    try {
      read_mesh(dir / name);
      ADD_FAILURE() << name << " accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), dir / name);
      EXPECT_NE(std::string(e.what()).find("are the units metres?"), std::string::npos) << e.what();
    }
  }
  // 100 km is odd for a liquid but legal.
  test::write_bytes(dir / "big.0001.ply", tetra_ply(1e5));
  EXPECT_EQ(read_mesh(dir / "big.0001.ply").triangle_count(), 4u);

  // inspect reports them (units_test.cpp has the rest); the bake refuses
  // them even with --units-ok.
  for (const std::string name : {"far", "neg"}) {
    const CliRun r = run_limited("inspect " + name + ".%04d.ply", dir);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("warning: " + name + ".0001.ply (frame 1): mesh bounds "), std::string::npos) << r.err;
  }
  expect_refused(run_limited("bake --mesh far.%04d.ply --allow-zero-velocity --exemplar pebbles --out out", dir),
                 {"far.0001.ply", "are the units metres?"});
  expect_refused(run_limited("bake --mesh neg.%04d.ply --allow-zero-velocity --exemplar pebbles --out out --units-ok",
                             dir),
                 {"neg.0001.ply", "mesh bounds 5.8e+24 m: are the units metres?"});
}

TEST(Budget, TinyRadiusIsRefusedWithThePatchCount) {
  TempDir dir("budget");
  test::write_bytes(dir / "m.0001.ply", tetra_ply(1.0));
  // Area 1.5 + sqrt(3)/2 = 2.37 m²: 7.5e11 patches of radius 1e-6.
  const CliRun r = run_limited("bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out "
                            "--radius 1e-6",
                            dir);
  expect_refused(r, {"--radius 1e-06 m on 2.37 m² of surface", "m.0001.ply", "7.5e+11 patches"});
  // Fewer patches that still do not fit 100 MB: the memory message, naming the radius.
  expect_refused(run_limited("bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out "
                             "--radius 0.005 --resolution 256 --max-memory 100M",
                             dir),
                 {"--max-memory 100 MiB", "--radius 0.005 m", "patches"});
  // Patches of 5.7e8 vertices each.
  expect_refused(run_limited("bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out "
                             "--remesh-edge 1e-4 --resolution 256",
                             dir),
                 {"patches of 5.67e+08 vertices", "--remesh-edge 0.0001"});
  expect_refused(run_limited("bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out "
                             "--spacing 1e-5 --resolution 256",
                             dir),
                 {"--spacing", "patches"});
  expect_refused(run_limited("bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out --spacing 0", dir),
                 {"--spacing must be positive"});
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
  // lapflow patches seeds with the same radius: the same refusal.
  expect_refused(run_limited("patches --mesh m.%04d.ply --allow-zero-velocity --out out --radius 1e-6", dir),
                 {"--radius 1e-06 m on 2.37 m² of surface", "7.5e+11 patches"});
}

TEST(Budget, ResolutionsOverTheBudgetAreRefusedBeforeAllocating) {
  TempDir dir("budget");
  test::write_bytes(dir / "m.0001.ply", tetra_ply(1.0));
  const std::string bake = "bake --mesh m.%04d.ply --allow-zero-velocity --exemplar pebbles --out out ";
  expect_refused(run_limited(bake + "--resolution 8192 --max-memory 100M", dir),
                 {"--resolution 8192", "--max-memory 100 MiB"});
  expect_refused(run_limited(bake + "--resolution 32768 --max-memory 16G", dir), {"--resolution 32768"});
  expect_refused(run_limited("atlas m.0001.ply --out a.obj --resolution 65536 --max-memory 16G", dir),
                 {"--resolution 65536", "m.0001.ply", "--max-memory 16 GiB"});
  EXPECT_FALSE(std::filesystem::exists(dir / "a.obj"));
  // A bad size is a usage error naming the option.
  expect_refused(run_limited(bake + "--max-memory 12Q", dir), {"--max-memory 12Q"});
  // The same bake within its budget runs (and the budget is what the estimate says).
  const CliRun ok = run_limited(bake + "--resolution 128 --max-memory 2G --quiet", dir);
  EXPECT_EQ(ok.code, 0) << ok.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "out/m.0001.obj"));
}

TEST(Budget, TheBudgetIsTheEstimate) {
  // resolve_bake_options refuses exactly what its estimate says does not fit.
  TempDir dir("budget");
  test::write_bytes(dir / "m.0001.ply", tetra_ply(1.0));
  BakeOptions o = test::small_pebbles_bake(dir.str(), dir / "out");
  o.allow_zero_velocity = true;
  o.patch.radius = 0.05;
  BakeOptions probe = o;
  const BakeMemoryEstimate e = resolve_bake_options(probe);
  EXPECT_NEAR(e.covering_patches, 2.366 / (3.14159265 * 0.05 * 0.05), 2.0);
  EXPECT_GT(e.total, e.atlas + e.patch_bytes + e.state);
  // The state file: at least the held cells (2 KiB) of every patch provisioned.
  EXPECT_GE(e.state, e.patches * 2048);
  // Four times the texels: four times the atlas buffers.
  BakeOptions twice = o;
  twice.atlas.resolution = 512;
  EXPECT_NEAR(resolve_bake_options(twice).atlas, 4 * e.atlas, 1.0);
  // Half the radius: four times the patches.
  BakeOptions half = o;
  half.patch.radius = 0.025;
  EXPECT_NEAR(resolve_bake_options(half).patches, 4 * e.patches, 1e-6 * e.patches);

  BakeOptions fits = o;
  fits.max_memory = std::size_t(e.total) + 1;
  EXPECT_NO_THROW(resolve_bake_options(fits));
  BakeOptions over = o;
  over.max_memory = std::size_t(e.total) - 1;
  EXPECT_THROW(resolve_bake_options(over), UsageError);
}
