// lapflow preview: known-answer renders of tiny scenes (colour, shadow, bump,
// background), a stored reference picture, determinism across thread
// counts, camera framing, labels, and the command (--compare, errors).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/addons/preview.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

const Vec3 kRed{0.8, 0.1, 0.1}, kBlue{0.1, 0.1, 0.8};

/// Adds quad [x0,x1] x [y0,y1] at height z (normal +z) with uv = ((x+1)/2, (y+1)/2)
/// clamped to `uv_box` (u0, v0, u1, v1) when given.
void add_quad(UvMesh& m, double x0, double y0, double x1, double y1, double z, bool own_uv = false, Vec2 uv = {}) {
  const int b = int(m.mesh.positions.size());
  const Vec3 p[4] = {{x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}};
  for (const Vec3& q : p) m.mesh.positions.push_back(q);
  m.mesh.triangles.push_back({b, b + 1, b + 2});
  m.mesh.triangles.push_back({b, b + 2, b + 3});
  for (const Tri& t : {Tri{0, 1, 2}, Tri{0, 2, 3}})
    for (int k : t) m.corner_uv.push_back(own_uv ? uv : Vec2{(p[k].x + 1) / 2, (p[k].y + 1) / 2});
}

/// A 16x16 atlas: left half red, right half blue.
Image red_blue_atlas() {
  Image a(16, 16, 4, 1.f);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x)
      for (int c = 0; c < 3; ++c) a.at(x, y, c) = float(x < 8 ? kRed[c] : kBlue[c]);
  return a;
}

/// Looking straight down -z at the unit square from z = 3, picture up = +y.
PreviewCamera top_camera() {
  PreviewCamera cam;
  cam.eye = {0, 0, 3};
  cam.target = {0, 0, 0};
  cam.up = {0, 1, 0};
  cam.fov = 60;
  return cam;
}

/// Plain lighting: no ground, specular or reflection; up = +y so a +z normal
/// gets the mean of the two fills.
PreviewOptions plain_options(const Vec3& light) {
  PreviewOptions o;
  o.width = 160;
  o.height = 90;
  o.samples = 4;
  o.look.up = {0, 1, 0};
  o.look.light_dir = light;
  o.look.light_angle = 0;
  o.look.ground = false;
  o.look.specular = 0;
  o.look.reflection = 0;
  return o;
}

/// Pixel of world point p under top_camera() for a w x h picture.
Vec2 project(const Vec3& p, int w, int h) {
  const double t = std::tan(30 * std::numbers::pi / 180), aspect = double(w) / h, depth = 3 - p.z;
  return {0.5 * w * (1 + p.x / (depth * t * aspect)), 0.5 * h * (1 - p.y / (depth * t))};
}

Vec3 pixel(const Image& img, const Vec2& at) {
  const int x = int(at.x), y = int(at.y);
  return {img.at(x, y, 0), img.at(x, y, 1), img.at(x, y, 2)};
}

void expect_color(const Vec3& got, const Vec3& want, double tol, const std::string& what) {
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], tol * std::max(0.05, want[c])) << what << " channel " << c;
}

Vec3 mul(const Vec3& a, const Vec3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

TEST(Preview, PlaneShowsItsAtlasUnderTheDocumentedLighting) {
  UvMesh m;
  add_quad(m, -1, -1, 1, 1, 0);
  // An occluder above the plane, lit from +x at 45 degrees: its shadow falls
  // 0.5 to the -x side of it, on both halves of the plane.
  add_quad(m, 0.3, -0.2, 0.7, 0.2, 0.5, true, {0.25, 0.5});
  const PreviewFrame frame = make_preview_frame(m, red_blue_atlas(), Image(), 1.0);
  const Vec3 light = normalized(Vec3{1, 0, 1});
  const PreviewOptions o = plain_options(light);
  Box3 box = bounding_box(m.mesh);
  const Image img = render_preview(frame, top_camera(), box, o);
  ASSERT_EQ(img.width, 160);
  ASSERT_EQ(img.height, 90);

  const PreviewLook& L = o.look;
  const Vec3 ambient = (L.sky_fill + L.ground_fill) * (0.5 * L.ambient);  // n = +z is level with up = +y
  const Vec3 lit = L.key * dot(Vec3{0, 0, 1}, light) + ambient;
  expect_color(pixel(img, project({-0.7, 0.6, 0}, 160, 90)), mul(kRed, lit), 0.02, "lit red");
  expect_color(pixel(img, project({0.7, -0.6, 0}, 160, 90)), mul(kBlue, lit), 0.02, "lit blue");
  // In the occluder's shadow only the ambient fill remains.
  expect_color(pixel(img, project({-0.12, 0, 0}, 160, 90)), mul(kRed, ambient), 0.02, "shadowed red");
  expect_color(pixel(img, project({0.12, 0, 0}, 160, 90)), mul(kBlue, ambient), 0.02, "shadowed blue");
  // Outside the plane: the sky, lerp(horizon, zenith, sqrt(max(0, d.up))).
  for (const Vec2 px : {Vec2{2.5, 2.5}, Vec2{157.5, 87.5}}) {
    const double t = std::tan(30 * std::numbers::pi / 180);
    const Vec3 d = normalized(Vec3{(2 * px.x / 160 - 1) * t * 160 / 90, (1 - 2 * px.y / 90) * t, -1});
    const Vec3 want = L.horizon + (L.zenith - L.horizon) * std::sqrt(std::max(0.0, d.y));
    expect_color(pixel(img, px), want, 0.02, "sky");
  }
}

TEST(Preview, BumpTiltsTheNormalDownTheDisplacementSlope) {
  // Height H = u over the plane: with bump * radius = 2 the surface rises
  // 2 * dH/dx = 2 * 0.5 = 1 m per metre towards +x, so its normal is (-1, 0, 1)/sqrt 2.
  UvMesh m;
  add_quad(m, -1, -1, 1, 1, 0);
  Image color(64, 64, 4, 1.f), height(64, 64, 1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      for (int c = 0; c < 3; ++c) color.at(x, y, c) = 0.5f;
      height.at(x, y, 0) = (x + 0.5f) / 64;
    }
  const PreviewFrame frame = make_preview_frame(m, color, height, 1.0);
  const Vec3 at{0.1, 0.2, 0};
  for (const double sx : {-1.0, 1.0}) {
    PreviewOptions o = plain_options(normalized(Vec3{sx, 0, 1}));
    o.look.bump = 2;
    const Image img = render_preview(frame, top_camera(), bounding_box(m.mesh), o);
    const Vec3 n = normalized(Vec3{-1, 0, 1});
    const Vec3 ambient = (o.look.sky_fill + o.look.ground_fill) * (0.5 * o.look.ambient);
    const Vec3 want = (o.look.key * std::max(0.0, dot(n, o.look.light_dir)) + ambient) * 0.5;
    expect_color(pixel(img, project(at, 160, 90)), want, 0.03, sx < 0 ? "light down the slope" : "light up the slope");
  }
}

/// The reference scene: a checkered, bumpy ball on the ground, default look.
PreviewFrame reference_frame() {
  UvMesh m;
  m.mesh = test::icosphere(3, 0.5, {0, 0, 0.5});
  const double pi = std::numbers::pi;
  for (const Tri& t : m.mesh.triangles) {
    Vec2 uv[3];
    for (int k = 0; k < 3; ++k) {
      const Vec3 d = normalized(m.mesh.positions[t[k]] - Vec3{0, 0, 0.5});
      uv[k] = {std::atan2(d.y, d.x) / (2 * pi) + 0.5, std::acos(std::clamp(d.z, -1.0, 1.0)) / pi};
    }
    for (int k = 0; k < 3; ++k)  // no triangle across the seam
      if (std::max({uv[0].x, uv[1].x, uv[2].x}) - uv[k].x > 0.5) uv[k].x += 1;
    for (const Vec2& u : uv) m.corner_uv.push_back(u);
  }
  Image color(64, 64, 4, 1.f), height(64, 64, 1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool odd = ((x / 8) + (y / 8)) % 2;
      const Vec3 c = odd ? Vec3{0.85, 0.45, 0.1} : Vec3{0.1, 0.45, 0.5};
      for (int k = 0; k < 3; ++k) color.at(x, y, k) = float(c[k]);
      height.at(x, y, 0) = odd ? 1.f : 0.f;
    }
  return make_preview_frame(std::move(m), color, height, 0.1);
}

TEST(Preview, SmallSceneMatchesTheStoredReferencePicture) {
  const PreviewFrame frame = reference_frame();
  PreviewOptions o;
  o.width = 160;
  o.height = 90;
  o.samples = 4;
  const Box3 box = bounding_box(frame.mesh.mesh);
  const Image img = render_preview(frame, frame_camera(frame.mesh.mesh.positions, o.look.up, 160.0 / 90), box, o);
  const std::string ref = LAPFLOW_SOURCE_DIR "/tests/data/preview_reference.png";
  if (std::getenv("LAPFLOW_UPDATE_REFERENCE")) {
    write_png(ref, img, true);
    GTEST_SKIP() << "wrote " << ref;
  }
  // Compare in sRGB 8-bit, as stored.
  test::TempDir dir("preview_ref");
  write_png(dir / "now.png", img, true);
  const Image now = read_image(dir / "now.png", ColorSpace::Linear), want = read_image(ref, ColorSpace::Linear);
  ASSERT_EQ(now.width, want.width);
  ASSERT_EQ(now.height, want.height);
  ASSERT_GE(want.channels, 3);
  double sum = 0, worst = 0;
  for (int y = 0; y < now.height; ++y)
    for (int x = 0; x < now.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const double d = std::abs(double(now.at(x, y, c)) - want.at(x, y, c));
        sum += d;
        worst = std::max(worst, d);
      }
  const double mad = sum / (3.0 * now.width * now.height);
  EXPECT_LT(mad, 2.0 / 255) << "mean absolute difference " << mad << ", worst pixel " << worst;
}

TEST(Preview, SameBytesAtOneAndTwoThreads) {
  const PreviewFrame frame = reference_frame();
  PreviewOptions o;
  o.width = 96;
  o.height = 64;
  o.samples = 9;
  const Box3 box = bounding_box(frame.mesh.mesh);
  const PreviewCamera cam = frame_camera(box, o.look.up, 1.5, 20, 35);
  set_thread_count(1);
  const Image one = render_preview(frame, cam, box, o);
  set_thread_count(2);
  const Image two = render_preview(frame, cam, box, o);
  set_thread_count(0);
  ASSERT_EQ(one.pixels.size(), two.pixels.size());
  EXPECT_EQ(0, std::memcmp(one.pixels.data(), two.pixels.data(), one.pixels.size() * sizeof(float)));
}

TEST(Preview, FramedCameraFitsTheWholeBoxTightly) {
  Box3 box;
  box.extend({0.04, 0.04, 0.04});
  box.extend({1.96, 0.96, 0.96});  // the dam break's tank
  for (const double aspect : {16.0 / 9, 1.0, 0.5})
    for (const double az : {-35.0, 0.0, 120.0}) {
      const PreviewCamera cam = frame_camera(box, {0, 0, 1}, aspect, az, 28, 30);
      const Vec3 f = normalized(cam.target - cam.eye), r = normalized(cross(f, cam.up)), u = cross(r, f);
      const double tv = std::tan(15 * std::numbers::pi / 180), th = tv * aspect;
      double most = 0;  // largest |projected coordinate| / half extent over the corners
      for (int k = 0; k < 8; ++k) {
        const Vec3 c{(k & 1) ? box.hi.x : box.lo.x, (k & 2) ? box.hi.y : box.lo.y, (k & 4) ? box.hi.z : box.lo.z};
        const Vec3 q = c - cam.eye;
        ASSERT_GT(dot(q, f), 0);
        most = std::max({most, std::abs(dot(q, r) / dot(q, f)) / th, std::abs(dot(q, u) / dot(q, f)) / tv});
      }
      EXPECT_LE(most, 0.9 + 1e-9) << "aspect " << aspect << " azimuth " << az;  // inside the 10% margin
      EXPECT_GT(most, 0.9 - 1e-9) << "aspect " << aspect << " azimuth " << az;        // and not far away
      EXPECT_GT(cam.eye.z, box.center().z);  // elevated
    }
}

TEST(Preview, LabelsNeedTheirFont) {
  Image img(120, 40, 3, 0.5f);
  EXPECT_FALSE(draw_label(img, 2, 2, "erosion", 16, "/nonexistent/font.ttf"));
  for (float v : img.pixels) ASSERT_EQ(v, 0.5f);  // untouched
  if (!std::filesystem::exists(default_label_font())) GTEST_SKIP() << "no " << default_label_font();
  ASSERT_TRUE(draw_label(img, 2, 2, "erosion", 16, default_label_font()));
  int white = 0, dark = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      white += img.at(x, y, 0) > 0.9f;
      dark += std::abs(img.at(x, y, 0) - 0.15f) < 1e-4f;
    }
  EXPECT_GT(white, 30);  // glyph pixels
  EXPECT_GT(dark, 200);  // the backing box
  for (int y = 30; y < 40; ++y) EXPECT_EQ(img.at(110, y, 0), 0.5f);  // nothing outside the box
}

/// A one-quad bake of frames 1-2 in `dir` whose atlas is one colour.
void write_fake_bake(const std::string& dir, const std::string& mode, const Vec3& color) {
  std::filesystem::create_directories(dir);
  BakeManifest m;
  m.name = "shot";
  m.dir = dir;
  m.frames = {1, 2};
  m.options.raster.mode = parse_raster_mode(mode);
  m.options.patch.radius = 0.1;
  write_bake_manifest(m, bake_manifest_path(dir, "shot"));
  for (int f : m.frames) {
    test::write_bytes(m.frame_file("obj", f),
                      "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                      "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
    Image c(8, 8, 4, 1.f), h(8, 8, 1, 0.f);
    for (int i = 0; i < 64; ++i)
      for (int k = 0; k < 3; ++k) c.pixels[4 * i + k] = float(color[k]);
    write_exr(m.frame_file("color", f), c, {"R", "G", "B", "A"});
    write_exr(m.frame_file("disp", f), h, {"Y"});
  }
}

TEST(PreviewCommand, CompareWritesOnePanelPerBakeSideBySide) {
  test::TempDir dir("preview_cmd");
  write_fake_bake(dir / "a", "erosion", kRed);
  write_fake_bake(dir / "b", "blend", kBlue);
  std::string out, err;
  const std::string cmd = std::string(LAPFLOW_BINARY) + " preview " + (dir / "a") + " --compare " + (dir / "b") +
                          " --width 64 --height 48 --samples 1 --no-video --out " + (dir / "out");
  ASSERT_EQ(test::run_command(cmd, &out, &err, dir), 0) << err;
  for (const char* f : {"shot.compare.0001.png", "shot.compare.0002.png"}) {
    const Image img = read_image(dir / ("out/" + std::string(f)), ColorSpace::Linear);
    EXPECT_EQ(img.width, 2 * 64 + 2) << f;  // two panels and a 2-pixel gap
    EXPECT_EQ(img.height, 48) << f;
    // The quad fills the middle of each panel: red on the left, blue on the right.
    const int y = 30;
    EXPECT_GT(img.at(32, y, 0), 2 * img.at(32, y, 2)) << f;
    EXPECT_GT(img.at(66 + 32, y, 2), 2 * img.at(66 + 32, y, 0)) << f;
  }
}

TEST(PreviewCommand, VideoWithFfmpegAndOneWarningWithout) {
  test::TempDir dir("preview_video");
  write_fake_bake(dir / "a", "erosion", kRed);
  std::string out, err;
  const std::string args = " preview " + (dir / "a") + " --width 48 --height 32 --samples 1 --out " + (dir / "out");
  // No ffmpeg on PATH: the pictures, no MP4, and a warning that says why.
  ASSERT_EQ(test::run_command("PATH=/nonexistent " + std::string(LAPFLOW_BINARY) + args, &out, &err, dir), 0) << err;
  EXPECT_TRUE(std::filesystem::exists(dir / "out/shot.preview.0002.png"));
  EXPECT_FALSE(std::filesystem::exists(dir / "out/shot.preview.mp4"));
  EXPECT_NE(err.find("no ffmpeg"), std::string::npos) << err;
  if (!ffmpeg_available()) GTEST_SKIP() << "no ffmpeg here";
  ASSERT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + args, &out, &err, dir), 0) << err;
  const std::string mp4 = test::read_bytes(dir / "out/shot.preview.mp4");
  ASSERT_GT(mp4.size(), 100u);
  EXPECT_EQ(mp4.substr(4, 4), "ftyp");  // an ISO media file
  for (const auto& e : std::filesystem::directory_iterator(dir / "out"))  // no scratch or temporary files left
    EXPECT_TRUE(e.path().extension() == ".png" || e.path().extension() == ".mp4") << e.path();
}

TEST(PreviewCommand, MissingFilesAreErrorsNamingThem) {
  test::TempDir dir("preview_bad");
  write_fake_bake(dir / "a", "erosion", kRed);
  std::string out, err;
  const std::string bin = LAPFLOW_BINARY;
  // A frame outside the bake.
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "a") + " --frames 1-3 --no-video", &out, &err, dir), 2);
  EXPECT_NE(err.find("shot.0003.obj"), std::string::npos) << err;
  // A deleted colour atlas.
  std::filesystem::remove(dir / "a/shot.color.0002.exr");
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "a") + " --width 32 --height 24 --no-video", &out, &err, dir), 2);
  EXPECT_NE(err.find("shot.color.0002.exr"), std::string::npos) << err;
  // No manifest.
  EXPECT_EQ(test::run_command(bin + " preview " + (dir / "out"), &out, &err, dir), 2);
  EXPECT_NE(err.find(dir / "out"), std::string::npos) << err;
}

}  // namespace

TEST(PreviewCameras, ATurntableKeepsItsLargestDistanceAndAFixedEyeOrbitsItsTarget) {
  // A long, flat slab: framed from each side, the distance needed differs.
  std::vector<Vec3> points;
  for (int k = 0; k < 8; ++k) points.push_back({(k & 1) ? 2.0 : -2.0, (k & 2) ? 0.5 : -0.5, (k & 4) ? 0.2 : 0.0});
  PreviewFraming f;
  f.turntable = true;
  const std::vector<PreviewCamera> spin = preview_cameras(points, f, 8);
  ASSERT_EQ(spin.size(), 8u);
  double largest = 0;
  for (int i = 0; i < 8; ++i) {
    const PreviewCamera alone = frame_camera(points, f.up, f.aspect, f.azimuth + 45.0 * i, f.elevation, f.fov);
    largest = std::max(largest, norm(alone.eye - alone.target));
  }
  for (const PreviewCamera& c : spin) EXPECT_NEAR(norm(c.eye - c.target), largest, 1e-9 * largest);

  PreviewCamera eye;
  eye.eye = {2, 0, 1};
  eye.target = {0, 0, 0};
  f.fixed = eye;
  const std::vector<PreviewCamera> orbit = preview_cameras(points, f, 4);
  ASSERT_EQ(orbit.size(), 4u);
  for (const PreviewCamera& c : orbit) {
    EXPECT_NEAR(norm(c.eye - c.target), std::sqrt(5.0), 1e-12);
    EXPECT_NEAR(c.eye.z, 1.0, 1e-12);  // around the up axis
  }
  EXPECT_NEAR(orbit[2].eye.x, -2.0, 1e-12);  // half way round
  EXPECT_NEAR(orbit[1].eye.y, 2.0, 1e-12);   // a quarter turn, counter-clockwise about +z
  f.turntable = false;
  for (const PreviewCamera& c : preview_cameras(points, f, 3)) EXPECT_EQ(c.eye.x, 2.0);
}

TEST(PreviewSetup, UpAxesByNameOrVectorAndPanelLabelsByModeElseFolder) {
  EXPECT_EQ(*parse_up_axis("y"), (Vec3{0, 1, 0}));
  EXPECT_EQ(*parse_up_axis("-x"), (Vec3{-1, 0, 0}));
  const std::optional<Vec3> tilted = parse_up_axis("0,3,4");
  ASSERT_TRUE(tilted);
  EXPECT_NEAR(tilted->y, 0.6, 1e-12);
  EXPECT_NEAR(tilted->z, 0.8, 1e-12);
  for (const char* bad : {"w", "0,0,0", "1,0", "1,0,x", "1,0,2,3", "nan,0,1", ""})
    EXPECT_FALSE(parse_up_axis(bad)) << bad;

  BakeManifest a, b;
  a.dir = "/shots/a_erosion";
  b.dir = "/shots/b_blend";
  a.options.raster.mode = RasterMode::Erosion;
  b.options.raster.mode = RasterMode::Blend;
  EXPECT_EQ(panel_labels({a, b}), (std::vector<std::string>{"erosion", "blend"}));
  b.options.raster.mode = RasterMode::Erosion;
  EXPECT_EQ(panel_labels({a, b}), (std::vector<std::string>{"a_erosion", "b_blend"}));
}

}  // namespace lapflow
