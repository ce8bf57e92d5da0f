// tools/blender/lapflow_import (the Blender add-on) in Debian's Blender: a small
// bake comes in as one object whose mesh and textures follow the scene frame,
// renders with the atlas's colours, reads the USD layers' velocity for motion
// blur and falls back to the OBJs. Skipped when `blender` is not on PATH.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "addons/albedo_helpers.hpp"
#include "io_test_helpers.hpp"
#include "lapflow/io/image.hpp"

namespace lapflow {
namespace {

using nlohmann::json;
using test::TempDir;
namespace fs = std::filesystem;

bool have_blender(const TempDir& dir) { return test::have_command("blender", dir); }

std::string import_test(const std::string& args) {
  return "blender -b --factory-startup -P '" LAPFLOW_SOURCE_DIR "/tools/blender/lapflow_import_test.py' -- " + args;
}

/// A 3-frame demo baked with lava into DIR/bake (meshes in DIR/mesh).
void bake_demo(const TempDir& dir) { test::bake_lava_demo(dir, 3, "--resolution 256"); }

std::string frame_file(const std::string& folder, const std::string& kind, int frame) {
  char digits[16];
  std::snprintf(digits, sizeof digits, "%04d", frame);
  if (kind == "obj") return folder + "/demo." + digits + ".obj";
  if (kind == "usd") return folder + "/demo.usd." + digits + ".usda";
  return folder + "/demo." + kind + "." + digits + ".exr";
}

std::vector<std::string> lines_of(const std::string& path) {
  std::istringstream in(test::read_bytes(path));
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::vector<std::string> words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> w;
  for (std::string s; in >> s;) w.push_back(s);
  return w;
}

struct ObjCounts {
  long vertices = 0, faces = 0;
};
ObjCounts obj_counts(const std::string& path) {
  ObjCounts c;
  for (const std::string& line : lines_of(path)) {
    if (line.rfind("v ", 0) == 0) ++c.vertices;
    if (line.rfind("f ", 0) == 0) ++c.faces;
  }
  return c;
}

/// The numbers of a USD layer's `velocities` (one line), as (x, y, z).
std::vector<std::array<double, 3>> usda_velocities(const std::string& path) {
  std::vector<std::array<double, 3>> v;
  for (std::string line : lines_of(path)) {
    const std::size_t name = line.find(" velocities"), eq = line.find('=');
    if (name == std::string::npos || eq == std::string::npos || line.find('[', eq) == std::string::npos) continue;
    line = line.substr(line.find('[', eq) + 1);
    for (char& c : line)
      if (c == '(' || c == ')' || c == ',' || c == ']' || c == '}') c = ' ';
    std::istringstream in(line);
    for (std::array<double, 3> p; in >> p[0] >> p[1] >> p[2];) v.push_back(p);
  }
  return v;
}

double max_speed(const std::vector<std::array<double, 3>>& v) {
  double m = 0;
  for (const auto& p : v) m = std::max(m, std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]));
  return m;
}

/// The test's own velocity of vertex i of n at `frame`, in m/s.
std::array<double, 3> fixture_velocity(long i, long n, int frame) { return {2.0 + double(i) / double(n), -1.0, 0.5 * frame}; }

/// Writes frame `frame`'s USD layer, in the shape lapflow bake writes, from
/// the bake's OBJ (points, st and normals as the OBJ's v, vt and vn text;
/// faces and per-corner st indices from its f lines) and fixture_velocity.
void write_usda_from_obj(const std::string& obj, int frame, const std::string& out) {
  std::vector<std::string> points, st, normals, counts, indices, st_indices;
  std::array<double, 3> lo{1e30, 1e30, 1e30}, hi{-1e30, -1e30, -1e30};
  for (const std::string& line : lines_of(obj)) {
    const std::vector<std::string> w = words(line);
    if (w.empty()) continue;
    if (w[0] == "v") {
      points.push_back("(" + w[1] + ", " + w[2] + ", " + w[3] + ")");
      for (int k = 0; k < 3; ++k) {
        lo[std::size_t(k)] = std::min(lo[std::size_t(k)], std::stod(w[std::size_t(k) + 1]));
        hi[std::size_t(k)] = std::max(hi[std::size_t(k)], std::stod(w[std::size_t(k) + 1]));
      }
    } else if (w[0] == "vt") {
      st.push_back("(" + w[1] + ", " + w[2] + ")");
    } else if (w[0] == "vn") {
      normals.push_back("(" + w[1] + ", " + w[2] + ", " + w[3] + ")");
    } else if (w[0] == "f") {
      counts.push_back(std::to_string(w.size() - 1));
      for (std::size_t k = 1; k < w.size(); ++k) {
        const std::size_t s1 = w[k].find('/'), s2 = w[k].find('/', s1 + 1);
        indices.push_back(std::to_string(std::stol(w[k].substr(0, s1)) - 1));
        st_indices.push_back(std::to_string(std::stol(w[k].substr(s1 + 1, s2 - s1 - 1)) - 1));
      }
    }
  }
  std::vector<std::string> velocities;
  for (long i = 0; i < long(points.size()); ++i) {
    const auto v = fixture_velocity(i, long(points.size()), frame);
    char b[96];
    std::snprintf(b, sizeof b, "(%.9g, %.9g, %.9g)", v[0], v[1], v[2]);
    velocities.push_back(b);
  }
  auto array = [](const std::vector<std::string>& items) {
    std::string s = "[";
    for (std::size_t i = 0; i < items.size(); ++i) s += (i ? ", " : "") + items[i];
    return s + "]";
  };
  char extent[256];
  std::snprintf(extent, sizeof extent, "[(%.9g, %.9g, %.9g), (%.9g, %.9g, %.9g)]", lo[0], lo[1], lo[2], hi[0], hi[1],
                hi[2]);
  const std::string f = std::to_string(frame);
  std::ostringstream o;
  o << "#usda 1.0\n(\n    doc = \"lapflow demo frame " << f << "\"\n)\n\ndef Mesh \"surface\"\n{\n"
    << "    float3[] extent.timeSamples = { " << f << ": " << extent << " }\n"
    << "    int[] faceVertexCounts.timeSamples = { " << f << ": " << array(counts) << " }\n"
    << "    int[] faceVertexIndices.timeSamples = { " << f << ": " << array(indices) << " }\n"
    << "    normal3f[] normals.timeSamples = { " << f << ": " << array(normals) << " }\n"
    << "    point3f[] points.timeSamples = { " << f << ": " << array(points) << " }\n"
    << "    int[] primvars:st:indices.timeSamples = { " << f << ": " << array(st_indices) << " }\n"
    << "    texCoord2f[] primvars:st.timeSamples = { " << f << ": " << array(st) << " }\n"
    << "    vector3f[] velocities.timeSamples = { " << f << ": " << array(velocities) << " }\n"
    << "}\n";
  test::write_bytes(out, o.str());
}

/// A copy of the bake's manifest and atlases, plus the files `keep` says.
void copy_bake(const std::string& from, const std::string& to, bool keep_obj, bool keep_usd) {
  fs::create_directories(to);
  for (const std::string& name : test::names_in(from)) {
    const bool manifest = name == "demo.bake.json";
    const bool atlas = name.find(".exr") != std::string::npos;
    const bool obj = name.find(".obj") != std::string::npos || name.find(".mtl") != std::string::npos;
    const bool usd = name.find(".usd") != std::string::npos;
    if (manifest || atlas || (keep_obj && obj) || (keep_usd && usd)) fs::copy_file(from + "/" + name, to + "/" + name);
  }
}

int occurrences(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

using test::Rgb;
using test::chroma_distance;
using test::luma;

/// The atlas's mean colour over chart texels (A = 1).
Rgb atlas_mean(const std::string& path) {
  const Image atlas = read_image(path);
  Rgb mean{};
  double n = 0;
  for (std::size_t p = 0; p < std::size_t(atlas.width) * atlas.height; ++p)
    if (atlas.pixels[p * 4 + 3] > 0.5f) {
      for (std::size_t c = 0; c < 3; ++c) mean[c] += atlas.pixels[p * 4 + c];
      ++n;
    }
  for (double& v : mean) v /= n;
  return mean;
}

/// What the camera saw of the object (blender_test.cpp's measure): over lit
/// object pixels, the mean textured and grey colours and the seen albedo
/// (textured / grey x 0.18), its variation, and the object's coverage.
struct Seen {
  Rgb tex{}, grey{}, albedo{};
  double lit = 0, object = 0, pixels = 0, variation = 0;
};
Seen seen_albedo(const Image& tex, const Image& grey) {
  Seen s;
  std::vector<double> albedo_luma;
  s.pixels = double(tex.width) * tex.height;
  for (std::size_t p = 0; p < std::size_t(tex.width) * tex.height; ++p) {
    const float* t = &tex.pixels[p * 4];
    const float* g = &grey.pixels[p * 4];
    if (t[3] > 0.5f) ++s.object;
    if (t[3] < 0.99f || g[3] < 0.99f || g[1] < 0.02f) continue;
    Rgb albedo;
    for (std::size_t c = 0; c < 3; ++c) {
      s.tex[c] += t[c];
      s.grey[c] += g[c];
      albedo[c] = 0.18 * t[c] / g[c];
      s.albedo[c] += albedo[c];
    }
    albedo_luma.push_back(luma(albedo));
  }
  s.lit = double(albedo_luma.size());
  if (s.lit == 0) return s;
  for (std::size_t c = 0; c < 3; ++c) s.tex[c] /= s.lit, s.grey[c] /= s.lit, s.albedo[c] /= s.lit;
  double var = 0;
  for (double l : albedo_luma) var += (l - luma(s.albedo)) * (l - luma(s.albedo));
  s.variation = std::sqrt(var / s.lit) / luma(s.albedo);
  return s;
}

/// Mean absolute difference of two renders' alpha (the object's silhouette).
double alpha_difference(const Image& a, const Image& b) {
  double d = 0;
  for (std::size_t p = 0; p < std::size_t(a.width) * a.height; ++p)
    d += std::abs(a.pixels[p * 4 + 3] - b.pixels[p * 4 + 3]);
  return d / (double(a.width) * a.height);
}

json facts_in(const std::string& out) { return json::parse(test::read_bytes(out + "/facts.json")); }

TEST(BlenderImport, ABakeIsOneObjectWhoseMeshAndTexturesFollowTheFrame) {
  TempDir dir("blender_import");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender add-on is not tested here";
  ASSERT_NO_FATAL_FAILURE(bake_demo(dir));
  const std::string bake = dir / "bake";
  std::map<int, ObjCounts> counts;
  for (int f = 1; f <= 3; ++f) counts[f] = obj_counts(frame_file(bake, "obj", f));
  const bool has_usd = fs::exists(frame_file(bake, "usd", 1));

  // Installed from a zip through Blender's preferences, into a scratch
  // user scripts folder; imported through the operator of the File > Import
  // entry; three frames stepped; frames 2 and 3 rendered as an animation.
  std::string out, err;
  fs::create_directories(dir / "scripts");
  ASSERT_EQ(test::run_command("BLENDER_USER_SCRIPTS='" + (dir / "scripts") + "' " +
                                  import_test("--bake '" + bake + "' --out '" + (dir / "out") +
                                              "' --install --samples 16 --resolution 160x120"),
                              &out, &err, dir),
            0)
      << out << err;
  const json facts = facts_in(dir / "out");
  EXPECT_EQ(facts["addon_file"].get<std::string>().rfind(dir / "scripts", 0), 0u) << facts["addon_file"];
  EXPECT_TRUE(facts["menu"].get<bool>());
  EXPECT_TRUE(facts["handler"].get<bool>());
  EXPECT_EQ(facts["operator"], json::array({"FINISHED"}));
  EXPECT_EQ(facts["objects"], json::array({"demo"}));
  EXPECT_EQ(facts["scene_frames"], json::array({1, 3}));

  // Steps: frames 1, 2, 3, back to 2, 2 again, sub-frames 1.6 and 2.4, then
  // frame 0 (before the bake: its first frame held) and 5 (after: the last).
  const json& steps = facts["steps"];
  ASSERT_EQ(steps.size(), 9u) << steps;
  const int step_frame[] = {1, 2, 3, 2, 2, 2, 2, 1, 3};
  const int step_loads[] = {1, 2, 3, 4, 4, 4, 4, 5, 6};  // no reload for the same frame or its sub-frames
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const json& s = steps[i];
    const int f = step_frame[i];
    SCOPED_TRACE("step " + std::to_string(i) + ": " + s.dump());
    EXPECT_EQ(s["mesh_frame"].get<int>(), f);
    EXPECT_EQ(s["vertices"].get<long>(), counts[f].vertices);
    EXPECT_EQ(s["faces"].get<long>(), counts[f].faces);
    EXPECT_EQ(s["corners"].get<long>(), 3 * counts[f].faces);
    EXPECT_EQ(s["evaluated_vertices"].get<long>(), counts[f].vertices);  // through the artist's modifier
    EXPECT_TRUE(s["uv"].get<bool>());
    EXPECT_EQ(s["loads"].get<int>(), step_loads[i]);
    EXPECT_EQ(s["source"], has_usd ? "usd" : "obj");
    if (i < 5 || i > 6) {  // whole frames: the texture shows the mesh's frame
      EXPECT_EQ(s["color_frame"].get<int>(), f);
      char name[64];
      std::snprintf(name, sizeof name, "demo.color.%04d.exr", f);
      EXPECT_EQ(s["color_file"], name);
    }
    const std::vector<std::array<double, 3>> v =
        has_usd ? usda_velocities(frame_file(bake, "usd", f)) : std::vector<std::array<double, 3>>{};
    EXPECT_EQ(s["velocity"].get<bool>(), !v.empty());
    if (!v.empty()) {
      EXPECT_EQ(s["velocity_domain"], "POINT");
      EXPECT_EQ(s["velocity_type"], "FLOAT_VECTOR");
      EXPECT_EQ(s["velocity_count"].get<long>(), counts[f].vertices);
      EXPECT_NEAR(s["velocity_max"].get<double>(), max_speed(v), 1e-5 * (1 + max_speed(v)));
      EXPECT_EQ(s["evaluated_velocity"].get<bool>(), true);
    }
  }
  if (!has_usd) {
    EXPECT_EQ(occurrences(out, "no USD layer"), 1) << out;  // said once, not per frame
  }

  // The artist's transforms, modifier, mesh and material survive the swaps.
  const json& kept = facts["kept"];
  EXPECT_NEAR(kept["location"][0].get<double>(), 0.05, 1e-6);
  EXPECT_NEAR(kept["scale"][2].get<double>(), 1.2, 1e-6);
  EXPECT_NEAR(kept["rotation"][2].get<double>(), 20 * std::numbers::pi / 180, 1e-6);
  EXPECT_EQ(kept["modifiers"], json::array({"TRIANGULATE"}));
  EXPECT_TRUE(kept["mesh_kept"].get<bool>());
  EXPECT_TRUE(kept["material_kept"].get<bool>());
  EXPECT_TRUE(kept["lock_interface"].get<bool>());

  // The animation render swapped the mesh per frame (textured, then grey).
  const json& rendered = facts["rendered_meshes"];
  ASSERT_EQ(rendered.size(), 4u) << rendered;
  for (const json& r : rendered) {
    const int f = r["frame"].get<int>();
    EXPECT_EQ(r["mesh_frame"].get<int>(), f) << r;
    EXPECT_EQ(r["vertices"].get<long>(), counts[f].vertices) << r;
  }
  EXPECT_EQ(rendered[0]["frame"], 2);
  EXPECT_EQ(rendered[1]["frame"], 3);

  // Each render shows its frame's atlas colours (blender_test.cpp's measure).
  for (const json& r : facts["renders"]) {
    const int f = r["frame"].get<int>();
    const Image tex = read_image(r["textured"].get<std::string>()), grey = read_image(r["grey"].get<std::string>());
    ASSERT_EQ(tex.width, 160);
    ASSERT_EQ(tex.height, 120);
    ASSERT_EQ(tex.channels, 4);
    ASSERT_EQ(grey.channels, 4);
    const Rgb atlas = atlas_mean(frame_file(bake, "color", f));
    const Seen s = seen_albedo(tex, grey);
    std::printf("frame %d: atlas mean %.3f %.3f %.3f | seen albedo %.3f %.3f %.3f (variation %.2f, object %.0f%%) | "
                "chroma distance textured %.3f, grey %.3f\n",
                f, atlas[0], atlas[1], atlas[2], s.albedo[0], s.albedo[1], s.albedo[2], s.variation,
                100 * s.object / s.pixels, chroma_distance(s.tex, atlas), chroma_distance(s.grey, atlas));
    ASSERT_GT(s.lit, 0.05 * s.pixels) << "frame " << f << ": the object covers too little of the frame";
    EXPECT_LT(s.object, 0.95 * s.pixels) << "frame " << f << ": the object fills the whole frame";
    EXPECT_LT(chroma_distance(s.albedo, atlas), 0.05) << "frame " << f;
    EXPECT_NEAR(luma(s.albedo) / luma(atlas), 1.0, 0.3) << "frame " << f;
    EXPECT_LT(chroma_distance(s.tex, atlas), 0.5 * chroma_distance(s.grey, atlas)) << "frame " << f;
    EXPECT_GT(s.variation, 0.2) << "frame " << f;
  }

  // Saved and opened again: the object is re-linked to its bake.
  const json& re = facts["reopened"];
  EXPECT_EQ(re["vertices"].get<long>(), counts[1].vertices) << re;
  EXPECT_EQ(re["stepped_mesh_frame"], 3) << re;
  EXPECT_EQ(re["stepped_vertices"].get<long>(), counts[3].vertices) << re;
  EXPECT_EQ(re["stepped_color_frame"], 3) << re;
  EXPECT_EQ(re["modifiers"], json::array({"TRIANGULATE"})) << re;
  EXPECT_NEAR(re["location"][0].get<double>(), 0.05, 1e-6) << re;
}

TEST(BlenderImport, ReadsTheUsdLayersVelocityForMotionBlurAndFallsBackToTheObjs) {
  TempDir dir("blender_import_usd");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender add-on is not tested here";
  ASSERT_NO_FATAL_FAILURE(bake_demo(dir));
  const std::string bake = dir / "bake";
  std::map<int, ObjCounts> counts;
  for (int f = 1; f <= 3; ++f) counts[f] = obj_counts(frame_file(bake, "obj", f));

  // USD layers only (no OBJ to fall back on), with a velocity the test knows.
  const std::string usd_only = dir / "usd_only";
  copy_bake(bake, usd_only, false, false);
  for (int f = 1; f <= 3; ++f) write_usda_from_obj(frame_file(bake, "obj", f), f, frame_file(usd_only, "usd", f));
  std::string out, err;
  ASSERT_EQ(test::run_command(import_test("--bake '" + usd_only + "' --out '" + (dir / "o_usd") +
                                          "' --no-render --motion-blur 2 --samples 4 --resolution 80x60"),
                              &out, &err, dir),
            0)
      << out << err;
  json facts = facts_in(dir / "o_usd");
  for (std::size_t i = 0; i < 3; ++i) {
    const json& s = facts["steps"][i];
    const int f = int(i) + 1;
    SCOPED_TRACE(s.dump());
    EXPECT_EQ(s["source"], "usd");
    EXPECT_EQ(s["vertices"].get<long>(), counts[f].vertices);
    EXPECT_EQ(s["faces"].get<long>(), counts[f].faces);
    EXPECT_EQ(s["color_frame"].get<int>(), f);
    ASSERT_TRUE(s["velocity"].get<bool>());
    const long n = counts[f].vertices;
    const auto first = fixture_velocity(0, n, f), last = fixture_velocity(n - 1, n, f);
    for (std::size_t k = 0; k < 3; ++k) {
      EXPECT_NEAR(s["velocity_first"][k].get<double>(), first[k], 1e-5);
      EXPECT_NEAR(s["velocity_last"][k].get<double>(), last[k], 1e-5);
    }
    EXPECT_NEAR(s["velocity_max"].get<double>(), std::sqrt(last[0] * last[0] + 1 + last[2] * last[2]), 1e-4);
  }
  EXPECT_EQ(occurrences(out, "no USD layer"), 0) << out;

  // Cycles blurs the mesh along its `velocity` attribute, and only along it:
  // without the attribute the blurred render is the still one.
  const json& mb = facts["motion_blur"];
  EXPECT_EQ(mb["loads"][0], mb["loads"][2]) << mb;  // no mesh read during the motion steps
  EXPECT_TRUE(mb["velocity_after_reload"].get<bool>());
  const Image still = read_image(mb["still"].get<std::string>());
  const Image blurred = read_image(mb["blurred"].get<std::string>());
  const Image no_velocity = read_image(mb["blurred_without_velocity"].get<std::string>());
  ASSERT_EQ(still.channels, 4);
  const double blur = alpha_difference(blurred, still), none = alpha_difference(no_velocity, still);
  std::printf("motion blur: silhouette change with velocity %.4f, without %.4f\n", blur, none);
  EXPECT_GT(blur, 0.005);
  EXPECT_LT(none, 0.1 * blur);

  // OBJs only: the same meshes, no velocity, said once.
  const std::string obj_only = dir / "obj_only";
  copy_bake(bake, obj_only, true, false);
  ASSERT_EQ(test::run_command(import_test("--bake '" + obj_only + "' --out '" + (dir / "o_obj") + "' --no-render"),
                              &out, &err, dir),
            0)
      << out << err;
  facts = facts_in(dir / "o_obj");
  for (std::size_t i = 0; i < 3; ++i) {
    const json& s = facts["steps"][i];
    const int f = int(i) + 1;
    SCOPED_TRACE(s.dump());
    EXPECT_EQ(s["source"], "obj");
    EXPECT_EQ(s["vertices"].get<long>(), counts[f].vertices);
    EXPECT_EQ(s["faces"].get<long>(), counts[f].faces);
    EXPECT_FALSE(s["velocity"].get<bool>());
  }
  EXPECT_EQ(occurrences(out, "no USD layer"), 1) << out;
}

TEST(BlenderImport, AMissingBakeFailsWithAClearMessage) {
  TempDir dir("blender_import_missing");
  if (!have_blender(dir)) GTEST_SKIP() << "blender is not on PATH: the Blender add-on is not tested here";
  std::string err;
  EXPECT_EQ(test::run_command(import_test("--bake '" + (dir / "no_such_bake") + "' --out '" + (dir / "o") + "'"),
                              nullptr, &err, dir),
            2);
  EXPECT_NE(err.find("no_such_bake"), std::string::npos) << err;
}

}  // namespace
}  // namespace lapflow
