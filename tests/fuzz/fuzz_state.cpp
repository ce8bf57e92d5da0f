// libFuzzer target: the bake state (NAME.state.N.bin) that `lapflow bake
// --resume` reads. The input's last four bytes are replaced by the CRC-32 of
// the rest before parsing, so that the fuzzer reaches the header and the
// patch data behind the checksum instead of stopping at it. A malformed
// state must end in an InputError naming the file.
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  std::string bytes(reinterpret_cast<const char*>(data), size);
  if (bytes.size() >= 4) {
    const uint32_t crc = uint32_t(crc32(0, reinterpret_cast<const Bytef*>(bytes.data()), uInt(bytes.size() - 4)));
    std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
  }
  try {
    const lapflow::BakeState s = lapflow::parse_bake_state(bytes, "fuzz.state.0001.bin");
    // Every triangle corner indexes its patch's vertices (the reader checks it).
    for (const lapflow::Patch& p : s.patches.patches)
      for (const lapflow::Tri& t : p.triangles)
        for (int32_t v : t)
          if (v < 0 || std::size_t(v) >= p.positions.size()) __builtin_trap();
  } catch (const lapflow::InputError& e) {
    if (e.file() != "fuzz.state.0001.bin") __builtin_trap();
  }
  return 0;
}
