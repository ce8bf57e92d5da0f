// Reading and writing fluid meshes (PLY binary/ASCII, OBJ).
//
// Why a hand-written PLY reader instead of OpenMesh's: OpenMesh silently drops
// vertex properties whose stored type differs from the one requested (the
// velocities just vanish), answers a malformed file with a bare `false`, and
// builds a halfedge structure we never use. This reader parses straight into
// flat arrays, accepts every PLY scalar type and list layout, and every
// failure names the file, the element and its index.
#include "lapflow/io/mesh_io.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string_view>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------- files ----

std::string load_file(const std::string& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) throw InputError(path, "file not found");
  if (fs::is_directory(st)) throw InputError(path, "is a directory, not a mesh file");
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  std::string data;
  const auto size = fs::file_size(path, ec);
  if (!ec) data.reserve(std::size_t(size));
  char buf[1 << 16];
  std::size_t got;
  while ((got = std::fread(buf, 1, sizeof buf, f.get())) > 0) data.append(buf, got);
  if (std::ferror(f.get())) throw InputError(path, std::string("read error: ") + std::strerror(errno));
  return data;
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

const char* non_finite_word(const Vec3& v) {
  return (std::isnan(v.x) || std::isnan(v.y) || std::isnan(v.z)) ? "NaN" : "infinite";
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

/// Splits on blanks; views into `line`.
std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    const std::size_t b = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
  return out;
}

bool parse_double(std::string_view s, double& v) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

/// Why `token` is not a double: out of range, or not a number at all.
std::string number_problem(std::string_view token) {
  std::string_view s = token;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  double v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  const bool whole = r.ptr == s.data() + s.size();
  return quote_token(token) + (r.ec == std::errc::result_out_of_range && whole ? " is out of range for a double"
                                                                               : " is not a number");
}

// ------------------------------------------------------------------ PLY ----

enum class Scalar : uint8_t { i8, u8, i16, u16, i32, u32, f32, f64 };

int scalar_size(Scalar t) {
  switch (t) {
    case Scalar::i8: case Scalar::u8: return 1;
    case Scalar::i16: case Scalar::u16: return 2;
    case Scalar::i32: case Scalar::u32: case Scalar::f32: return 4;
    case Scalar::f64: return 8;
  }
  return 0;
}

bool parse_scalar(std::string_view w, Scalar& t) {
  static const std::pair<std::string_view, Scalar> names[] = {
      {"char", Scalar::i8},    {"int8", Scalar::i8},     {"uchar", Scalar::u8},   {"uint8", Scalar::u8},
      {"short", Scalar::i16},  {"int16", Scalar::i16},   {"ushort", Scalar::u16}, {"uint16", Scalar::u16},
      {"int", Scalar::i32},    {"int32", Scalar::i32},   {"uint", Scalar::u32},   {"uint32", Scalar::u32},
      {"float", Scalar::f32},  {"float32", Scalar::f32}, {"double", Scalar::f64}, {"float64", Scalar::f64}};
  for (const auto& [n, s] : names)
    if (n == w) { t = s; return true; }
  return false;
}

bool is_integer(Scalar t) { return t != Scalar::f32 && t != Scalar::f64; }

struct PlyProperty {
  std::string name;
  Scalar type = Scalar::f32;
  std::string type_word;  ///< the type as the header spells it ("int", "int32"), for warnings
  bool is_list = false;
  Scalar count_type = Scalar::u8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> props;
};

enum class PlyFormat { ascii, binary_le, binary_be };

struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
  std::size_t data_offset = 0;
  int data_line = 1;  ///< line number of the first data line (ASCII errors)
};

PlyHeader parse_ply_header(const std::string& path, const std::string& data) {
  PlyHeader h;
  if (data.size() < 4 || data.compare(0, 3, "ply") != 0 || !(data[3] == '\n' || data[3] == '\r'))
    throw InputError(path, "not a PLY file: it does not start with the 'ply' magic line");
  std::size_t pos = 0;
  int line_no = 0;
  bool have_format = false;
  for (;;) {
    const std::size_t nl = data.find('\n', pos);
    if (nl == std::string::npos) throw InputError(path, "PLY header has no 'end_header' line (file truncated?)");
    std::string_view line(data.data() + pos, nl - pos);
    pos = nl + 1;
    ++line_no;
    if (line_no == 1) continue;  // the magic
    const auto w = split_words(line);
    if (w.empty()) continue;
    auto bad = [&](const std::string& what) {
      return InputError(path, "PLY header line " + std::to_string(line_no) + ": " + what);
    };
    if (w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "end_header") break;
    if (w[0] == "format") {
      if (w.size() < 2) throw bad("'format' without a value");
      if (w[1] == "ascii") h.format = PlyFormat::ascii;
      else if (w[1] == "binary_little_endian") h.format = PlyFormat::binary_le;
      else if (w[1] == "binary_big_endian") h.format = PlyFormat::binary_be;
      else throw bad("unknown format " + quote_token(w[1]) + " (ascii, binary_little_endian or binary_big_endian)");
      have_format = true;
    } else if (w[0] == "element") {
      if (w.size() != 3) throw bad("expected 'element <name> <count>'");
      PlyElement e;
      e.name = std::string(w[1]);
      const auto r = std::from_chars(w[2].data(), w[2].data() + w[2].size(), e.count);
      if (r.ec != std::errc() || r.ptr != w[2].data() + w[2].size())
        throw bad("element " + quote_token(e.name) + " has an invalid count " + quote_token(w[2]));
      h.elements.push_back(std::move(e));
    } else if (w[0] == "property") {
      if (h.elements.empty()) throw bad("'property' before any 'element'");
      PlyProperty p;
      if (w.size() >= 2 && w[1] == "list") {
        if (w.size() != 5) throw bad("expected 'property list <count type> <item type> <name>'");
        p.is_list = true;
        if (!parse_scalar(w[2], p.count_type)) throw bad("unknown type " + quote_token(w[2]));
        if (!is_integer(p.count_type)) throw bad("list count type must be an integer type");
        if (!parse_scalar(w[3], p.type)) throw bad("unknown type " + quote_token(w[3]));
        p.type_word = std::string(w[3]);
        p.name = std::string(w[4]);
      } else {
        if (w.size() != 3) throw bad("expected 'property <type> <name>'");
        if (!parse_scalar(w[1], p.type)) throw bad("unknown type " + quote_token(w[1]));
        p.type_word = std::string(w[1]);
        p.name = std::string(w[2]);
      }
      h.elements.back().props.push_back(std::move(p));
    } else {
      throw bad("unexpected keyword " + quote_token(w[0]));
    }
  }
  if (!have_format) throw InputError(path, "PLY header has no 'format' line");
  h.data_offset = pos;
  h.data_line = line_no + 1;
  return h;
}

/// Reads numbers from the data section, binary (either byte order) or ASCII,
/// and reports where the data ended for a truncated file.
class PlyData {
 public:
  PlyData(const std::string& path, const std::string& data, const PlyHeader& h)
      : path_(path), p_(data.data() + h.data_offset), end_(data.data() + data.size()), ascii_(h.format == PlyFormat::ascii),
        swap_((h.format == PlyFormat::binary_be) != (std::endian::native == std::endian::big)), line_(h.data_line) {}

  /// Sets the element instance named in error messages.
  void at(const std::string& element, uint64_t index, uint64_t count) {
    element_ = &element;
    index_ = index;
    count_ = count;
  }

  double read(Scalar t) { return ascii_ ? read_ascii() : read_binary(t); }

  /// A list's length: a whole number no larger than the bytes left (every
  /// item takes at least one), else an InputError. A raw cast of an ASCII
  /// length of 3e62 would be undefined.
  uint64_t list_length(Scalar count_type) {
    const double n = read(count_type);
    if (!(n >= 0) || n != std::floor(n) || n > double(end_ - p_))
      throw InputError(path_, where() + ": invalid list length " + std::to_string(n));
    return uint64_t(n);
  }

  void skip(Scalar t, uint64_t n) {
    if (ascii_) {
      for (uint64_t i = 0; i < n; ++i) read_ascii();
      return;
    }
    const uint64_t bytes = n * uint64_t(scalar_size(t));
    if (uint64_t(end_ - p_) < bytes) truncated();
    p_ += bytes;
  }

  /// Throws unless only blanks follow the last element (a header whose counts
  /// are too small would otherwise silently lose geometry).
  void expect_end() {
    const char* q = p_;
    while (q < end_ && (is_space(*q) || (!ascii_ && *q == '\0'))) ++q;
    if (q == end_) return;
    if (ascii_) {
      int line = line_;
      for (const char* r = p_; r < q; ++r) line += (*r == '\n');
      throw InputError(path_, "unexpected data at line " + std::to_string(line) +
                                  " after the last element (the header's element counts are too small)");
    }
    throw InputError(path_, std::to_string(end_ - p_) +
                                " bytes of unexpected data after the last element (the header's element counts are "
                                "too small, or the format line is wrong)");
  }

  [[noreturn]] void truncated() const {
    throw InputError(path_, "file truncated: data ends in " + element_label() + " " + std::to_string(index_) + " of " +
                                std::to_string(count_) + " (the header promises more than the file holds)");
  }

  std::string where() const {
    std::string s = element_label() + " " + std::to_string(index_);
    if (ascii_) s = "line " + std::to_string(line_) + " (" + s + ")";
    return s;
  }

 private:
  template <typename U>
  U load() {
    U u;
    std::memcpy(&u, p_, sizeof u);
    if (swap_) {
      if constexpr (sizeof(U) == 2) u = __builtin_bswap16(u);
      if constexpr (sizeof(U) == 4) u = __builtin_bswap32(u);
      if constexpr (sizeof(U) == 8) u = __builtin_bswap64(u);
    }
    p_ += sizeof u;
    return u;
  }

  double read_binary(Scalar t) {
    if (end_ - p_ < scalar_size(t)) truncated();
    switch (t) {
      case Scalar::i8: return double(int8_t(*p_++));
      case Scalar::u8: return double(uint8_t(*p_++));
      case Scalar::i16: return double(int16_t(load<uint16_t>()));
      case Scalar::u16: return double(load<uint16_t>());
      case Scalar::i32: return double(int32_t(load<uint32_t>()));
      case Scalar::u32: return double(load<uint32_t>());
      case Scalar::f32: return double(std::bit_cast<float>(load<uint32_t>()));
      case Scalar::f64: return std::bit_cast<double>(load<uint64_t>());
    }
    return 0;
  }

  double read_ascii() {
    while (p_ < end_ && is_space(*p_)) line_ += (*p_++ == '\n');
    if (p_ == end_) truncated();
    const char* b = p_;
    while (p_ < end_ && !is_space(*p_)) ++p_;
    double v;
    if (!parse_double(std::string_view(b, std::size_t(p_ - b)), v))
      throw InputError(path_, where() + ": " + quote_token(std::string_view(b, std::size_t(p_ - b))) + " is not a number");
    return v;
  }

  /// The element's name as the header spells it when that is a plain word
  /// ("vertex"), else quoted: a name of raw bytes (a NUL would end the
  /// message) or a megabyte long.
  std::string element_label() const {
    const bool plain = element_->size() <= 40 && std::all_of(element_->begin(), element_->end(), [](char c) {
      return c > 0x20 && c < 0x7f;
    });
    return plain ? *element_ : quote_token(*element_);
  }

  const std::string& path_;
  const char* p_;
  const char* end_;
  bool ascii_, swap_;
  int line_;
  const std::string* element_ = nullptr;
  uint64_t index_ = 0, count_ = 0;
};

int find_prop(const PlyElement& e, std::initializer_list<const char*> names) {
  for (const char* n : names)
    for (std::size_t i = 0; i < e.props.size(); ++i)
      if (!e.props[i].is_list && e.props[i].name == n) return int(i);
  return -1;
}

/// Property slots of the vertex element: 0-2 position, 3-5 velocity, 6 + j
/// attribute j, -1 skip.
std::vector<int> vertex_slots(const std::string& path, const PlyElement& e, bool& has_velocity,
                              const std::vector<std::string>& attributes) {
  std::vector<int> slot(e.props.size(), -1);
  const char* axes[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    const int i = find_prop(e, {axes[k]});
    if (i < 0) throw InputError(path, std::string("PLY vertex element has no '") + axes[k] + "' property");
    slot[i] = k;
  }
  static const char* const velocity_names[3][3] = {
      {"vx", "vy", "vz"}, {"velocity_x", "velocity_y", "velocity_z"}, {"v_x", "v_y", "v_z"}};
  has_velocity = false;
  for (const auto& names : velocity_names) {
    int idx[3];
    int found = 0;
    for (int k = 0; k < 3; ++k) found += (idx[k] = find_prop(e, {names[k]})) >= 0;
    if (found == 0) continue;
    if (found < 3)
      throw InputError(path, std::string("PLY vertex velocity is incomplete: expected '") + names[0] + " " + names[1] +
                                 " " + names[2] + "', some are missing");
    for (int k = 0; k < 3; ++k) slot[idx[k]] = 3 + k;
    has_velocity = true;
    break;
  }
  for (std::size_t j = 0; j < attributes.size(); ++j) {
    int i = -1;
    for (std::size_t k = 0; k < e.props.size() && i < 0; ++k)
      if (e.props[k].name == attributes[j]) i = int(k);
    if (i < 0) {
      std::string have;
      for (const PlyProperty& p : e.props) have += (have.empty() ? "" : " ") + p.name;
      throw InputError(path, "PLY vertex element has no property " + quote_token(attributes[j]) + " (it has: " + have + ")");
    }
    if (e.props[i].is_list)
      throw InputError(path, "PLY vertex property " + quote_token(attributes[j]) + " is a list, expected a number");
    if (slot[i] >= 0 && slot[i] < 6)
      throw InputError(path, "PLY vertex property " + quote_token(attributes[j]) +
                                 " is a position or velocity component, not an attribute (use speed)");
    slot[i] = 6 + int(j);
  }
  for (std::size_t i = 0; i < slot.size(); ++i)
    if (slot[i] >= 0 && e.props[i].is_list)
      throw InputError(path, "PLY vertex property '" + e.props[i].name + "' is a list, expected a number");
  return slot;
}

TriMesh read_ply(const std::string& path, const std::string& data, MeshFileInfo* declared,
                 const std::vector<std::string>& attributes = {},
                 std::vector<std::vector<float>>* attribute_values = nullptr) {
  const PlyHeader h = parse_ply_header(path, data);
  PlyData in(path, data, h);
  TriMesh m;
  std::vector<int32_t> face_of_triangle;  // to name the face when an index is bad
  bool seen_vertex = false;
  for (const PlyElement& e : h.elements) {
    if (e.name == "vertex" && !seen_vertex) {
      seen_vertex = true;
      if (e.count > uint64_t(INT32_MAX)) throw InputError(path, "PLY has more vertices than lapflow supports (2^31)");
      bool has_velocity = false;
      const std::vector<int> slot = vertex_slots(path, e, has_velocity, attributes);
      if (declared) {
        for (int want = 0; want < 6; ++want)
          for (std::size_t k = 0; k < slot.size(); ++k)
            if (slot[k] == want) {
              const PlyProperty& p = e.props[k];
              (want < 3 ? declared->positions : declared->velocities).push_back({p.name, p.type_word, is_integer(p.type)});
            }
        for (std::size_t k = 0; k < slot.size(); ++k)
          if ((slot[k] < 0 || slot[k] >= 6) && !e.props[k].is_list) declared->attributes.push_back(e.props[k].name);
      }
      // Never trust the count for allocation beyond what the file can hold.
      const std::size_t cap = std::min<uint64_t>(e.count, data.size());
      m.positions.reserve(cap);
      if (has_velocity) m.velocities.reserve(cap);
      std::vector<double> v(6 + attributes.size(), 0.0);
      if (attribute_values) attribute_values->assign(attributes.size(), {});
      if (attribute_values)
        for (auto& column : *attribute_values) column.reserve(cap);
      for (uint64_t i = 0; i < e.count; ++i) {
        in.at(e.name, i, e.count);
        for (std::size_t k = 0; k < e.props.size(); ++k) {
          const PlyProperty& p = e.props[k];
          if (p.is_list) {
            in.skip(p.type, in.list_length(p.count_type));
          } else if (slot[k] >= 0) {
            v[slot[k]] = in.read(p.type);
          } else {
            in.skip(p.type, 1);
          }
        }
        const Vec3 pos{v[0], v[1], v[2]};
        if (!is_finite(pos)) throw InputError(path, "vertex " + std::to_string(i) + ": position is " + non_finite_word(pos));
        m.positions.push_back(pos);
        if (has_velocity) {
          const Vec3 vel{v[3], v[4], v[5]};
          if (!is_finite(vel))
            throw InputError(path, "vertex " + std::to_string(i) + ": velocity is " + non_finite_word(vel));
          m.velocities.push_back(vel);
        }
        for (std::size_t j = 0; j < attributes.size(); ++j) {
          const double a = v[6 + j];
          if (!std::isfinite(float(a)))
            throw InputError(path, "vertex " + std::to_string(i) + ": property " + quote_token(attributes[j]) + " is " +
                                       (std::isnan(a) ? "NaN" : "not a finite float"));
          if (attribute_values) (*attribute_values)[j].push_back(float(a));
        }
      }
    } else if (e.name == "face" && face_of_triangle.empty()) {
      int list = -1;
      for (std::size_t k = 0; k < e.props.size() && list < 0; ++k)
        if (e.props[k].is_list && (e.props[k].name == "vertex_indices" || e.props[k].name == "vertex_index"))
          list = int(k);
      if (list < 0 && e.count > 0)
        throw InputError(path, "PLY face element has no 'vertex_indices' (or 'vertex_index') list property");
      if (list >= 0 && !is_integer(e.props[list].type))
        throw InputError(path, "PLY face vertex indices must have an integer type");
      m.triangles.reserve(std::min<uint64_t>(e.count, data.size()));
      std::vector<int64_t> poly;
      for (uint64_t i = 0; i < e.count; ++i) {
        in.at(e.name, i, e.count);
        for (std::size_t k = 0; k < e.props.size(); ++k) {
          const PlyProperty& p = e.props[k];
          if (int(k) == list) {
            const uint64_t n = in.list_length(p.count_type);
            if (n < 3)
              throw InputError(path, in.where() + " has " + std::to_string(n) + " vertices (a face needs at least 3)");
            // One value at a time: a corrupt huge count hits the end of the
            // data (truncated) before it can allocate much.
            poly.clear();
            for (uint64_t j = 0; j < n; ++j) {
              const double x = in.read(p.type);
              if (!(x >= 0 && x <= double(INT32_MAX)))
                throw InputError(path, "face " + std::to_string(i) + ": vertex index " +
                                           std::to_string(int64_t(std::fmax(std::fmin(x, 9e18), -9e18))) +
                                           " is out of range");
              poly.push_back(int64_t(x));
            }
            for (std::size_t j = 1; j + 1 < poly.size(); ++j) {
              m.triangles.push_back({int32_t(poly[0]), int32_t(poly[j]), int32_t(poly[j + 1])});
              face_of_triangle.push_back(int32_t(i));
            }
          } else if (p.is_list) {
            in.skip(p.type, in.list_length(p.count_type));
          } else {
            in.skip(p.type, 1);
          }
        }
      }
    } else {
      // Elements lapflow does not use (edges, materials, a second vertex set):
      // walk over them so the data after them stays aligned. One with no
      // property holds no data: a count of 2e14 must not be walked.
      if (e.props.empty()) continue;
      for (uint64_t i = 0; i < e.count; ++i) {
        in.at(e.name, i, e.count);
        for (const PlyProperty& p : e.props) {
          if (p.is_list) {
            in.skip(p.type, in.list_length(p.count_type));
          } else {
            in.skip(p.type, 1);
          }
        }
      }
    }
  }
  if (!seen_vertex) throw InputError(path, "PLY has no 'vertex' element");
  in.expect_end();
  const int32_t nv = int32_t(m.positions.size());
  for (std::size_t t = 0; t < m.triangles.size(); ++t)
    for (int32_t x : m.triangles[t])
      if (x >= nv)
        throw InputError(path, "face " + std::to_string(face_of_triangle[t]) + ": vertex index " + std::to_string(x) +
                                   " is out of range (the file has " + std::to_string(nv) + " vertices)");
  return m;
}

// ------------------------------------------------------------------ OBJ ----

// With `corner_uv`, also the texture coordinates: 3 per triangle (the `vt`
// of each corner), or none when the file has no `vt`.
TriMesh read_obj(const std::string& path, const std::string& data, std::vector<Vec2>* corner_uv = nullptr) {
  TriMesh m;
  std::vector<int32_t> line_of_triangle;  // to name the line when an index is bad
  std::vector<int64_t> poly, poly_vt;
  std::vector<Vec2> vts;
  bool any_missing_vt = false;
  std::size_t pos = 0;
  int line_no = 0;
  while (pos < data.size()) {
    std::size_t nl = data.find('\n', pos);
    if (nl == std::string::npos) nl = data.size();
    std::string_view line(data.data() + pos, nl - pos);
    pos = nl + 1;
    ++line_no;
    if (const auto hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const auto w = split_words(line);
    if (w.empty()) continue;
    auto bad = [&](const std::string& what) {
      return InputError(path, "line " + std::to_string(line_no) + ": " + what);
    };
    if (w[0] == "v") {
      double c[3];
      if (w.size() < 4) throw bad("malformed vertex: expected 'v x y z'");
      for (int k = 0; k < 3; ++k)
        if (!parse_double(w[1 + k], c[k]))
          throw bad("malformed vertex " + std::to_string(m.positions.size()) + ": " + number_problem(w[1 + k]));
      const Vec3 p{c[0], c[1], c[2]};
      if (!is_finite(p))
        throw bad("vertex " + std::to_string(m.positions.size()) + ": position is " + non_finite_word(p));
      m.positions.push_back(p);
    } else if (w[0] == "vt" && corner_uv) {
      double c[2];
      if (w.size() < 3) throw bad("malformed texture coordinate: expected 'vt u v'");
      for (int k = 0; k < 2; ++k)
        if (!parse_double(w[1 + k], c[k]) || !std::isfinite(c[k]))
          throw bad("malformed texture coordinate: " + quote_token(w[1 + k]) + " is not a finite number");
      vts.push_back({c[0], c[1]});
    } else if (w[0] == "f") {
      if (w.size() < 4) throw bad("malformed face: a face needs at least 3 vertices");
      poly.clear();
      poly_vt.clear();
      for (std::size_t k = 1; k < w.size(); ++k) {
        if (corner_uv) {
          // v/vt or v/vt/vn: the texture coordinate index, when present.
          const std::size_t slash = w[k].find('/');
          int64_t t = 0;
          if (slash != std::string_view::npos) {
            const std::string_view tok = w[k].substr(slash + 1, w[k].find('/', slash + 1) - slash - 1);
            if (!tok.empty()) {
              const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), t);
              if (r.ec != std::errc() || r.ptr != tok.data() + tok.size() || t == 0)
                throw bad("malformed face: " + quote_token(w[k]) + " has a bad texture coordinate index");
              t = t > 0 ? t - 1 : int64_t(vts.size()) + t;
              if (t < 0 || t >= int64_t(vts.size()))
                throw bad("texture coordinate index in " + quote_token(w[k]) + " is out of range (" +
                          std::to_string(vts.size()) + " defined so far)");
              poly_vt.push_back(t);
            } else {
              any_missing_vt = true;
            }
          } else {
            any_missing_vt = true;
          }
        }
        const std::string_view tok = w[k].substr(0, w[k].find('/'));
        int64_t idx = 0;
        const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), idx);
        if (r.ec != std::errc() || r.ptr != tok.data() + tok.size() || tok.empty())
          throw bad("malformed face: " + quote_token(w[k]) + " is not a vertex index");
        if (idx == 0) throw bad("vertex index 0 is invalid (OBJ indices start at 1)");
        // Negative indices count back from the last vertex defined so far.
        const int64_t resolved = idx > 0 ? idx - 1 : int64_t(m.positions.size()) + idx;
        if (resolved < 0 || resolved > INT32_MAX)
          throw bad("vertex index " + std::to_string(idx) + " is out of range (" + std::to_string(m.positions.size()) +
                    " vertices defined so far)");
        poly.push_back(resolved);
      }
      for (std::size_t j = 1; j + 1 < poly.size(); ++j) {
        m.triangles.push_back({int32_t(poly[0]), int32_t(poly[j]), int32_t(poly[j + 1])});
        line_of_triangle.push_back(line_no);
        if (corner_uv && poly_vt.size() == poly.size())
          for (const std::size_t k : {std::size_t(0), j, j + 1}) corner_uv->push_back(vts[poly_vt[k]]);
      }
    } else {
      // vt, vn, o, g, s, usemtl, mtllib, l, p and the free-form statements
      // carry nothing lapflow needs; anything that is not a keyword is garbage.
      for (char c : w[0])
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'))
          throw bad("malformed line: " + quote_token(w[0]) + " is not an OBJ statement");
    }
  }
  // Positive indices may legally refer to vertices defined later in the file.
  const int32_t nv = int32_t(m.positions.size());
  for (std::size_t t = 0; t < m.triangles.size(); ++t)
    for (int32_t x : m.triangles[t])
      if (x >= nv)
        throw InputError(path, "line " + std::to_string(line_of_triangle[t]) + ": vertex index " +
                                   std::to_string(int64_t(x) + 1) + " is out of range (the file has " +
                                   std::to_string(nv) + " vertices)");
  if (corner_uv) {
    if (any_missing_vt && !corner_uv->empty())
      throw InputError(path, "some faces have texture coordinates and some do not");
    if (corner_uv->size() != 3 * m.triangles.size()) corner_uv->clear();
  }
  return m;
}

}  // namespace

UvMesh read_uv_mesh_from_memory(const std::string& data, const std::string& name) {
  UvMesh out;
  out.mesh = read_obj(name, data, &out.corner_uv);
  return out;
}

UvMesh read_uv_mesh(const std::string& path) {
  const std::string ext = lower(fs::path(path).extension().string());
  if (ext != ".obj") throw InputError(path, "a UV mesh must be an OBJ file (lapflow writes NAME.N.obj)");
  return read_uv_mesh_from_memory(load_file(path), path);
}

namespace {
/// Largest distance of a used vertex from the origin along an axis (m).
double mesh_reach(const TriMesh& mesh) {
  const Box3 b = bounding_box(mesh);
  return std::max({std::abs(b.lo.x), std::abs(b.lo.y), std::abs(b.lo.z), std::abs(b.hi.x), std::abs(b.hi.y),
                   std::abs(b.hi.z)});
}
}  // namespace

void check_mesh_bounds(const TriMesh& mesh, const std::string& path) {
  if (mesh.empty()) return;
  const Box3 b = bounding_box(mesh);
  const double reach = mesh_reach(mesh);
  if (!(reach <= kMaxMeshCoordinate))
    throw InputError(path, fmt::format("mesh bounds {:.3g} m: are the units metres? (bounds ({:.3g}, {:.3g}, {:.3g}) - "
                                       "({:.3g}, {:.3g}, {:.3g}); lapflow refuses coordinates beyond {:.0e} m)",
                                       reach, b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z, kMaxMeshCoordinate));
}

namespace {

TriMesh parse_mesh(const std::string& data, const std::string& path, MeshFileInfo* declared,
                   const std::vector<std::string>& attributes = {},
                   std::vector<std::vector<float>>* attribute_values = nullptr) {
  const std::string ext = lower(fs::path(path).extension().string());
  const bool ply_magic = data.size() >= 4 && data.compare(0, 3, "ply") == 0 && (data[3] == '\n' || data[3] == '\r');
  if (ext == ".ply" || (ext != ".obj" && ply_magic)) return read_ply(path, data, declared, attributes, attribute_values);
  if (ext == ".obj") {
    if (!attributes.empty())
      throw InputError(path, "an OBJ has no vertex properties: the attribute " + quote_token(attributes[0]) +
                                 " needs PLY frames");
    return read_obj(path, data);
  }
  throw InputError(path, "unknown mesh format " + quote_token(ext) + " (lapflow reads .ply and .obj)");
}

}  // namespace

TriMesh read_mesh_from_memory(const std::string& data, const std::string& path) {
  TriMesh mesh = parse_mesh(data, path, nullptr);
  check_mesh_bounds(mesh, path);
  return mesh;
}

MeshFile read_mesh_file(const std::string& path, bool check_bounds, const std::vector<std::string>& attributes) {
  MeshFile f;
  f.mesh = parse_mesh(load_file(path), path, &f.declared, attributes, &f.attributes);
  if (check_bounds) check_mesh_bounds(f.mesh, path);
  return f;
}

TriMesh read_mesh(const std::string& path) { return read_mesh_file(path).mesh; }

std::vector<std::string> units_problems(const TriMesh& mesh, const MeshFileInfo& declared, bool check_velocity) {
  std::vector<std::string> problems;
  if (!mesh.empty()) {
    const Vec3 size = bounding_box(mesh).size();
    const double across = std::max({size.x, size.y, size.z});
    if (!(across <= kMaxLiquidSize))
      problems.push_back(fmt::format("mesh bounds {:.3g} m across: over {:g} km, are the units metres?", across,
                                     kMaxLiquidSize / 1000));
    const double reach = mesh_reach(mesh);
    if (!(reach <= kMaxMeshCoordinate))
      problems.push_back(fmt::format("a vertex {:.3g} m from the origin: a bake refuses coordinates beyond {:.0e} m, "
                                     "even with --units-ok",
                                     reach, kMaxMeshCoordinate));
    if (check_velocity && mesh.has_velocities()) {
      std::vector<uint8_t> used(mesh.vertex_count(), 0);
      for (const Tri& t : mesh.triangles)
        for (int32_t v : t) used[std::size_t(v)] = 1;
      double fastest = 0;
      std::size_t at = 0;
      for (std::size_t v = 0; v < used.size(); ++v)
        if (used[v] && norm(mesh.velocities[v]) > fastest) fastest = norm(mesh.velocities[v]), at = v;
      if (!(fastest <= kMaxLiquidSpeed)) problems.push_back(speed_problem(fastest, at, "the vertex velocity"));
    }
  }
  // A type is a statement about the whole file, empty frame or not. Names
  // and types are words the reader knows (x, vx, int, uint8...).
  auto integer_types = [](const std::vector<MeshFileInfo::Property>& props) {
    std::string list;
    for (const MeshFileInfo::Property& p : props)
      if (p.integer) list += (list.empty() ? "" : ", ") + p.name + " " + p.type;
    return list;
  };
  if (const std::string list = integer_types(declared.positions); !list.empty())
    problems.push_back("PLY position properties declared as integers (" + list +
                       "): an integer cannot hold a liquid surface's sub-millimetre coordinates (float or double "
                       "expected)");
  if (const std::string list = integer_types(declared.velocities); check_velocity && !list.empty())
    problems.push_back("PLY velocity properties declared as integers (" + list +
                       "): an integer cannot hold velocities in m/s finer than 1 m/s (float or double expected)");
  return problems;
}

std::string speed_problem(double speed, std::size_t vertex, const std::string& source) {
  return fmt::format("{} at vertex {} is {:.3g} m/s: over {:g} km/s, are the velocities in m/s?", source, vertex,
                     speed, kMaxLiquidSpeed / 1000);
}

void write_ply(const std::string& path, const TriMesh& m) {
  const bool vel = m.has_velocities();
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by lapflow\n";
  out += "element vertex " + std::to_string(m.positions.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  if (vel) out += "property float vx\nproperty float vy\nproperty float vz\n";
  out += "element face " + std::to_string(m.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  const std::size_t header = out.size();
  const std::size_t vstride = vel ? 24 : 12;
  out.resize(header + m.positions.size() * vstride + m.triangles.size() * 13);
  char* p = out.data() + header;
  auto put = [&](auto value) {
    if constexpr (std::endian::native == std::endian::big) {
      auto u = std::bit_cast<std::conditional_t<sizeof(value) == 4, uint32_t, uint8_t>>(value);
      if constexpr (sizeof(value) == 4) u = __builtin_bswap32(u);
      std::memcpy(p, &u, sizeof u);
    } else {
      std::memcpy(p, &value, sizeof value);
    }
    p += sizeof value;
  };
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3& x = m.positions[i];
    put(float(x.x)), put(float(x.y)), put(float(x.z));
    if (vel) {
      const Vec3& v = m.velocities[i];
      put(float(v.x)), put(float(v.y)), put(float(v.z));
    }
  }
  for (const Tri& t : m.triangles) {
    put(uint8_t(3));
    put(t[0]), put(t[1]), put(t[2]);
  }
  write_text_atomically(path, out);  // binary-safe: writes the bytes as they are
}

std::string default_output_name(const std::string& mesh_pattern) {
  std::string name = fs::path(mesh_pattern).filename().string();
  // Drop the extension and the frame token with its separator.
  name = std::regex_replace(name, std::regex(R"(\.[A-Za-z]+$)"), "");
  name = std::regex_replace(name, std::regex(R"([._-]?(%0?\d*d|#+|\$F\d?)$)"), "");
  return name.empty() ? "lapflow" : name;
}

std::string units_thresholds_text() {
  return fmt::format("bounds more than {:g} km across, a vertex faster than {:g} km/s, or a position or velocity "
                     "property declared with an integer PLY type (char, uchar, short, ushort, int, uint)",
                     kMaxLiquidSize / 1000, kMaxLiquidSpeed / 1000);
}

std::string units_ok_help(const std::string& verb) {
  return fmt::format("Also {} frames no liquid in metres has: {}. Without it such a frame is exit 2 naming the file "
                     "and frame (lapflow inspect warns about them). Coordinates beyond {:g} km stay refused",
                     verb, units_thresholds_text(), kMaxMeshCoordinate / 1000);
}

}  // namespace lapflow
