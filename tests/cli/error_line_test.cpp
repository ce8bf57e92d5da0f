// Every error the CLI prints is one printable line of at most about 300
// characters (issue 14 item 5), whatever the input put in the message: raw
// bytes, a 5 MB token, a library's own chatter (libpng's "libpng error:").
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <string>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;

namespace {

struct CliResult {
  int code = -1;
  std::string err;
};

CliResult run(const TempDir& dir, const std::string& args) {
  CliResult r;
  r.code = test::run_command(fmt::format("cd '{}' && '{}' {}", dir.str(), LAPFLOW_BINARY, args), nullptr, &r.err,
                             dir);
  return r;
}

/// stderr is exactly one line "error: ...", printable ASCII or UTF-8, at
/// most kMaxMessageChars after "error: ", holding every one of `parts`.
void expect_one_error_line(const CliResult& r, std::initializer_list<std::string> parts) {
  EXPECT_EQ(r.code, 2) << r.err.substr(0, 2000);
  ASSERT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err.substr(0, 2000);
  ASSERT_EQ(r.err.rfind("error: ", 0), 0u) << r.err.substr(0, 2000);
  const std::string message = r.err.substr(7, r.err.size() - 8);
  EXPECT_LE(message.size(), kMaxMessageChars) << message.substr(0, 2000);
  for (unsigned char c : message) EXPECT_TRUE(c >= 0x20 && c != 0x7f) << "byte " << int(c) << " in: " << message;
  for (const std::string& p : parts) EXPECT_NE(message.find(p), std::string::npos) << "'" << p << "' not in: " << message;
}

/// A sphere in metres with velocities, as dir/m.0001.ply.
void write_mesh(const TempDir& dir) {
  TriMesh m = test::icosphere(2, 0.3);
  m.velocities.assign(m.positions.size(), Vec3{0, 0, 0.5});
  write_ply(dir / "m.0001.ply", m);
}

const std::string kPebbles = std::string(LAPFLOW_SOURCE_DIR) + "/exemplars/pebbles";

}  // namespace

TEST(ErrorLine, RawBytesFromAPlyHeaderAreEscapedAndCut) {
  TempDir dir("error_line");
  // An element named by 1 MB of raw bytes (no blank, so it is one word),
  // whose data is missing: the truncation message names the element.
  std::string name;
  for (int i = 0; name.size() < (1u << 20); ++i) {
    const char c = char(i % 256);
    if (c != ' ' && c != '\t' && c != '\n' && c != '\r' && c != '\f' && c != '\v') name += c;
  }
  test::write_bytes(dir / "raw.0001.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                          "property float z\nelement " + name + " 5\nproperty float a\nend_header\n"
                                          "0 0 0\n");
  const CliResult r = run(dir, "inspect raw.%04d.ply --quiet");
  expect_one_error_line(r, {"raw.0001.ply (frame 1): file truncated: data ends in '\\x00\\x01\\x02",
                            "...' (1048576 characters) 0 of 5"});
}

TEST(ErrorLine, A5MbNumberInAnObjIsOneShortLine) {
  TempDir dir("error_line");
  test::write_bytes(dir / "m.0001.obj", "v 0 0 0\nv " + std::string(5'000'000, '7') + " 0 0\nv 0 1 0\nf 1 2 3\n");
  expect_one_error_line(run(dir, "inspect m.%04d.obj --quiet"),
                        {"m.0001.obj (frame 1): line 2: malformed vertex 1", "(5000000 characters)"});
}

TEST(ErrorLine, AnOptionValueOfRawBytesIsOneShortLine) {
  // CLI11 echoes the value in full and adds a second line of its own.
  TempDir dir("error_line");
  write_mesh(dir);
  const CliResult r = run(dir, "bake --mesh m.%04d.ply --exemplar pebbles --out out --fps "
                         "\"$(head -c 100000 /dev/zero | tr '\\0' '9')$(printf '\\001\\377')\"");
  expect_one_error_line(r, {"--fps", "(--help lists the options)"});
}

TEST(ErrorLine, ACorruptPngIsOneLineWithoutLibpngsOwn) {
  // libpng prints "libpng error: ..." on stderr itself before OIIO's error
  // comes back; lapflow's line must be the only one.
  TempDir dir("error_line");
  write_mesh(dir);
  const std::string png = test::read_bytes(kPebbles + ".color.png");
  test::write_bytes(dir / "truncated.png", png.substr(0, 3000));  // the header reads, the pixels do not
  std::string garbage = png.substr(0, 40);  // the signature and part of IHDR, then junk
  for (int i = 0; i < 3000; ++i) garbage += char((i * 7919) % 251);
  test::write_bytes(dir / "garbage.png", garbage);
  for (const std::string file : {"truncated.png", "garbage.png"}) {
    SCOPED_TRACE(file);
    const CliResult baked = run(dir, fmt::format("bake --mesh m.%04d.ply --exemplar {} --feature {}.feature.png --out out "
                                          "--resolution 128 --quiet",
                                          file, kPebbles));
    expect_one_error_line(baked, {file + ": cannot read image: ", "PNG read error"});
    EXPECT_EQ(baked.err.find("libpng error"), std::string::npos) << baked.err;
    const CliResult map = run(dir, fmt::format("feature-map {} -o map.png --quiet", file));
    expect_one_error_line(map, {file + ": cannot read image: "});
    EXPECT_EQ(map.err.find("libpng error"), std::string::npos) << map.err;
  }
}

TEST(Cli, ABareLapflowListsEachCommandOnceAndExits0) {
  TempDir dir("bare");
  std::string out, err;
  const int code = test::run_command(fmt::format("cd '{}' && '{}'", dir.str(), LAPFLOW_BINARY), &out, &err, dir);
  EXPECT_EQ(code, 0) << err;
  EXPECT_TRUE(err.empty()) << err;
  for (const char* command : {"demo", "inspect", "atlas", "patches", "bake", "track", "render", "eval", "preview",
                              "feature-map", "farm"}) {
    const std::string line = fmt::format("\n  {:<12} ", command);
    const std::size_t at = out.find(line);
    ASSERT_NE(at, std::string::npos) << command << " not listed in:\n" << out;
    EXPECT_EQ(out.find(line, at + 1), std::string::npos) << command << " listed twice";
    const std::size_t end = out.find('\n', at + 1);
    EXPECT_GT(end - at - line.size(), 10u) << command << " has no description";
    EXPECT_LE(end - at, 120u) << "not one short line: " << out.substr(at + 1, end - at - 1);
  }
}

// A studio path of 300 characters: the line loses the middle of the path,
// not the reason at its end; a name too long for the file system says so.
TEST(ErrorLine, ALongPathKeepsTheReasonAtTheEnd) {
  TempDir dir("error_line");
  std::string folder = dir.str();
  for (int i = 0; folder.size() < 300; ++i) folder += fmt::format("/sequence_{:02d}", i);
  const CliResult missing = run(dir, "render '" + folder + "/shot'");
  expect_one_error_line(missing, {"/...", "/shot: cannot open the bake manifest: No such file or directory"});
  EXPECT_TRUE(missing.err.ends_with("/shot: cannot open the bake manifest: No such file or directory\n"))
      << missing.err;
  const CliResult too_long = run(dir, "render " + std::string(300, 'a'));
  expect_one_error_line(too_long, {"aaa: cannot open the bake manifest: File name too long"});
}
