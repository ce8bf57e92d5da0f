#pragma once
/// \file state.hpp NAME.state.N.bin: everything a bake carries from frame N
/// to the next frame, written with frame N's files so that `lapflow bake
/// --resume` can continue from it, and readable on its own by frame number
/// (docs/bake.md, "Checkpoints and --resume").
#include <cstdint>
#include <string>

#include "lapflow/patches/patches.hpp"

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// The state at the end of one frame. The previous frame's velocity, which
/// the next advection also reads, is not in it: it is read again from that
/// frame's input (the same bytes give the same field).
struct BakeStateHeader {
  static constexpr int kVersion = 1;
  std::string name;               ///< the bake's NAME
  int frame = 0;                  ///< the frame the state ends
  uint32_t options_checksum = 0;  ///< bake_manifest_checksum() of the bake that wrote it
  /// The frame's NAME.stats.jsonl line with its timings and memory zeroed,
  /// to put back when a kill came between the frame's files and that line.
  std::string stats_line;
};
struct BakeState {
  BakeStateHeader header;
  PatchSet patches;  ///< every Patch field and next_id, bit for bit
};

/// The file's bytes: one line of JSON (format, version, name, frame,
/// checksum of the options, counts, sizes, the stats line), the binary patch
/// data (little-endian), then a CRC-32 of everything before it.
std::string encode_bake_state(const BakeStateHeader& header, const PatchSet& patches);

/// Writes encode_bake_state(state) to `path` atomically, or into `staged`.
void write_bake_state(const std::string& path, const std::string& bytes, StagedFiles* staged = nullptr);

/// Reads a state file. Throws InputError naming `path` and what is wrong:
/// missing, truncated, checksum mismatch (a changed byte), not a state file,
/// another version, inconsistent counts.
BakeState read_bake_state(const std::string& path);
/// The same from the file's bytes in memory (`path` names it in errors).
BakeState parse_bake_state(const std::string& bytes, const std::string& path);

}  // namespace lapflow
