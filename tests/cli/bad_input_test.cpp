// Every malformed input gets one InputError naming the file, the element and
// what is wrong; legal oddities (an empty frame) are not errors.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/velocity.hpp"

using namespace lapflow;
using lapflow::test::TempDir;

namespace {

/// Runs `f`, expects an InputError for `file` whose message contains every
/// one of `parts`; returns the message.
std::string expect_input_error(const std::function<void()>& f, const std::string& file,
                               std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), file) << what;
    EXPECT_NE(what.find(file), std::string::npos) << what;
    for (const std::string& p : parts) EXPECT_NE(what.find(p), std::string::npos) << "'" << p << "' not in: " << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << "one line: " << what;
    return what;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected InputError for " << file << ", nothing thrown";
  return "";
}

/// A binary LE PLY in the layout of ../shared/data with `nv` declared
/// vertices, of which the data holds `nv_data`, and the given faces.
std::string tetra_ply(long declared_vertices, long declared_faces, const std::vector<Vec3>& pos,
                      const std::vector<Vec3>& vel, const std::vector<Tri>& faces) {
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(declared_vertices) +
                  "\nproperty float x\nproperty float y\nproperty float z\n"
                  "property float vx\nproperty float vy\nproperty float vz\n"
                  "element face " + std::to_string(declared_faces) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (std::size_t i = 0; i < pos.size(); ++i) {
    for (int k = 0; k < 3; ++k) test::append_raw(s, float(pos[i][k]));
    for (int k = 0; k < 3; ++k) test::append_raw(s, float(vel[i][k]));
  }
  for (const Tri& f : faces) {
    test::append_raw(s, uint8_t(3));
    for (int32_t x : f) test::append_raw(s, x);
  }
  return s;
}

const std::vector<Vec3> kPos = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const std::vector<Vec3> kVel = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
const std::vector<Tri> kFaces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

}  // namespace

TEST(BadInput, ValidTetraPlyReads) {
  // The baseline every corruption below starts from.
  TempDir tmp("bad");
  test::write_bytes(tmp / "ok.ply", tetra_ply(4, 4, kPos, kVel, kFaces));
  const TriMesh m = read_mesh(tmp / "ok.ply");
  EXPECT_EQ(m.vertex_count(), 4u);
  EXPECT_EQ(m.triangles, kFaces);
}

TEST(BadInput, TruncatedBinaryPlyNamesWhereTheDataEnds) {
  TempDir tmp("bad");
  const std::string full = tetra_ply(4, 4, kPos, kVel, kFaces);
  // Cut inside face 2 (each face is 13 bytes after 4 * 24 vertex bytes).
  test::write_bytes(tmp / "cut.ply", full.substr(0, full.size() - 13 - 5));
  expect_input_error([&] { read_mesh(tmp / "cut.ply"); }, tmp / "cut.ply", {"truncated", "face 2 of 4"});
  // Cut inside the vertices.
  test::write_bytes(tmp / "cut2.ply", full.substr(0, full.find("end_header\n") + 11 + 24 + 10));
  expect_input_error([&] { read_mesh(tmp / "cut2.ply"); }, tmp / "cut2.ply", {"truncated", "vertex 1 of 4"});
  // Cut inside the header.
  test::write_bytes(tmp / "cut3.ply", full.substr(0, 60));
  expect_input_error([&] { read_mesh(tmp / "cut3.ply"); }, tmp / "cut3.ply", {"end_header"});
}

TEST(BadInput, PlyHeaderLyingAboutCounts) {
  TempDir tmp("bad");
  // Promises more vertices than there are: the faces are eaten as vertices
  // and the data ends early.
  test::write_bytes(tmp / "more.ply", tetra_ply(6, 4, kPos, kVel, kFaces));
  expect_input_error([&] { read_mesh(tmp / "more.ply"); }, tmp / "more.ply", {"truncated"});
  // Promises fewer faces than there are: geometry would be silently lost.
  test::write_bytes(tmp / "fewer.ply", tetra_ply(4, 2, kPos, kVel, kFaces));
  expect_input_error([&] { read_mesh(tmp / "fewer.ply"); }, tmp / "fewer.ply", {"after the last element", "counts"});
  // ASCII: one face line missing.
  test::write_bytes(tmp / "ascii.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  expect_input_error([&] { read_mesh(tmp / "ascii.ply"); }, tmp / "ascii.ply", {"truncated", "face 1 of 2"});
}

TEST(BadInput, NonFiniteVelocityOrPositionNamesTheVertex) {
  TempDir tmp("bad");
  std::vector<Vec3> vel = kVel;
  vel[2].y = std::numeric_limits<double>::quiet_NaN();
  test::write_bytes(tmp / "nan.ply", tetra_ply(4, 4, kPos, vel, kFaces));
  expect_input_error([&] { read_mesh(tmp / "nan.ply"); }, tmp / "nan.ply", {"vertex 2", "velocity is NaN"});
  vel = kVel;
  vel[3].z = INFINITY;
  test::write_bytes(tmp / "inf.ply", tetra_ply(4, 4, kPos, vel, kFaces));
  expect_input_error([&] { read_mesh(tmp / "inf.ply"); }, tmp / "inf.ply", {"vertex 3", "velocity is infinite"});
  std::vector<Vec3> pos = kPos;
  pos[1].x = -INFINITY;
  test::write_bytes(tmp / "pinf.ply", tetra_ply(4, 4, pos, kVel, kFaces));
  expect_input_error([&] { read_mesh(tmp / "pinf.ply"); }, tmp / "pinf.ply", {"vertex 1", "position is infinite"});
}

TEST(BadInput, PlyFaceIndexOutOfRange) {
  TempDir tmp("bad");
  std::vector<Tri> faces = kFaces;
  faces[3][1] = 7;
  test::write_bytes(tmp / "idx.ply", tetra_ply(4, 4, kPos, kVel, faces));
  expect_input_error([&] { read_mesh(tmp / "idx.ply"); }, tmp / "idx.ply", {"face 3", "vertex index 7", "out of range"});
  faces = kFaces;
  faces[1][0] = -1;
  test::write_bytes(tmp / "neg.ply", tetra_ply(4, 4, kPos, kVel, faces));
  expect_input_error([&] { read_mesh(tmp / "neg.ply"); }, tmp / "neg.ply", {"face 1", "vertex index -1"});
}

TEST(BadInput, PlyMagicFormatAndHeader) {
  TempDir tmp("bad");
  test::write_bytes(tmp / "magic.ply", "PLY\nformat ascii 1.0\nend_header\n");
  expect_input_error([&] { read_mesh(tmp / "magic.ply"); }, tmp / "magic.ply", {"not a PLY file"});
  test::write_bytes(tmp / "fmt.ply", "ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n");
  expect_input_error([&] { read_mesh(tmp / "fmt.ply"); }, tmp / "fmt.ply", {"line 2", "unknown format"});
  test::write_bytes(tmp / "type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n");
  expect_input_error([&] { read_mesh(tmp / "type.ply"); }, tmp / "type.ply", {"line 4", "unknown type 'float128'"});
  test::write_bytes(tmp / "novel.ply",
                    "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float vx\nend_header\n0 0 0 1\n");
  expect_input_error([&] { read_mesh(tmp / "novel.ply"); }, tmp / "novel.ply", {"velocity is incomplete"});
  test::write_bytes(tmp / "word.ply",
                    "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                    "end_header\n0 zero 0\n");
  expect_input_error([&] { read_mesh(tmp / "word.ply"); }, tmp / "word.ply", {"line 8", "vertex 0", "'zero' is not a number"});
}

TEST(BadInput, ObjOutOfRangeAndMalformedLines) {
  TempDir tmp("bad");
  test::write_bytes(tmp / "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n");
  expect_input_error([&] { read_mesh(tmp / "range.obj"); }, tmp / "range.obj", {"line 5", "vertex index 9", "out of range"});
  test::write_bytes(tmp / "rel.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n");
  expect_input_error([&] { read_mesh(tmp / "rel.obj"); }, tmp / "rel.obj", {"line 3", "vertex index -3"});
  test::write_bytes(tmp / "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  expect_input_error([&] { read_mesh(tmp / "zero.obj"); }, tmp / "zero.obj", {"line 4", "index 0"});
  test::write_bytes(tmp / "v.obj", "v 0 0 0\nv 1 0\n");
  expect_input_error([&] { read_mesh(tmp / "v.obj"); }, tmp / "v.obj", {"line 2", "malformed vertex"});
  test::write_bytes(tmp / "f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x3\n");
  expect_input_error([&] { read_mesh(tmp / "f.obj"); }, tmp / "f.obj", {"line 4", "malformed face", "'x3'"});
  test::write_bytes(tmp / "nan.obj", "v 0 0 0\nv nan 0 0\n");
  expect_input_error([&] { read_mesh(tmp / "nan.obj"); }, tmp / "nan.obj", {"line 2", "vertex 1", "NaN"});
  test::write_bytes(tmp / "bin.obj", std::string("v 0 0 0\n\x01\x02\x03 junk\n", 17));
  expect_input_error([&] { read_mesh(tmp / "bin.obj"); }, tmp / "bin.obj", {"line 2", "malformed line"});
}

TEST(BadInput, ObjHugeNumbersGiveAShortLineNamingTheFile) {
  // A 1 MB number: out of range of a double, quoted in 40 characters, not in full.
  TempDir tmp("bad");
  test::write_bytes(tmp / "huge.obj", "v 0 0 0\nv 1 " + std::string(1 << 20, '9') + " 0\nv 0 1 0\nf 1 2 3\n");
  std::string what = expect_input_error([&] { read_mesh(tmp / "huge.obj"); }, tmp / "huge.obj",
                                        {"line 2", "malformed vertex 1", "'" + std::string(40, '9') + "...'",
                                         "(1048576 characters)", "is out of range for a double"});
  EXPECT_LT(what.size(), 300u);
  // Garbage with raw bytes: escaped, and cut the same way.
  test::write_bytes(tmp / "junk.obj", "v 0 0 0\nv 0 0 1.5\x01\xff" + std::string(100000, '5') + "\n");
  what = expect_input_error([&] { read_mesh(tmp / "junk.obj"); }, tmp / "junk.obj",
                            {"line 2", "malformed vertex 1", "'1.5\\x01\\xff555", "(100005 characters)", "is not a number"});
  EXPECT_LT(what.size(), 300u);
  EXPECT_EQ(what.find('\x01'), std::string::npos);
}

TEST(BadInput, MissingUnreadableAndUnknownFiles) {
  TempDir tmp("bad");
  expect_input_error([&] { read_mesh(tmp / "nothing.ply"); }, tmp / "nothing.ply", {"file not found"});
  std::filesystem::create_directory(tmp / "dir.ply");
  expect_input_error([&] { read_mesh(tmp / "dir.ply"); }, tmp / "dir.ply", {"is a directory"});
  test::write_bytes(tmp / "mesh.stl", "solid x\nendsolid x\n");
  expect_input_error([&] { read_mesh(tmp / "mesh.stl"); }, tmp / "mesh.stl", {"unknown mesh format '.stl'"});
  if (::geteuid() != 0) {  // root reads anything
    test::write_bytes(tmp / "locked.ply", "ply\n");
    std::filesystem::permissions(tmp / "locked.ply", std::filesystem::perms::none);
    expect_input_error([&] { read_mesh(tmp / "locked.ply"); }, tmp / "locked.ply", {"cannot open"});
  }
}

TEST(BadInput, MissingFrameInsideARangeNamesFileAndFrame) {
  TempDir tmp("bad");
  for (int f : {1, 2, 4}) write_ply(FramePattern(tmp / "s.%04d.ply").path(f), TriMesh{});
  const FramePattern p(tmp / "s.%04d.ply");
  try {
    resolve_frames(p, FrameRange{1, 4});
    ADD_FAILURE() << "missing frame 3 not reported";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), tmp / "s.0003.ply");
    EXPECT_EQ(e.frame(), 3);
    EXPECT_NE(std::string(e.what()).find("frame 3"), std::string::npos) << e.what();
  }
  EXPECT_EQ(resolve_frames(p, std::nullopt), (std::vector<int>{1, 2, 4}));
  expect_input_error([&] { resolve_frames(FramePattern(tmp / "none.%04d.ply"), std::nullopt); },
                     tmp / "none.%04d.ply", {"no file matches"});
}

TEST(BadInput, EmptyFrameIsLegalAndReported) {
  TempDir tmp("bad");
  // Header-only file: no liquid left in this frame.
  test::write_bytes(tmp / "empty.ply",
                    "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                    "property float z\nproperty float vx\nproperty float vy\nproperty float vz\nelement face 0\n"
                    "property list uchar int vertex_indices\nend_header\n");
  const TriMesh m = read_mesh(tmp / "empty.ply");
  EXPECT_TRUE(m.empty());
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.triangles, 0u);
  EXPECT_EQ(r.components, 0);
  EXPECT_TRUE(r.bounds.empty());
}

TEST(BadInput, VdbWithoutTheNamedGridListsTheGridsItHas) {
  TempDir tmp("bad");
  expect_input_error([&] { VelocityGrid(tmp / "none.vdb"); }, tmp / "none.vdb", {"file not found"});
  test::write_bytes(tmp / "junk.vdb", "this is not an OpenVDB file, just text long enough to be read");
  expect_input_error([&] { VelocityGrid(tmp / "junk.vdb"); }, tmp / "junk.vdb", {"cannot read OpenVDB file"});
  LAPFLOW_NEED_SHARED(test::shared_data_path());
  const std::string dir = test::shared_data_dir();
  const std::string vdb = dir + "/dam_break/dam_break.0001.vdb";
  expect_input_error([&] { VelocityGrid(vdb, "vel"); }, vdb, {"no vector grid named 'vel'", "velocity (vec3s)"});
  EXPECT_EQ(VelocityGrid(vdb).grid_name(), "velocity");  // found by the default search
}

TEST(BadInput, RandomCorruptionsEitherReadOrThrowInputError) {
  // Truncation at every length and random byte changes of a PLY (binary and
  // ASCII) and an OBJ: the reader returns a consistent mesh or one InputError.
  TempDir tmp("bad");
  std::string ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                      "property float vx\nproperty float vy\nproperty float vz\nelement face 4\n"
                      "property list uchar int vertex_indices\nend_header\n";
  for (std::size_t i = 0; i < kPos.size(); ++i)
    ascii += fmt::format("{} {} {} 0 0 1\n", kPos[i].x, kPos[i].y, kPos[i].z);
  for (const Tri& f : kFaces) ascii += fmt::format("3 {} {} {}\n", f[0], f[1], f[2]);
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf -4 -1 -2\nf 2/1 3/2 4/3\n";
  const std::pair<std::string, std::string> sources[] = {
      {"f.ply", tetra_ply(4, 4, kPos, kVel, kFaces)}, {"f.ply", ascii}, {"f.obj", obj}};
  int errors = 0, reads = 0;
  auto check = [&](const std::string& name, const std::string& bytes) {
    const std::string path = tmp / name;
    test::write_bytes(path, bytes);
    try {
      const TriMesh m = read_mesh(path);
      for (const Tri& f : m.triangles)
        for (int32_t x : f) ASSERT_TRUE(x >= 0 && x < int32_t(m.vertex_count()));
      for (const Vec3& p : m.positions) ASSERT_TRUE(is_finite(p));
      if (m.has_velocities()) {
        ASSERT_EQ(m.velocities.size(), m.positions.size());
      }
      ++reads;
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), path);
      ++errors;
    }
  };
  for (const auto& [name, bytes] : sources) {
    for (std::size_t n = 0; n < bytes.size(); ++n) check(name, bytes.substr(0, n));
    for (uint64_t k = 0; k < 150; ++k) {
      std::string b = bytes;
      for (int j = 0; j < 3; ++j) {
        const uint64_t h = hash64(k, j, bytes.size());
        b[h % b.size()] = char(h >> 40);
      }
      check(name, b);
    }
  }
  EXPECT_GT(errors, 100);
  EXPECT_GT(reads, 3);
}

TEST(BadInput, AsciiPlyListLengthsMustBeWholeNumbersTheDataCanHold) {
  // Found by fuzz_ply (tests/fuzz/corpus/ply/regress_ascii_list_length_3e62.ply): an
  // ASCII list length of 3e62 was cast to an integer unchecked.
  TempDir tmp("bad");
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
  for (const char* face : {"3e62 0 1 2\n", "3.5 0 1 2\n", "-1 0 1 2\n", "9999 0 1 2\n"}) {
    test::write_bytes(tmp / "list.ply", head + std::string(face));
    expect_input_error([&] { read_mesh(tmp / "list.ply"); }, tmp / "list.ply", {"face 0", "invalid list length"});
  }
  // The same in a property lapflow skips.
  const std::string skipped =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
      "property list uchar float extra\nend_header\n0 0 0 3e62 1\n";
  test::write_bytes(tmp / "skip.ply", skipped);
  expect_input_error([&] { read_mesh(tmp / "skip.ply"); }, tmp / "skip.ply", {"vertex 0", "invalid list length"});
  test::write_bytes(tmp / "ok.ply", head + "3 0 1 2\n");
  EXPECT_EQ(read_mesh(tmp / "ok.ply").triangle_count(), 1u);
}

TEST(BadInput, AnElementWithNoPropertiesAndAHugeCountReadsAtOnce) {
  // Found by fuzz_ply (tests/fuzz/corpus/ply/regress_empty_element_2e14.ply): an
  // unused element with no property and a count of 2e14 was walked instance by
  // instance, a hang of hours.
  TempDir tmp("bad");
  test::write_bytes(tmp / "empty.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement junk 213333333333333\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  // A walk would not end within the test's ctest TIMEOUT (CMakeLists.txt).
  EXPECT_EQ(read_mesh(tmp / "empty.ply").triangle_count(), 1u);
}
