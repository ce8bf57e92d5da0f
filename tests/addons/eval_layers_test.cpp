// `lapflow eval` of a bake with exemplar layers (docs/eval.md, "Exemplar
// layers"): each layer's texels are compared with its own exemplar, the
// layers' shares follow the rule, the shown layer agrees with the rule away
// from its boundary, and a bake of one exemplar reports no layer figure.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "io_test_helpers.hpp"
#include "lapflow/addons/eval.hpp"
#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/image.hpp"
#include "test_helpers.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
using lapflow::test::shipped;
using lapflow::test::shipped_layer;
namespace fs = std::filesystem;

namespace {


/// The unit plane of write_heat_plane with heat = x over `frames` frames,
/// baked with AOVs at 256^2: `hot` (lava) where heat > 0.5, else `calm`
/// (pebbles); with `layered` false, pebbles alone.
std::string bake_heat_plane(const TempDir& dir, int frames, bool layered) {
  const std::string in = dir / "in", out = dir / (layered ? "layered" : "one");
  if (!fs::exists(in)) {
    fs::create_directories(in);
    test::write_heat_plane(in, frames, [](double x, int) { return x; });
  }
  BakeOptions o = default_bake_options();
  o.mesh_pattern = in + "/m.%04d.ply";
  o.out_dir = out;
  o.name = "t";
  o.patch.radius = 0.05;
  o.atlas.resolution = 256;
  o.aov = true;
  o.usd = false;
  if (layered) {
    o.layers = {shipped_layer("hot", "lava"), shipped_layer("calm", "pebbles")};
    o.layer_rules = {{"hot", "heat > 0.5"}};
  } else {
    o.exemplar_color = shipped("pebbles", "color");
    o.exemplar_feature = shipped("pebbles", "feature");
    o.exemplar_displacement = shipped("pebbles", "disp");
  }
  resolve_bake_options(o);
  bake(o);
  return out;
}

}  // namespace

TEST(EvalLayers, EachLayerFollowsTheRuleAndIsComparedWithItsOwnExemplar) {
  TempDir dir("eval_layers");
  constexpr int kFrames = 3;
  const std::string out = bake_heat_plane(dir, kFrames, true);
  const EvalReport r = evaluate_bake(out);
  ASSERT_EQ(r.layers.size(), 2u);
  EXPECT_EQ(r.layers[0].name, "hot");
  EXPECT_EQ(r.layers[1].name, "calm");
  EXPECT_EQ(r.layers[0].exemplar, shipped("lava", "color"));
  ASSERT_EQ(r.frames.size(), std::size_t(kFrames));
  for (const FrameMetrics& m : r.frames) {
    SCOPED_TRACE(fmt::format("frame {}", m.frame));
    ASSERT_EQ(m.layers.size(), 2u);
    // Half the plane is hot (x > 0.5).
    EXPECT_NEAR(m.layers[0].share + m.layers[1].share, 1.0, 1e-12);
    EXPECT_NEAR(m.layers[0].share, 0.5, 0.1);
    EXPECT_NEAR(m.layers[1].share, 0.5, 0.1);
    EXPECT_EQ(m.layers[0].texels + m.layers[1].texels, m.layer_agreement_texels);
    // A patch keeps the layer of its birth point and reaches r = 0.05 from
    // it: off the boundary's triangles, the shown layer is the rule's.
    EXPECT_GE(m.layer_agreement_interior, 0.95);
    EXPECT_GE(m.layer_agreement, 0.8);
    EXPECT_GT(m.layer_agreement_interior_texels, m.layer_agreement_texels / 2);
    EXPECT_LT(m.layer_agreement_interior_texels, m.layer_agreement_texels);
    // The frame's contrast is the layers' weighted by their texels.
    const double w0 = double(m.layers[0].texels), w1 = double(m.layers[1].texels);
    EXPECT_NEAR(m.contrast, (w0 * m.layers[0].contrast + w1 * m.layers[1].contrast) / (w0 + w1), 1e-12);
    EXPECT_TRUE(std::isfinite(m.layers[0].sliced_wasserstein) && std::isfinite(m.layers[1].sliced_wasserstein));
    if (m.frame > 1) {
      EXPECT_GT(m.layers[0].popping_texels + m.layers[1].popping_texels, 0u);
      EXPECT_LE(m.layers[0].popping_texels + m.layers[1].popping_texels, m.popping_texels);
    }
  }

  // The same bake against the layers' exemplars swapped: every layer's
  // colours and windows are farther from the other layer's exemplar.
  BakeManifest swapped = read_bake_manifest(out);
  std::swap(swapped.options.layers[0].color, swapped.options.layers[1].color);
  write_bake_manifest(swapped, bake_manifest_path(out, "t"));
  const EvalReport s = evaluate_bake(out);
  for (std::size_t k = 0; k < r.frames.size(); ++k)
    for (std::size_t l = 0; l < 2; ++l) {
      SCOPED_TRACE(fmt::format("frame {}, layer {}", r.frames[k].frame, r.layers[l].name));
      EXPECT_LT(r.frames[k].layers[l].histogram_distance, s.frames[k].layers[l].histogram_distance);
      EXPECT_LT(r.frames[k].layers[l].sliced_wasserstein, s.frames[k].layers[l].sliced_wasserstein);
      EXPECT_EQ(r.frames[k].layers[l].share, s.frames[k].layers[l].share);
    }
}

TEST(EvalLayers, ReportsNameTheLayersAndOneExemplarHasNone) {
  TempDir dir("eval_layers_report");
  const std::string layered = bake_heat_plane(dir, 2, true), one = bake_heat_plane(dir, 2, false);
  const EvalReport r = evaluate_bake(layered);
  const auto j = nlohmann::json::parse(eval_report_json(r));
  ASSERT_EQ(j.at("layers").size(), 2u);
  EXPECT_EQ(j["layers"][1]["name"], "calm");
  EXPECT_TRUE(j["exemplar_luminance_std"].is_null());
  const auto& f = j.at("frames").at(1);
  EXPECT_EQ(f.at("layer_agreement").get<double>(), r.frames[1].layer_agreement);
  EXPECT_EQ(f.at("layers").at("hot").at("share").get<double>(), r.frames[1].layers[0].share);
  EXPECT_EQ(f.at("layers").at("calm").at("popping").get<double>(), r.frames[1].layers[1].popping);
  const auto& summary = j.at("summary");
  EXPECT_EQ(summary.at("layer_agreement_interior").at("frames").get<int>(), 2);
  EXPECT_NEAR(summary.at("layers").at("hot").at("share").at("mean").get<double>(),
              (r.frames[0].layers[0].share + r.frames[1].layers[0].share) / 2, 1e-12);
  EXPECT_EQ(summary.at("layers").at("hot").at("popping").at("frames").get<int>(), 1);
  // The whole-surface summary is not the last layer's.
  EXPECT_EQ(summary.at("popping").at("mean").get<double>(), r.frames[1].popping);
  const std::string table = eval_report_table(r);
  for (const char* text : {"layers hot (lava.color.png), calm (pebbles.color.png)", "agree%", "inner%", "share%",
                           "hot: contrast", "calm: contrast"})
    EXPECT_NE(table.find(text), std::string::npos) << text << "\n" << table;

  // Each layer has its own exemplar: --exemplar is refused.
  EvalOptions other;
  other.exemplar = shipped("squares", "color");
  EXPECT_THROW(evaluate_bake(layered, other), UsageError);

  // An AOV without its layer channel is bad input naming the file.
  const std::string aov = layered + "/t.aov.0002.exr";
  const Image five = read_image(aov, ColorSpace::Linear);
  Image four(five.width, five.height, 4);
  for (std::size_t p = 0; p < std::size_t(five.width) * five.height; ++p)
    for (int c = 0; c < 4; ++c) four.pixels[4 * p + c] = five.pixels[5 * p + c];
  write_exr(aov, four, {"patch_id", "u", "v", "w"}, {ExrPixelType::Float, ExrCompression::Zip});
  try {
    evaluate_bake(layered);
    ADD_FAILURE() << "a layered bake's AOV without a layer channel";
  } catch (const InputError& e) {
    EXPECT_EQ(fs::path(e.file()), fs::path(aov));
    EXPECT_NE(std::string(e.what()).find("no channel 'layer'"), std::string::npos) << e.what();
  }

  // One exemplar: none of the layer keys.
  const EvalReport o = evaluate_bake(one);
  EXPECT_TRUE(o.layers.empty());
  const auto k = nlohmann::json::parse(eval_report_json(o));
  EXPECT_FALSE(k.contains("layers"));
  for (const auto& frame : k.at("frames"))
    for (const char* key : {"layers", "layer_agreement", "layer_agreement_interior"}) EXPECT_FALSE(frame.contains(key)) << key;
  for (const char* key : {"layers", "layer_agreement", "layer_agreement_interior"})
    EXPECT_FALSE(k.at("summary").contains(key)) << key;
  EXPECT_EQ(eval_report_table(o).find("agree%"), std::string::npos);
}
