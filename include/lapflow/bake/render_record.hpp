#pragma once
/// \file render_record.hpp NAME.render.N.json: what one frame's atlas and UV
/// mesh were made with, written with the frame's files (before its OBJ), by
/// `lapflow bake` and `lapflow render` alike. A tracked folder is shared by
/// renders of several resolutions and exemplars; the record, not the
/// manifest, says what each frame on disk is (docs/farm.md, "One truth per
/// frame"). `render --skip-done` trusts a frame only when its record matches
/// what is asked and its files have the recorded sizes.
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"

namespace lapflow {

struct RenderRecord {
  static constexpr int kVersion = 1;
  std::string name;  ///< the bake's NAME
  int frame = 0;
  /// bake_tracking_checksum() of the tracking the frame's patches came from.
  uint32_t tracking_checksum = 0;
  /// bake_state_patches_crc() of the patch state the frame was drawn from;
  /// none when a bake kept no state.
  std::optional<uint32_t> patches_crc;
  /// exemplar_digest() of the colour, feature and displacement maps used.
  std::string exemplar_digest;
  /// Their files, absolute, as they were given (what `lapflow eval` compares
  /// the frame with); not compared by render_record_differences: the digest
  /// stands for them.
  std::string exemplar_color, exemplar_feature, exemplar_displacement;
  /// Every picture option of the option table but the exemplar paths (the
  /// digest stands for them) and --dump-patches, by name, as the command
  /// line spells them: "resolution" -> "512", "compression" -> "rle".
  std::map<std::string, std::string> options;
  /// The frame's pictures and UV mesh (names, without the folder: OBJ, MTL,
  /// colour, displacement, AOV) and their sizes in bytes.
  std::vector<std::pair<std::string, std::uintmax_t>> files;
};

/// The record a frame made with `options` (of the bake in `manifest`) has:
/// name, frame, tracking checksum, exemplar digest and options; no files.
RenderRecord make_render_record(const BakeOptions& options, const BakeManifest& manifest, int frame,
                                const std::string& exemplar_digest);

/// The record as one JSON object (keys in a fixed order: the same record
/// gives the same bytes).
std::string encode_render_record(const RenderRecord& record);
/// Reads a record. Throws InputError naming `path` and the key for a missing
/// key, a wrong type or another format.
RenderRecord parse_render_record(const std::string& text, const std::string& path);
RenderRecord read_render_record(const std::string& path);

/// What a frame on disk (`on_disk`) and the frame asked for (`wanted`, no
/// files) disagree on, one entry each: "resolution: 256 on disk, 512 asked",
/// "the exemplar", "the patches (tracked again since)". Empty when the same.
std::vector<std::string> render_record_differences(const RenderRecord& on_disk, const RenderRecord& wanted);

/// Why the files of frame `record.frame` in `folder`'s bake are not whole:
/// "NAME.0003.obj is missing", "NAME.color.0003.exr has 1024 bytes, 4096
/// recorded"; "" when every file of the record and the OBJ are there.
std::string render_record_file_problem(const BakeManifest& folder, const RenderRecord& record);

/// What a render writes into a frame's lock (file_lock.hpp): "render
/// 1a2b3c4d, resolution 512", the same for every frame of two renders that
/// write the same bytes (frame, patches and files aside).
std::string render_lock_purpose(const RenderRecord& wanted);

/// A short digest of an exemplar's three maps as the bake uses them:
/// exemplar_feature_digest() of each, joined by '-'.
std::string exemplar_digest(const Exemplar& exemplar);

}  // namespace lapflow
