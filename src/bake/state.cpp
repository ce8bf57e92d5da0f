// NAME.state.N.bin: the patch state at the end of a frame, for --resume.
#include "lapflow/bake/state.hpp"

#include <zlib.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <type_traits>
#include <vector>

#include "core/json_number.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/atomic_file.hpp"

namespace lapflow {
namespace {

static_assert(std::endian::native == std::endian::little, "the state format is little-endian");
static_assert(sizeof(Vec3) == 24 && sizeof(Vec2) == 16 && sizeof(Tri) == 12, "packed value types");

constexpr const char* kMagic = "lapflow_state";

uint32_t crc_of(const char* data, std::size_t size) {
  return uint32_t(crc32(0, reinterpret_cast<const Bytef*>(data), uInt(size)));
}

/// Raw little-endian values and arrays appended to a byte string.
struct Encoder {
  std::string bytes;
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  template <class T>
  void put_array(const std::vector<T>& v) {
    if (!v.empty()) bytes.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
};

/// The same, read back with every size checked against what is left.
struct Decoder {
  const std::string& path;
  const char* at;
  const char* end;
  void need(std::size_t n) const {
    if (n > std::size_t(end - at)) throw InputError(path, "damaged state: the patch data ends early");
  }
  template <class T>
  T get() {
    need(sizeof(T));
    T v;
    std::memcpy(&v, at, sizeof v);
    at += sizeof v;
    return v;
  }
  template <class T>
  void get_array(std::vector<T>& v, uint64_t n) {
    if (n > uint64_t(end - at) / sizeof(T)) throw InputError(path, "damaged state: a count larger than the file");
    v.resize(n);
    if (n > 0) std::memcpy(v.data(), at, n * sizeof(T));  // an empty vector's data() may be null
    at += n * sizeof(T);
  }
};

}  // namespace

std::string encode_bake_state(const BakeStateHeader& s, const PatchSet& patches) {
  const bool layered = s.layers > 1;
  Encoder e;
  e.put(patches.next_id);
  e.put(uint64_t(patches.patches.size()));
  for (const Patch& p : patches.patches) {
    e.put(p.id);
    e.put(int32_t(p.birth_frame));
    e.put(p.center);
    e.put(p.center_normal);
    e.put(p.center_uv);
    e.put(uint8_t(p.at_rest));
    if (layered) {
      e.put(p.layer);
      e.put(p.layer_off);
    }
    e.put(uint64_t(p.positions.size()));
    e.put(uint64_t(p.triangles.size()));
    e.put(uint64_t(p.held.size()));
    // Per vertex, then per triangle, then the held bits.
    e.put_array(p.positions);
    e.put_array(p.rest_uv);
    e.put_array(p.surface_triangle);
    e.put_array(p.quality);
    e.put_array(p.border);
    e.put_array(p.weight);
    e.put_array(p.triangles);
    e.put_array(p.triangle_quality);
    e.put_array(p.triangle_delta);
    e.put_array(p.held);
  }
  // Ordered: the magic key comes first, so a file is recognised by its start.
  nlohmann::ordered_json header = {{kMagic, BakeStateHeader::kVersion},
                           {"name", s.name},
                           {"frame", s.frame},
                           {"options_checksum", s.options_checksum},
                           {"patches", patches.patches.size()},
                           {"next_id", patches.next_id},
                           {"payload_bytes", e.bytes.size()},
                           {"stats", s.stats_line.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json::parse(s.stats_line)}};
  if (s.mesh) header["mesh"] = {{"file", s.mesh->file}, {"bytes", s.mesh->bytes}, {"crc32", s.mesh->crc}};
  if (layered) header["layers"] = s.layers;
  std::string bytes = header.dump() + "\n";
  bytes += e.bytes;
  const uint32_t crc = crc_of(bytes.data(), bytes.size());
  bytes.append(reinterpret_cast<const char*>(&crc), sizeof crc);
  return bytes;
}

void write_bake_state(const std::string& path, const std::string& bytes, StagedFiles* staged) {
  write_text_atomically(path, bytes, staged);
}

InputStamp stamp_input_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the file");
  InputStamp stamp;
  stamp.file = std::filesystem::path(path).filename().string();
  uLong crc = crc32(0, nullptr, 0);
  std::vector<char> buffer(std::size_t(1) << 20);
  while (in) {
    in.read(buffer.data(), std::streamsize(buffer.size()));
    const std::streamsize n = in.gcount();
    if (n <= 0) break;
    crc = crc32(crc, reinterpret_cast<const Bytef*>(buffer.data()), uInt(n));
    stamp.bytes += uint64_t(n);
  }
  if (in.bad()) throw InputError(path, "cannot read the file");
  stamp.crc = uint32_t(crc);
  return stamp;
}

uint32_t bake_state_patches_crc(const std::string& bytes) {
  const std::size_t newline = bytes.find('\n');
  if (newline == std::string::npos || bytes.size() < newline + 1 + sizeof(uint32_t)) return 0;
  return crc_of(bytes.data() + newline + 1, bytes.size() - newline - 1 - sizeof(uint32_t));
}

std::optional<uint32_t> bake_state_file_patches_crc(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) return std::nullopt;
  return bake_state_patches_crc(bytes);
}

BakeState read_bake_state(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the bake state");
  const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) throw InputError(path, "cannot read the bake state");
  return parse_bake_state(bytes, path);
}

BakeState parse_bake_state(const std::string& bytes, const std::string& path) {
  using detail::whole_number;
  const std::size_t newline = bytes.find('\n');
  if (newline == std::string::npos || !bytes.starts_with(std::string("{\"") + kMagic + "\""))
    throw InputError(path, "not a lapflow bake state (it does not start with {\"lapflow_state\")");
  uint32_t stored = 0;
  if (bytes.size() < newline + 1 + sizeof stored)
    throw InputError(path, "damaged state: truncated (" + std::to_string(bytes.size()) + " bytes)");
  std::memcpy(&stored, bytes.data() + bytes.size() - sizeof stored, sizeof stored);
  if (crc_of(bytes.data(), bytes.size() - sizeof stored) != stored)
    throw InputError(path, "damaged state: checksum mismatch (the file is truncated or a byte changed)");

  BakeState state;
  BakeStateHeader& s = state.header;
  nlohmann::json header;
  uint64_t header_patches = 0;
  uint32_t header_next_id = 0;
  try {
    header = nlohmann::json::parse(bytes.begin(), bytes.begin() + std::ptrdiff_t(newline));
    const int version = whole_number<int>(header.at(kMagic), kMagic, path);
    if (version != BakeStateHeader::kVersion)
      throw InputError(path, "state format version " + std::to_string(version) + ", this lapflow reads version " +
                                 std::to_string(BakeStateHeader::kVersion));
    s.name = header.at("name").get<std::string>();
    s.frame = whole_number<int>(header.at("frame"), "frame", path);
    s.options_checksum = whole_number<uint32_t>(header.at("options_checksum"), "options_checksum", path);
    if (!header.at("stats").is_null()) s.stats_line = header["stats"].dump();
    if (header.contains("mesh")) {
      const nlohmann::json& m = header.at("mesh");
      if (!m.is_object() || !m.contains("file") || !m.at("file").is_string())
        throw InputError(path, "bad state header: 'mesh' must be an object with a 'file' name");
      s.mesh = InputStamp{m.at("file").get<std::string>(), whole_number<uint64_t>(m.value("bytes", nlohmann::json()), "mesh.bytes", path),
                          whole_number<uint32_t>(m.value("crc32", nlohmann::json()), "mesh.crc32", path)};
    }
    if (header.contains("layers")) {
      s.layers = whole_number<int>(header.at("layers"), "layers", path);
      if (s.layers < 2 || s.layers > 255)
        throw InputError(path, "bad state header: 'layers' must be from 2 to 255, not " + std::to_string(s.layers));
    }
    header_patches = whole_number<uint64_t>(header.at("patches"), "patches", path);
    header_next_id = whole_number<uint32_t>(header.at("next_id"), "next_id", path);
    const std::size_t payload = whole_number<std::size_t>(header.at("payload_bytes"), "payload_bytes", path);
    if (payload != bytes.size() - newline - 1 - sizeof stored)
      throw InputError(path, "damaged state: " + std::to_string(payload) + " bytes of patch data announced, " +
                                 std::to_string(bytes.size() - newline - 1 - sizeof stored) + " present");
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, std::string("bad state header: ") + e.what());
  }

  Decoder d{path, bytes.data() + newline + 1, bytes.data() + bytes.size() - sizeof stored};
  state.patches.next_id = d.get<uint32_t>();
  const uint64_t count = d.get<uint64_t>();
  if (count != header_patches || state.patches.next_id != header_next_id)
    throw InputError(path, "damaged state: the header and the patch data disagree");
  for (uint64_t i = 0; i < count; ++i) {
    Patch& p = state.patches.patches.emplace_back();
    p.id = d.get<uint32_t>();
    p.birth_frame = d.get<int32_t>();
    p.center = d.get<Vec3>();
    p.center_normal = d.get<Vec3>();
    p.center_uv = d.get<Vec2>();
    p.at_rest = d.get<uint8_t>() != 0;
    if (s.layers > 1) {
      p.layer = d.get<uint16_t>();
      p.layer_off = d.get<uint16_t>();
      if (p.layer >= s.layers)
        throw InputError(path, "damaged state: patch " + std::to_string(p.id) + " has layer " + std::to_string(p.layer) +
                                   " of " + std::to_string(s.layers));
    }
    const uint64_t nv = d.get<uint64_t>(), nt = d.get<uint64_t>(), nh = d.get<uint64_t>();
    d.get_array(p.positions, nv);
    d.get_array(p.rest_uv, nv);
    d.get_array(p.surface_triangle, nv);
    d.get_array(p.quality, nv);
    d.get_array(p.border, nv);
    d.get_array(p.weight, nv);
    d.get_array(p.triangles, nt);
    d.get_array(p.triangle_quality, nt);
    d.get_array(p.triangle_delta, nt);
    d.get_array(p.held, nh);
    if (nh != 0 && nh != kHeldWords)
      throw InputError(path, "damaged state: patch " + std::to_string(p.id) + " has " + std::to_string(nh) +
                                 " held words (0 or " + std::to_string(kHeldWords) + " expected)");
    for (const Tri& t : p.triangles)
      for (const int32_t v : t)
        if (v < 0 || uint64_t(v) >= nv)
          throw InputError(path, "damaged state: patch " + std::to_string(p.id) + " has a triangle corner " +
                                     std::to_string(v) + " outside its " + std::to_string(nv) + " vertices");
  }
  if (d.at != d.end) throw InputError(path, "damaged state: bytes left after the last patch");
  return state;
}

}  // namespace lapflow
