#pragma once
/// \file render.hpp `lapflow render`: the output half of a bake, from the
/// patch states that `lapflow track` (or a bake) wrote. Each frame is
/// rasterized from its own NAME.state.N.bin, independently of the others,
/// at any resolution and with any exemplar of the same feature map
/// (docs/farm.md).
#include <functional>
#include <optional>
#include <string>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"

namespace lapflow {

struct RenderOptions {
  std::string dir;                        ///< the tracked folder (NAME.bake.json and the states)
  std::string name;                       ///< picks the manifest when the folder holds several
  std::optional<FrameRange> frames;       ///< every frame of the manifest when empty
  int resolution = 0;                     ///< 0: the manifest's
  std::string exemplar_color, exemplar_feature, exemplar_displacement;  ///< empty: the manifest's
  /// A tracking with exemplar layers: layers whose exemplar this render
  /// swaps, by name (each feature map must be the tracked one).
  std::vector<ExemplarLayer> layers;
  std::string out_dir;                    ///< empty: `dir`
  std::optional<bool> aov;                ///< the manifest's when empty
  std::optional<bool> usd;                ///< the manifest's when empty
  std::string texture;                    ///< "scanline" or "tiled" (--texture); empty: the manifest's
  std::optional<char> up_axis;            ///< 'Y' or 'Z'; the manifest's when empty
  /// Skip a frame already in out_dir whose record (NAME.render.N.json) says
  /// it was made from the same patches with the same options and whose files
  /// have their recorded sizes (a re-submitted farm job); render any other
  /// again, saying why (RenderedFrame::reason).
  bool skip_done = false;
  /// With skip_done: a frame there made with other options is an InputError
  /// naming its record, not rendered again.
  bool refuse_other_options = false;
  /// Render a frame whose mesh file changed since it was tracked (its size
  /// or CRC-32 differs from its state's stamp); else an InputError naming it.
  bool allow_changed_input = false;
  std::size_t max_memory = 0;             ///< as BakeOptions::max_memory
};

/// What render() did with one frame.
struct RenderedFrame {
  int frame = 0;
  bool skipped = false;  ///< already there (RenderOptions::skip_done)
  int resolution = 0;    ///< the atlas's
  FrameStats stats;      ///< counts and seconds of a rendered frame
  /// With skip_done, why a frame that was on disk was rendered again
  /// ("made with other options: resolution: 256 on disk, 512 asked").
  std::string reason;
};

struct BakeState;  // lapflow/bake/state.hpp

/// A state `path` read for frame `frame` of the bake in `manifest` is that
/// bake's, of that frame, with the manifest's tracking options
/// (bake_tracking_checksum): what `--resume` and `lapflow render` check
/// before they use it. Throws InputError naming `path`.
void check_bake_state(const BakeState& state, const std::string& path, const BakeManifest& manifest, int frame);

/// The bake's options as a manifest records them (the inverse of
/// make_bake_manifest, for the options it holds). Throws InputError naming
/// the manifest when a setting does not read back.
BakeOptions bake_options_from_manifest(const BakeManifest& manifest);

/// Renders the frames of the tracked folder in `options.frames` whose state
/// exists, writing NAME.N.obj + .mtl, NAME.color.N.exr, NAME.disp.N.exr (and
/// NAME.aov.N.exr) and NAME.render.N.json into out_dir as `lapflow bake`
/// would, each frame's files renamed into place together, the OBJ last.
/// Each frame is written under its lock (.NAME.N.lock): a frame another
/// render of the same options holds is done last, once that render let go
/// of it; one held by a process with other options is refused. The tracked
/// manifest is never rewritten; another out_dir gets NAME.bake.json when it
/// has none of this tracking. Temporary files of killed runs in out_dir are
/// removed first. Throws InputError naming the manifest, a state file
/// (missing for a frame asked for: after the other frames are written;
/// damaged; of another tracking), the exemplar (its feature map differs from
/// the tracked one) or a refused frame's lock or record (after the other
/// frames), OutputError naming what cannot be written, Interrupted on
/// SIGINT / SIGTERM between frames.
void render(const RenderOptions& options, const std::function<void(const RenderedFrame&)>& on_frame = {});

}  // namespace lapflow
