// MP4 of a preview sequence through Debian's ffmpeg program (libx264): the
// pictures are linked under consecutive numbers in a scratch folder so any
// frame numbering encodes, and the MP4 is written atomically.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lapflow/io/atomic_file.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/addons/preview.hpp"

extern char** environ;

namespace lapflow {
namespace fs = std::filesystem;

bool ffmpeg_available() {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::stringstream dirs(path);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    if (dir.empty()) continue;
    const fs::path exe = fs::path(dir) / "ffmpeg";
    if (::access(exe.c_str(), X_OK) == 0) return true;
  }
  return false;
}

namespace {

/// Runs argv[0] with its arguments, stdout and stderr into `log`; returns the exit code.
int run_program(const std::vector<std::string>& args, const std::string& log) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  pid_t pid = 0;
  const int err = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (err != 0) return -1;
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

void encode_video(const std::vector<std::string>& pngs, const std::string& mp4_path, double fps) {
  if (pngs.empty()) throw std::invalid_argument("encode_video: no pictures");
  std::error_code ec;
  const fs::path scratch = fs::path(mp4_path).parent_path() /
                           (".lapflow_video_" + std::to_string(::getpid()) + "_" +
                            std::to_string(hash64(std::hash<std::string>{}(mp4_path)) % 1000000));
  fs::remove_all(scratch, ec);
  fs::create_directories(scratch, ec);
  if (ec) throw OutputError(scratch.string() + ": cannot create a scratch folder for the video: " + ec.message());
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code e;
      fs::remove_all(dir, e);
    }
  } cleanup{scratch};
  for (std::size_t i = 0; i < pngs.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "f%06zu.png", i);
    fs::create_symlink(fs::absolute(pngs[i], ec), scratch / name, ec);
    if (ec) throw OutputError((scratch / name).string() + ": cannot link the picture: " + ec.message());
  }
  const std::string log = (scratch / "ffmpeg.log").string();
  write_atomically(mp4_path, [&](const std::string& tmp) {
    const int code = run_program({"ffmpeg", "-nostdin", "-y", "-loglevel", "error", "-framerate",
                                  std::to_string(fps > 0 ? fps : 24.0), "-i", (scratch / "f%06d.png").string(),
                                  "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", "libx264", "-preset", "medium",
                                  "-crf", "18", "-pix_fmt", "yuv420p", "-movflags", "+faststart", "-f", "mp4", tmp},
                                 log);
    if (code != 0) {
      std::ifstream in(log);
      std::string first;
      std::getline(in, first);
      throw OutputError(mp4_path + ": ffmpeg failed (exit " + std::to_string(code) + ")" +
                        (first.empty() ? std::string() : ": " + first));
    }
  });
}

}  // namespace lapflow
