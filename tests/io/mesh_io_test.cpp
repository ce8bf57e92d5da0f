// Readers and writers of fluid meshes: real Mantaflow frames, every PLY layout
// users produce, OBJ, and frame patterns.
#include <gtest/gtest.h>

#include <cmath>
#include <regex>

#include "io_test_helpers.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;

namespace {

/// "element <name> N" from a PLY header, read independently of the reader.
long header_count(const std::string& path, const std::string& element) {
  const std::string text = test::read_bytes(path).substr(0, 2000);
  std::smatch m;
  if (!std::regex_search(text, m, std::regex("element " + element + " ([0-9]+)"))) return -1;
  return std::stol(m[1]);
}

void check_real_frame(const std::string& path, const Box3& domain) {
  SCOPED_TRACE(path);
  const TriMesh m = read_mesh(path);
  EXPECT_EQ(long(m.vertex_count()), header_count(path, "vertex"));
  EXPECT_EQ(long(m.triangle_count()), header_count(path, "face"));
  ASSERT_TRUE(m.has_velocities());
  ASSERT_EQ(m.velocities.size(), m.positions.size());
  double max_speed = 0;
  for (const Vec3& v : m.velocities) {
    ASSERT_TRUE(is_finite(v));
    max_speed = std::max(max_speed, norm(v));
  }
  // Plausible for a 1 m liquid under gravity: not all zero (even liquid at
  // rest keeps a few cm/s), and far below free fall from 5 m.
  EXPECT_GT(max_speed, 0.005);
  EXPECT_LT(max_speed, 10.0);
  // Inside the simulation domain (the scene's JSON).
  const Box3 b = bounding_box(m);
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(b.lo[k], domain.lo[k] - 1e-6);
    EXPECT_LE(b.hi[k], domain.hi[k] + 1e-6);
  }
  // The README promises closed, manifold surfaces.
  const MeshReport r = analyze_mesh(m);
  EXPECT_EQ(r.boundary_edges, 0u);
  EXPECT_EQ(r.non_manifold_edges, 0u);
}

TriMesh sample_mesh_with_velocity() {
  TriMesh m = test::icosphere(2, 0.3, {0.5, 0.4, 0.2});
  for (const Vec3& p : m.positions) m.velocities.push_back({-p.y, p.x, 0.25 * p.z});
  return m;
}

std::string ascii_ply() {
  // Doubles with the velocity_x naming, properties to skip before, between
  // and after, a quad, a vertex list property and a trailing `edge` element.
  return "ply\r\n"
         "format ascii 1.0\n"
         "comment made by hand\n"
         "element vertex 4\n"
         "property uchar red\n"
         "property double x\n"
         "property double y\n"
         "property list uchar float weights\n"
         "property double z\n"
         "property double velocity_x\n"
         "property double velocity_y\n"
         "property double velocity_z\n"
         "property float nx\n"
         "element face 2\n"
         "property list uchar uint vertex_indices\n"
         "property int material\n"
         "element edge 1\n"
         "property int vertex1\n"
         "property int vertex2\n"
         "end_header\n"
         "255 0 0 2 0.5 0.5 0 1 0 0 1\n"
         "10 1 0 0 0 0 2 0 1\n"
         "0 1 1 1 7 0 3 -1.5 0 1\n"
         "0 0 1 0 0 4e-1 0.5 +2 1\n"
         "4 0 1 2 3 7\n"
         "3 0 2 1 8\n"
         "0 1\n";
}

}  // namespace

TEST(ReadMesh, RealDamBreakAndViscousDropFramesMatchTheirHeaders) {
  LAPFLOW_NEED_SHARED(test::shared_data_path());
  const std::string dir = test::shared_data_dir();
  const Box3 dam{{0, 0, 0}, {2, 1, 1}}, drop{{-0.8, -0.8, 0}, {0.8, 0.8, 1}};
  for (const char* f : {"/dam_break/dam_break.0001.ply", "/dam_break/dam_break.0050.ply", "/dam_break/dam_break.0100.ply"})
    check_real_frame(dir + f, dam);
  for (const char* f : {"/viscous_drop/viscous_drop.0001.ply", "/viscous_drop/viscous_drop.0072.ply"})
    check_real_frame(dir + f, drop);
}

TEST(ReadMesh, BinaryPlyRoundTripKeepsFloatPrecision) {
  TempDir tmp("mesh_io");
  const TriMesh m = sample_mesh_with_velocity();
  write_ply(tmp / "sphere.ply", m);
  const TriMesh r = read_mesh(tmp / "sphere.ply");
  ASSERT_EQ(r.positions.size(), m.positions.size());
  ASSERT_EQ(r.velocities.size(), m.velocities.size());
  EXPECT_EQ(r.triangles, m.triangles);
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    EXPECT_NEAR(norm(r.positions[i] - m.positions[i]), 0, 1e-7);
    EXPECT_NEAR(norm(r.velocities[i] - m.velocities[i]), 0, 1e-7);
  }
  // The file has the layout of ../shared/data (float x y z vx vy vz, uchar int list).
  EXPECT_EQ(std::filesystem::file_size(tmp / "sphere.ply"),
            test::read_bytes(tmp / "sphere.ply").find("end_header\n") + 11 + m.positions.size() * 24 +
                m.triangles.size() * 13);
}

TEST(ReadMesh, PlyWithoutVelocityHasNone) {
  TempDir tmp("mesh_io");
  TriMesh m = test::icosphere(1);
  write_ply(tmp / "novel.ply", m);
  const TriMesh r = read_mesh(tmp / "novel.ply");
  EXPECT_FALSE(r.has_velocities());
  EXPECT_EQ(r.triangles, m.triangles);
}

TEST(ReadMesh, AsciiPlySkipsUnusedPropertiesAndSplitsQuads) {
  TempDir tmp("mesh_io");
  test::write_bytes(tmp / "a.ply", ascii_ply());
  const TriMesh m = read_mesh(tmp / "a.ply");
  ASSERT_EQ(m.vertex_count(), 4u);
  EXPECT_EQ(m.positions[0], Vec3(0, 0, 0));
  EXPECT_EQ(m.positions[1], Vec3(1, 0, 0));
  EXPECT_EQ(m.positions[2], Vec3(1, 1, 0));
  EXPECT_EQ(m.positions[3], Vec3(0, 1, 0));
  ASSERT_TRUE(m.has_velocities());
  EXPECT_EQ(m.velocities[0], Vec3(1, 0, 0));
  EXPECT_EQ(m.velocities[1], Vec3(0, 2, 0));
  EXPECT_EQ(m.velocities[2], Vec3(3, -1.5, 0));
  EXPECT_EQ(m.velocities[3], Vec3(0.4, 0.5, 2));
  const std::vector<Tri> expected = {{0, 1, 2}, {0, 2, 3}, {0, 2, 1}};
  EXPECT_EQ(m.triangles, expected);
}

TEST(ReadMesh, BigEndianPlyWithMixedTypes) {
  // double positions, float v_x velocities, a short to skip, uint-counted
  // short indices named vertex_index, extra face scalar and list.
  std::string s =
      "ply\nformat binary_big_endian 1.0\n"
      "element vertex 3\n"
      "property double x\nproperty double y\nproperty double z\n"
      "property short flags\n"
      "property float v_x\nproperty float v_y\nproperty float v_z\n"
      "element face 1\n"
      "property uchar tag\n"
      "property list uint short vertex_index\n"
      "property list uchar float uv\n"
      "end_header\n";
  const double pos[3][3] = {{0.125, -2, 3}, {4, 5.5, -6}, {1e-3, 8, 9}};
  for (int i = 0; i < 3; ++i) {
    for (double c : pos[i]) test::append_raw(s, c, true);
    test::append_raw(s, int16_t(-7), true);
    for (int k = 0; k < 3; ++k) test::append_raw(s, float(i + 0.5f * k), true);
  }
  test::append_raw(s, uint8_t(9), true);
  test::append_raw(s, uint32_t(3), true);
  for (int16_t x : {2, 0, 1}) test::append_raw(s, x, true);
  test::append_raw(s, uint8_t(2), true);
  test::append_raw(s, 0.5f, true), test::append_raw(s, 0.25f, true);

  TempDir tmp("mesh_io");
  test::write_bytes(tmp / "be.ply", s);
  const TriMesh m = read_mesh(tmp / "be.ply");
  ASSERT_EQ(m.vertex_count(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(m.positions[i], Vec3(pos[i][0], pos[i][1], pos[i][2]));
    EXPECT_EQ(m.velocities[i], Vec3(i, i + 0.5, i + 1.0));
  }
  ASSERT_EQ(m.triangle_count(), 1u);
  EXPECT_EQ(m.triangles[0], (Tri{2, 0, 1}));
}

TEST(ReadMesh, ObjWithQuadsSlashesAndNegativeIndices) {
  TempDir tmp("mesh_io");
  test::write_bytes(tmp / "q.obj",
                    "# a unit square as one quad, then a triangle with relative indices\n"
                    "mtllib q.mtl\n"
                    "o square\n"
                    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\n"
                    "vt 0 0\nvn 0 0 1\n"
                    "usemtl water\n"
                    "s off\n"
                    "f 1/1/1 2/1/1 3//1 4\n"
                    "v 2 0 0\r\n"
                    "v 2 1 0\n"
                    "f -5 -2 -1\n");
  const TriMesh m = read_mesh(tmp / "q.obj");
  ASSERT_EQ(m.vertex_count(), 6u);
  EXPECT_EQ(m.positions[4], Vec3(2, 0, 0));
  EXPECT_FALSE(m.has_velocities());
  const std::vector<Tri> expected = {{0, 1, 2}, {0, 2, 3}, {1, 4, 5}};
  EXPECT_EQ(m.triangles, expected);
  EXPECT_NEAR(surface_area(m), 1.5, 1e-12);
}

TEST(ReadMesh, EmptyFrameIsLegal) {
  TempDir tmp("mesh_io");
  write_ply(tmp / "empty.ply", TriMesh{});
  const TriMesh m = read_mesh(tmp / "empty.ply");
  EXPECT_TRUE(m.empty());
  EXPECT_EQ(m.vertex_count(), 0u);
  test::write_bytes(tmp / "empty.obj", "# nothing left\n");
  EXPECT_TRUE(read_mesh(tmp / "empty.obj").empty());
}

TEST(FramePattern, AllTokenFormsNameTheSameFiles) {
  EXPECT_EQ(FramePattern("a/fluid.%04d.ply").path(7), "a/fluid.0007.ply");
  EXPECT_EQ(FramePattern("fluid.%d.ply").path(7), "fluid.7.ply");
  EXPECT_EQ(FramePattern("fluid.####.ply").path(12), "fluid.0012.ply");
  EXPECT_EQ(FramePattern("fluid.$F4.ply").path(123), "fluid.0123.ply");
  EXPECT_EQ(FramePattern("fluid.$F.ply").path(123), "fluid.123.ply");
  EXPECT_EQ(FramePattern("fluid.%04d.ply").path(12345), "fluid.12345.ply");
  EXPECT_EQ(FramePattern("fluid.%04d.ply").path(-3), "fluid.-0003.ply");
  EXPECT_EQ(FramePattern("#dir/fluid.####.ply").path(1), "#dir/fluid.0001.ply");
  const FramePattern single("still.ply");
  EXPECT_FALSE(single.has_frame_token());
  EXPECT_EQ(single.path(5), "still.ply");
  EXPECT_THROW(FramePattern("fluid.%4d.ply"), UsageError);
  EXPECT_THROW(FramePattern("frames.%04d/fluid.ply"), UsageError);
}

TEST(FramePattern, FramesOnDiskMatchOnlyTheTokensPadding) {
  TempDir tmp("frames");
  for (const char* n : {"f.0001.ply", "f.0002.ply", "f.0010.ply", "f.1.ply", "f.00003.ply", "f.0004.obj",
                        "g.0005.ply", "f.abcd.ply"})
    test::write_bytes(tmp / n, "");
  std::filesystem::create_directory(tmp / "f.0006.ply");  // a folder is not a frame
  EXPECT_EQ(FramePattern(tmp / "f.%04d.ply").frames_on_disk(), (std::vector<int>{1, 2, 10}));
  EXPECT_EQ(FramePattern(tmp / "f.####.ply").frames_on_disk(), (std::vector<int>{1, 2, 10}));
  EXPECT_EQ(FramePattern(tmp / "f.$F.ply").frames_on_disk(), (std::vector<int>{1}));
  EXPECT_EQ(resolve_frames(FramePattern(tmp / "f.$F4.ply"), std::nullopt), (std::vector<int>{1, 2, 10}));
  EXPECT_EQ(resolve_frames(FramePattern(tmp / "f.%04d.ply"), FrameRange{1, 2}), (std::vector<int>{1, 2}));
}

TEST(FramePattern, ParseFrameRange) {
  EXPECT_EQ(parse_frame_range("1-100").first, 1);
  EXPECT_EQ(parse_frame_range("1-100").last, 100);
  EXPECT_EQ(parse_frame_range("42").first, 42);
  EXPECT_EQ(parse_frame_range("42").last, 42);
  EXPECT_EQ(parse_frame_range("-5-3").first, -5);
  EXPECT_THROW(parse_frame_range("10-1"), UsageError);
  EXPECT_THROW(parse_frame_range("a-b"), UsageError);
  EXPECT_THROW(parse_frame_range(""), UsageError);
  EXPECT_THROW(parse_frame_range("1-"), UsageError);
}

TEST(ReadMesh, VertexPropertiesByNameForLayerRules) {
  TempDir tmp("mesh_io_attributes");
  test::write_bytes(tmp / "a.ply", ascii_ply());
  // Any number type, read as float, in the order asked; the file's other
  // properties are declared for `lapflow inspect`.
  const MeshFile f = read_mesh_file(tmp / "a.ply", true, {"nx", "red"});
  ASSERT_EQ(f.attributes.size(), 2u);
  EXPECT_EQ(f.attributes[0], (std::vector<float>{1, 1, 1, 1}));
  EXPECT_EQ(f.attributes[1], (std::vector<float>{255, 10, 0, 0}));
  EXPECT_EQ(f.declared.attributes, (std::vector<std::string>{"red", "nx"}));
  EXPECT_EQ(read_mesh_file(tmp / "a.ply").mesh.triangles, f.mesh.triangles) << "the same mesh";
  // A name the file lacks, a list, a velocity component: the file and the property.
  EXPECT_EQ(test::input_error_of([&] { read_mesh_file(tmp / "a.ply", true, {"foam"}); }),
            tmp / "a.ply" + ": PLY vertex element has no property 'foam' (it has: red x y weights z velocity_x "
                             "velocity_y velocity_z nx)");
  EXPECT_NE(test::input_error_of([&] { read_mesh_file(tmp / "a.ply", true, {"weights"}); }).find("'weights' is a list"),
            std::string::npos);
  EXPECT_NE(test::input_error_of([&] { read_mesh_file(tmp / "a.ply", true, {"velocity_x"}); })
                .find("is a position or velocity component"),
            std::string::npos);
  // A NaN value names the vertex.
  std::string nan = ascii_ply();
  nan.replace(nan.find("0 1 1 1 7 0 3 -1.5 0 1"), 22, "0 1 1 1 7 0 3 -1.5 0 nan");
  test::write_bytes(tmp / "nan.ply", nan);
  EXPECT_NE(test::input_error_of([&] { read_mesh_file(tmp / "nan.ply", true, {"nx"}); }).find("vertex 2: property 'nx' is NaN"),
            std::string::npos);
  // An OBJ has no vertex properties.
  test::write_bytes(tmp / "q.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_NE(test::input_error_of([&] { read_mesh_file(tmp / "q.obj", true, {"foam"}); }).find("needs PLY frames"),
            std::string::npos);
}
