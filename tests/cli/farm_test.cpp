// `lapflow farm` as a process. `farm slurm --dry-run` writes the tracking
// chain and the rendering arrays with the right chunk boundaries and the
// bake's arguments verbatim; without --dry-run it submits them to `sbatch`
// (here a stand-in script on PATH) with each dependency on the id the
// previous submission printed; the scripts, run by bash, call lapflow with
// the frame of their array task. `farm status` counts the frames from the
// files in a folder. Bad input is exit 2 with one line saying what is wrong.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"

using namespace lapflow;
using lapflow::test::read_bytes;
using lapflow::test::TempDir;
using lapflow::test::write_bytes;
namespace fs = std::filesystem;

namespace {

struct Outcome {
  int exit_code = -1;
  std::string out, err;
};

/// Runs `program args` in folder `cwd`, with PATH = `bin` when given (a real
/// sbatch in /usr/bin must not answer) and `env` added to the environment;
/// stdout and stderr captured.
Outcome run_in(const std::string& cwd, const std::string& program, const std::vector<std::string>& args,
           const std::string& bin = "", const std::vector<std::string>& env = {}) {
  const std::string out_path = cwd + "/.stdout.txt", err_path = cwd + "/.stderr.txt";
  std::vector<std::string> all = {program};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string path = bin.empty() ? "/usr/local/bin:/usr/bin:/bin" : bin;
  std::vector<std::string> environment = {"PATH=" + path, "HOME=/tmp"};
  environment.insert(environment.end(), env.begin(), env.end());
  std::vector<char*> envp;
  for (std::string& e : environment) envp.push_back(e.data());
  envp.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int out = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (out < 0 || err < 0 || ::chdir(cwd.c_str()) != 0) ::_exit(126);
    ::dup2(out, STDOUT_FILENO);
    ::dup2(err, STDERR_FILENO);
    ::execve(argv[0], argv.data(), envp.data());
    ::_exit(127);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  Outcome r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = read_bytes(out_path);
  r.err = read_bytes(err_path);
  return r;
}

Outcome lapflow_in(const std::string& cwd, const std::vector<std::string>& args, const std::string& bin = "") {
  return run_in(cwd, LAPFLOW_BINARY, args, bin);
}

void write_executable(const std::string& path, const std::string& text) {
  write_bytes(path, text);
  fs::permissions(path, fs::perms::owner_all);
}

/// A folder with m.0001.ply ... m.0010.ply (empty: the farm only checks that
/// the frames exist) and shot.toml naming them, pebbles and --out baked.
struct Shot {
  TempDir dir{"farm"};
  Shot() {
    for (int f = 1; f <= 10; ++f) write_bytes(dir / fmt::format("m.{:04d}.ply", f), "");
    write_bytes(dir / "shot.toml", "mesh = \"m.%04d.ply\"\nexemplar = \"pebbles\"\nout = \"baked\"\n");
  }
  std::string farm(const std::string& file) const { return dir / ("baked/farm/" + file); }
};

bool contains(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  for (std::size_t nl; (nl = text.find('\n', start)) != std::string::npos; start = nl + 1)
    lines.push_back(text.substr(start, nl - start));
  if (start < text.size()) lines.push_back(text.substr(start));
  return lines;
}

/// A stand-in for sbatch: appends its arguments (one line) to calls.txt and
/// prints the next job id, 101, 102, ..., the way `--parsable` does on a
/// cluster with a name ("ID;CLUSTER").
void write_fake_sbatch(const Shot& s) {
  fs::create_directories(s.dir / "bin");
  write_executable(s.dir / "bin/sbatch",
                   "#!/bin/bash\n"
                   "echo \"$*\" >> " + s.dir / "calls.txt" + "\n"
                   "n=$(/usr/bin/wc -l < " + s.dir / "calls.txt" + ")\n"
                   "echo \"$((100 + n));local\"\n");
}

}  // namespace

TEST(FarmSlurm, DryRunWritesTheTrackingChainAndOneArrayPerChunk) {
  Shot s;
  write_fake_sbatch(s);
  const Outcome r = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--radius", "0.05", "--threads", "2", "--frames",
                                         "1-10", "--chunk", "4", "--dry-run"}, s.dir / "bin");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(s.dir / "calls.txt")) << "--dry-run submitted";
  // Chunks of 4 frames: 1-4, 5-8 and the rest, 9-10.
  for (const char* chunk : {"0001-0004", "0005-0008", "0009-0010"}) {
    EXPECT_TRUE(fs::is_regular_file(s.farm(fmt::format("track.{}.sh", chunk)))) << chunk;
    EXPECT_TRUE(fs::is_regular_file(s.farm(fmt::format("render.{}.sh", chunk)))) << chunk;
  }
  EXPECT_FALSE(fs::exists(s.farm("track.0009-0012.sh")));
  EXPECT_TRUE(fs::is_directory(s.farm("logs")));

  // Tracking: the scene file and options as given, the whole range, --resume and the chunk's last frame.
  const std::string bin = fs::canonical(LAPFLOW_BINARY).string();
  const std::string track = read_bytes(s.farm("track.0005-0008.sh"));
  EXPECT_TRUE(contains(track, "\ncd " + s.dir.str() + " || exit 2\n")) << track;
  EXPECT_TRUE(contains(track, "\n" + bin + " track shot.toml --radius 0.05 --threads 2 --frames 1-10 --frames 1-10 "
                                           "--resume --until 8\n"))
      << track;
  EXPECT_TRUE(contains(track, "#SBATCH --cpus-per-task=2\n")) << track;
  EXPECT_TRUE(contains(track, "#SBATCH --output=" + s.farm("logs/track.0005-0008.log") + "\n")) << track;
  EXPECT_TRUE(contains(read_bytes(s.farm("track.0009-0010.sh")), " --resume --until 10\n"));

  // Rendering: one task per frame of the chunk, task I renders the chunk's first frame + I.
  const std::string render = read_bytes(s.farm("render.0009-0010.sh"));
  EXPECT_TRUE(contains(render, "#SBATCH --array=0-1\n")) << render;
  EXPECT_TRUE(contains(render, "\nframe=$((9 + ${SLURM_ARRAY_TASK_ID")) << render;
  EXPECT_TRUE(contains(render, "\n" + bin + " render " + s.dir / "baked" +
                                   " --name m --frames \"$frame-$frame\" --skip-done --threads 2\n"))
      << render;
  EXPECT_TRUE(contains(render, "#SBATCH --output=" + s.farm("logs/render.0009-0010.%a.log") + "\n")) << render;
  EXPECT_TRUE(contains(read_bytes(s.farm("render.0001-0004.sh")), "#SBATCH --array=0-3\n"));

  // What it would submit: the chain t1 -> t2 -> t3, each r_k after t_k.
  const std::vector<std::string> want = {
      "t1=$(sbatch --parsable " + s.farm("track.0001-0004.sh") + ")",
      "r1=$(sbatch --parsable --dependency=afterok:${t1%%;*} --kill-on-invalid-dep=yes " +
          s.farm("render.0001-0004.sh") + ")",
      "t2=$(sbatch --parsable --dependency=afterok:${t1%%;*} --kill-on-invalid-dep=yes " +
          s.farm("track.0005-0008.sh") + ")",
      "r2=$(sbatch --parsable --dependency=afterok:${t2%%;*} --kill-on-invalid-dep=yes " +
          s.farm("render.0005-0008.sh") + ")",
      "t3=$(sbatch --parsable --dependency=afterok:${t2%%;*} --kill-on-invalid-dep=yes " +
          s.farm("track.0009-0010.sh") + ")",
      "r3=$(sbatch --parsable --dependency=afterok:${t3%%;*} --kill-on-invalid-dep=yes " +
          s.farm("render.0009-0010.sh") + ")"};
  std::vector<std::string> printed;
  for (const std::string& line : lines_of(r.out))
    if (!line.empty() && line[0] != '#') printed.push_back(line);
  EXPECT_EQ(printed, want) << r.out;
  EXPECT_TRUE(contains(read_bytes(s.farm("submit.sh")), want[3]));

  const nlohmann::json record = nlohmann::json::parse(read_bytes(s.farm("farm.json")));
  EXPECT_EQ(record["submitted"], false);
  EXPECT_EQ(record["name"], "m");
  EXPECT_EQ(record["chunks"].size(), 3u);
}

TEST(FarmSlurm, WithoutThreadsEveryJobAsksForAWholeNodeAndAPartitionGoesIntoEveryScript) {
  Shot s;
  const Outcome r = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--chunk", "10", "--partition", "fx",
                                         "--dry-run", "--quiet"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  // No --frames: every frame on disk, 1-10, in one chunk.
  for (const char* script : {"track.0001-0010.sh", "render.0001-0010.sh"}) {
    const std::string text = read_bytes(s.farm(script));
    EXPECT_TRUE(contains(text, "#SBATCH --exclusive\n")) << text;
    EXPECT_FALSE(contains(text, "--cpus-per-task")) << text;
    EXPECT_TRUE(contains(text, "#SBATCH --partition=fx\n")) << text;
  }
  EXPECT_TRUE(contains(read_bytes(s.farm("track.0001-0010.sh")), " track shot.toml --quiet --frames 1-10 --resume "
                                                                 "--until 10\n"));
  EXPECT_TRUE(contains(read_bytes(s.farm("render.0001-0010.sh")), " --skip-done --quiet\n"));
}

TEST(FarmSlurm, SubmitsEachJobAfterTheIdItDependsOn) {
  Shot s;
  write_fake_sbatch(s);
  const Outcome r = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--threads", "1", "--frames", "3-9",
                                         "--chunk", "3", "--name", "shot"}, s.dir / "bin");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::vector<std::string> want = {
      "--parsable " + s.farm("track.0003-0005.sh"),
      "--parsable --dependency=afterok:101 --kill-on-invalid-dep=yes " + s.farm("render.0003-0005.sh"),
      "--parsable --dependency=afterok:101 --kill-on-invalid-dep=yes " + s.farm("track.0006-0008.sh"),
      "--parsable --dependency=afterok:103 --kill-on-invalid-dep=yes " + s.farm("render.0006-0008.sh"),
      "--parsable --dependency=afterok:103 --kill-on-invalid-dep=yes " + s.farm("track.0009-0009.sh"),
      "--parsable --dependency=afterok:105 --kill-on-invalid-dep=yes " + s.farm("render.0009-0009.sh")};
  EXPECT_EQ(lines_of(read_bytes(s.dir / "calls.txt")), want);
  const nlohmann::json record = nlohmann::json::parse(read_bytes(s.farm("farm.json")));
  EXPECT_EQ(record["submitted"], true);
  EXPECT_EQ(record["chunks"][1]["track_job"], "103");
  EXPECT_EQ(record["chunks"][2]["render_job"], "106");
  // How to re-run one frame alone is printed: frame 9 is task 0 of the last chunk.
  EXPECT_TRUE(contains(r.out, "sbatch --array=0 " + s.farm("render.0009-0009.sh"))) << r.out;
  EXPECT_TRUE(contains(read_bytes(s.farm("render.0006-0008.sh")), " --name shot --frames"));
}

TEST(FarmSlurm, TheScriptsRunLapflowWithTheirArgumentsAndTheTaskFrame) {
  Shot s;
  // A stand-in lapflow: prints its folder and each argument on a line, exits with $FAKE_EXIT.
  write_executable(s.dir / "fake-lapflow", "#!/bin/bash\npwd\nfor a in \"$@\"; do echo \"[$a]\"; done\n"
                                           "exit \"${FAKE_EXIT:-0}\"\n");
  const Outcome r = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--seed", "7", "--orientation", "world:1,0,0",
                                         "--feature", "it's a map.png", "--chunk", "4", "--dry-run", "--binary",
                                         "fake-lapflow"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const TempDir elsewhere("farm_elsewhere");  // a job starts in another folder
  const Outcome track = run_in(elsewhere.str(), "/bin/bash", {s.farm("track.0005-0008.sh")});
  EXPECT_EQ(track.exit_code, 0) << track.err;
  const std::vector<std::string> want_track = {
      s.dir.str(), "[track]", "[shot.toml]", "[--seed]", "[7]", "[--orientation]", "[world:1,0,0]", "[--feature]",
      "[it's a map.png]", "[--frames]", "[1-10]", "[--resume]", "[--until]", "[8]", "lapflow farm: exit 0"};
  EXPECT_EQ(lines_of(track.out), want_track);

  const Outcome render = run_in(elsewhere.str(), "/bin/bash", {s.farm("render.0005-0008.sh")}, "",
                            {"SLURM_ARRAY_TASK_ID=2", "FAKE_EXIT=3"});
  EXPECT_EQ(render.exit_code, 3) << "the job fails when lapflow does";
  const std::vector<std::string> want_render = {
      "lapflow farm: frame 7", elsewhere.str(), "[render]",  "[" + s.dir / "baked" + "]", "[--name]", "[m]",
      "[--frames]",            "[7-7]",         "[--skip-done]", "lapflow farm: exit 3"};
  EXPECT_EQ(lines_of(render.out), want_render);
  // Outside an array job the render script says so instead of rendering a wrong frame.
  const Outcome no_task = run_in(elsewhere.str(), "/bin/bash", {s.farm("render.0005-0008.sh")});
  EXPECT_NE(no_task.exit_code, 0);
  EXPECT_TRUE(contains(no_task.err, "SLURM_ARRAY_TASK_ID")) << no_task.err;
}

TEST(FarmSlurm, BadInputIsExit2WithOneLineSayingWhatIsWrong) {
  Shot s;
  write_bytes(s.dir / "no_out.toml", "mesh = \"m.%04d.ply\"\nexemplar = \"pebbles\"\n");
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{"no_out.toml", "--chunk", "4"}, "--out is required"},
      {{"shot.toml", "--chunk", "0"}, "--chunk 0: a chunk holds at least 1 frame"},
      {{"shot.toml", "--chunk", "1001"}, "--chunk 1001: at most 1000 frames"},
      {{"shot.toml"}, "--chunk is required"},
      {{"shot.toml", "--frames", "5-12", "--chunk", "4"}, "m.0011.ply (frame 11): file not found"},
      {{"shot.toml", "--frames", "8-3", "--chunk", "4"}, "the last frame comes before the first"},
      {{"--exemplar", "pebbles", "--out", "x", "--chunk", "4"}, "--mesh is required"},
      {{"missing.toml", "--chunk", "4"}, "missing.toml: scene file not found"},
      {{"shot.toml", "--threads", "many", "--chunk", "4"}, "--threads: 'many' is not a count"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = {"farm", "slurm"};
    args.insert(args.end(), c.args.begin(), c.args.end());
    args.push_back("--dry-run");
    const Outcome r = lapflow_in(s.dir.str(), args);
    EXPECT_EQ(r.exit_code, 2) << c.message << ": " << r.err;
    EXPECT_TRUE(contains(r.err, c.message)) << r.err;
    EXPECT_EQ(lines_of(r.err).size(), 1u) << r.err;
  }
  EXPECT_FALSE(fs::exists(s.dir / "baked")) << "nothing is written for bad input";
  // A gap in the frames on disk needs --frames.
  fs::remove(s.dir / "m.0006.ply");
  const Outcome gap = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--chunk", "4", "--dry-run"});
  EXPECT_EQ(gap.exit_code, 2);
  EXPECT_TRUE(contains(gap.err, "frame 6 is missing between frames 1 and 10")) << gap.err;
}

TEST(FarmSlurm, NoSbatchOrARefusedJobIsExit2WithSbatchsMessage) {
  Shot s;
  const Outcome none = lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--chunk", "4"}, s.dir / "bin");
  EXPECT_EQ(none.exit_code, 2);
  EXPECT_TRUE(contains(none.err, "sbatch not found on PATH")) << none.err;

  fs::create_directories(s.dir / "bin");
  write_executable(s.dir / "bin/sbatch",
                   "#!/bin/bash\necho 'sbatch: error: invalid partition specified: nope' >&2\nexit 1\n");
  const Outcome refused =
      lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--chunk", "4", "--partition", "nope"}, s.dir / "bin");
  EXPECT_EQ(refused.exit_code, 2);
  // One error line, after the line saying what was being submitted.
  const std::vector<std::string> lines = lines_of(refused.err);
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.back().rfind("error: `sbatch --parsable " + s.farm("track.0001-0004.sh") + "` failed (exit 1): sbatch: "
                               "error: invalid partition specified: nope", 0), 0u)
      << refused.err;
}

namespace {

/// A manifest of bake `name` over frames first..last in `dir`, as `lapflow track` writes it.
void write_manifest(const std::string& dir, const std::string& name, int first, int last) {
  BakeManifest m;
  m.name = name;
  m.dir = dir;
  m.options.mesh_pattern = dir + "/m.%04d.ply";
  m.options.exemplar_color = m.options.exemplar_feature = m.options.exemplar_displacement = dir + "/x.png";
  for (int f = first; f <= last; ++f) m.frames.push_back(f);
  write_bake_manifest(m, bake_manifest_path(dir, name));
}

void touch(const std::string& path) { write_bytes(path, "x"); }

/// A state of frame `f` of the bake `name` in `dir` (its manifest written), with no patch.
void write_state(const std::string& dir, const std::string& name, int f) {
  const BakeManifest m = read_bake_manifest(dir, name);
  BakeStateHeader h;
  h.name = name;
  h.frame = f;
  h.options_checksum = bake_tracking_checksum(m);
  write_bytes(m.frame_file("state", f), encode_bake_state(h, PatchSet{}));
}

}  // namespace

TEST(FarmStatus, CountsRenderedTrackedAndPendingFramesFromTheFiles) {
  TempDir dir("farm_status");
  write_manifest(dir.str(), "t", 1, 6);
  for (int f : {1, 2, 3, 4}) write_state(dir.str(), "t", f);
  for (int f : {1, 2}) touch(dir / fmt::format("t.{:04d}.obj", f));
  touch(dir / "t.0005.mtl");  // a frame is rendered when its OBJ is there, not before

  const Outcome json_run = lapflow_in(dir.str(), {"farm", "status", dir.str(), "--json"});
  ASSERT_EQ(json_run.exit_code, 0) << json_run.err;
  const nlohmann::json j = nlohmann::json::parse(json_run.out);
  EXPECT_EQ(j["total"], 6);
  EXPECT_EQ(j["rendered"], 2);
  EXPECT_EQ(j["tracked"], 2);
  EXPECT_EQ(j["pending"], 2);
  EXPECT_EQ(j["failed"], 0);
  std::vector<std::string> statuses;
  for (const auto& f : j["frames"]) statuses.push_back(f["status"]);
  EXPECT_EQ(statuses, (std::vector<std::string>{"rendered", "rendered", "tracked", "tracked", "pending", "pending"}));

  const Outcome text = lapflow_in(dir.str(), {"farm", "status", dir.str()});
  ASSERT_EQ(text.exit_code, 0) << text.err;
  const std::vector<std::string> want = {"t in " + dir.str() + ": frames 1-6", "  rendered  1-2   no record", "  tracked   3-4",
                                         "  pending   5-6",
                                         "6 frames: 2 rendered, 2 tracked (not yet rendered), 0 failed, 2 pending"};
  EXPECT_EQ(lines_of(text.out), want);
}

TEST(FarmStatus, ReadsTheFarmsRecordBeforeTheManifestAndNamesTheFailedJobsRerun) {
  Shot s;
  ASSERT_EQ(lapflow_in(s.dir.str(), {"farm", "slurm", "shot.toml", "--chunk", "4", "--dry-run"}).exit_code, 0);
  const std::string baked = s.dir / "baked";
  // Submitted, nothing ran: the frames come from farm.json.
  const Outcome before = lapflow_in(s.dir.str(), {"farm", "status", "baked", "--json"});
  ASSERT_EQ(before.exit_code, 0) << before.err;
  EXPECT_EQ(nlohmann::json::parse(before.out)["pending"], 10);

  // Tracked 1-6; frame 1 rendered, frame 2's task failed, 3's is still to come; 5-8's tracking failed at 7.
  write_manifest(baked, "m", 1, 10);
  for (int f = 1; f <= 6; ++f) write_state(baked, "m", f);
  touch(baked + "/m.0001.obj");
  write_bytes(s.farm("logs/render.0001-0004.1.log"), "lapflow farm: frame 2\nerror: boom\nlapflow farm: exit 2\n");
  write_bytes(s.farm("logs/render.0001-0004.2.log"), "lapflow farm: frame 3\n");
  write_bytes(s.farm("logs/track.0005-0008.log"), "error: frame 7\nlapflow farm: exit 2\n");
  const Outcome after = lapflow_in(s.dir.str(), {"farm", "status", "baked", "--json"});
  ASSERT_EQ(after.exit_code, 0) << after.err;
  const nlohmann::json j = nlohmann::json::parse(after.out);
  EXPECT_EQ(j["rendered"], 1);
  EXPECT_EQ(j["tracked"], 4);   // 3, 4, 5, 6
  EXPECT_EQ(j["failed"], 3);    // 2 (render), 7 and 8 (tracking)
  EXPECT_EQ(j["pending"], 2);   // 9, 10: their chain was cancelled, no log says so
  EXPECT_EQ(j["frames"][1]["rerun"], "sbatch --array=1 " + s.farm("render.0001-0004.sh"));
  EXPECT_TRUE(contains(j["frames"][6]["rerun"], "farm slurm shot.toml --chunk 4")) << j["frames"][6];
  const Outcome text = lapflow_in(s.dir.str(), {"farm", "status", "baked"});
  EXPECT_TRUE(contains(text.out, "  failed    2   re-run: sbatch --array=1 " + s.farm("render.0001-0004.sh") + "\n"))
      << text.out;
  EXPECT_TRUE(contains(text.out, "10 frames: 1 rendered, 4 tracked (not yet rendered), 3 failed, 2 pending\n"));
}

TEST(FarmStatus, DamagedStatesAndFramesAreReportedAsSuchAndRenderedOnesWithTheirOptions) {
  TempDir dir("farm_status_damaged");
  write_manifest(dir.str(), "t", 1, 5);
  for (int f : {1, 2, 3, 4, 5}) write_state(dir.str(), "t", f);
  // 1: rendered, whole; 2: rendered, its colour cut short; 3: an OBJ of an older lapflow (no record);
  // 4: a state cut short; 5: a state of another bake.
  const BakeManifest m = read_bake_manifest(dir.str(), "t");
  for (int f : {1, 2}) {
    write_bytes(m.frame_file("color", f), std::string(100, 'c'));
    write_bytes(m.frame_file("obj", f), "v 0 0 0\n");
    BakeOptions o = m.options;
    o.atlas.resolution = 512;
    RenderRecord r = make_render_record(o, m, f, "0123456789abcdef-x-y");
    r.files = {{fs::path(m.frame_file("color", f)).filename().string(), 100},
               {fs::path(m.frame_file("obj", f)).filename().string(), 8}};
    write_bytes(m.frame_file("render", f), encode_render_record(r));
  }
  write_bytes(m.frame_file("color", 2), std::string(60, 'c'));
  touch(m.frame_file("obj", 3));
  const std::string state4 = read_bytes(m.frame_file("state", 4));
  write_bytes(m.frame_file("state", 4), state4.substr(0, state4.size() - 3));
  BakeStateHeader other;
  other.name = "u";
  other.frame = 5;
  write_bytes(m.frame_file("state", 5), encode_bake_state(other, PatchSet{}));

  const Outcome run = lapflow_in(dir.str(), {"farm", "status", dir.str(), "--json"});
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["rendered"], 2);
  EXPECT_EQ(j["damaged"], 3);
  EXPECT_EQ(j["tracked"], 0);
  const nlohmann::json& frames = j["frames"];
  EXPECT_EQ(frames[0]["status"], "rendered");
  EXPECT_EQ(frames[0]["made_with"], "resolution 512, exemplar 01234567");
  EXPECT_EQ(frames[1]["status"], "damaged");
  EXPECT_EQ(frames[1]["problem"], "t.color.0002.exr has 60 bytes, 100 recorded");
  EXPECT_EQ(frames[2]["status"], "rendered");
  EXPECT_EQ(frames[2]["made_with"], "no record");
  EXPECT_EQ(frames[3]["status"], "damaged");
  EXPECT_TRUE(contains(frames[3]["problem"].get<std::string>(), "t.state.0004.bin: damaged state")) << frames[3];
  EXPECT_EQ(frames[4]["status"], "damaged");
  EXPECT_TRUE(contains(frames[4]["problem"].get<std::string>(), "the state is of bake 'u' frame 5")) << frames[4];
  const Outcome text = lapflow_in(dir.str(), {"farm", "status", dir.str()});
  EXPECT_TRUE(contains(text.out, "  damaged   2   t.color.0002.exr has 60 bytes, 100 recorded\n")) << text.out;
  EXPECT_TRUE(contains(text.out, "5 frames: 2 rendered, 0 tracked (not yet rendered), 3 damaged, 0 failed, 0 pending\n"))
      << text.out;
}

TEST(FarmStatus, AFolderWithoutABakeIsExit2NamingIt) {
  TempDir dir("farm_status_none");
  const Outcome r = lapflow_in(dir.str(), {"farm", "status", dir.str()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, dir.str() + ": no *.bake.json in this folder")) << r.err;
}
