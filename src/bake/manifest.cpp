// NAME.bake.json: the inputs and settings of a bake, for eval and preview.
#include "lapflow/bake/manifest.hpp"

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

namespace lapflow {
namespace fs = std::filesystem;

namespace {

std::string absolute_or_empty(const std::string& p) {
  if (p.empty()) return p;
  std::error_code ec;
  const fs::path a = fs::absolute(p, ec);
  return ec ? p : a.lexically_normal().string();
}

// A field that must be a whole number of type T: nlohmann's get<int>() of
// 1e30 converts out of range (undefined behaviour) and of 2.5 truncates.
template <typename T>
T whole_number(const nlohmann::json& v, const std::string& key, const std::string& path) {
  if (v.is_number_unsigned()) {
    if (const uint64_t u = v.get<uint64_t>(); std::in_range<T>(u)) return T(u);
  } else if (v.is_number_integer()) {
    if (const int64_t i = v.get<int64_t>(); std::in_range<T>(i)) return T(i);
  }
  throw InputError(path, "'" + key + "' must be a whole number from " + std::to_string(std::numeric_limits<T>::min()) +
                             " to " + std::to_string(std::numeric_limits<T>::max()) + ", got " + v.dump().substr(0, 40));
}

template <typename T>
T whole_number(const nlohmann::json& j, const std::string& key, T fallback, const std::string& path) {
  return j.contains(key) ? whole_number<T>(j.at(key), key, path) : fallback;
}

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

std::vector<std::string> bake_file_stem_patterns(const std::string& name) {
  std::string n;
  for (char c : name) {
    if (std::string_view("\\^$.|?*+()[]{}").find(c) != std::string_view::npos) n += '\\';
    n += c;
  }
  // The kinds of frame_file() below, and the two files of the whole bake.
  return {n + "\\.(color|disp|aov|patches)\\.[0-9]+", n + "\\.[0-9]+", n + "\\.stats", n + "\\.bake"};
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
  m.merge = o.raster.merge;
  m.delta_max = o.weights.delta_max;
  m.resolution = o.atlas.resolution;
  m.seed = o.seed;
  m.aov = o.aov;
  m.dump_patches = o.dump_patches;
  return m;
}

void write_bake_manifest(const BakeManifest& m, const std::string& path) {
  const nlohmann::json j = {{"lapflow_bake", m.version},
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
                            {"merge", m.merge},
                            {"delta_max", m.delta_max},
                            {"resolution", m.resolution},
                            {"seed", m.seed},
                            {"aov", m.aov},
                            {"dump_patches", m.dump_patches}};
  write_text_atomically(path, j.dump(2) + "\n");
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
    m.merge = j.value("merge", 0.0);
    m.delta_max = j.value("delta_max", 0.0);
    m.resolution = whole_number<int>(j, "resolution", 0, path.string());
    m.seed = whole_number<uint64_t>(j, "seed", 0, path.string());
    m.aov = j.value("aov", false);
    m.dump_patches = j.value("dump_patches", false);
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
