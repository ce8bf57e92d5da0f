#pragma once
/// \file state.hpp NAME.state.N.bin: everything a bake carries from frame N
/// to the next frame, written with frame N's files so that `lapflow bake
/// --resume` can continue from it, and readable on its own by frame number
/// (docs/bake.md, "Checkpoints and --resume").
#include <cstdint>
#include <optional>
#include <string>

#include "lapflow/patches/patches.hpp"

namespace lapflow {

class StagedFiles;  // lapflow/io/atomic_file.hpp

/// An input file as the tracking read it: what `lapflow render` checks the
/// file against before it draws the frame again.
struct InputStamp {
  std::string file;    ///< its name, without the folder
  uint64_t bytes = 0;  ///< its size
  uint32_t crc = 0;    ///< a CRC-32 of its bytes
  bool operator==(const InputStamp&) const = default;
};
/// The stamp of the file at `path`. Throws InputError naming it when it
/// cannot be read.
InputStamp stamp_input_file(const std::string& path);

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
  /// The frame's mesh file as it was tracked (none in a state written
  /// before stamps were kept).
  std::optional<InputStamp> mesh;
  /// The bake's exemplar layers. With more than one, the header says how
  /// many and each patch also holds Patch::layer and Patch::layer_off; a
  /// bake of one exemplar writes the same bytes as before layers existed.
  int layers = 1;
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

/// A CRC-32 of the patch data of a state file's bytes (`bytes`, as
/// encode_bake_state gives them): the same patches give the same CRC
/// whatever the header holds (a bake's and a track's stats differ). 0 for
/// bytes that are not a state.
uint32_t bake_state_patches_crc(const std::string& bytes);
/// The same of the file at `path`; none when it cannot be read.
std::optional<uint32_t> bake_state_file_patches_crc(const std::string& path);
/// Reads a state file. Throws InputError naming `path` and what is wrong:
/// missing, truncated, checksum mismatch (a changed byte), not a state file,
/// another version, inconsistent counts.
BakeState read_bake_state(const std::string& path);
/// The same from the file's bytes in memory (`path` names it in errors).
BakeState parse_bake_state(const std::string& bytes, const std::string& path);

}  // namespace lapflow
