// libFuzzer target: the bake manifest (NAME.bake.json) that `lapflow eval`
// and `lapflow preview` read. A malformed file must end in an InputError
// naming it.
#include <cstddef>
#include <cstdint>
#include <string>

#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const lapflow::BakeManifest m = lapflow::parse_bake_manifest(text, "fuzz.bake.json");
    // Every frame's file name can be formed.
    for (int f : m.frames) (void)m.frame_file("color", f);
  } catch (const lapflow::InputError& e) {
    if (e.file() != "fuzz.bake.json") __builtin_trap();
  }
  return 0;
}
