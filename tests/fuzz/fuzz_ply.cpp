// libFuzzer target: the PLY reader (binary little/big endian and ASCII).
// A malformed file must end in an InputError naming the input, never in a
// crash, a sanitizer report, another exception or a large allocation.
#include <cstddef>
#include <cstdint>
#include <string>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    const lapflow::TriMesh mesh = lapflow::read_mesh_from_memory(bytes, "fuzz.ply");
    // What the reader promises of an accepted mesh.
    for (const lapflow::Tri& t : mesh.triangles)
      for (int32_t v : t)
        if (v < 0 || std::size_t(v) >= mesh.vertex_count()) __builtin_trap();
    if (mesh.has_velocities() && mesh.velocities.size() != mesh.vertex_count()) __builtin_trap();
  } catch (const lapflow::InputError& e) {
    if (e.file() != "fuzz.ply") __builtin_trap();
  }
  return 0;
}
