#pragma once
/// \file layers.hpp Exemplar layers (docs/layers.md): a bake may name several
/// exemplars, and rules over per-vertex attributes of the simulation choose
/// one where each patch is born. The first layer whose rule holds wins; the
/// last, which has no rule, is the default.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "lapflow/core/rule.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/raster/raster.hpp"
#include "lapflow/surface/mesh.hpp"

namespace lapflow {

struct BakeOptions;  // lapflow/bake/bake.hpp
struct Frame;        // lapflow/bake/frame.hpp

/// One layer's exemplar files, as `--layer NAME=COLOR[,FEATURE[,DISP]]`
/// gives them (empty feature, displacement: beside the colour image).
struct ExemplarLayer {
  std::string name;
  std::string color, feature, displacement;
  bool operator==(const ExemplarLayer&) const = default;
};

/// A layer's name: letters, digits, '_' and '-', starting with a letter.
bool is_layer_name(const std::string& name);

/// Parses "NAME=COLOR[,FEATURE[,DISP]]"; throws std::invalid_argument whose
/// what() completes "'TEXT' is not ..." ("a layer NAME=COLOR[,FEATURE[,DISP]]").
ExemplarLayer parse_layer(const std::string& text);
/// The text parse_layer reads back.
std::string layer_text(const ExemplarLayer& layer);

/// Parses "NAME:RULE" (the rule checked by Rule::parse); throws
/// std::invalid_argument completing "'TEXT' is not ...", with the rule's
/// column for a rule that does not parse.
std::pair<std::string, std::string> parse_layer_rule(const std::string& text);

/// The attributes a rule may read besides the PLY's own properties: the
/// simulation's speed at the vertex (m/s, as the simulator gave it, before
/// --min-speed) and the surface's mean curvature (1/m, positive where convex).
inline constexpr const char* kSpeedAttribute = "speed";
inline constexpr const char* kCurvatureAttribute = "curvature";

/// The layers' rules, checked and compiled, and the attributes they read.
struct LayerRules {
  std::vector<std::string> names;  ///< the layers, in the order rules are tried
  std::vector<Rule> rules;         ///< one per layer; the last is empty (the default)
  /// Every attribute a rule reads, each once: speed, curvature or a PLY vertex property.
  std::vector<std::string> attributes;
  /// Per rule, the index in `attributes` of each of its names().
  std::vector<std::vector<int>> slots;

  std::size_t size() const { return names.size(); }
  /// The attributes read from the frames' PLY files (all but speed and curvature).
  std::vector<std::string> file_attributes() const;
  bool reads(const std::string& attribute) const;
  /// The first layer whose rule holds for `values` (one per attribute).
  int choose(const float* values) const;
};

/// The rules of BakeOptions::layers and layer_rules: every layer but the
/// last needs a rule, the last takes none, and every rule names a layer.
/// Throws UsageError naming the layer (and the rule's column). Empty when
/// the bake has one exemplar (no --layer).
LayerRules layer_rules(const BakeOptions& options);

/// One frame's attributes per vertex and the layer the rules choose at any
/// surface point.
class LayerField {
 public:
  LayerField() = default;
  /// The attributes of `rules` on `frame`'s mesh: speed from the frame's
  /// velocity source, curvature from its mesh, the rest from
  /// Frame::attributes (read in LayerRules::file_attributes' order).
  LayerField(const LayerRules& rules, const Frame& frame);

  bool empty() const { return rules_ == nullptr; }
  /// The layer at the point of fluid triangle `triangle` with barycentrics
  /// (b1, b2) of its vertices 1 and 2: the rules over the attributes
  /// interpolated there.
  int layer_at(int triangle, double b1, double b2) const;
  /// The same at 3D point `p` (its closest point on the frame's surface;
  /// the default layer where there is none).
  int layer_at(const Vec3& p) const;
  /// Per vertex, the layer the rules choose there.
  std::vector<uint8_t> vertex_layers() const;

 private:
  const LayerRules* rules_ = nullptr;
  const Frame* frame_ = nullptr;
  std::vector<std::vector<float>> columns_;  ///< per attribute, per vertex
};

/// A bake's exemplars, one per layer (one without --layer), loaded and
/// prepared for the raster. An animated exemplar's frames are prepared once
/// each (RasterExemplar::later); the loaded images are not kept.
struct BakeExemplars {
  std::vector<std::string> names;  ///< the layers' names (empty names for a bake of one exemplar)
  std::vector<RasterExemplar> raster;
  /// Per layer: exemplar_feature_digest and exemplar_digest of its frames
  /// (one frame's alone; an animated exemplar's chained, "CRC/FRAMES").
  std::vector<std::string> feature_digests, digests;
  ExemplarLayers layers() const { return raster; }
  /// exemplar_feature_digest of each layer: one layer's alone, else
  /// "NAME:DIGEST" joined by ',' (the names and order are part of the tracking).
  std::string feature_digest() const;
  /// exemplar_digest of each layer, joined the same way.
  std::string digest() const;
};

/// Loads the exemplar of every layer (BakeOptions::layers, else the
/// exemplar_* files). Layers' exemplars may differ in size. Throws InputError
/// naming a file that cannot be read.
BakeExemplars load_bake_exemplars(const BakeOptions& options);

}  // namespace lapflow
