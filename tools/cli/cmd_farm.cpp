// `lapflow farm`: one bake split into jobs for a render farm (docs/farm.md).
// The plan, the scripts, the submission and the status are the library's
// (bake/farm.hpp); this parses, prints and runs the submission loop.
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>

#include "cli_common.hpp"
#include "scene_file.hpp"
#include "lapflow/bake/farm.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow::cli {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

struct SlurmCli {
  int chunk = 0;
  std::string partition, binary;
  bool dry_run = false;
};

void run_slurm(const SlurmCli& c, const std::vector<std::string>& command, const std::vector<std::string>& bake_args) {
  std::vector<std::string> expanded{"track"};
  expanded.insert(expanded.end(), bake_args.begin(), bake_args.end());
  expand_scene_files(expanded);
  expanded.erase(expanded.begin());
  FarmPlan p = make_farm_plan(command, bake_args, expanded, c.chunk, c.partition, c.binary);
  globals().quiet = p.quiet;
  write_farm_scripts(p);
  info("lapflow farm slurm: {} frames {}-{} into {} in {} chunks of {}; scripts in {}", p.name, p.frames.first,
       p.frames.last, p.dir, p.chunks.size(), p.chunk, p.farm_dir());
  const std::string submit_path = (fs::path(p.farm_dir()) / "submit.sh").string();
  if (c.dry_run) {
    write_farm_record(p, false);
    const std::string script = farm_submit_script(p);
    fmt::print("# --dry-run: nothing submitted; `bash {}` would submit:\n{}", shell_quote(submit_path),
               script.substr(script.find("set -e\n") + 7));
    return;
  }
  for (std::size_t k = 0; k < p.chunks.size(); ++k) {
    FarmChunk& ch = p.chunks[k];
    for (const bool track : {true, false}) {
      const std::vector<std::string> args =
          track ? sbatch_arguments(ch.track_script, k > 0 ? p.chunks[k - 1].track_job : "")
                : sbatch_arguments(ch.render_script, ch.track_job);
      try {
        (track ? ch.track_job : ch.render_job) = sbatch_submit(args);
      } catch (...) {
        write_farm_record(p, false);  // with the ids submitted so far
        throw;
      }
      fmt::print("{}   # job {}: {} {}-{}\n", shell_words(args), track ? ch.track_job : ch.render_job,
                 track ? "tracking" : "rendering", ch.first, ch.last);
    }
  }
  write_farm_record(p, true);
  const FarmChunk& last = p.chunks.back();
  fmt::print(
      "submitted {} tracking jobs and {} rendering arrays; job ids in {}\n"
      "progress:           {} farm status {} --name {}\n"
      "re-run frame F:     sbatch --array=$((F - FIRST)) {}/render.FIRST-LAST.sh, e.g. frame {}: {}\n"
      "re-run a tracking chunk: {} (it continues after the last tracked frame)\n",
      p.chunks.size(), p.chunks.size(), p.record_path(), shell_quote(p.lapflow),
      shell_quote(p.dir), shell_quote(p.name), p.farm_dir(), last.last, render_rerun(last, last.last),
      track_rerun(last));
}

struct StatusCli {
  std::string dir, name;
  bool json = false;
};

void run_status(const StatusCli& c) {
  apply_global_options();
  const FarmStatus s = farm_status(c.dir, c.name);
  const BakeManifest& m = s.manifest;
  const std::vector<FarmFrameReport>& frames = s.frames;
  auto count = [&](FrameStatus st) { return s.counts.count(st) ? s.counts.at(st) : 0; };
  if (c.json) {
    json list = json::array();
    for (const FarmFrameReport& r : frames) {
      json j = {{"frame", r.frame}, {"status", frame_status_name(r.status)}};
      if (!r.rerun.empty()) j["rerun"] = r.rerun;
      if (!r.detail.empty()) j[r.status == FrameStatus::Damaged ? "problem" : "made_with"] = r.detail;
      list.push_back(j);
    }
    const json out = {{"dir", m.dir},
                      {"name", m.name},
                      {"frames", list},
                      {"total", frames.size()},
                      {"rendered", count(FrameStatus::Rendered)},
                      {"tracked", count(FrameStatus::Tracked)},
                      {"damaged", count(FrameStatus::Damaged)},
                      {"failed", count(FrameStatus::Failed)},
                      {"pending", count(FrameStatus::Pending)}};
    fmt::print("{}\n", out.dump(2, ' ', false, json::error_handler_t::replace));
    return;
  }
  fmt::print("{} in {}: {}\n", m.name, m.dir,
             m.frames.empty() ? "no frames" : fmt::format("frames {}-{}", m.frames.front(), m.frames.back()));
  // One line per run of consecutive frames with the same status (and the same re-run command).
  for (std::size_t i = 0; i < frames.size();) {
    std::size_t j = i + 1;
    while (j < frames.size() && frames[j].status == frames[i].status && frames[j].rerun == frames[i].rerun &&
           frames[j].detail == frames[i].detail && frames[j].frame == frames[j - 1].frame + 1)
      ++j;
    const std::string span =
        j - i == 1 ? std::to_string(frames[i].frame) : fmt::format("{}-{}", frames[i].frame, frames[j - 1].frame);
    fmt::print("  {:<9} {}{}{}\n", frame_status_name(frames[i].status), span,
               frames[i].detail.empty() ? "" : "   " + printable_line(frames[i].detail),
               frames[i].rerun.empty() ? "" : "   re-run: " + frames[i].rerun);
    i = j;
  }
  fmt::print("{} frames: {} rendered, {} tracked (not yet rendered), {}{} failed, {} pending\n", frames.size(),
             count(FrameStatus::Rendered), count(FrameStatus::Tracked),
             count(FrameStatus::Damaged) ? fmt::format("{} damaged, ", count(FrameStatus::Damaged)) : "",
             count(FrameStatus::Failed), count(FrameStatus::Pending));
}

}  // namespace

void add_farm_command(CLI::App& app) {
  static SlurmCli slurm_cli;
  static StatusCli status_cli;
  CLI::App* farm = app.add_subcommand("farm", "Split a bake into render-farm jobs (Slurm) and follow their progress");
  farm->description(
      "Split a bake into render-farm jobs and follow their progress (docs/farm.md).\n\n"
      "A bake is two passes: tracking (`lapflow track`) carries the patches from frame to frame and writes\n"
      "each frame's state, so it is sequential; rendering (`lapflow render`) rasterizes a frame from its\n"
      "state alone, so frames render in parallel, each as soon as it is tracked.");
  farm->require_subcommand(1);

  CLI::App* slurm = farm->add_subcommand("slurm", "Write sbatch scripts for a bake and submit them");
  slurm->description(
      "Write sbatch scripts for a bake into OUT/farm/ and submit them with `sbatch --parsable`.\n\n"
      "Every argument other than --chunk, --partition, --dry-run and --binary is the bake's (a scene file\n"
      "and `lapflow bake` options, --out included) and reaches `lapflow track` verbatim:\n"
      "  tracking    a chain of jobs of --chunk frames each; chunk k runs\n"
      "              lapflow track ARGS --frames A-B --resume --until LAST_k\n"
      "              after chunk k-1 succeeded (--dependency=afterok)\n"
      "  rendering   one array job per chunk, one task per frame, after its chunk's tracking succeeded:\n"
      "              lapflow render OUT --name NAME --frames F-F --skip-done\n"
      "--threads N in the bake's options becomes --cpus-per-task=N; without it (or 0: all cores) every job asks\n"
      "for a whole node (--exclusive). Logs go to OUT/farm/logs/, the submitted job ids to OUT/farm/farm.json,\n"
      "the submission as a script to OUT/farm/submit.sh. Submitting the same command again skips the work\n"
      "already done: tracking resumes after its last state, rendering skips frames whose OBJ is there.\n\n"
      "Exit codes: 0 submitted (or written, with --dry-run), 2 bad input or usage (no --out, --chunk 0, a\n"
      "frame missing from the sequence) or sbatch refused a job (its message is printed).");
  slurm->allow_extras();
  slurm->add_option("--chunk", slurm_cli.chunk, "Frames per tracking job (and per rendering array)")->required();
  slurm->add_option("--partition", slurm_cli.partition, "Slurm partition of every job (default: the cluster's)");
  slurm->add_flag("--dry-run", slurm_cli.dry_run,
                  "Write the scripts and OUT/farm/submit.sh, print the sbatch commands, submit nothing");
  slurm->add_option("--binary", slurm_cli.binary,
                    "The lapflow the jobs run (default: this one); for nodes that mount it elsewhere");
  slurm->footer(
      "EXAMPLES\n"
      "  lapflow farm slurm shot.toml --threads 4 --frames 1-240 --chunk 24 --partition fx\n"
      "  lapflow farm slurm --mesh sim/fluid.%04d.ply --exemplar pebbles --out baked --chunk 10 --dry-run");
  slurm->callback([slurm] {
    const std::vector<std::string> bake_args = slurm->remaining();
    std::error_code ec;
    std::vector<std::string> command{fs::read_symlink("/proc/self/exe", ec).string(), "farm", "slurm"};
    // The command as typed, for re-submitting: the bake's arguments and the farm's own.
    command.insert(command.end(), bake_args.begin(), bake_args.end());
    command.insert(command.end(), {"--chunk", std::to_string(slurm_cli.chunk)});
    if (!slurm_cli.partition.empty()) command.insert(command.end(), {"--partition", slurm_cli.partition});
    if (!slurm_cli.binary.empty()) command.insert(command.end(), {"--binary", slurm_cli.binary});
    run_slurm(slurm_cli, command, bake_args);
  });

  CLI::App* status = farm->add_subcommand("status", "Per-frame progress of a (farm) bake from the files on disk");
  status->description(
      "Per-frame progress of a bake folder from its files: a frame is rendered when NAME.N.obj is there (with\n"
      "what its NAME.render.N.json says it was made with), tracked when only its state NAME.state.N.bin is\n"
      "and reads, damaged when its state does not read or a file its record lists is missing or of another\n"
      "size, failed when its job's log in OUT/farm/logs/ ends\n"
      "with a non-zero exit code (with the sbatch command that re-runs it), pending otherwise. The frames\n"
      "come from NAME.bake.json, or from OUT/farm/farm.json before the first tracking job wrote it.\n"
      "A job killed by the scheduler (time limit, memory, scancel) logs no exit code: its frames stay\n"
      "tracked or pending; squeue tells whether it is still running. Exit code 0, 2 when DIR holds no bake.");
  status->add_option("dir", status_cli.dir, "The bake folder (--out of the farm)")->required();
  status->add_option("--name", status_cli.name, "The bake's NAME when the folder holds several");
  status->add_flag("--json", status_cli.json, "Print one JSON document: every frame's status, the counts");
  add_global_options(*status);
  status->callback([] { run_status(status_cli); });
}

}  // namespace lapflow::cli
