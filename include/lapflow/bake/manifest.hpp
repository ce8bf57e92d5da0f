#pragma once
/// \file bake_manifest.hpp NAME.bake.json: what a bake was made from, written
/// atomically when the bake starts, so that `lapflow eval` and
/// `lapflow preview` can find the inputs and the per-frame files of a bake
/// folder without being told again.
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "lapflow/bake/bake.hpp"

namespace lapflow {

struct BakeManifest {
  int version = 1;
  std::string name;                  ///< NAME: outputs are NAME.color.N.exr, ...
  std::string dir;                   ///< the folder holding the manifest (filled by read_bake_manifest)
  std::vector<int> frames;           ///< every frame the bake was asked for, in order
  /// Every option the option table records (lapflow/bake/options.hpp: a
  /// BakeOption with a manifest_key), paths absolute; the others keep
  /// BakeOptions' defaults. What `--resume` compares.
  BakeOptions options;
  /// settings/feature_digest: exemplar_feature_digest of the tracked feature
  /// map (empty: not recorded).
  std::string feature_digest;

  /// Path of frame `frame`'s file of the given kind: "obj", "mtl", "color",
  /// "disp", "aov", "patches", "state" (NAME.state.N.bin, bake/state.hpp),
  /// "render" (NAME.render.N.json, bake/render_record.hpp), "lock"
  /// (.NAME.N.lock, held while a process writes the frame), "usd"
  /// (NAME.usd.N.usda, the frame's USD layer: io/usd.hpp).
  std::string frame_file(const std::string& kind, int frame) const;
  /// A file of the whole shot in `dir`: "usd" NAME.usda (the USD stage),
  /// "usd-clips" NAME.manifest.usda (its clip manifest), "usd-lock"
  /// .NAME.usda.lock (held while the stage is rewritten).
  std::string shot_file(const std::string& kind) const;
};

/// ECMAScript regexes matching the whole stem (the name before the last
/// extension) of every file a bake named `name` writes: `NAME\.color\.[0-9]+`,
/// `NAME\.[0-9]+`, `NAME\.stats`, ... For remove_stale_temporaries().
std::vector<std::string> bake_file_stem_patterns(const std::string& name);

/// An ECMAScript regex matching the whole file name of every state file of a
/// bake named `name` (NAME.state.N.bin).
std::string bake_state_file_pattern(const std::string& name);

/// Path of NAME.bake.json in `dir`.
std::string bake_manifest_path(const std::string& dir, const std::string& name);

/// The manifest of a resolved bake (resolve_bake_options already ran).
BakeManifest make_bake_manifest(const BakeOptions& options, const std::vector<int>& frames);
void write_bake_manifest(const BakeManifest& manifest, const std::string& path);

/// The options `current` and the manifest at `path` disagree on, one entry
/// per key: "radius: 0.05 in the manifest, 0.04 now". Empty when they match.
/// Throws InputError naming `path` when it cannot be read.
/// With `tracking_only`, only the options that change the patches count:
/// not the output's (exemplar paths, resolution, gutter, AOV, EXR
/// settings, ...), which `lapflow render` may set anew.
std::vector<std::string> bake_manifest_differences(const std::string& path, const BakeManifest& current,
                                                   bool tracking_only = false);

/// A checksum (CRC-32) of the manifest's options: a state file records the
/// one of the bake that wrote it.
uint32_t bake_manifest_checksum(const BakeManifest& manifest);
/// The same over the options that change the patches only (see
/// bake_manifest_differences): what a state file records, so that a render
/// at another resolution or with another exemplar (of the same feature map)
/// accepts it.
uint32_t bake_tracking_checksum(const BakeManifest& manifest);

/// A digest of the feature map as the bake uses it (size and pixels, after
/// resampling to the colour's size): settings["feature_digest"], so that
/// `lapflow render --exemplar` can tell that another exemplar erodes the
/// same way.
std::string exemplar_feature_digest(const Image& feature);

/// Reads `path`, or the single *.bake.json in `path` when it is a folder
/// (`name` picks one when there are several). Throws InputError naming the
/// file and what is wrong.
BakeManifest read_bake_manifest(const std::string& path, const std::string& name = "");
/// The manifest in `text` (the JSON of NAME.bake.json; `path` names it in
/// errors and gives BakeManifest::dir). Throws InputError. The fuzzers' entry.
BakeManifest parse_bake_manifest(const std::string& text, const std::string& path);

/// The name of a RasterMode as the command line spells it, and back (throws UsageError).
std::string raster_mode_name(RasterMode mode);
RasterMode parse_raster_mode(const std::string& name);

}  // namespace lapflow
