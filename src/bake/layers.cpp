// Exemplar layers: the option texts, the rules over the simulation's
// attributes, the frame's layer field and the layers' exemplars.
#include "lapflow/bake/layers.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <limits>
#include <stdexcept>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {

std::vector<std::string> LayerRules::file_attributes() const {
  std::vector<std::string> out;
  for (const std::string& a : attributes)
    if (a != kSpeedAttribute && a != kCurvatureAttribute) out.push_back(a);
  return out;
}

bool LayerRules::reads(const std::string& attribute) const {
  return std::find(attributes.begin(), attributes.end(), attribute) != attributes.end();
}

int LayerRules::choose(const float* values) const {
  float mine[Rule::kStack];
  for (std::size_t l = 0; l + 1 < rules.size(); ++l) {
    const std::vector<int>& s = slots[l];
    for (std::size_t k = 0; k < s.size() && k < std::size(mine); ++k) mine[k] = values[s[k]];
    if (rules[l].holds(mine)) return int(l);
  }
  return int(rules.size()) - 1;
}

LayerRules layer_rules(const BakeOptions& o) {
  LayerRules r;
  if (o.layers.empty()) {
    if (!o.layer_rules.empty())
      throw UsageError("--where " + o.layer_rules.front().first + ":...: no --layer defines a layer");
    return r;
  }
  if (o.layers.size() > kMaxLayers)
    throw UsageError("--layer: " + std::to_string(o.layers.size()) + " layers, lapflow takes at most " +
                     std::to_string(kMaxLayers));
  for (const auto& [name, text] : o.layer_rules)
    if (std::none_of(o.layers.begin(), o.layers.end(), [&](const ExemplarLayer& l) { return l.name == name; }))
      throw UsageError("--where " + name + ":" + text + ": no --layer is named '" + name + "'");
  for (std::size_t l = 0; l < o.layers.size(); ++l) {
    const ExemplarLayer& layer = o.layers[l];
    const bool last = l + 1 == o.layers.size();
    const auto rule = std::find_if(o.layer_rules.begin(), o.layer_rules.end(),
                                   [&](const auto& w) { return w.first == layer.name; });
    if (last && rule != o.layer_rules.end())
      throw UsageError("--where " + layer.name + ":" + rule->second + ": layer '" + layer.name +
                       "' is the last, the default where no other rule holds: it takes no rule");
    if (!last && rule == o.layer_rules.end())
      throw UsageError("--layer " + layer.name + ": no --where " + layer.name +
                       ":RULE; every layer but the last (the default) needs a rule");
    r.names.push_back(layer.name);
    Rule compiled;
    if (!last) {
      try {
        compiled = Rule::parse(rule->second);
      } catch (const RuleError& e) {
        throw UsageError("--where " + layer.name + ":" + rule->second + ": " + e.what());
      }
    }
    std::vector<int> slot;
    for (const std::string& name : compiled.names()) {
      auto at = std::find(r.attributes.begin(), r.attributes.end(), name);
      if (at == r.attributes.end()) at = r.attributes.insert(r.attributes.end(), name);
      slot.push_back(int(at - r.attributes.begin()));
    }
    r.rules.push_back(std::move(compiled));
    r.slots.push_back(std::move(slot));
  }
  if (r.attributes.size() > std::size_t(Rule::kStack))
    throw UsageError("--where: the rules read " + std::to_string(r.attributes.size()) + " attributes, at most " +
                     std::to_string(Rule::kStack));
  return r;
}

LayerField::LayerField(const LayerRules& rules, const Frame& frame) : rules_(&rules), frame_(&frame) {
  const TriMesh& mesh = frame.mesh;
  const std::vector<std::string> from_file = rules.file_attributes();
  columns_.resize(rules.attributes.size());
  for (std::size_t a = 0; a < rules.attributes.size(); ++a) {
    const std::string& name = rules.attributes[a];
    std::vector<float>& column = columns_[a];
    if (name == kSpeedAttribute) {
      const std::vector<Vec3> v = surface_velocities(frame);
      column.assign(mesh.vertex_count(), 0.f);
      for (std::size_t i = 0; i < v.size() && i < column.size(); ++i) column[i] = float(norm(v[i]));
    } else if (name == kCurvatureAttribute) {
      column = vertex_mean_curvature(mesh);
    } else {
      const std::size_t k = std::size_t(std::find(from_file.begin(), from_file.end(), name) - from_file.begin());
      if (k >= frame.attributes.size() || frame.attributes[k].size() != mesh.vertex_count())
        throw InputError(frame.path, "the frame has no vertex attribute '" + name + "' (a layer rule reads it)",
                         frame.number);
      column = frame.attributes[k];
    }
  }
}

int LayerField::layer_at(int triangle, double b1, double b2) const {
  if (!rules_) return 0;
  const TriMesh& mesh = frame_->mesh;
  float values[Rule::kStack];
  const std::size_t n = std::min(columns_.size(), std::size(values));
  if (triangle < 0 || std::size_t(triangle) >= mesh.triangle_count()) {
    return int(rules_->size()) - 1;
  }
  const Tri& t = mesh.triangles[triangle];
  const double b0 = 1 - b1 - b2;
  for (std::size_t a = 0; a < n; ++a) {
    const std::vector<float>& c = columns_[a];
    values[a] = float(b0 * c[t[0]] + b1 * c[t[1]] + b2 * c[t[2]]);
  }
  return rules_->choose(values);
}

int LayerField::layer_at(const Vec3& p) const {
  if (!rules_) return 0;
  const ClosestHit hit = frame_->surface->closest(p, std::numeric_limits<double>::infinity());
  if (!hit.found) return int(rules_->size()) - 1;
  return layer_at(hit.triangle, hit.b1, hit.b2);
}

std::vector<uint8_t> LayerField::vertex_layers() const {
  const std::size_t nv = frame_ ? frame_->mesh.vertex_count() : 0;
  std::vector<uint8_t> out(nv, 0);
  if (!rules_) return out;
  float values[Rule::kStack];
  const std::size_t n = std::min(columns_.size(), std::size(values));
  for (std::size_t v = 0; v < nv; ++v) {
    for (std::size_t a = 0; a < n; ++a) values[a] = columns_[a][v];
    out[v] = uint8_t(rules_->choose(values));
  }
  return out;
}

namespace {

// One frame's digest alone; an animated exemplar's frames' chained.
std::string sequence_digest(const std::vector<std::string>& frames) {
  if (frames.size() == 1) return frames.front();
  uLong crc = crc32(0, nullptr, 0);
  for (const std::string& f : frames) crc = crc32(crc, reinterpret_cast<const Bytef*>(f.data()), uInt(f.size()));
  return fmt::format("{:08x}/{}", uint32_t(crc), frames.size());
}

std::string joined(const std::vector<std::string>& names, const std::vector<std::string>& digests) {
  if (digests.size() == 1 && names.front().empty()) return digests.front();
  std::string out;
  for (std::size_t l = 0; l < digests.size(); ++l) out += (l ? "," : "") + names[l] + ":" + digests[l];
  return out;
}

}  // namespace

std::string BakeExemplars::feature_digest() const { return joined(names, feature_digests); }

std::string BakeExemplars::digest() const { return joined(names, digests); }

BakeExemplars load_bake_exemplars(const BakeOptions& o) {
  BakeExemplars e;
  const auto add = [&](const std::string& name, const ExemplarLayer& files) {
    const std::vector<Exemplar> frames = load_exemplar_frames(files.color, files.feature, files.displacement);
    std::vector<std::string> feature, all;
    for (const Exemplar& f : frames) {
      feature.push_back(exemplar_feature_digest(f.feature));
      all.push_back(exemplar_digest(f));
    }
    e.names.push_back(name);
    e.feature_digests.push_back(sequence_digest(feature));
    e.digests.push_back(sequence_digest(all));
    e.raster.push_back(prepare_raster_exemplar(frames, o.raster.epsilon));
  };
  if (o.layers.empty())
    add("", ExemplarLayer{"", o.exemplar_color, o.exemplar_feature, o.exemplar_displacement});
  else
    for (const ExemplarLayer& layer : o.layers) add(layer.name, layer);
  return e;
}

}  // namespace lapflow
