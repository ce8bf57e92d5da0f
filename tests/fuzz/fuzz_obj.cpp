// libFuzzer target: the OBJ reader, as a fluid mesh and as a baked UV mesh
// (with `vt`). A malformed file must end in an InputError naming the input.
#include <cstddef>
#include <cstdint>
#include <string>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace {

void check(const lapflow::TriMesh& mesh) {
  for (const lapflow::Tri& t : mesh.triangles)
    for (int32_t v : t)
      if (v < 0 || std::size_t(v) >= mesh.vertex_count()) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    check(lapflow::read_mesh_from_memory(bytes, "fuzz.obj"));
  } catch (const lapflow::InputError& e) {
    if (e.file() != "fuzz.obj") __builtin_trap();
  }
  try {
    const lapflow::UvMesh uv = lapflow::read_uv_mesh_from_memory(bytes, "fuzz.obj");
    check(uv.mesh);
    if (!uv.corner_uv.empty() && uv.corner_uv.size() != 3 * uv.mesh.triangle_count()) __builtin_trap();
  } catch (const lapflow::InputError& e) {
    if (e.file() != "fuzz.obj") __builtin_trap();
  }
  return 0;
}
