// libFuzzer target: the TOML scene file of `lapflow bake scene.toml`. A
// malformed file must end in an InputError naming it; an accepted one gives
// only `--key...` arguments.
#include <cstddef>
#include <cstdint>
#include <string>

#include "lapflow/core/errors.hpp"
#include "scene_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    for (const std::string& arg : lapflow::cli::scene_text_arguments(text, "scenes/fuzz.toml"))
      if (arg.size() < 3 || arg.compare(0, 2, "--") != 0) __builtin_trap();
  } catch (const lapflow::InputError& e) {
    if (e.file() != "scenes/fuzz.toml") __builtin_trap();
  }
  return 0;
}
