// OBJ + MTL writer for the fluid mesh with its atlas UVs.
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <numeric>
#include <stdexcept>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/uv_mesh.hpp"

namespace lapflow {

std::string uv_mesh_mtl_path(const std::string& obj_path) {
  return std::filesystem::path(obj_path).replace_extension(".mtl").string();
}

UvMeshCorners uv_mesh_corners(const TriMesh& mesh, const SurfaceAtlas& atlas) {
  const std::size_t nt = mesh.triangle_count();
  if (atlas.corner_uv.size() != 3 * nt || atlas.chart_of_triangle.size() != nt)
    throw std::invalid_argument("uv_mesh_corners: the atlas was built for another mesh");
  // One vt per distinct (vertex, chart, uv): corners of one vertex inside one
  // chart share it (a collapsed degenerate triangle may differ).
  std::vector<uint32_t> order(3 * nt);
  std::iota(order.begin(), order.end(), 0u);
  auto key_less = [&](uint32_t a, uint32_t b) {
    const int32_t va = mesh.triangles[a / 3][a % 3], vb = mesh.triangles[b / 3][b % 3];
    if (va != vb) return va < vb;
    const int32_t ca = atlas.chart_of_triangle[a / 3], cb = atlas.chart_of_triangle[b / 3];
    if (ca != cb) return ca < cb;
    const Vec2 &ua = atlas.corner_uv[a], &ub = atlas.corner_uv[b];
    if (ua.x != ub.x) return ua.x < ub.x;
    if (ua.y != ub.y) return ua.y < ub.y;
    return a < b;
  };
  std::sort(order.begin(), order.end(), key_less);
  UvMeshCorners out;
  std::vector<uint32_t>& vt_of_corner = out.uv_of_corner;
  vt_of_corner.resize(3 * nt);
  std::vector<uint32_t>& vt_corner = out.corner_of_uv;
  for (std::size_t i = 0; i < order.size(); ++i) {
    const uint32_t c = order[i];
    if (i > 0) {
      const uint32_t p = order[i - 1];
      if (mesh.triangles[p / 3][p % 3] == mesh.triangles[c / 3][c % 3] &&
          atlas.chart_of_triangle[p / 3] == atlas.chart_of_triangle[c / 3] && atlas.corner_uv[p] == atlas.corner_uv[c]) {
        vt_of_corner[c] = vt_of_corner[p];
        continue;
      }
    }
    vt_of_corner[c] = uint32_t(vt_corner.size());
    vt_corner.push_back(c);
  }
  return out;
}

void write_uv_mesh_obj(const std::string& obj_path, const TriMesh& mesh, const SurfaceAtlas& atlas,
                       const UvMeshMaterial& material, StagedFiles* staged) {
  const std::size_t nt = mesh.triangle_count();
  if (atlas.corner_uv.size() != 3 * nt || atlas.chart_of_triangle.size() != nt)
    throw std::invalid_argument("write_uv_mesh_obj: the atlas was built for another mesh");
  const std::string mtl_path = uv_mesh_mtl_path(obj_path);

  fmt::memory_buffer mtl;
  fmt::format_to(std::back_inserter(mtl), "# lapflow atlas material\nnewmtl {}\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n",
                 material.name);
  if (!material.color_texture.empty()) fmt::format_to(std::back_inserter(mtl), "map_Kd {}\n", material.color_texture);
  if (!material.displacement_texture.empty())
    fmt::format_to(std::back_inserter(mtl), "disp {}\nmap_disp {}\n", material.displacement_texture,
                   material.displacement_texture);

  const UvMeshCorners corners = uv_mesh_corners(mesh, atlas);
  const std::vector<uint32_t>& vt_of_corner = corners.uv_of_corner;
  const std::vector<uint32_t>& vt_corner = corners.corner_of_uv;

  const std::vector<Vec3> normals = vertex_normals(mesh);
  fmt::memory_buffer obj;
  auto out = std::back_inserter(obj);
  fmt::format_to(out, "# lapflow UV mesh: vertex i is source vertex i; {} charts, atlas {}x{}\nmtllib {}\n",
                 atlas.chart_count, atlas.resolution, atlas.resolution,
                 std::filesystem::path(mtl_path).filename().string());
  for (const Vec3& p : mesh.positions) fmt::format_to(out, "v {:.9g} {:.9g} {:.9g}\n", p.x, p.y, p.z);
  for (uint32_t c : vt_corner) fmt::format_to(out, "vt {:.9g} {:.9g}\n", atlas.corner_uv[c].x, atlas.corner_uv[c].y);
  for (const Vec3& n : normals) {
    // Isolated vertices have no normal; a unit placeholder keeps readers happy.
    const Vec3 m = norm2(n) > 0 ? n : Vec3{0, 0, 1};
    fmt::format_to(out, "vn {:.6g} {:.6g} {:.6g}\n", m.x, m.y, m.z);
  }
  fmt::format_to(out, "usemtl {}\n", material.name);
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri& f = mesh.triangles[t];
    fmt::format_to(out, "f {0}/{1}/{0} {2}/{3}/{2} {4}/{5}/{4}\n", f[0] + 1, vt_of_corner[3 * t] + 1, f[1] + 1,
                   vt_of_corner[3 * t + 1] + 1, f[2] + 1, vt_of_corner[3 * t + 2] + 1);
  }
  write_text_atomically(mtl_path, fmt::to_string(mtl), staged);
  write_text_atomically(obj_path, fmt::to_string(obj), staged);
}

}  // namespace lapflow
