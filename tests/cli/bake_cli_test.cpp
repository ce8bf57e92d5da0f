// `lapflow bake` as a process: SIGTERM / SIGINT stop it with 143 / 130 and
// whole frames only, identical to an uninterrupted bake's; output problems
// (--out a file, a read-only --out, a file-size limit hit mid-bake) are exit
// 2 naming the folder or file, with earlier frames intact; a huge number in
// an OBJ gives a short message naming the file.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <linux/capability.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/io/mesh_io.hpp"

using namespace lapflow;
using lapflow::test::TempDir;
namespace fs = std::filesystem;

namespace {

struct Limits {
  long file_size = -1;      ///< RLIMIT_FSIZE in bytes, -1 = none
  bool drop_root = false;   ///< as root, drop the capabilities that override permission bits
};

/// Starts the lapflow binary with `args`; stderr goes to `err_path`.
pid_t start_lapflow(const std::vector<std::string>& args, const std::string& err_path, Limits limits = {}) {
  std::vector<std::string> all = {LAPFLOW_BINARY};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  // The child: only async-signal-safe calls until exec.
  const int err = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  const int null = ::open("/dev/null", O_WRONLY);
  if (err < 0 || null < 0) ::_exit(126);
  ::dup2(null, STDOUT_FILENO);
  ::dup2(err, STDERR_FILENO);
  if (limits.file_size >= 0) {
    const rlimit r{rlim_t(limits.file_size), rlim_t(limits.file_size)};
    if (::setrlimit(RLIMIT_FSIZE, &r) != 0) ::_exit(126);
  }
  // Root without the capabilities that override permission bits: the bits
  // bind, and the binary, its libraries and the test's folders (perhaps in a
  // private 0700 temp folder) stay reachable, as they would not for nobody.
  if (limits.drop_root && ::geteuid() == 0 &&
      (::prctl(PR_CAPBSET_DROP, CAP_DAC_OVERRIDE, 0, 0, 0) != 0 ||
       ::prctl(PR_CAPBSET_DROP, CAP_DAC_READ_SEARCH, 0, 0, 0) != 0))
    ::_exit(126);
  ::execv(argv[0], argv.data());
  ::_exit(127);
}

/// The exit code, or -signal when the process was killed by one.
int wait_for(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return WIFSIGNALED(status) ? -WTERMSIG(status) : -1000;
}

struct Result {
  int exit_code;
  std::string err;
};

Result run_lapflow(const std::vector<std::string>& args, const TempDir& scratch, Limits limits = {}) {
  const std::string err = scratch / "stderr.txt";
  const int code = wait_for(start_lapflow(args, err, limits));
  return {code, test::read_bytes(err)};
}

/// `bake` of dir/m.%04d.ply into `out` at 128^2 (with AOVs), name "t".
std::vector<std::string> bake_args(const std::string& meshes, const std::string& out, bool aov = true) {
  std::vector<std::string> args = {"bake", "--mesh", meshes + "/m.%04d.ply", "--exemplar", "pebbles",
                                   "--resolution", "128", "--out", out, "--name", "t", "--threads", "1", "--quiet"};
  if (aov) args.push_back("--aov");
  return args;
}

/// The demo's vortex as dir/m.%04d.ply: frames 1..n at `voxel` metres.
void write_demo_frames(const std::string& dir, int first, int last, double voxel) {
  DemoOptions demo;
  demo.voxel_size = voxel;
  for (int f = first; f <= last; ++f) write_ply(fmt::format("{}/m.{:04d}.ply", dir, f), demo_frame(demo, f));
}

std::string frame_file(const std::string& dir, const char* kind, int frame) {
  return fmt::format(fmt::runtime(std::string(dir) + "/" + kind), frame);
}

const std::vector<const char*> kFrameFiles = {"t.{:04d}.obj", "t.{:04d}.mtl", "t.color.{:04d}.exr",
                                             "t.disp.{:04d}.exr", "t.aov.{:04d}.exr"};
/// Without the AOV (bake_args(..., false)).
const std::vector<const char*> kFrameFilesNoAov(kFrameFiles.begin(), kFrameFiles.end() - 1);

using test::temporaries_in;

/// Every frame of `out` whose OBJ (the commit file) is there has all its
/// files, byte-identical to `ref`'s. Returns those frames.
std::vector<int> expect_whole_frames_identical_to(const std::string& out, const std::string& ref, int frames,
                                                  const std::vector<const char*>& kinds = kFrameFiles) {
  std::vector<int> present;
  for (int f = 1; f <= frames; ++f) {
    if (!fs::exists(frame_file(out, kinds[0], f))) continue;
    present.push_back(f);
    for (const char* kind : kinds) {
      const std::string a = frame_file(out, kind, f), b = frame_file(ref, kind, f);
      if (!fs::exists(a)) {
        ADD_FAILURE() << a << " is missing beside its OBJ";
        continue;
      }
      EXPECT_TRUE(test::read_bytes(a) == test::read_bytes(b)) << a << " differs from an uninterrupted bake's";
    }
  }
  return present;
}

std::size_t lines_in(const std::string& path) {
  const std::string s = test::read_bytes(path);
  return std::size_t(std::count(s.begin(), s.end(), '\n'));
}

}  // namespace

// ---------------------------------------------------------------- signals --

class BakeSignals : public ::testing::Test {
 protected:
  static constexpr int kFrames = 5;
  static void SetUpTestSuite() {
    meshes_ = new TempDir("signals_in");
    ref_ = new TempDir("signals_ref");
    write_demo_frames(meshes_->str(), 1, kFrames, 1.0 / 60);
    const Result r = run_lapflow(bake_args(meshes_->str(), ref_->str()), *meshes_);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    std::istringstream stats(test::read_bytes(*ref_ / "t.stats.jsonl"));
    std::string line;
    std::getline(stats, line);
    std::getline(stats, line);
    frame_seconds_ = nlohmann::json::parse(line).at("seconds").at("total").get<double>();
  }
  static void TearDownTestSuite() {
    delete meshes_;
    delete ref_;
    meshes_ = ref_ = nullptr;
  }

  /// Starts a bake, waits for frame 1's OBJ and then `delay` of a frame's
  /// time (0.3: frame 2 is computing), sends `signals`, each after the
  /// previous one was handled (two pending signals would merge into one),
  /// and checks what every stop must leave: only whole frames, 1..k,
  /// identical to an uninterrupted bake's; after SIGINT or SIGTERM no
  /// temporary file either. After a SIGKILL, which nothing can clean up
  /// after, it re-runs the bake: no temporary file, every frame identical.
  /// Returns the stopped run's result and the frames it left.
  std::pair<Result, std::vector<int>> bake_and_stop(const std::vector<int>& signals, double delay) {
    TempDir out("signals_out"), scratch("signals_err");
    const std::string err = scratch / "stderr.txt";
    const pid_t pid = start_lapflow(bake_args(meshes_->str(), out.str()), err);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (!fs::exists(frame_file(out.str(), kFrameFiles[0], 1)) && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    std::this_thread::sleep_for(std::chrono::duration<double>(delay * frame_seconds_));
    for (std::size_t i = 0; i < signals.size(); ++i) {
      if (i > 0) {
        const auto handled = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (test::read_bytes(err).find("stopping after the frame in hand") == std::string::npos &&
               std::chrono::steady_clock::now() < handled)
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      ::kill(pid, signals[i]);
    }
    const Result r{wait_for(pid), test::read_bytes(err)};
    const bool killed = signals == std::vector<int>{SIGKILL};
    if (!killed) {
      EXPECT_TRUE(temporaries_in(out.str()).empty()) << ::testing::PrintToString(temporaries_in(out.str()));
    }
    const std::vector<int> present = expect_whole_frames_identical_to(out.str(), ref_->str(), kFrames);
    EXPECT_FALSE(present.empty());
    EXPECT_LT(present.size(), std::size_t(kFrames)) << "the bake ended before the signal: make the frames slower";
    for (std::size_t i = 0; i < present.size(); ++i) EXPECT_EQ(present[i], int(i) + 1);
    if (signals.size() == 1 && !killed) {
      // A clean stop: the frames after the last complete one have no file
      // at all, and the stats have one line per complete frame.
      for (int f = int(present.size()) + 1; f <= kFrames; ++f)
        for (const char* kind : kFrameFiles) EXPECT_FALSE(fs::exists(frame_file(out.str(), kind, f)));
      EXPECT_EQ(lines_in(out / "t.stats.jsonl"), present.size());
    }
    if (killed) {
      const Result again = run_lapflow(bake_args(meshes_->str(), out.str()), scratch);
      EXPECT_EQ(again.exit_code, 0) << again.err;
      EXPECT_TRUE(temporaries_in(out.str()).empty()) << ::testing::PrintToString(temporaries_in(out.str()));
      EXPECT_EQ(expect_whole_frames_identical_to(out.str(), ref_->str(), kFrames).size(), std::size_t(kFrames));
    }
    return {r, present};
  }

  static TempDir* meshes_;
  static TempDir* ref_;
  static double frame_seconds_;  ///< frame 2's time in the uninterrupted bake
};
TempDir* BakeSignals::meshes_ = nullptr;
TempDir* BakeSignals::ref_ = nullptr;
double BakeSignals::frame_seconds_ = 0;

TEST_F(BakeSignals, SigtermStopsWithWholeFramesAndExit143) {
  const auto [r, present] = bake_and_stop({SIGTERM}, 0.3);  // frame 2 is abandoned
  EXPECT_EQ(r.exit_code, 143) << r.err;
  ASSERT_FALSE(present.empty());
  EXPECT_NE(r.err.find(fmt::format("stopped by SIGTERM; the last complete frame is {}", present.back())),
            std::string::npos)
      << r.err;
}

TEST_F(BakeSignals, SigintStopsWithWholeFramesAndExit130) {
  const auto [r, present] = bake_and_stop({SIGINT}, 0);  // at a frame boundary
  EXPECT_EQ(r.exit_code, 130) << r.err;
  ASSERT_FALSE(present.empty());
  EXPECT_NE(r.err.find(fmt::format("stopped by SIGINT; the last complete frame is {}", present.back())),
            std::string::npos)
      << r.err;
}

TEST_F(BakeSignals, ASecondSigintStopsAtOnceWithoutAHalfFile) {
  const auto [r, present] = bake_and_stop({SIGINT, SIGINT}, 0.3);
  EXPECT_EQ(r.exit_code, 130) << r.err;
  EXPECT_NE(r.err.find("SIGINT again: stopped at once, temporary files removed"), std::string::npos) << r.err;
}

// A SIGKILL while frame 2 is being written (the last tenth of its time):
// frame 1 whole, frame 2 whole or without its OBJ, and a re-run removes the
// temporary files the kill left and bakes every frame as an uninterrupted
// bake does.
TEST_F(BakeSignals, AKillLeavesWholeFramesAndAReRunCleansUp) {
  const auto [r, present] = bake_and_stop({SIGKILL}, 0.95);
  EXPECT_EQ(r.exit_code, -SIGKILL);
}

// SIGKILLs at several moments (frame 2 computing, frame 2 being written,
// frame 3 computing), each followed by `--resume`: the resumed bake removes
// the kill's temporary files, and every file it leaves (states, manifest,
// EXRs, OBJs, MTLs) has the bytes of an uninterrupted bake; the stats lines
// differ only in timings and memory.
TEST_F(BakeSignals, KilledAtSeveralMomentsAndResumedGivesTheSameBytes) {
  for (const double delay : {0.3, 0.95, 1.5}) {
    SCOPED_TRACE(fmt::format("killed {} frames after frame 1", delay));
    TempDir out("resume_kill"), scratch("resume_kill_err");
    const pid_t pid = start_lapflow(bake_args(meshes_->str(), out.str()), scratch / "stderr.txt");
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (!fs::exists(frame_file(out.str(), kFrameFiles[0], 1)) && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    std::this_thread::sleep_for(std::chrono::duration<double>(delay * frame_seconds_));
    ::kill(pid, SIGKILL);
    EXPECT_EQ(wait_for(pid), -SIGKILL);
    const std::vector<int> present = expect_whole_frames_identical_to(out.str(), ref_->str(), kFrames);
    ASSERT_FALSE(present.empty());
    EXPECT_LT(present.size(), std::size_t(kFrames)) << "the bake ended before the kill: make the frames slower";
    // The last complete frame has its state (written in the same group).
    EXPECT_TRUE(fs::exists(out / fmt::format("t.state.{:04d}.bin", present.back())));

    std::vector<std::string> args = bake_args(meshes_->str(), out.str());
    args.push_back("--resume");
    const Result again = run_lapflow(args, scratch);
    ASSERT_EQ(again.exit_code, 0) << again.err;
    EXPECT_TRUE(temporaries_in(out.str()).empty()) << ::testing::PrintToString(temporaries_in(out.str()));
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(ref_->str())) files.push_back(e.path().filename().string());
    std::size_t out_files = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(out.str())) ++out_files;
    EXPECT_EQ(out_files, files.size());
    for (const std::string& f : files) {
      if (f == "t.stats.jsonl") continue;
      EXPECT_TRUE(test::read_bytes(out / f) == test::read_bytes(*ref_ / f)) << f << " differs after the resume";
    }
    EXPECT_EQ(test::stats_without_timings(out / "t.stats.jsonl"), test::stats_without_timings(*ref_ / "t.stats.jsonl"));
  }
}

// `--resume` over a damaged state (one changed byte) or with another
// option: exit 2, one line naming the file and what is wrong.
TEST_F(BakeSignals, ResumeOfADamagedStateOrOtherOptionsIsExit2NamingTheFile) {
  TempDir out("resume_cli_bad"), scratch("resume_cli_bad_err");
  fs::copy(ref_->str(), out.str(), fs::copy_options::overwrite_existing | fs::copy_options::recursive);
  std::vector<std::string> args = bake_args(meshes_->str(), out.str());
  args.push_back("--resume");

  std::vector<std::string> other = args;
  other.insert(other.end(), {"--spacing", "1.5"});
  Result r = run_lapflow(other, scratch);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("t.bake.json"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("settings/spacing: \"1\" in the manifest, \"1.5\" now"), std::string::npos) << r.err;

  const std::string state = out / fmt::format("t.state.{:04d}.bin", kFrames);
  std::string bytes = test::read_bytes(state);
  ASSERT_FALSE(bytes.empty());
  bytes[bytes.size() / 2] = char(bytes[bytes.size() / 2] ^ 0x40);
  test::write_bytes(state, bytes);
  r = run_lapflow(args, scratch);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(state), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("checksum mismatch"), std::string::npos) << r.err;
}

// ----------------------------------------------------------- exit codes --

TEST(BakeCliOutput, OutIsAFileIsExit2NamingIt) {
  TempDir dir("out_file");
  write_demo_frames(dir.str(), 1, 1, 1.0 / 20);
  test::write_bytes(dir / "out", "not a folder");
  const Result r = run_lapflow(bake_args(dir.str(), dir / "out"), dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(dir / "out" + ": the output folder (--out) is a file"), std::string::npos) << r.err;
  EXPECT_EQ(test::read_bytes(dir / "out"), "not a folder");
}

TEST(BakeCliOutput, ReadOnlyOutIsExit2NamingIt) {
  TempDir dir("out_ro");
  write_demo_frames(dir.str(), 1, 1, 1.0 / 20);
  fs::create_directories(dir / "ro");
  fs::permissions(dir / "ro", fs::perms::owner_read | fs::perms::owner_exec | fs::perms::group_read |
                                  fs::perms::group_exec | fs::perms::others_read | fs::perms::others_exec);
  const Result r = run_lapflow(bake_args(dir.str(), dir / "ro"), dir, {.drop_root = true});
  fs::permissions(dir / "ro", fs::perms::owner_all);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(dir / "ro" + ": cannot write in the output folder (--out): Permission denied"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(fs::is_empty(dir / "ro"));
}

namespace {

/// A write that fails mid-bake (here a file-size limit: frame 3's OBJ is more
/// than twice as large as any earlier file, without state files) is exit 2
/// naming the file; frames 1-2 stay as an uninterrupted bake wrote them,
/// frame 3 has no file, no temporary file is left and the stats have two
/// lines. lapflow ignores SIGXFSZ itself, so the limit makes write() fail
/// with EFBIG instead of killing it. `tag` names the temporary folders;
/// `extra` goes to the limited bake only (the reference bakes without it).
void expect_a_failed_write_keeps_earlier_frames(const std::string& tag, const std::vector<std::string>& extra) {
  TempDir meshes(tag + "_in"), ref(tag + "_ref"), out(tag + "_out");
  write_demo_frames(meshes.str(), 1, 2, 1.0 / 20);
  write_demo_frames(meshes.str(), 3, 3, 1.0 / 80);
  // No state files: they are larger than the OBJs (docs/bake.md).
  const auto bake_args = [](const std::string& in, const std::string& to, const std::vector<std::string>& more) {
    std::vector<std::string> args = ::bake_args(in, to, false);
    args.insert(args.end(), {"--keep-states", "none"});
    args.insert(args.end(), more.begin(), more.end());
    return args;
  };
  const Result full = run_lapflow(bake_args(meshes.str(), ref.str(), {}), meshes);
  ASSERT_EQ(full.exit_code, 0) << full.err;
  std::uintmax_t earlier = 0;
  for (const auto& e : fs::directory_iterator(ref.str()))
    if (e.path().filename().string().find(".0003.") == std::string::npos) earlier = std::max(earlier, e.file_size());
  const std::uintmax_t obj3 = fs::file_size(frame_file(ref.str(), kFrameFiles[0], 3));
  ASSERT_GT(obj3, 2 * earlier) << "frame 3's OBJ must be the only file over the limit";

  const Result r =
      run_lapflow(bake_args(meshes.str(), out.str(), extra), meshes, {.file_size = long(earlier + obj3) / 2});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(frame_file(out.str(), kFrameFiles[0], 3) + ": write failed: File too large"), std::string::npos)
      << r.err;
  EXPECT_EQ(expect_whole_frames_identical_to(out.str(), ref.str(), 3, kFrameFilesNoAov), (std::vector<int>{1, 2}));
  for (const char* kind : kFrameFiles) EXPECT_FALSE(fs::exists(frame_file(out.str(), kind, 3))) << kind;
  EXPECT_TRUE(temporaries_in(out.str()).empty());
  EXPECT_EQ(lines_in(out / "t.stats.jsonl"), 2u);
}

}  // namespace

TEST(BakeCliOutput, AWriteErrorMidBakeIsExit2NamingTheFileWithEarlierFramesIntact) {
  expect_a_failed_write_keeps_earlier_frames("fsize", {});
}

// --write-behind writes a frame's files while the next one computes: the
// same files as in line, and a failed write still ends the bake as above.
TEST(BakeCliOutput, WriteBehindGivesTheSameFilesAndNamesAFailedWrite) {
  TempDir meshes("behind_in"), ref("behind_ref"), same("behind_same");
  write_demo_frames(meshes.str(), 1, 3, 1.0 / 20);
  const Result in_line = run_lapflow(bake_args(meshes.str(), ref.str(), false), meshes);
  ASSERT_EQ(in_line.exit_code, 0) << in_line.err;
  std::vector<std::string> args = bake_args(meshes.str(), same.str(), false);
  args.push_back("--write-behind");
  const Result behind = run_lapflow(args, meshes);
  ASSERT_EQ(behind.exit_code, 0) << behind.err;
  EXPECT_EQ(expect_whole_frames_identical_to(same.str(), ref.str(), 3, kFrameFilesNoAov), (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(lines_in(same / "t.stats.jsonl"), 3u);

  expect_a_failed_write_keeps_earlier_frames("behind_fsize", {"--write-behind"});
}

TEST(BakeCliInput, AHugeNumberInAnObjGivesOneShortLineNamingTheFile) {
  TempDir dir("long_number");
  test::write_bytes(dir / "m.0001.obj", "v 0 0 0\nv " + std::string(5'000'000, '7') + " 0 0\nv 0 1 0\nf 1 2 3\n");
  std::vector<std::string> args = bake_args(dir.str(), dir / "out");
  args[2] = dir / "m.%04d.obj";
  const Result r = run_lapflow(args, dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find(dir / "m.0001.obj (frame 1): line 2: malformed vertex 1:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("is out of range for a double"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_LT(r.err.size(), 300u + (dir / "m.0001.obj").size()) << r.err;
}
