// UV mesh writer (OBJ + MTL) and the `lapflow atlas` command end to end.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lapflow/atlas/atlas.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/io/uv_mesh.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("lapflow_uvmesh_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(UvMeshObj, ReadUvMeshGivesBackTheWrittenCorners) {
  const TriMesh m = test::icosphere(2, 0.5);
  AtlasOptions o;
  o.resolution = 256;
  const SurfaceAtlas a = build_surface_atlas(m, o);
  const fs::path dir = temp_dir("readback");
  write_uv_mesh_obj((dir / "f.0001.obj").string(), m, a, {});
  const UvMesh r = read_uv_mesh((dir / "f.0001.obj").string());
  ASSERT_EQ(r.mesh.triangles.size(), m.triangles.size());
  ASSERT_EQ(r.corner_uv.size(), a.corner_uv.size());
  for (std::size_t t = 0; t < m.triangles.size(); ++t) EXPECT_EQ(r.mesh.triangles[t], m.triangles[t]);
  for (std::size_t c = 0; c < a.corner_uv.size(); ++c) {
    EXPECT_NEAR(r.corner_uv[c].x, a.corner_uv[c].x, 1e-6);
    EXPECT_NEAR(r.corner_uv[c].y, a.corner_uv[c].y, 1e-6);
  }
  // Faces with and without vt in one file, and a vt index past the end, are errors naming the file.
  std::ofstream(dir / "mixed.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 1 2 3\n";
  std::ofstream(dir / "range.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/3\n";
  for (const char* bad : {"mixed.obj", "range.obj"}) {
    try {
      read_uv_mesh((dir / bad).string());
      ADD_FAILURE() << bad << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
  fs::remove_all(dir);
}

TEST(UvMeshObj, EveryCornerKeepsItsSourceVertexAndAtlasUv) {
  TriMesh m = test::icosphere(2, 0.5);
  m.triangles.push_back({0, 0, 1});  // a degenerate triangle collapses to a point
  AtlasOptions o;
  o.resolution = 512;
  const SurfaceAtlas a = build_surface_atlas(m, o);
  const fs::path dir = temp_dir("corners");
  UvMeshMaterial mat;
  mat.name = "fluid";
  mat.color_texture = "frame.color.0001.exr";
  mat.displacement_texture = "frame.disp.0001.exr";
  write_uv_mesh_obj((dir / "frame.0001.obj").string(), m, a, mat);

  // Parse the OBJ back by hand: v in source order, vt per corner, f v/vt/vn.
  std::ifstream in(dir / "frame.0001.obj");
  std::vector<Vec3> v;
  std::vector<Vec2> vt;
  std::size_t vn = 0;
  std::vector<std::array<int, 9>> faces;
  std::string line, mtllib, usemtl;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      Vec3 p;
      ls >> p.x >> p.y >> p.z;
      v.push_back(p);
    } else if (tag == "vt") {
      Vec2 p;
      ls >> p.x >> p.y;
      vt.push_back(p);
    } else if (tag == "vn") {
      ++vn;
    } else if (tag == "f") {
      std::array<int, 9> f{};
      for (int k = 0; k < 3; ++k) {
        char s1, s2;
        ls >> f[3 * k] >> s1 >> f[3 * k + 1] >> s2 >> f[3 * k + 2];
      }
      faces.push_back(f);
    } else if (tag == "mtllib") {
      ls >> mtllib;
    } else if (tag == "usemtl") {
      ls >> usemtl;
    }
  }
  ASSERT_EQ(v.size(), m.vertex_count());
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_LT(norm(v[i] - m.positions[i]), 1e-7);
  EXPECT_EQ(vn, m.vertex_count());
  ASSERT_EQ(faces.size(), m.triangle_count());
  EXPECT_LT(vt.size(), 3 * m.triangle_count());  // corners of one vertex in one chart share a vt
  for (std::size_t t = 0; t < faces.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(faces[t][3 * k] - 1, m.triangles[t][k]);
      EXPECT_EQ(faces[t][3 * k + 2] - 1, m.triangles[t][k]);
      const Vec2 uv = vt.at(faces[t][3 * k + 1] - 1);
      EXPECT_NEAR(uv.x, a.corner_uv[3 * t + k].x, 1e-8);
      EXPECT_NEAR(uv.y, a.corner_uv[3 * t + k].y, 1e-8);
    }
  EXPECT_EQ(mtllib, "frame.0001.mtl");
  EXPECT_EQ(usemtl, "fluid");
  const std::string mtl = slurp(dir / "frame.0001.mtl");
  EXPECT_NE(mtl.find("newmtl fluid"), std::string::npos);
  EXPECT_NE(mtl.find("map_Kd frame.color.0001.exr"), std::string::npos);
  EXPECT_NE(mtl.find("disp frame.disp.0001.exr"), std::string::npos);
  EXPECT_NE(mtl.find("map_disp frame.disp.0001.exr"), std::string::npos);
  // lapflow's own reader sees the same mesh.
  const TriMesh back = read_mesh((dir / "frame.0001.obj").string());
  EXPECT_EQ(back.triangles, m.triangles);
  fs::remove_all(dir);
}

TEST(AtlasCommand, WritesObjAndReportsFiguresAsJson) {
  const fs::path dir = temp_dir("cli");
  write_ply((dir / "ball.ply").string(), test::icosphere(3, 1.0));
  const std::string cmd = std::string(LAPFLOW_BINARY) + " atlas " + (dir / "ball.ply").string() +
                          " --resolution 512 --gutter 2 --checker --json --threads 2 --out " + (dir / "ball.obj").string() +
                          " > " + (dir / "out.json").string();
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const nlohmann::json j = nlohmann::json::parse(slurp(dir / "out.json"));
  EXPECT_EQ(j["triangles"], 1280);
  EXPECT_EQ(j["resolution"], 512);
  EXPECT_GE(j["charts"].get<int>(), 6);
  EXPECT_GT(j["utilization"].get<double>(), 0.4);
  EXPECT_GE(j["area_in_density_bounds"].get<double>(), 0.95);
  EXPECT_EQ(j["flipped_triangles"], 0);
  EXPECT_TRUE(fs::exists(dir / "ball.obj"));
  EXPECT_TRUE(fs::exists(dir / "ball.checker.png"));
  EXPECT_NE(slurp(dir / "ball.mtl").find("map_Kd ball.checker.png"), std::string::npos);
  // A missing mesh is bad input: exit code 2, nothing written.
  const std::string bad = std::string(LAPFLOW_BINARY) + " atlas " + (dir / "missing.ply").string() + " --out " +
                          (dir / "missing.obj").string() + " 2> /dev/null";
  const int rc = std::system(bad.c_str());
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  EXPECT_FALSE(fs::exists(dir / "missing.obj"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace lapflow
