// NAME.bake.json: the inputs and settings of a bake, for eval and preview.
#include "lapflow/bake/manifest.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string_view>
#include <utility>

#include "lapflow/bake/options.hpp"
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
  return {n + "\\.(color|disp|aov|patches|state|render|usd)\\.[0-9]+", n + "\\.[0-9]+", n + "\\.stats", n + "\\.bake",
          n, n + "\\.manifest"};
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
  else if (kind == "render")
    file = name + ".render." + digits + ".json";
  else if (kind == "lock")
    file = "." + name + "." + digits + ".lock";
  else if (kind == "usd")
    file = name + ".usd." + digits + ".usda";
  else
    file = name + "." + kind + "." + digits + ".exr";
  return (fs::path(dir) / file).string();
}

std::string BakeManifest::shot_file(const std::string& kind) const {
  std::string file;
  if (kind == "usd") file = name + ".usda";
  else if (kind == "usd-clips") file = name + ".manifest.usda";
  else if (kind == "usd-lock") file = "." + name + ".usda.lock";
  else throw std::invalid_argument("BakeManifest::shot_file: no kind " + kind);
  return (fs::path(dir) / file).string();
}

BakeManifest make_bake_manifest(const BakeOptions& o, const std::vector<int>& frames) {
  BakeManifest m;
  m.name = o.name;
  m.dir = absolute_or_empty(o.out_dir);
  m.frames = frames;
  m.options = o;
  for (const BakeOption& option : bake_option_table())
    if (option.kind == OptionKind::Path && !option.manifest_key.empty())
      option.set(m.options, absolute_or_empty(option.get(o)));
  for (ExemplarLayer& layer : m.options.layers)
    for (std::string* path : {&layer.color, &layer.feature, &layer.displacement}) *path = absolute_or_empty(*path);
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

/// The manifest's text of `option` in `o`.
std::string manifest_text(const BakeOption& option, const BakeOptions& o) {
  return option.manifest_get ? option.manifest_get(o) : option.get(o);
}

/// "settings/spacing" -> ("settings", "spacing"); "radius" -> ("", "radius").
std::pair<std::string, std::string> split_key(const std::string& key) {
  const std::size_t slash = key.find('/');
  if (slash == std::string::npos) return {"", key};
  return {key.substr(0, slash), key.substr(slash + 1)};
}

/// The JSON value of `option` at the top of the manifest (or nested in an
/// object other than settings): typed by its kind. Settings hold text.
nlohmann::json typed_value(const BakeOption& option, const std::string& text) {
  switch (option.kind) {
    case OptionKind::Number: return std::stod(text);
    case OptionKind::Integer:
      if (!text.empty() && text[0] == '-') return std::stoll(text);
      return std::stoull(text);
    case OptionKind::Flag: return text == "true";
    default: return text;
  }
}

nlohmann::json manifest_json(const BakeManifest& m) {
  nlohmann::json j = {{"lapflow_bake", m.version}, {"name", m.name}, {"frames", m.frames}};
  nlohmann::json settings = nlohmann::json::object();
  for (const BakeOption& option : bake_option_table()) {
    if (option.manifest_key.empty()) continue;
    const std::string text = manifest_text(option, m.options);
    const auto [parent, key] = split_key(option.manifest_key);
    if (parent == "settings")
      settings[key] = text;
    else if (parent.empty())
      j[key] = typed_value(option, text);
    else
      j[parent][key] = typed_value(option, text);
  }
  if (!m.feature_digest.empty()) settings["feature_digest"] = m.feature_digest;
  j["settings"] = std::move(settings);
  return j;
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
/// and UV mesh, not the patches (OptionEffect::Picture, docs/farm.md):
/// `lapflow render` may set them anew. The feature map counts through
/// settings/feature_digest.
bool output_only_key(const std::string& key) {
  for (const BakeOption& o : bake_option_table())
    if (o.effect != OptionEffect::Animation && !o.manifest_key.empty() && key == "/" + o.manifest_key) return true;
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
  errno = 0;
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw InputError(path.string(), std::string("cannot open the bake manifest") +
                                        (errno != 0 ? std::string(": ") + std::strerror(errno) : std::string()));
  std::ostringstream text;
  text << in.rdbuf();
  return parse_bake_manifest(text.str(), path.string());
}

namespace {

/// Reads `option` from the manifest `j` (its settings `settings`) into `o`:
/// a key the manifest lacks stands for option.absent (or the default), a
/// value of the wrong type or one that does not parse is an InputError
/// naming the key ("settings.spacing: 'x' is not a number").
void read_option(const nlohmann::json& j, const nlohmann::json& settings, const BakeOption& option, BakeOptions& o,
                 const std::string& path) {
  const auto [parent, key] = split_key(option.manifest_key);
  const nlohmann::json* node = nullptr;
  if (parent == "settings") {
    if (settings.contains(key)) node = &settings[key];
  } else if (parent.empty()) {
    if (j.contains(key)) node = &j[key];
  } else if (j.contains(parent)) {
    if (!j[parent].is_object()) throw InputError(path, "'" + parent + "' must be an object");
    if (j[parent].contains(key)) node = &j[parent][key];
  }
  const std::string dotted = parent.empty() ? key : parent + "." + key;
  std::string text;
  if (!node) {
    if (!option.absent) return;
    text = *option.absent;
  } else if (parent == "settings" || node->is_string()) {
    if (!node->is_string()) throw InputError(path, dotted + " must be text, got " + node->dump().substr(0, 40));
    text = node->get<std::string>();
  } else if (option.kind == OptionKind::Number && node->is_number()) {
    text = fmt::format("{}", node->get<double>());
  } else if (option.kind == OptionKind::Integer) {
    text = node->is_number_unsigned() ? fmt::format("{}", whole_number<uint64_t>(*node, key, path))
                                      : fmt::format("{}", whole_number<int64_t>(*node, key, path));
  } else if (option.kind == OptionKind::Flag && node->is_boolean()) {
    text = node->get<bool>() ? "true" : "false";
  } else {
    const char* expected = option.kind == OptionKind::Flag     ? "true or false"
                           : option.kind == OptionKind::Number ? "a number"
                                                               : "text";
    throw InputError(path, dotted + ": " + node->dump().substr(0, 40) + " is not " + expected);
  }
  try {
    (option.manifest_set ? option.manifest_set : option.set)(o, text);
  } catch (const std::invalid_argument& e) {
    throw InputError(path, dotted + ": '" + text + "' is not " + e.what());
  }
}

}  // namespace

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
    if (!j.is_object() || !j.contains("lapflow_bake"))
      throw InputError(path.string(), "not a lapflow bake manifest (no 'lapflow_bake')");
    m.version = whole_number<int>(j.at("lapflow_bake"), "lapflow_bake", path.string());
    if (!j.contains("name") || !j["name"].is_string()) throw InputError(path.string(), "'name' must be text");
    m.name = j["name"].get<std::string>();
    if (!j.contains("frames") || !j["frames"].is_array())
      throw InputError(path.string(), "'frames' must be an array of frame numbers");
    if (m.name.empty() || m.name == "." || m.name == ".." || m.name.find_first_of("/\\") != std::string::npos)
      throw InputError(path.string(), "name: " + quote_token(m.name) +
                                          " is not a file name (it names the bake's files, in this folder)");
    for (const nlohmann::json& f : j["frames"]) m.frames.push_back(whole_number<int>(f, "frames", path.string()));
    for (std::size_t i = 1; i < m.frames.size(); ++i)
      if (m.frames[i] <= m.frames[i - 1])
        throw InputError(path.string(), "frames: " + std::to_string(m.frames[i]) + " follows " +
                                            std::to_string(m.frames[i - 1]) +
                                            " (frame numbers must be strictly increasing)");
    const nlohmann::json no_settings = nlohmann::json::object();
    const nlohmann::json& settings = j.contains("settings") ? j["settings"] : no_settings;
    if (!settings.is_object()) throw InputError(path.string(), "'settings' must be an object");
    for (const BakeOption& option : bake_option_table())
      if (!option.manifest_key.empty()) read_option(j, settings, option, m.options, path.string());
    // The values bake itself refuses (resolve_bake_options), named by key.
    if (!(m.options.fps > 0)) throw InputError(path.string(), fmt::format("fps: {} is not positive", m.options.fps));
    if (!(m.options.patch.radius >= 0))
      throw InputError(path.string(), fmt::format("radius: {} is negative (0 = automatic)", m.options.patch.radius));
    if (!(m.options.seeding.spacing > 0))
      throw InputError(path.string(), fmt::format("settings.spacing: {} is not positive", m.options.seeding.spacing));
    if (settings.contains("feature_digest")) {
      if (!settings["feature_digest"].is_string())
        throw InputError(path.string(), "settings.feature_digest must be text");
      m.feature_digest = settings["feature_digest"].get<std::string>();
    }
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
