// NAME.bake.json round trip and its errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace {

/// The JSON NAME.bake.json holds for a bake with options `o`.
nlohmann::json manifest_json_of(const BakeOptions& o) {
  test::TempDir dir("manifest_json");
  const std::string path = bake_manifest_path(dir.str(), o.name);
  write_bake_manifest(make_bake_manifest(o, {1, 2}), path);
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

TEST(BakeManifest, RoundTripsAndFindsFilesBesideItself) {
  test::TempDir dir("manifest");
  BakeOptions o;
  o.name = "shot";
  o.out_dir = dir.str();
  o.mesh_pattern = "sim/fluid.%04d.ply";
  o.exemplar_color = "pebbles.color.png";
  o.raster.mode = RasterMode::NoErosion;
  o.patch.radius = 0.04;
  o.atlas.resolution = 2048;
  o.seed = 7;
  o.aov = true;
  const BakeManifest m = make_bake_manifest(o, {3, 4, 5});
  EXPECT_TRUE(std::filesystem::path(m.options.mesh_pattern).is_absolute());
  write_bake_manifest(m, bake_manifest_path(dir.str(), "shot"));

  // Read from the folder (the only manifest there) and from the file.
  for (const std::string& where : {dir.str(), bake_manifest_path(dir.str(), "shot")}) {
    const BakeManifest r = read_bake_manifest(where);
    EXPECT_EQ(r.name, "shot");
    EXPECT_EQ(r.frames, (std::vector<int>{3, 4, 5}));
    EXPECT_EQ(r.options.raster.mode, RasterMode::NoErosion);
    EXPECT_EQ(r.options.mesh_pattern, m.options.mesh_pattern);
    EXPECT_DOUBLE_EQ(r.options.patch.radius, 0.04);
    EXPECT_EQ(r.options.atlas.resolution, 2048);
    EXPECT_EQ(r.options.seed, 7u);
    EXPECT_TRUE(r.options.aov);
    EXPECT_EQ(r.frame_file("color", 4), dir / "shot.color.0004.exr");
    EXPECT_EQ(r.frame_file("obj", 12), dir / "shot.0012.obj");
    EXPECT_EQ(r.frame_file("patches", 5), dir / "shot.patches.0005.ply");
  }
  EXPECT_EQ(parse_raster_mode(raster_mode_name(RasterMode::Blend)), RasterMode::Blend);
  EXPECT_THROW(parse_raster_mode("fade"), UsageError);
}

// Rules younger than the manifest format (--through-flow, --rest-bound,
// --run-off) read back, and a manifest without one's key reads as that rule
// off, so --resume and the render of an older bake decide as
// that bake did.
TEST(BakeManifest, LaterRulesReadBackAndAreOffForOlderManifests) {
  struct Rule {
    const char* key;
    bool& (*of)(BakeOptions&);
  };
  const Rule rules[] = {
      {"advect_through_flow", [](BakeOptions& o) -> bool& { return o.advect.through_flow; }},
      {"rest_bound", [](BakeOptions& o) -> bool& { return o.raster.rest_bound; }},
      {"advect_run_off", [](BakeOptions& o) -> bool& { return o.advect.run_off; }},
  };
  for (const Rule& rule : rules) {
    SCOPED_TRACE(rule.key);
    BakeOptions o;
    o.name = "shot";
    o.out_dir = "/tmp";
    o.mesh_pattern = "sim/fluid.%04d.ply";
    o.patch.radius = 0.04;
    EXPECT_TRUE(rule.of(o)) << "on by default";
    for (const bool on : {true, false}) {
      rule.of(o) = on;
      nlohmann::json j = manifest_json_of(o);
      EXPECT_EQ(j["settings"][rule.key], on ? "true" : "false");
      BakeOptions back = bake_options_from_manifest(parse_bake_manifest(j.dump(), "/tmp/shot.bake.json"));
      EXPECT_EQ(rule.of(back), on);
    }
    rule.of(o) = true;
    nlohmann::json old = manifest_json_of(o);
    old["settings"].erase(rule.key);
    BakeOptions older = parse_bake_manifest(old.dump(), "/tmp/shot.bake.json").options;
    EXPECT_FALSE(rule.of(older));
    old["settings"][rule.key] = "maybe";
    try {
      parse_bake_manifest(old.dump(), "/tmp/shot.bake.json");
      ADD_FAILURE() << "a malformed setting must be an InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("settings.") + rule.key + ": 'maybe'"), std::string::npos)
          << e.what();
    }
  }
}

TEST(BakeManifest, ErrorsNameTheFile) {
  test::TempDir dir("manifest_bad");
  EXPECT_THROW(read_bake_manifest(dir.str()), InputError);  // no manifest at all
  test::write_bytes(dir / "a.bake.json", "{\"lapflow_bake\": 1, \"name\": \"a\", \"frames\": [1, ");
  try {
    read_bake_manifest(dir / "a.bake.json");
    FAIL() << "truncated JSON accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("a.bake.json"), std::string::npos) << e.what();
  }
  test::write_bytes(dir / "b.bake.json", "{\"name\": \"b\"}");
  EXPECT_THROW(read_bake_manifest(dir / "b.bake.json"), InputError);  // not ours
  EXPECT_THROW(read_bake_manifest(dir.str()), InputError);           // two manifests: ambiguous
  EXPECT_THROW(read_bake_manifest(dir.str(), "c"), InputError);      // named one missing
}

TEST(BakeManifest, FramesOutOfOrderAndANameWithAPathAreInputErrorsNamingTheKey) {
  // Frames in descending order once crashed `lapflow render`; a name with a
  // path in it would have the files written outside the folder.
  const std::vector<std::pair<std::string, std::string>> bad{
      {R"({"lapflow_bake": 1, "name": "m", "frames": [3, 2, 1]})", "frames: 2 follows 3"},
      {R"({"lapflow_bake": 1, "name": "m", "frames": [1, 1]})", "frames: 1 follows 1"},
      {R"({"lapflow_bake": 1, "name": "../m", "frames": [1]})", "name: '../m' is not a file name"},
      {R"({"lapflow_bake": 1, "name": "a/b", "frames": [1]})", "name: 'a/b' is not a file name"},
      {R"({"lapflow_bake": 1, "name": "a\\b", "frames": [1]})", "is not a file name"},
      {R"({"lapflow_bake": 1, "name": "..", "frames": [1]})", "is not a file name"},
      {R"({"lapflow_bake": 1, "name": "", "frames": [1]})", "is not a file name"},
      {R"({"lapflow_bake": 1, "name": "m", "frames": [1], "radius": -1})", "radius: -1 is negative"},
      {R"({"lapflow_bake": 1, "name": "m", "frames": [1], "fps": 0})", "fps: 0 is not positive"},
      {R"({"lapflow_bake": 1, "name": "m", "frames": [1], "delta_max": "x"})", "delta_max"},
      {R"({"lapflow_bake": 1, "name": "m", "frames": [1], "settings": {"gutter": 3}})", "settings.gutter must be text"},
      {R"({"lapflow_bake": 1, "frames": [1]})", "'name' must be text"},
      {R"({"lapflow_bake": 1, "name": "m"})", "'frames' must be an array"}};
  for (const auto& [text, reason] : bad) {
    try {
      parse_bake_manifest(text, "m.bake.json");
      ADD_FAILURE() << text << " accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "m.bake.json");
      EXPECT_NE(std::string(e.what()).find(reason), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(parse_bake_manifest(R"({"lapflow_bake": 1, "name": "m", "frames": [1, 5, 9]})", "m.bake.json").frames,
            (std::vector<int>{1, 5, 9}));
}

TEST(RenderRecord, RoundTripsAndAProblemIsAnInputErrorNamingTheKey) {
  RenderRecord r;
  r.name = "shot";
  r.frame = 7;
  r.tracking_checksum = 4000000000u;
  r.patches_crc = 12345u;
  r.exemplar_digest = "a-b-c";
  r.exemplar_color = "/maps/rock.color.png";
  r.options = {{"resolution", "512"}, {"aov", "true"}};
  r.files = {{"shot.0007.obj", 10}, {"shot.color.0007.exr", 5000000000u}};
  const std::string text = encode_render_record(r);
  const RenderRecord back = parse_render_record(text, "shot.render.0007.json");
  EXPECT_EQ(encode_render_record(back), text);
  EXPECT_TRUE(render_record_differences(back, r).empty());
  RenderRecord other = r;
  other.options["resolution"] = "256";
  other.patches_crc = 1u;
  EXPECT_EQ(render_record_differences(r, other),
            (std::vector<std::string>{"the patches (the frame was tracked again since)",
                                      "resolution: 512 on disk, 256 asked"}));
  const std::vector<std::pair<std::string, std::string>> bad{
      {"[1]", "not a lapflow render record"},
      {R"({"lapflow_render": 2})", "render record version 2"},
      {R"({"lapflow_render": 1, "name": "s", "frame": 1})", "'tracking_checksum' is missing"},
      {R"({"lapflow_render": 1, "name": "s", "frame": 1.5})", "'frame' must be a whole number"},
      {R"({"lapflow_render": 1, "name": "s", "frame": 1, "tracking_checksum": 1, "exemplar_digest": "d",
           "options": {"resolution": 512}, "files": {}})",
       "'options.resolution' must be a string"},
      {R"({"lapflow_render": 1, "name": "s", "frame": 1, "tracking_checksum": 1, "exemplar_digest": "d",
           "options": {}, "files": {"../x.exr": 1}})",
       "files: '../x.exr' is not a file name"},
      {R"({"lapflow_render": 1, "name": "s", "frame": 1, "tracking_checksum": 1, "exemplar_digest": "d",
           "options": {}, "files": {"x.exr": -1}})",
       "'files.x.exr' must be a whole number"},
      {"{\"lapflow_render\": 1, \"na", "not JSON"}};
  for (const auto& [bytes, reason] : bad) {
    try {
      parse_render_record(bytes, "s.render.0001.json");
      ADD_FAILURE() << bytes << " accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "s.render.0001.json");
      EXPECT_NE(std::string(e.what()).find(reason), std::string::npos) << e.what();
    }
  }
}

TEST(BakeManifest, NumbersOutOfRangeAreAnInputErrorNotUndefinedBehaviour) {
  // Found by fuzz_manifest (tests/fuzz/corpus/manifest/regress_seed_beyond_uint64.bake.json):
  // a seed of 1.8e19 written as a float was converted to uint64_t unchecked.
  const std::string head = R"({"lapflow_bake": 1, "name": "m", "frames": [1, 2])";
  for (const char* field : {R"("seed": 18446744147419103230.0)", R"("seed": -1)", R"("resolution": 2.5)",
                                   R"("resolution": 1e30)", R"("lapflow_bake": 1e300)"}) {
    try {
      parse_bake_manifest(head + ", " + std::string(field) + "}", "m.bake.json");
      ADD_FAILURE() << field << " accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "m.bake.json");
      EXPECT_NE(std::string(e.what()).find("whole number"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(parse_bake_manifest(R"({"lapflow_bake": 1, "name": "m", "frames": [1, 3e9]})", "m.bake.json"),
               InputError);
  EXPECT_THROW(parse_bake_manifest(R"({"lapflow_bake": 1, "name": "m", "frames": 7})", "m.bake.json"), InputError);
  // The largest seed still reads back exactly.
  const BakeManifest m =
      parse_bake_manifest(head + R"(, "seed": 18446744073709551615, "resolution": 4096})", "m.bake.json");
  EXPECT_EQ(m.options.seed, 18446744073709551615u);
  EXPECT_EQ(m.options.atlas.resolution, 4096);
  EXPECT_EQ(m.frames, (std::vector<int>{1, 2}));
}

}  // namespace
}  // namespace lapflow
