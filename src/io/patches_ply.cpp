// Patches as one PLY per frame, for looking at them in Houdini or Blender
// (the paper's Fig. 1, left): colour by patch_id, or show w / uv.
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow {
namespace {

template <typename T>
void put(std::string& buf, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // little-endian hosts only (x86-64, arm64)
  buf.append(bytes, sizeof(T));
}

}  // namespace

void write_patches_ply(const std::string& path, const PatchSet& patches, StagedFiles* staged) {
  std::size_t nv = 0, nt = 0;
  for (const Patch& p : patches.patches) nv += p.positions.size(), nt += p.triangles.size();
  std::string header =
      "ply\nformat binary_little_endian 1.0\ncomment lapflow patches: rest uv (u v), weight w (ALGORITHM.md step 5)\n";
  header += "element vertex " + std::to_string(nv) +
            "\nproperty float x\nproperty float y\nproperty float z\nproperty int patch_id\n"
            "property float u\nproperty float v\nproperty float w\n";
  header += "element face " + std::to_string(nt) +
            "\nproperty list uchar int vertex_indices\nproperty int patch_id\nend_header\n";
  std::string body;
  body.reserve(nv * 28 + nt * 17);
  for (const Patch& p : patches.patches)
    for (std::size_t v = 0; v < p.positions.size(); ++v) {
      put(body, float(p.positions[v].x));
      put(body, float(p.positions[v].y));
      put(body, float(p.positions[v].z));
      put(body, int32_t(p.id));
      put(body, float(p.rest_uv[v].x));
      put(body, float(p.rest_uv[v].y));
      put(body, v < p.weight.size() ? p.weight[v] : 0.f);
    }
  std::size_t base = 0;
  for (const Patch& p : patches.patches) {
    for (const Tri& f : p.triangles) {
      put(body, uint8_t(3));
      for (int k = 0; k < 3; ++k) put(body, int32_t(base + f[k]));
      put(body, int32_t(p.id));
    }
    base += p.positions.size();
  }
  write_text_atomically(path, header + body, staged);  // binary-safe: writes the bytes as they are
}

}  // namespace lapflow
