// `lapflow farm`'s library: one bake split into Slurm jobs and the progress
// of a bake folder (docs/farm.md). Tracking (`lapflow track`) carries the
// patches from frame to frame, so it is one chain of jobs of K frames each;
// rendering (`lapflow render`) needs only a frame's state, so each chunk's
// frames are one array job that starts as soon as that chunk is tracked.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "lapflow/bake/manifest.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow {

/// Slurm's default MaxArraySize is 1001: array indices 0-1000.
inline constexpr int kMaxFarmChunk = 1000;

struct FarmChunk {
  int first = 0, last = 0;
  std::string track_script, render_script;  ///< absolute paths
  std::string track_job, render_job;        ///< Slurm job ids once submitted
};

struct FarmPlan {
  std::vector<std::string> command;    ///< the farm command line itself, for re-submitting
  std::vector<std::string> bake_args;  ///< passed to every `lapflow track` verbatim
  std::string lapflow;                 ///< absolute path of the binary the jobs run
  std::string cwd;                     ///< where the bake's relative paths start
  std::string dir, name;               ///< absolute --out, NAME
  FrameRange frames;
  int chunk = 0;
  int threads = 0;
  bool quiet = false;
  std::string partition;
  std::vector<FarmChunk> chunks;

  std::string farm_dir() const;  ///< OUT/farm
  std::string log_dir() const;   ///< OUT/farm/logs
  std::string record_path() const;  ///< OUT/farm/farm.json
};

/// The plan of `lapflow farm slurm`: `bake_args` go to every job verbatim
/// (a scene file stays a scene file), `expanded_args` are the same with the
/// scene files' keys spelled out (the plan reads --out, --name, --mesh,
/// --frames, --threads and --quiet from them, the last occurrence winning).
/// `binary`: the lapflow the jobs run ("" = this process's). Throws
/// UsageError or InputError (a frame missing from the sequence).
FarmPlan make_farm_plan(const std::vector<std::string>& command, const std::vector<std::string>& bake_args,
                        const std::vector<std::string>& expanded_args, int chunk, const std::string& partition,
                        const std::string& binary);

/// Writes every chunk's track and render script and OUT/farm/submit.sh.
void write_farm_scripts(const FarmPlan& plan);
/// Writes OUT/farm/farm.json: the plan and the job ids submitted so far.
void write_farm_record(const FarmPlan& plan, bool submitted);
/// The submission as a shell script (OUT/farm/submit.sh).
std::string farm_submit_script(const FarmPlan& plan);
/// `sbatch --parsable [--dependency=afterok:AFTER --kill-on-invalid-dep=yes] SCRIPT`.
std::vector<std::string> sbatch_arguments(const std::string& script, const std::string& after);
/// Runs `args` (sbatch ...) and returns the job id; UsageError with sbatch's
/// message when it fails or is not on PATH.
std::string sbatch_submit(const std::vector<std::string>& args);
/// The commands that re-run one frame's rendering and one chunk's tracking alone.
std::string render_rerun(const FarmChunk& chunk, int frame);
std::string track_rerun(const FarmChunk& chunk);
/// `s` as one shell word; words as one shell line.
std::string shell_quote(const std::string& s);
std::string shell_words(const std::vector<std::string>& words);

/// Rendered: NAME.N.obj is there, with the files its record lists; Tracked:
/// only its state is, and it reads; Damaged: a state that does not read (or
/// is another tracking's), a record that does not, or a file of the record
/// missing or of another size; Failed: its farm job logged a non-zero exit.
enum class FrameStatus { Rendered, Tracked, Damaged, Failed, Pending };
const char* frame_status_name(FrameStatus s);

struct FarmFrameReport {
  int frame = 0;
  FrameStatus status = FrameStatus::Pending;
  std::string rerun;    ///< for a failed frame: the command that re-runs it
  /// For a rendered frame: what its record says it was made with
  /// ("resolution 512, exemplar 512636c0", "no record" for a frame of an
  /// older lapflow); for a damaged one: what is wrong.
  std::string detail;
};

/// Per-frame progress of a bake folder from its files (`lapflow farm status`).
struct FarmStatus {
  BakeManifest manifest;  ///< name, absolute folder and frames
  std::vector<FarmFrameReport> frames;
  std::map<FrameStatus, int> counts;
};
/// `name` "" = the folder's one bake. Throws InputError when DIR holds no bake.
FarmStatus farm_status(const std::string& dir, const std::string& name);

}  // namespace lapflow
