// USDA text for a bake: per-frame clip layers, the clip manifest and the stage.
#include "lapflow/io/usd.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <iterator>
#include <stdexcept>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/uv_mesh.hpp"

namespace lapflow {
namespace {

using UsdBuffer = fmt::memory_buffer;

// The clipped attributes: type, name, and the interpolation the stage
// declares (empty: the attribute's own default).
struct UsdClipAttribute {
  const char* type;
  const char* name;
  const char* interpolation;
};
constexpr UsdClipAttribute kUsdClipAttributes[] = {
    {"float3[]", "extent", ""},
    {"int[]", "faceVertexCounts", ""},
    {"int[]", "faceVertexIndices", ""},
    {"normal3f[]", "normals", "vertex"},
    {"point3f[]", "points", ""},
    {"int[]", "primvars:st:indices", ""},
    {"texCoord2f[]", "primvars:st", "faceVarying"},
    {"vector3f[]", "velocities", ""},
};

/// An asset path: @path@, or @@@path@@@ when it holds an '@'.
std::string usd_asset(const std::string& path) {
  if (path.find('@') == std::string::npos) return "@./" + path + "@";
  return "@@@./" + path + "@@@";
}

/// A quoted USDA string.
std::string usd_string(const std::string& text) {
  std::string q = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') q += '\\';
    if (c == '\n') {
      q += "\\n";
      continue;
    }
    q += c;
  }
  return q + "\"";
}

/// A time code or a rate: integers without a fraction.
std::string usd_number(double x) { return fmt::format("{}", x); }

template <typename Each>
void usd_time_samples(UsdBuffer& out, const char* type, const char* name, int frame, std::size_t count, Each each) {
  fmt::format_to(std::back_inserter(out), "    {} {}.timeSamples = {{ {}: [", type, name, frame);
  for (std::size_t i = 0; i < count; ++i) {
    if (i > 0) out.append(std::string_view(", "));
    each(i);
  }
  out.append(std::string_view("] }\n"));
}

void usd_vec3f(UsdBuffer& out, const Vec3& v) {
  fmt::format_to(std::back_inserter(out), "({}, {}, {})", float(v.x), float(v.y), float(v.z));
}

}  // namespace

std::string usd_prim_name(const std::string& name) {
  std::string id;
  for (unsigned char c : name) id += std::isalnum(c) && c < 128 ? char(c) : '_';
  if (id.empty() || std::isdigit(static_cast<unsigned char>(id[0]))) id = "_" + id;
  return id;
}

void write_usd_frame_layer(const std::string& path, int frame, const TriMesh& mesh, const SurfaceAtlas& atlas,
                           std::span<const Vec3> velocities, StagedFiles* staged) {
  if (!velocities.empty() && velocities.size() != mesh.vertex_count())
    throw std::invalid_argument("write_usd_frame_layer: one velocity per vertex");
  const UvMeshCorners corners = uv_mesh_corners(mesh, atlas);
  const std::vector<Vec3> normals = vertex_normals(mesh);
  const std::size_t nt = mesh.triangle_count(), nv = mesh.vertex_count();

  UsdBuffer out;
  auto it = std::back_inserter(out);
  fmt::format_to(it, "#usda 1.0\n(\n    doc = \"lapflow frame {}\"\n)\n\ndef Mesh \"{}\"\n{{\n", frame, kUsdClipPrim);
  // The interpolations again, as the stage declares them: a reader of the
  // layer alone (TinyUSDZ) needs them to read st and normals per corner.
  out.append(std::string_view("    normal3f[] normals (\n        interpolation = \"vertex\"\n    )\n"
                              "    texCoord2f[] primvars:st (\n        interpolation = \"faceVarying\"\n    )\n"));
  Vec3 lo{0, 0, 0}, hi{0, 0, 0};
  if (nv > 0) {
    lo = hi = mesh.positions[0];
    for (const Vec3& p : mesh.positions) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
  }
  usd_time_samples(out, "float3[]", "extent", frame, 2, [&](std::size_t i) { usd_vec3f(out, i == 0 ? lo : hi); });
  usd_time_samples(out, "int[]", "faceVertexCounts", frame, nt, [&](std::size_t) { out.push_back('3'); });
  usd_time_samples(out, "int[]", "faceVertexIndices", frame, 3 * nt,
                     [&](std::size_t c) { fmt::format_to(it, "{}", mesh.triangles[c / 3][c % 3]); });
  usd_time_samples(out, "normal3f[]", "normals", frame, nv, [&](std::size_t v) {
    // Isolated vertices have no normal; a unit placeholder, as in the OBJ.
    const Vec3& n = normals[v];
    const Vec3 m = norm2(n) > 0 ? n : Vec3{0, 0, 1};
    fmt::format_to(it, "({:.6g}, {:.6g}, {:.6g})", float(m.x), float(m.y), float(m.z));
  });
  usd_time_samples(out, "point3f[]", "points", frame, nv, [&](std::size_t v) { usd_vec3f(out, mesh.positions[v]); });
  usd_time_samples(out, "int[]", "primvars:st:indices", frame, 3 * nt,
                     [&](std::size_t c) { fmt::format_to(it, "{}", corners.uv_of_corner[c]); });
  usd_time_samples(out, "texCoord2f[]", "primvars:st", frame, corners.corner_of_uv.size(), [&](std::size_t i) {
    const Vec2& uv = atlas.corner_uv[corners.corner_of_uv[i]];
    fmt::format_to(it, "({}, {})", float(uv.x), float(uv.y));
  });
  if (!velocities.empty())
    usd_time_samples(out, "vector3f[]", "velocities", frame, nv, [&](std::size_t v) { usd_vec3f(out, velocities[v]); });
  out.append(std::string_view("}\n"));
  write_text_atomically(path, fmt::to_string(out), staged);
}

void write_usd_clip_manifest(const std::string& path, StagedFiles* staged) {
  UsdBuffer out;
  auto it = std::back_inserter(out);
  fmt::format_to(it, "#usda 1.0\n(\n    doc = \"lapflow: the attributes each frame's layer authors\"\n)\n\n"
                     "def Mesh \"{}\"\n{{\n", kUsdClipPrim);
  for (const UsdClipAttribute& a : kUsdClipAttributes) fmt::format_to(it, "    {} {}\n", a.type, a.name);
  out.append(std::string_view("}\n"));
  write_text_atomically(path, fmt::to_string(out), staged);
}

void write_usd_stage(const std::string& path, const UsdStage& s, StagedFiles* staged) {
  if (s.frames.empty()) throw std::invalid_argument("write_usd_stage: no frame");
  if (s.up_axis != 'Y' && s.up_axis != 'Z') throw std::invalid_argument("write_usd_stage: up axis Y or Z");
  const std::string root = "/" + usd_prim_name(s.name);
  const std::string looks = root + "/Looks/atlas";
  UsdBuffer out;
  auto it = std::back_inserter(out);
  fmt::format_to(it,
                 "#usda 1.0\n(\n    defaultPrim = \"{}\"\n    doc = {}\n    startTimeCode = {}\n    endTimeCode = {}\n"
                 "    timeCodesPerSecond = {}\n    framesPerSecond = {}\n    metersPerUnit = 1\n    upAxis = \"{}\"\n)\n\n",
                 usd_prim_name(s.name), usd_string("lapflow bake " + s.name), s.frames.front().frame,
                 s.frames.back().frame, usd_number(s.fps), usd_number(s.fps), s.up_axis);
  fmt::format_to(it, "def Xform \"{}\" (\n    kind = \"component\"\n)\n{{\n", usd_prim_name(s.name));

  // The mesh: its clips, and every clipped attribute declared with its interpolation.
  fmt::format_to(it,
                 "    def Mesh \"{}\" (\n        prepend apiSchemas = [\"MaterialBindingAPI\"]\n        clips = {{\n"
                 "            dictionary default = {{\n",
                 kUsdClipPrim);
  out.append(std::string_view("                asset[] assetPaths = ["));
  for (std::size_t i = 0; i < s.frames.size(); ++i)
    fmt::format_to(it, "{}{}", i ? ", " : "", usd_asset(s.frames[i].layer));
  out.append(std::string_view("]\n                double2[] active = ["));
  for (std::size_t i = 0; i < s.frames.size(); ++i) fmt::format_to(it, "{}({}, {})", i ? ", " : "", s.frames[i].frame, i);
  out.append(std::string_view("]\n                double2[] times = ["));
  for (std::size_t i = 0; i < s.frames.size(); ++i)
    fmt::format_to(it, "{}({}, {})", i ? ", " : "", s.frames[i].frame, s.frames[i].frame);
  fmt::format_to(it,
                 "]\n                string primPath = \"/{}\"\n                asset manifestAssetPath = {}\n"
                 "            }}\n        }}\n    )\n    {{\n",
                 kUsdClipPrim, usd_asset(s.clip_manifest));
  for (const UsdClipAttribute& a : kUsdClipAttributes) {
    if (*a.interpolation)
      fmt::format_to(it, "        {} {} (\n            interpolation = \"{}\"\n        )\n", a.type, a.name,
                     a.interpolation);
    else
      fmt::format_to(it, "        {} {}\n", a.type, a.name);
  }
  fmt::format_to(it,
                 "        uniform token orientation = \"rightHanded\"\n"
                 "        uniform token subdivisionScheme = \"none\"\n"
                 "        rel material:binding = <{}>\n    }}\n\n",
                 looks);

  // The material: the frame's colour and height atlases through st.
  auto files = [&](const char* input, std::string UsdStageFrame::*file) {
    fmt::format_to(it, "                asset {} = {}\n                asset {}.timeSamples = {{\n", input,
                   usd_asset(s.frames.front().*file), input);
    for (const UsdStageFrame& f : s.frames) fmt::format_to(it, "                    {}: {},\n", f.frame, usd_asset(f.*file));
    out.append(std::string_view("                }\n"));
  };
  const double scale = s.displacement_scale;
  fmt::format_to(it,
                 "    def Scope \"Looks\"\n    {{\n        def Material \"atlas\"\n        {{\n"
                 "            token outputs:surface.connect = <{0}/surface.outputs:surface>\n"
                 "            token outputs:displacement.connect = <{0}/surface.outputs:displacement>\n\n"
                 "            def Shader \"surface\"\n            {{\n"
                 "                uniform token info:id = \"UsdPreviewSurface\"\n"
                 "                color3f inputs:diffuseColor.connect = <{0}/color.outputs:rgb>\n"
                 "                float inputs:roughness = 0.25\n"
                 "                float inputs:displacement.connect = <{0}/height.outputs:r>\n"
                 "                token outputs:surface\n                token outputs:displacement\n            }}\n\n"
                 "            def Shader \"st\"\n            {{\n"
                 "                uniform token info:id = \"UsdPrimvarReader_float2\"\n"
                 "                token inputs:varname = \"st\"\n"
                 "                float2 outputs:result\n            }}\n\n"
                 "            def Shader \"color\"\n            {{\n"
                 "                uniform token info:id = \"UsdUVTexture\"\n",
                 looks);
  files("inputs:file", &UsdStageFrame::color);
  fmt::format_to(it,
                 "                float2 inputs:st.connect = <{0}/st.outputs:result>\n"
                 "                token inputs:sourceColorSpace = \"raw\"\n"
                 "                token inputs:wrapS = \"clamp\"\n                token inputs:wrapT = \"clamp\"\n"
                 "                float3 outputs:rgb\n            }}\n\n"
                 "            def Shader \"height\"\n            {{\n"
                 "                uniform token info:id = \"UsdUVTexture\"\n",
                 looks);
  files("inputs:file", &UsdStageFrame::displacement);
  fmt::format_to(it,
                 "                float2 inputs:st.connect = <{0}/st.outputs:result>\n"
                 "                token inputs:sourceColorSpace = \"raw\"\n"
                 "                token inputs:wrapS = \"clamp\"\n                token inputs:wrapT = \"clamp\"\n"
                 "                float4 inputs:scale = ({1}, {1}, {1}, {1})\n"
                 "                float4 inputs:bias = ({2}, {2}, {2}, {2})\n"
                 "                float outputs:r\n            }}\n        }}\n    }}\n}}\n",
                 looks, float(scale), float(-0.5 * scale));
  write_text_atomically(path, fmt::to_string(out), staged);
}

}  // namespace lapflow
