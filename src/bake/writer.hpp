#pragma once
// Writing a baked frame (ALGORITHM.md step 10): its atlas images, UV mesh,
// optional AOV and patch dump, each atomically, and its line of
// NAME.stats.jsonl once all of them are on disk.
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>

#include "lapflow/bake/bake.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/io/file_lock.hpp"

namespace lapflow {
class StagedFiles;
}

namespace lapflow::detail {

class FrameWriter {
 public:
  /// `stats_file`: append each frame's line to NAME.stats.jsonl (a render,
  /// whose frames are written by many processes at once, keeps none).
  FrameWriter(const BakeOptions& options, const BakeManifest& names, std::function<void(const FrameStats&)> on_frame,
              bool stats_file = true);
  /// Takes the frame's textures and atlas (moved out of `frame`, the atlas
  /// without its texel map, which the files do not need; the mesh is shared)
  /// and writes its files. `compute_seconds` is the wall time the
  /// frame took before writing. With BakeOptions::background_write the files
  /// are written while the caller goes on (at most one frame in flight);
  /// otherwise they are on disk when this returns.
  ///
  /// Unless tracking only, the frame's files include NAME.render.N.json
  /// (render_record.hpp) and are written under the frame's lock
  /// (.NAME.N.lock): `lock` when the caller holds it, else taken here
  /// (InputError naming the lock file when another process holds it).
  /// `patches_crc`: the patch state's, when the frame keeps no state of its
  /// own (a render).
  void write(const std::shared_ptr<Frame>& frame, const PatchSet& patches, double compute_seconds,
             std::optional<uint32_t> patches_crc = {}, std::optional<FileLock> lock = {});
  /// exemplar_digest() of the exemplar the frames are drawn with, for their records.
  void set_exemplar_digest(std::string digest) { exemplar_digest_ = std::move(digest); }
  /// With BakeOptions::usd: rewrites NAME.usda (and its clip manifest) to
  /// name every frame of the bake whose USD layer and OBJ are on disk.
  void write_usd_stage_file() const;
  /// Waits for the frame in flight, if any; rethrows its write error.
  void finish();
  /// A resumed bake: NAME.stats.jsonl starts with these lines (the frames
  /// already baked), and frame `last_frame` counts as complete.
  void resume(std::string stats_lines, int last_frame);
  /// NAME.stats.jsonl's line of `stats` with its timings and memory zeroed
  /// (what a state file keeps).
  static std::string stats_line_without_timings(const FrameStats& stats);
  /// The last frame whose files and stats line are all written, if any.
  std::optional<int> last_complete_frame() const { return last_complete_frame_; }

 private:
  struct Job;
  double write_files(const Job& job) const;
  /// Stages NAME.render.N.json with the sizes of the files staged so far.
  void write_record(const Job& job, StagedFiles& staged) const;
  /// Removes the state keep_states frames before `frame`.
  void remove_old_state(int frame) const;

  const BakeOptions& options_;
  const BakeManifest& names_;
  std::function<void(const FrameStats&)> on_frame_;
  std::string stats_path_, stats_text_;
  std::future<double> pending_;
  FrameStats pending_stats_;
  double pending_compute_seconds_ = 0;
  std::optional<int> last_complete_frame_;
  uint32_t options_checksum_ = 0;
  std::string exemplar_digest_;
  bool stats_file_ = true;
};

/// --out: created when missing, a writable folder, and rid of the temporary
/// files that killed runs of this bake left there. Throws OutputError naming
/// the folder.
void prepare_output_folder(const BakeOptions& options);

}  // namespace lapflow::detail
