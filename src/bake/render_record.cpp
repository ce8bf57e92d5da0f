// NAME.render.N.json: what one rendered frame was made with.
#include "lapflow/bake/render_record.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>

#include "core/json_number.hpp"
#include "lapflow/bake/options.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace fs = std::filesystem;
using detail::whole_number;

namespace {

constexpr const char* kRecordKey = "lapflow_render";

/// The picture options a record holds: the exemplar paths are not (the
/// digest stands for them), nor --dump-patches (a file beside the frame,
/// not a picture of it).
bool recorded(const BakeOption& option) {
  return option.effect == OptionEffect::Picture && !option.manifest_key.empty() && option.kind != OptionKind::Path &&
         option.name != "dump-patches";
}

}  // namespace

RenderRecord make_render_record(const BakeOptions& o, const BakeManifest& manifest, int frame,
                                const std::string& digest) {
  RenderRecord r;
  r.name = manifest.name;
  r.frame = frame;
  r.tracking_checksum = bake_tracking_checksum(manifest);
  r.exemplar_digest = digest;
  const auto absolute = [](const std::string& p) {
    std::error_code ec;
    const fs::path a = p.empty() ? fs::path() : fs::absolute(p, ec);
    return ec ? p : a.lexically_normal().string();
  };
  r.exemplar_color = absolute(o.exemplar_color);
  r.exemplar_feature = absolute(o.exemplar_feature);
  r.exemplar_displacement = absolute(o.exemplar_displacement);
  for (const BakeOption& option : bake_option_table())
    if (recorded(option)) r.options[option.name] = option.get(o);
  return r;
}

std::string encode_render_record(const RenderRecord& r) {
  nlohmann::ordered_json j = {{kRecordKey, RenderRecord::kVersion},
                              {"name", r.name},
                              {"frame", r.frame},
                              {"tracking_checksum", r.tracking_checksum}};
  if (r.patches_crc) j["patches_crc"] = *r.patches_crc;
  j["exemplar_digest"] = r.exemplar_digest;
  j["exemplar"] = {{"color", r.exemplar_color},
                   {"feature", r.exemplar_feature},
                   {"displacement", r.exemplar_displacement}};
  nlohmann::ordered_json options = nlohmann::ordered_json::object(), files = nlohmann::ordered_json::object();
  for (const auto& [key, value] : r.options) options[key] = value;
  for (const auto& [file, size] : r.files) files[file] = size;
  j["options"] = options;
  j["files"] = files;
  return j.dump(2) + "\n";
}

RenderRecord parse_render_record(const std::string& text, const std::string& path) {
  RenderRecord r;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path, std::string("not JSON: ") + e.what());
  }
  if (!j.is_object() || !j.contains(kRecordKey))
    throw InputError(path, "not a lapflow render record (no \"lapflow_render\" key)");
  const int version = whole_number<int>(j.at(kRecordKey), kRecordKey, path);
  if (version != RenderRecord::kVersion)
    throw InputError(path, fmt::format("render record version {}, this lapflow reads version {}", version,
                                       RenderRecord::kVersion));
  const auto need = [&](const char* key) -> const nlohmann::json& {
    if (!j.contains(key)) throw InputError(path, fmt::format("'{}' is missing", key));
    return j.at(key);
  };
  const auto text_of = [&](const nlohmann::json& v, const std::string& key) {
    if (!v.is_string()) throw InputError(path, fmt::format("'{}' must be a string, got {}", key, v.dump().substr(0, 40)));
    return v.get<std::string>();
  };
  r.name = text_of(need("name"), "name");
  r.frame = whole_number<int>(need("frame"), "frame", path);
  r.tracking_checksum = whole_number<uint32_t>(need("tracking_checksum"), "tracking_checksum", path);
  if (j.contains("patches_crc")) r.patches_crc = whole_number<uint32_t>(j.at("patches_crc"), "patches_crc", path);
  r.exemplar_digest = text_of(need("exemplar_digest"), "exemplar_digest");
  if (j.contains("exemplar")) {
    const nlohmann::json& e = j.at("exemplar");
    if (!e.is_object()) throw InputError(path, "'exemplar' must be an object");
    const auto file = [&](const char* key) {
      return e.contains(key) ? text_of(e.at(key), std::string("exemplar.") + key) : std::string();
    };
    r.exemplar_color = file("color");
    r.exemplar_feature = file("feature");
    r.exemplar_displacement = file("displacement");
  }
  const nlohmann::json& options = need("options");
  const nlohmann::json& files = need("files");
  if (!options.is_object()) throw InputError(path, "'options' must be an object");
  if (!files.is_object()) throw InputError(path, "'files' must be an object");
  for (const auto& [key, value] : options.items()) r.options[key] = text_of(value, "options." + key);
  for (const auto& [file, size] : files.items()) {
    if (file.empty() || file.find('/') != std::string::npos || file.find('\\') != std::string::npos ||
        file == "." || file == "..")
      throw InputError(path, fmt::format("files: '{}' is not a file name", file));
    r.files.emplace_back(file, whole_number<std::uintmax_t>(size, "files." + file, path));
  }
  return r;
}

RenderRecord read_render_record(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the render record");
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) throw InputError(path, "cannot read the render record");
  return parse_render_record(text, path);
}

std::vector<std::string> render_record_differences(const RenderRecord& disk, const RenderRecord& wanted) {
  std::vector<std::string> out;
  if (disk.name != wanted.name || disk.frame != wanted.frame)
    out.push_back(fmt::format("the frame: {} frame {} on disk, {} frame {} asked", disk.name, disk.frame, wanted.name,
                              wanted.frame));
  if (disk.tracking_checksum != wanted.tracking_checksum) out.push_back("the tracking (another tracking's options)");
  if (disk.patches_crc && wanted.patches_crc && *disk.patches_crc != *wanted.patches_crc)
    out.push_back("the patches (the frame was tracked again since)");
  if (disk.exemplar_digest != wanted.exemplar_digest)
    out.push_back(fmt::format("the exemplar: {} on disk, {} asked", disk.exemplar_digest, wanted.exemplar_digest));
  for (const auto& [key, value] : wanted.options) {
    const auto at = disk.options.find(key);
    if (at == disk.options.end()) out.push_back(fmt::format("{}: not recorded, {} asked", key, value));
    else if (at->second != value) out.push_back(fmt::format("{}: {} on disk, {} asked", key, at->second, value));
  }
  for (const auto& [key, value] : disk.options)
    if (!wanted.options.contains(key)) out.push_back(fmt::format("{}: {} on disk, unknown here", key, value));
  return out;
}

std::string render_record_file_problem(const BakeManifest& folder, const RenderRecord& record) {
  std::error_code ec;
  const std::string obj = folder.frame_file("obj", record.frame);
  if (!fs::exists(obj, ec)) return fs::path(obj).filename().string() + " is missing";
  for (const auto& [file, size] : record.files) {
    const fs::path p = fs::path(folder.dir) / file;
    const std::uintmax_t actual = fs::file_size(p, ec);
    if (ec) return file + " is missing";
    if (actual != size) return fmt::format("{} has {} bytes, {} recorded", file, actual, size);
  }
  return "";
}

std::string render_lock_purpose(const RenderRecord& wanted) {
  RenderRecord r = wanted;
  r.frame = 0;
  r.patches_crc.reset();
  r.files.clear();
  const std::string text = encode_render_record(r);
  const auto crc = uint32_t(crc32(0, reinterpret_cast<const Bytef*>(text.data()), uInt(text.size())));
  const auto res = wanted.options.find("resolution");
  return fmt::format("render {:08x}, resolution {}", crc, res == wanted.options.end() ? "?" : res->second);
}

std::string exemplar_digest(const Exemplar& e) {
  return exemplar_feature_digest(e.color) + "-" + exemplar_feature_digest(e.feature) + "-" +
         exemplar_feature_digest(e.displacement);
}

}  // namespace lapflow
