// NAME.bake.json: the inputs and settings of a bake, for eval and preview.
#include "lapflow/bake/manifest.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string_view>
#include <utility>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/core/errors.hpp"
#include "core/json_number.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {

std::string absolute_or_empty(const std::string& p) {
  if (p.empty()) return p;
  std::error_code ec;
  const fs::path a = fs::absolute(p, ec);
  return ec ? p : a.lexically_normal().string();
}

using detail::whole_number;

}  // namespace

std::string raster_mode_name(RasterMode mode) {
  switch (mode) {
    case RasterMode::Erosion: return "erosion";
    case RasterMode::Blend: return "blend";
    case RasterMode::NoErosion: return "advect";
  }
  return "erosion";
}

RasterMode parse_raster_mode(const std::string& name) {
  if (name == "erosion") return RasterMode::Erosion;
  if (name == "blend") return RasterMode::Blend;
  if (name == "advect") return RasterMode::NoErosion;
  throw UsageError("unknown mode '" + name + "' (expected erosion, blend or advect)");
}

namespace {

/// `name` as a regex matching itself.
std::string regex_escaped(const std::string& name) {
  std::string n;
  for (char c : name) {
    if (std::string_view("\\^$.|?*+()[]{}").find(c) != std::string_view::npos) n += '\\';
    n += c;
  }
  return n;
}

}  // namespace

std::string bake_state_file_pattern(const std::string& name) {
  return regex_escaped(name) + "\\.state\\.[0-9]+\\.bin";
}

std::vector<std::string> bake_file_stem_patterns(const std::string& name) {
  const std::string n = regex_escaped(name);
  // The kinds of frame_file() below, and the two files of the whole bake.
  return {n + "\\.(color|disp|aov|patches|state)\\.[0-9]+", n + "\\.[0-9]+", n + "\\.stats", n + "\\.bake"};
}

std::string bake_manifest_path(const std::string& dir, const std::string& name) {
  return (fs::path(dir) / (name + ".bake.json")).string();
}

std::string BakeManifest::frame_file(const std::string& kind, int frame) const {
  char digits[16];
  std::snprintf(digits, sizeof digits, "%04d", frame);
  std::string file;
  if (kind == "obj" || kind == "mtl")
    file = name + "." + digits + "." + kind;
  else if (kind == "patches")
    file = name + ".patches." + digits + ".ply";
  else if (kind == "state")
    file = name + ".state." + digits + ".bin";
  else
    file = name + "." + kind + "." + digits + ".exr";
  return (fs::path(dir) / file).string();
}

BakeManifest make_bake_manifest(const BakeOptions& o, const std::vector<int>& frames) {
  BakeManifest m;
  m.name = o.name;
  m.dir = absolute_or_empty(o.out_dir);
  m.mesh_pattern = absolute_or_empty(o.mesh_pattern);
  m.velocity_vdb_pattern = absolute_or_empty(o.velocity_vdb_pattern);
  m.velocity_grid = o.velocity_grid;
  m.frames = frames;
  m.fps = o.fps;
  m.min_speed = o.min_speed;
  m.allow_zero_velocity = o.allow_zero_velocity;
  m.exemplar_color = absolute_or_empty(o.exemplar_color);
  m.exemplar_feature = absolute_or_empty(o.exemplar_feature);
  m.exemplar_displacement = absolute_or_empty(o.exemplar_displacement);
  m.mode = raster_mode_name(o.raster.mode);
  m.radius = o.patch.radius;
  m.epsilon = o.raster.epsilon;
  m.hold = o.raster.hold;
  m.hold_margin = o.raster.hold_margin;
  m.small_hole = o.raster.small_hole;
  m.rest_hole = o.raster.rest_hole;
  m.merge = o.raster.merge;
  m.delta_max = o.weights.delta_max;
  m.resolution = o.atlas.resolution;
  m.seed = o.seed;
  m.aov = o.aov;
  m.dump_patches = o.dump_patches;
  // fmt's shortest representation reads back to the same double.
  const auto text = [](auto v) { return fmt::format("{}", v); };
  std::map<std::string, std::string>& s = m.settings;
  s["velocity_band"] = text(o.velocity_band);
  s["velocity_voxel"] = text(o.velocity_voxel);
  s["spacing"] = text(o.seeding.spacing);
  s["remesh"] = text(o.patch.remesh);
  s["remesher"] = text(int(o.patch.remesher));
  s["remesh_edge"] = text(o.patch.remesh_edge);
  s["anticipate"] = text(o.patch.anticipate);
  s["anticipate_horizon"] = text(o.patch.anticipate_horizon);
  s["align"] = o.patch.align ? fmt::format("{},{},{}", o.patch.align_direction.x, o.patch.align_direction.y,
                                           o.patch.align_direction.z)
                             : "random";
  s["advect_max_step_fraction"] = text(o.advect.max_step_fraction);
  s["advect_max_turn"] = text(o.advect.max_turn);
  s["advect_max_projection"] = text(o.advect.max_projection);
  s["advect_through_flow"] = text(o.advect.through_flow);
  s["advect_run_off"] = text(o.advect.run_off);
  s["center_radius"] = text(o.weights.center_radius);
  s["gutter"] = text(o.atlas.gutter);
  s["max_stretch"] = text(o.atlas.max_stretch);
  s["fill_holes"] = text(o.raster.fill_holes);
  s["retire"] = text(o.raster.retire);
  s["rest_bound"] = text(o.raster.rest_bound);
  s["mipmap"] = text(o.raster.mipmap);
  s["trilinear"] = text(o.raster.trilinear);
  s["dilate"] = text(o.raster.dilate);
  s["max_hole_patches"] = text(o.raster.max_hole_patches);
  s["exr_type"] = text(int(o.exr.type));
  s["exr_compression"] = text(int(o.exr.compression));
  s["track_texel"] = text(o.track_texel);
  return m;
}

std::string exemplar_feature_digest(const Image& feature) {
  uLong crc = crc32(0, nullptr, 0);
  const int32_t size[3] = {feature.width, feature.height, feature.channels};
  crc = crc32(crc, reinterpret_cast<const Bytef*>(size), sizeof size);
  // In slices: uInt is 32 bits.
  const auto* bytes = reinterpret_cast<const Bytef*>(feature.pixels.data());
  for (std::size_t left = feature.pixels.size() * sizeof(float); left > 0;) {
    const std::size_t n = std::min<std::size_t>(left, std::size_t(1) << 30);
    crc = crc32(crc, bytes, uInt(n));
    bytes += n, left -= n;
  }
  return fmt::format("{:08x}", uint32_t(crc));
}

namespace {

nlohmann::json manifest_json(const BakeManifest& m) {
  return {{"lapflow_bake", m.version},
                            {"name", m.name},
                            {"mesh", m.mesh_pattern},
                            {"velocity_vdb", m.velocity_vdb_pattern},
                            {"velocity_grid", m.velocity_grid},
                            {"frames", m.frames},
                            {"fps", m.fps},
                            {"min_speed", m.min_speed},
                            {"allow_zero_velocity", m.allow_zero_velocity},
                            {"exemplar", {{"color", m.exemplar_color},
                                          {"feature", m.exemplar_feature},
                                          {"displacement", m.exemplar_displacement}}},
                            {"mode", m.mode},
                            {"radius", m.radius},
                            {"epsilon", m.epsilon},
                            {"hold", m.hold},
                            {"hold_margin", m.hold_margin},
                            {"small_hole", m.small_hole},
                            {"rest_hole", m.rest_hole},
                            {"merge", m.merge},
                            {"delta_max", m.delta_max},
                            {"resolution", m.resolution},
                            {"seed", m.seed},
                            {"aov", m.aov},
                            {"dump_patches", m.dump_patches},
                            {"settings", m.settings}};
}

/// The manifest file at `path` as JSON; throws InputError naming it.
nlohmann::json read_manifest_json(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot open the bake manifest");
  try {
    return nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw InputError(path, std::string("not valid JSON: ") + e.what());
  }
}

}  // namespace

void write_bake_manifest(const BakeManifest& m, const std::string& path) {
  write_text_atomically(path, manifest_json(m).dump(2) + "\n");
}

namespace {

/// The flattened keys of the options that change only the output images
/// and UV mesh, not the patches (docs/farm.md): `lapflow render` may set
/// them anew. The feature map counts through settings/feature_digest.
bool output_only_key(const std::string& key) {
  static const char* const keys[] = {"/exemplar/color", "/exemplar/feature", "/exemplar/displacement",
                                     "/resolution", "/aov", "/dump_patches", "/settings/gutter",
                                     "/settings/mipmap", "/settings/trilinear", "/settings/dilate",
                                     "/settings/exr_type", "/settings/exr_compression"};
  for (const char* k : keys)
    if (key == k) return true;
  return false;
}

nlohmann::json tracking_part(const nlohmann::json& flat) {
  nlohmann::json t = nlohmann::json::object();
  for (const auto& [key, value] : flat.items())
    if (!output_only_key(key)) t[key] = value;
  return t;
}

}  // namespace

std::vector<std::string> bake_manifest_differences(const std::string& path, const BakeManifest& current,
                                                   bool tracking_only) {
  const nlohmann::json was = read_manifest_json(path), now = manifest_json(current);
  if (!was.is_object() || !was.contains("lapflow_bake"))
    throw InputError(path, "not a lapflow bake manifest (no 'lapflow_bake')");
  // Both flattened to "/settings/gutter"-style keys, so a nested option is
  // named by itself.
  nlohmann::json a = was.flatten(), b = now.flatten();
  if (tracking_only) a = tracking_part(a), b = tracking_part(b);
  std::vector<std::string> differences;
  const auto shown = [](const nlohmann::json& j, const std::string& key) {
    return j.contains(key) ? j[key].dump() : std::string("(absent)");
  };
  for (const auto& [key, value] : b.items())
    if (!a.contains(key) || a[key] != value)
      differences.push_back(key.substr(1) + ": " + shown(a, key) + " in the manifest, " + value.dump() + " now");
  for (const auto& [key, value] : a.items())
    if (!b.contains(key)) differences.push_back(key.substr(1) + ": " + value.dump() + " in the manifest, (absent) now");
  return differences;
}

uint32_t bake_manifest_checksum(const BakeManifest& m) {
  const std::string text = manifest_json(m).dump();
  return uint32_t(crc32(0, reinterpret_cast<const Bytef*>(text.data()), uInt(text.size())));
}

uint32_t bake_tracking_checksum(const BakeManifest& m) {
  const std::string text = tracking_part(manifest_json(m).flatten()).dump();
  return uint32_t(crc32(0, reinterpret_cast<const Bytef*>(text.data()), uInt(text.size())));
}

BakeManifest read_bake_manifest(const std::string& path_in, const std::string& name) {
  fs::path path = path_in;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (!name.empty()) {
      path = bake_manifest_path(path_in, name);
    } else {
      std::vector<fs::path> found;
      for (const auto& e : fs::directory_iterator(path, ec)) {
        const std::string f = e.path().filename().string();
        if (f.size() > 10 && f.ends_with(".bake.json")) found.push_back(e.path());
      }
      if (found.empty()) throw InputError(path_in, "no *.bake.json in this folder: is it a lapflow bake output?");
      if (found.size() > 1)
        throw InputError(path_in, "several bakes in this folder (" + found[0].filename().string() + ", " +
                                      found[1].filename().string() + ", ...): name one with --name");
      path = found.front();
    }
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), "cannot open the bake manifest");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_bake_manifest(text.str(), path.string());
}

BakeManifest parse_bake_manifest(const std::string& text, const std::string& path_text) {
  const fs::path path = path_text;
  std::error_code ec;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    throw InputError(path.string(), std::string("not valid JSON: ") + e.what());
  }
  BakeManifest m;
  try {
    if (!j.contains("lapflow_bake")) throw InputError(path.string(), "not a lapflow bake manifest (no 'lapflow_bake')");
    m.version = whole_number<int>(j.at("lapflow_bake"), "lapflow_bake", path.string());
    m.name = j.at("name").get<std::string>();
    m.mesh_pattern = j.value("mesh", "");
    m.velocity_vdb_pattern = j.value("velocity_vdb", "");
    m.velocity_grid = j.value("velocity_grid", "");
    const nlohmann::json& frames = j.at("frames");
    if (!frames.is_array()) throw InputError(path.string(), "'frames' must be an array of frame numbers");
    for (const nlohmann::json& f : frames) m.frames.push_back(whole_number<int>(f, "frames", path.string()));
    m.fps = j.value("fps", 24.0);
    m.min_speed = j.value("min_speed", 0.0);
    m.allow_zero_velocity = j.value("allow_zero_velocity", false);
    if (j.contains("exemplar")) {
      const auto& e = j["exemplar"];
      m.exemplar_color = e.value("color", "");
      m.exemplar_feature = e.value("feature", "");
      m.exemplar_displacement = e.value("displacement", "");
    }
    m.mode = j.value("mode", "erosion");
    m.radius = j.value("radius", 0.0);
    m.epsilon = j.value("epsilon", 0.0);
    m.hold = j.value("hold", false);
    m.hold_margin = j.value("hold_margin", 0.0);
    m.small_hole = j.value("small_hole", 0.0);
    m.rest_hole = j.value("rest_hole", 0.0);  // absent before stop 24: no such rule
    m.merge = j.value("merge", 0.0);
    m.delta_max = j.value("delta_max", 0.0);
    m.resolution = whole_number<int>(j, "resolution", 0, path.string());
    m.seed = whole_number<uint64_t>(j, "seed", 0, path.string());
    m.aov = j.value("aov", false);
    m.dump_patches = j.value("dump_patches", false);
    if (j.contains("settings")) m.settings = j["settings"].get<std::map<std::string, std::string>>();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path.string(), std::string("bad bake manifest: ") + e.what());
  }
  // Files sit beside the manifest, wherever the folder was moved.
  m.dir = fs::absolute(path, ec).parent_path().string();
  return m;
}

}  // namespace lapflow
