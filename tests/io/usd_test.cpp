// The USD output (io/usd.hpp): every frame's layer read back by an
// independent reader (TinyUSDZ, tests/usd/read_usd.mjs) equals the same
// frame's OBJ; the velocities are the simulation's; the stage names every
// frame on disk, also after a resumed bake and a render into another folder.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "io_test_helpers.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/io/usd.hpp"

namespace lapflow {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

/// An OBJ as lapflow writes it: positions, texture coordinates, and per
/// corner the position and texture-coordinate indices (0-based).
struct Obj {
  std::vector<double> v, vt;
  std::vector<int> corner_v, corner_vt;
};

Obj read_obj(const std::string& path) {
  Obj o;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "v") {
      double x, y, z;
      s >> x >> y >> z;
      o.v.insert(o.v.end(), {x, y, z});
    } else if (tag == "vt") {
      double u, v;
      s >> u >> v;
      o.vt.insert(o.vt.end(), {u, v});
    } else if (tag == "f") {
      std::string corner;
      while (s >> corner) {
        int a = 0, b = 0, c = 0;
        EXPECT_EQ(std::sscanf(corner.c_str(), "%d/%d/%d", &a, &b, &c), 3) << corner;
        o.corner_v.push_back(a - 1);
        o.corner_vt.push_back(b - 1);
      }
    }
  }
  return o;
}

/// The numbers of one attribute's time sample at `frame` in a layer lapflow wrote.
std::vector<double> authored(const std::string& layer_text, const std::string& attribute, int frame) {
  const std::string key = attribute + ".timeSamples = { " + std::to_string(frame) + ": [";
  const std::size_t at = layer_text.find(key);
  if (at == std::string::npos) return {};
  const std::size_t end = layer_text.find(']', at + key.size());
  std::string body = layer_text.substr(at + key.size(), end - at - key.size());
  for (char& c : body)
    if (c == '(' || c == ')' || c == ',') c = ' ';
  std::istringstream s(body);
  std::vector<double> values;
  for (double x; s >> x;) values.push_back(x);
  return values;
}

bool have_node(const TempDir& dir) { return test::have_command("node", dir); }

/// A three-frame demo baked with the lava exemplar into `dir`/bake (`extra` options added).
void bake_demo(const TempDir& dir, const std::string& extra = "") {
  test::bake_lava_demo(dir, 3, "--resolution 128 " + extra);
}

std::string frame_name(const char* pattern, int frame) {
  char name[128];
  std::snprintf(name, sizeof name, pattern, frame);
  return name;
}

TEST(UsdLayer, AnIndependentReaderReadsEveryFrameAsItsObj) {
  TempDir dir("usd_read");
  if (!have_node(dir)) GTEST_SKIP() << "node is not on PATH: the USD layers are not read back here";
  bake_demo(dir);
  for (int f = 1; f <= 3; ++f) {
    SCOPED_TRACE("frame " + std::to_string(f));
    const std::string layer = dir / ("bake/" + frame_name("demo.usd.%04d.usda", f));
    std::string out, err;
    ASSERT_EQ(test::run_command("node '" LAPFLOW_SOURCE_DIR "/tests/usd/read_usd.mjs' '" + layer + "'", &out, &err, dir),
              0)
        << err;
    const nlohmann::json read = nlohmann::json::parse(out);
    ASSERT_EQ(read.at("meshes").size(), 1u);
    const nlohmann::json& m = read["meshes"][0];
    EXPECT_EQ(m.at("path"), "/surface");
    const Obj obj = read_obj(dir / ("bake/" + frame_name("demo.%04d.obj", f)));
    const auto counts = m.at("faceVertexCounts").get<std::vector<int>>();
    const auto indices = m.at("faceVertexIndices").get<std::vector<int>>();
    const auto points = m.at("points").get<std::vector<double>>();
    const auto st = m.at("st").get<std::vector<double>>();
    ASSERT_EQ(3 * counts.size(), obj.corner_v.size());
    ASSERT_EQ(indices.size(), obj.corner_v.size());
    for (int c : counts) ASSERT_EQ(c, 3);
    // The reader splits points along st seams: compare corner by corner. The
    // layer holds the float nearest each double; the OBJ's 9 digits of that
    // double give that float or, next to a midpoint, its neighbour.
    auto same = [](double usd, double obj) {
      const float o = float(obj);
      return std::abs(usd - double(o)) <= double(std::nextafter(std::abs(o), INFINITY) - std::abs(o));
    };
    std::size_t differ = 0;
    for (std::size_t c = 0; c < indices.size(); ++c) {
      const std::size_t u = std::size_t(indices[c]), v = std::size_t(obj.corner_v[c]), t = std::size_t(obj.corner_vt[c]);
      ASSERT_LT(3 * u + 2, points.size());
      ASSERT_LT(2 * u + 1, st.size());
      for (int k = 0; k < 3; ++k) differ += !same(points[3 * u + k], obj.v[3 * v + k]);
      for (int k = 0; k < 2; ++k) differ += !same(st[2 * u + k], obj.vt[2 * t + k]);
    }
    EXPECT_EQ(differ, 0u) << "corner values that differ from the OBJ's";
  }
}

TEST(UsdLayer, VelocitiesAreTheSimulationsAtEveryVertex) {
  TempDir dir("usd_velocity");
  bake_demo(dir);
  for (int f = 1; f <= 3; ++f) {
    const MeshFile input = read_mesh_file(dir / ("mesh/" + frame_name("demo.%04d.ply", f)));
    ASSERT_TRUE(input.mesh.has_velocities());
    const std::string text = test::read_bytes(dir / ("bake/" + frame_name("demo.usd.%04d.usda", f)));
    const std::vector<double> v = authored(text, "vector3f[] velocities", f);
    const std::vector<double> p = authored(text, "point3f[] points", f);
    ASSERT_EQ(v.size(), 3 * input.mesh.vertex_count());
    ASSERT_EQ(p.size(), v.size());
    double fastest = 0;
    for (std::size_t i = 0; i < input.mesh.vertex_count(); ++i) {
      const Vec3 want = input.mesh.velocities[i];
      EXPECT_EQ(float(v[3 * i]), float(want.x));
      EXPECT_EQ(float(v[3 * i + 1]), float(want.y));
      EXPECT_EQ(float(v[3 * i + 2]), float(want.z));
      EXPECT_EQ(float(p[3 * i]), float(input.mesh.positions[i].x));
      EXPECT_EQ(float(p[3 * i + 2]), float(input.mesh.positions[i].z));
      fastest = std::max(fastest, norm(want));
    }
    EXPECT_GT(fastest, 0.01) << "the demo moves: its velocities are not all zero";
    // The extent bounds the points.
    const std::vector<double> e = authored(text, "float3[] extent", f);
    ASSERT_EQ(e.size(), 6u);
    for (std::size_t i = 0; i < p.size(); ++i) {
      EXPECT_LE(e[i % 3], p[i]);
      EXPECT_GE(e[3 + i % 3], p[i]);
    }
  }
}

/// The frames the stage's clips name, in order, and the colour atlas of each
/// time sample.
struct StageFrames {
  std::vector<int> clips, textures;
  std::vector<std::string> layers;
};
StageFrames stage_frames(const std::string& path) {
  const std::string text = test::read_bytes(path);
  StageFrames s;
  const std::regex layer(R"(@\./(\w+)\.usd\.(\d+)\.usda@)"), active(R"(\((\d+), (\d+)\))"),
      texture(R"((\d+): @\./\w+\.color\.(\d+)\.exr@)");
  for (std::sregex_iterator i(text.begin(), text.end(), layer), e; i != e; ++i) {
    s.clips.push_back(std::stoi((*i)[2]));
    s.layers.push_back((*i)[0]);
  }
  for (std::sregex_iterator i(text.begin(), text.end(), texture), e; i != e; ++i) {
    EXPECT_EQ((*i)[1], std::to_string(std::stoi((*i)[2])));  // time code = the atlas's frame
    s.textures.push_back(std::stoi((*i)[2]));
  }
  return s;
}

TEST(UsdStage, NamesEveryFrameOnDiskAfterABakeAResumeAndARender) {
  TempDir dir("usd_stage");
  bake_demo(dir, "--keep-states all");
  const std::string stage = dir / "bake/demo.usda";
  ASSERT_TRUE(fs::exists(stage));
  EXPECT_TRUE(fs::exists(dir / "bake/demo.manifest.usda"));
  StageFrames s = stage_frames(stage);
  EXPECT_EQ(s.clips, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(s.textures, (std::vector<int>{1, 2, 3}));
  const std::string text = test::read_bytes(stage);
  EXPECT_NE(text.find("startTimeCode = 1\n"), std::string::npos);
  EXPECT_NE(text.find("endTimeCode = 3\n"), std::string::npos);
  EXPECT_NE(text.find("double2[] active = [(1, 0), (2, 1), (3, 2)]"), std::string::npos);
  EXPECT_NE(text.find("texCoord2f[] primvars:st (\n            interpolation = \"faceVarying\""), std::string::npos);
  EXPECT_NE(text.find("asset inputs:file = @./demo.color.0001.exr@"), std::string::npos) << "a default value";

  // A bake killed after frame 2: frame 3 never happened, the stage names 1-2
  // (made here by removing frame 3's files and the stage). --resume rewrites it.
  for (const char* kind : {"demo.%04d.obj", "demo.%04d.mtl", "demo.usd.%04d.usda", "demo.state.%04d.bin"})
    fs::remove(dir / ("bake/" + frame_name(kind, 3)));
  fs::remove(stage);
  bake_demo(dir, "--keep-states all --resume");
  s = stage_frames(stage);
  EXPECT_EQ(s.clips, (std::vector<int>{1, 2, 3}));

  // A render of frames 2-3 into another folder: its stage names those two.
  std::string err;
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " render '" + (dir / "bake") +
                                  "' --frames 2-3 --exemplar lava --resolution 64 -q --out '" + (dir / "r") + "'",
                              nullptr, &err, dir),
            0)
      << err;
  s = stage_frames(dir / "r/demo.usda");
  EXPECT_EQ(s.clips, (std::vector<int>{2, 3}));
  EXPECT_NE(test::read_bytes(dir / "r/demo.usda").find("startTimeCode = 2\n"), std::string::npos);
  // The render's layers are the bake's mesh and uvs of a smaller atlas: the
  // same points and indices.
  const std::string a = test::read_bytes(dir / "bake/demo.usd.0002.usda"), b = test::read_bytes(dir / "r/demo.usd.0002.usda");
  EXPECT_EQ(authored(a, "point3f[] points", 2), authored(b, "point3f[] points", 2));
  EXPECT_EQ(authored(a, "vector3f[] velocities", 2), authored(b, "vector3f[] velocities", 2));

  // --no-usd: no layer, no stage.
  TempDir other("usd_none");
  bake_demo(other, "--no-usd");
  EXPECT_FALSE(fs::exists(other / "bake/demo.usda"));
  EXPECT_FALSE(fs::exists(other / "bake/demo.usd.0001.usda"));
}

// --texture tiled: the same atlases, tiled and mip-mapped, under the same
// names (the MTL and the stage need no change), and recorded as such.
TEST(RenderReadyTextures, TextureTiledWritesTheSameAtlasesTiledAndMipMapped) {
  TempDir dir("tiled");
  bake_demo(dir, "--no-usd");
  fs::rename(dir / "bake", dir / "scanline");
  bake_demo(dir, "--no-usd --texture tiled");
  for (const char* kind : {"color", "disp"}) {
    const std::string file = std::string("demo.") + kind + ".0002.exr";
    const ImageHeader tiled = read_image_header(dir / ("bake/" + file)), plain = read_image_header(dir / ("scanline/" + file));
    EXPECT_EQ(plain.tile_width, 0) << file;
    EXPECT_EQ(tiled.tile_width, 64) << file;
    EXPECT_EQ(tiled.mip_levels, 8) << file << ": 128 down to 1";
    const Image a = read_image(dir / ("bake/" + file), ColorSpace::Linear),
                b = read_image(dir / ("scanline/" + file), ColorSpace::Linear);
    EXPECT_TRUE(a.pixels == b.pixels) << file << ": level 0 is the scanline file's";
  }
  EXPECT_EQ(test::read_bytes(dir / "bake/demo.0002.mtl"), test::read_bytes(dir / "scanline/demo.0002.mtl"));
  EXPECT_NE(test::read_bytes(dir / "bake/demo.render.0002.json").find("\"texture\": \"tiled\""), std::string::npos);
}

TEST(UsdStage, PrimNamesAreIdentifiers) {
  EXPECT_EQ(usd_prim_name("dam-break.v2"), "dam_break_v2");
  EXPECT_EQ(usd_prim_name("3d"), "_3d");
  EXPECT_EQ(usd_prim_name(""), "_");
  EXPECT_EQ(usd_prim_name("splash_A"), "splash_A");
}

}  // namespace
}  // namespace lapflow
