// `lapflow farm`'s library (bake/farm.hpp, docs/farm.md).
#include "lapflow/bake/farm.hpp"

#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>

#include "lapflow/bake/render.hpp"
#include "lapflow/bake/render_record.hpp"
#include "lapflow/bake/state.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/atomic_file.hpp"

namespace lapflow {
namespace fs = std::filesystem;
using nlohmann::json;

std::string FarmPlan::farm_dir() const { return (fs::path(dir) / "farm").string(); }
std::string FarmPlan::log_dir() const { return (fs::path(dir) / "farm" / "logs").string(); }

namespace {

/// Written with the scripts into OUT/farm/: what was submitted, for `farm status`.
constexpr const char* kFarmRecord = "farm.json";
/// The line every job script prints last, with lapflow's exit code.
constexpr const char* kExitMarker = "lapflow farm: exit ";

/// What the farm needs from a bake's options; as in `lapflow bake`, the last
/// occurrence of an option wins and the command line overrides a scene file.
struct BakeArguments {
  std::string out, name, mesh, frames;
  int threads = 0;  ///< 0 = all cores
  bool quiet = false;
};

BakeArguments scan_bake_arguments(const std::vector<std::string>& expanded) {
  std::vector<std::string> args{"track"};
  args.insert(args.end(), expanded.begin(), expanded.end());
  BakeArguments b;
  std::string threads;
  for (std::size_t i = 1; i < args.size(); ++i) {
    const std::string& a = args[i];
    // `--opt VALUE` or `--opt=VALUE`.
    auto value = [&](const std::string& option, std::string& into) {
      if (a == option) {
        if (i + 1 >= args.size()) throw UsageError(option + " needs a value");
        into = args[++i];
        return true;
      }
      if (a.rfind(option + "=", 0) != 0) return false;
      into = a.substr(option.size() + 1);
      return true;
    };
    if (value("--out", b.out) || value("--name", b.name) || value("--mesh", b.mesh) || value("--frames", b.frames) ||
        value("--threads", threads))
      continue;
    if (a == "--quiet" || a == "-q") b.quiet = true;
    if (a.rfind("--quiet=", 0) == 0) b.quiet = a != "--quiet=false" && a != "--quiet=0";
  }
  if (!threads.empty()) {
    std::size_t used = 0;
    try {
      b.threads = std::stoi(threads, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != threads.size() || b.threads < 0)
      throw UsageError("--threads: '" + threads + "' is not a count of threads (0 = all cores)");
  }
  return b;
}

/// The frames of the bake: --frames, else every frame on disk, which must
/// then be one range (the jobs are given it as A-B).
FrameRange bake_frames(const BakeArguments& b) {
  if (b.mesh.empty())
    throw UsageError("--mesh is required (on the command line or in the scene file): the farm checks its frames");
  const FramePattern pattern(b.mesh);
  std::optional<FrameRange> range;
  if (!b.frames.empty()) range = parse_frame_range(b.frames);
  const std::vector<int> frames = resolve_frames(pattern, range);
  for (std::size_t i = 1; i < frames.size(); ++i)
    if (frames[i] != frames[i - 1] + 1)
      throw InputError(pattern.path(frames[i - 1] + 1), "file not found: frame " + std::to_string(frames[i - 1] + 1) +
                                                            " is missing between frames " +
                                                            std::to_string(frames.front()) + " and " +
                                                            std::to_string(frames.back()) +
                                                            "; give --frames for the range to bake");
  return {frames.front(), frames.back()};
}

/// Frame numbers in file names: 4 digits, like the bake's own files.
std::string frame_label(int first, int last) { return fmt::format("{:04d}-{:04d}", first, last); }

std::string track_log(const FarmPlan& p, const FarmChunk& c) {
  return (fs::path(p.log_dir()) / ("track." + frame_label(c.first, c.last) + ".log")).string();
}
/// Slurm names it per array task: %a is the frame's index in its chunk.
std::string render_log(const FarmPlan& p, const FarmChunk& c, const std::string& index) {
  return (fs::path(p.log_dir()) / ("render." + frame_label(c.first, c.last) + "." + index + ".log")).string();
}

}  // namespace

std::string FarmPlan::record_path() const { return (fs::path(farm_dir()) / kFarmRecord).string(); }

/// `s` as one shell word.
std::string shell_quote(const std::string& s) {
  const bool plain = !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("-_./=:,+@%", c) != nullptr;
  });
  if (plain) return s;
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string shell_words(const std::vector<std::string>& words) {
  std::string line;
  for (const std::string& w : words) line += (line.empty() ? "" : " ") + shell_quote(w);
  return line;
}

namespace {

/// An `#SBATCH` value: sbatch reads double quotes there, not single ones.
std::string sbatch_value(const std::string& s) {
  return s.find_first_of(" \t") == std::string::npos ? s : "\"" + s + "\"";
}

/// The `#SBATCH` lines both kinds of job share: name, log, CPUs, partition.
std::string sbatch_header(const FarmPlan& p, const std::string& job_name, const std::string& log) {
  std::string h = "#!/bin/bash\n";
  h += "#SBATCH --job-name=" + sbatch_value(job_name) + "\n";
  h += "#SBATCH --output=" + sbatch_value(log) + "\n";
  // --threads N reserves N CPUs; 0 (lapflow's default: all cores) a whole node.
  h += p.threads > 0 ? fmt::format("#SBATCH --cpus-per-task={}\n", p.threads) : "#SBATCH --exclusive\n";
  if (!p.partition.empty()) h += "#SBATCH --partition=" + sbatch_value(p.partition) + "\n";
  return h;
}

/// The lines that end every job: lapflow's exit code, in the log for `farm status`, and as the job's.
std::string exit_lines() {
  return fmt::format("code=$?\necho \"{}$code\"\nexit \"$code\"\n", kExitMarker);
}

std::vector<std::string> track_command(const FarmPlan& p, const FarmChunk& c) {
  std::vector<std::string> cmd{p.lapflow, "track"};
  cmd.insert(cmd.end(), p.bake_args.begin(), p.bake_args.end());
  // The whole range every time, so that every chunk writes the same manifest.
  cmd.insert(cmd.end(), {"--frames", fmt::format("{}-{}", p.frames.first, p.frames.last), "--resume", "--until",
                         std::to_string(c.last)});
  return cmd;
}

}  // namespace

/// The commands that re-run one frame's rendering and one chunk's tracking alone.
std::string render_rerun(const FarmChunk& c, int frame) {
  return fmt::format("sbatch --array={} {}", frame - c.first, shell_quote(c.render_script));
}
std::string track_rerun(const FarmChunk& c) { return "sbatch " + shell_quote(c.track_script); }

namespace {

std::string track_script(const FarmPlan& p, const FarmChunk& c, std::size_t k) {
  std::string s = sbatch_header(p, p.name + ".track." + frame_label(c.first, c.last), track_log(p, c));
  s += fmt::format(
      "# lapflow farm, {}: tracking of frames {}-{} (chunk {} of {}, frames {}-{}), written by\n"
      "# `lapflow farm slurm`; submitted to run after the previous chunk's tracking succeeded (afterok).\n"
      "# `lapflow track --resume` continues after the last tracked frame, so this re-runs the chunk alone\n"
      "# (a no-op once it is done): {}\n",
      p.name, c.first, c.last, k + 1, p.chunks.size(), p.frames.first, p.frames.last, track_rerun(c));
  s += "cd " + shell_quote(p.cwd) + " || exit 2\n";
  s += shell_words(track_command(p, c)) + "\n";
  return s + exit_lines();
}

std::string render_script(const FarmPlan& p, const FarmChunk& c, std::size_t k) {
  std::string s = sbatch_header(p, p.name + ".render." + frame_label(c.first, c.last), render_log(p, c, "%a"));
  s += fmt::format("#SBATCH --array=0-{}\n", c.last - c.first);
  s += fmt::format(
      "# lapflow farm, {}: rendering of frames {}-{} (chunk {} of {}), one array task per frame: task I\n"
      "# renders frame {} + I; submitted to run after the tracking of these frames succeeded (afterok).\n"
      "# Re-run frame F alone: sbatch --array=$((F - {})) {}\n",
      p.name, c.first, c.last, k + 1, p.chunks.size(), c.first, c.first, shell_quote(c.render_script));
  s += fmt::format("frame=$(({} + ${{SLURM_ARRAY_TASK_ID:?is not set: submit with sbatch --array=I}}))\n", c.first);
  s += "echo \"lapflow farm: frame $frame\"\n";
  std::vector<std::string> cmd{p.lapflow, "render", p.dir, "--name", p.name};
  std::string line = shell_words(cmd) + " --frames \"$frame-$frame\" --skip-done";
  if (p.threads > 0) line += fmt::format(" --threads {}", p.threads);
  if (p.quiet) line += " --quiet";
  s += line + "\n";
  return s + exit_lines();
}

}  // namespace

/// `sbatch --parsable [--dependency=afterok:AFTER --kill-on-invalid-dep=yes] SCRIPT`: tracking chunk k
/// runs after tracking chunk k-1, rendering chunk k after tracking chunk k.
std::vector<std::string> sbatch_arguments(const std::string& script, const std::string& after) {
  std::vector<std::string> a{"sbatch", "--parsable"};
  // A failed dependency cancels the jobs waiting for it, instead of leaving them pending for ever.
  if (!after.empty()) a.insert(a.end(), {"--dependency=afterok:" + after, "--kill-on-invalid-dep=yes"});
  a.push_back(script);
  return a;
}

FarmPlan make_farm_plan(const std::vector<std::string>& command, const std::vector<std::string>& bake_args,
                        const std::vector<std::string>& expanded_args, int chunk, const std::string& partition,
                        const std::string& binary) {
  FarmPlan p;
  p.command = command;
  p.bake_args = bake_args;
  const BakeArguments b = scan_bake_arguments(expanded_args);
  if (b.out.empty())
    throw UsageError("--out is required (on the command line or in the scene file): the folder the jobs bake into");
  if (chunk < 1) throw UsageError(fmt::format("--chunk {}: a chunk holds at least 1 frame", chunk));
  if (chunk > kMaxFarmChunk)
    throw UsageError(fmt::format("--chunk {}: at most {} frames, the array tasks of one chunk (Slurm's default "
                                 "MaxArraySize is 1001)",
                                 chunk, kMaxFarmChunk));
  p.frames = bake_frames(b);
  p.chunk = chunk;
  p.threads = b.threads;
  p.quiet = b.quiet;
  p.partition = partition;
  p.cwd = fs::current_path().string();
  p.dir = fs::absolute(b.out).lexically_normal().string();
  if (p.dir.size() > 1 && p.dir.back() == '/') p.dir.pop_back();
  p.name = b.name.empty() ? default_output_name(b.mesh) : b.name;
  std::error_code ec;
  p.lapflow = binary.empty() ? fs::read_symlink("/proc/self/exe", ec).string() : fs::absolute(binary).string();
  if (p.lapflow.empty()) throw UsageError("cannot find this program's path in /proc/self/exe: give --binary");
  // Slurm reads %x in an #SBATCH --output path as a pattern, and no quoting saves a newline.
  for (const std::string* path : {&p.dir, &p.lapflow, &p.cwd})
    if (path->find_first_of("\n\r\"%") != std::string::npos)
      throw UsageError("'" + *path + "': a path with a newline, a double quote or a % cannot go into an sbatch script");

  for (int64_t first = p.frames.first; first <= p.frames.last; first += chunk) {
    FarmChunk c;
    c.first = int(first);
    c.last = int(std::min<int64_t>(first + chunk - 1, p.frames.last));
    c.track_script = (fs::path(p.farm_dir()) / ("track." + frame_label(c.first, c.last) + ".sh")).string();
    c.render_script = (fs::path(p.farm_dir()) / ("render." + frame_label(c.first, c.last) + ".sh")).string();
    p.chunks.push_back(c);
  }
  return p;
}

namespace {

json plan_json(const FarmPlan& p, bool submitted) {
  json chunks = json::array();
  for (const FarmChunk& c : p.chunks)
    chunks.push_back({{"first", c.first},
                      {"last", c.last},
                      {"track_script", c.track_script},
                      {"render_script", c.render_script},
                      {"track_log", track_log(p, c)},
                      {"render_log", render_log(p, c, "%a")},
                      {"track_job", c.track_job},
                      {"render_job", c.render_job}});
  return {{"version", 1},          {"scheduler", "slurm"}, {"submitted", submitted}, {"command", p.command},
          {"dir", p.dir},          {"name", p.name},       {"first", p.frames.first}, {"last", p.frames.last},
          {"chunk", p.chunk},      {"lapflow", p.lapflow}, {"cwd", p.cwd},           {"bake_args", p.bake_args},
          {"chunks", chunks}};
}

}  // namespace

void write_farm_record(const FarmPlan& p, bool submitted) {
  write_text_atomically(p.record_path(),
                        plan_json(p, submitted).dump(2, ' ', false, json::error_handler_t::replace) + "\n");
}

/// The submission as a shell script, what `farm slurm` runs: for a look, or
/// for a later `bash OUT/farm/submit.sh` after --dry-run.
std::string farm_submit_script(const FarmPlan& p) {
  std::string s = fmt::format(
      "#!/bin/bash\n"
      "# lapflow farm, {}: submits the tracking chain and the rendering arrays of frames {}-{} in chunks of {}.\n"
      "# Written by `lapflow farm slurm`, which submits the same commands.\n"
      "set -e\n",
      p.name, p.frames.first, p.frames.last, p.chunk);
  for (std::size_t k = 0; k < p.chunks.size(); ++k) {
    // sbatch_arguments() with the previous job's id from a shell variable.
    const std::string after =
        k == 0 ? "" : fmt::format(" --dependency=afterok:${{t{}%%;*}} --kill-on-invalid-dep=yes", k);
    s += fmt::format("t{}=$(sbatch --parsable{} {})\n", k + 1, after, shell_quote(p.chunks[k].track_script));
    s += fmt::format("r{0}=$(sbatch --parsable --dependency=afterok:${{t{0}%%;*}} --kill-on-invalid-dep=yes {1})\n",
                     k + 1, shell_quote(p.chunks[k].render_script));
  }
  return s;
}

void write_farm_scripts(const FarmPlan& p) {
  std::error_code ec;
  fs::create_directories(p.log_dir(), ec);
  if (ec || !fs::is_directory(p.log_dir()))
    throw OutputError(p.log_dir() + ": cannot create the farm's folder: " + ec.message());
  auto write_script = [](const std::string& path, const std::string& text) {
    write_text_atomically(path, text);
    std::error_code e;
    fs::permissions(path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                    fs::perm_options::add, e);
  };
  for (std::size_t k = 0; k < p.chunks.size(); ++k) {
    write_script(p.chunks[k].track_script, track_script(p, p.chunks[k], k));
    write_script(p.chunks[k].render_script, render_script(p, p.chunks[k], k));
  }
  write_script((fs::path(p.farm_dir()) / "submit.sh").string(), farm_submit_script(p));
}

namespace {

struct Captured {
  int exit_code = 0;
  std::string out, err;
};

/// Runs `argv` (found on PATH) and returns its exit code, stdout and stderr.
Captured run_captured(const std::vector<std::string>& argv) {
  int out_pipe[2], err_pipe[2];
  if (::pipe(out_pipe) != 0) throw std::runtime_error("pipe: " + std::string(std::strerror(errno)));
  if (::pipe(err_pipe) != 0) {
    ::close(out_pipe[0]);
    ::close(out_pipe[1]);
    throw std::runtime_error("pipe: " + std::string(std::strerror(errno)));
  }
  std::vector<std::string> args = argv;
  std::vector<char*> cargs;
  for (std::string& a : args) cargs.push_back(a.data());
  cargs.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int error = errno;
    for (int fd : {out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]}) ::close(fd);
    throw std::runtime_error("fork: " + std::string(std::strerror(error)));
  }
  if (pid == 0) {
    ::dup2(out_pipe[1], STDOUT_FILENO);
    ::dup2(err_pipe[1], STDERR_FILENO);
    ::close(out_pipe[0]);
    ::close(err_pipe[0]);
    ::execvp(cargs[0], cargs.data());
    ::_exit(127);
  }
  ::close(out_pipe[1]);
  ::close(err_pipe[1]);
  Captured r;
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* into[2] = {&r.out, &r.err};
  int open = 2;
  while (open > 0) {
    if (::poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || fds[i].revents == 0) continue;
      char buf[4096];
      const ssize_t n = ::read(fds[i].fd, buf, sizeof buf);
      if (n > 0) {
        into[i]->append(buf, std::size_t(n));
      } else if (n == 0 || errno != EINTR) {
        ::close(fds[i].fd);
        fds[i].fd = -1;
        --open;
      }
    }
  }
  for (pollfd& f : fds)
    if (f.fd >= 0) ::close(f.fd);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

std::string trimmed(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  std::size_t b = 0;
  while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  return s.substr(b);
}

}  // namespace

/// Submits with `sbatch --parsable` and returns the job id.
std::string sbatch_submit(const std::vector<std::string>& args) {
  const Captured r = run_captured(args);
  if (r.exit_code == 127 && r.out.empty())
    throw UsageError("sbatch not found on PATH: run `lapflow farm slurm` on a Slurm submit host, or --dry-run to only "
                     "write the scripts");
  const std::string out = trimmed(r.out);
  const std::string id = out.substr(0, out.find(';'));  // --parsable: "ID" or "ID;CLUSTER"
  const bool numeric = !id.empty() && std::all_of(id.begin(), id.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (r.exit_code != 0 || !numeric)
    throw UsageError(fmt::format("`{}` failed (exit {}): {}", shell_words(args), r.exit_code,
                                 trimmed(r.err).empty() ? "no job id printed: '" + out + "'" : trimmed(r.err)));
  return id;
}

namespace {

/// lapflow's exit code from a job's log (the line exit_lines() prints), if it got there.
std::optional<int> logged_exit(const std::string& log) {
  std::ifstream in(log);
  std::string line;
  std::optional<int> code;
  while (std::getline(in, line))
    if (line.rfind(kExitMarker, 0) == 0) {
      try {
        code = std::stoi(line.substr(std::strlen(kExitMarker)));
      } catch (const std::exception&) {
      }
    }
  return code;
}

}  // namespace

const char* frame_status_name(FrameStatus s) {
  switch (s) {
    case FrameStatus::Rendered: return "rendered";
    case FrameStatus::Tracked: return "tracked";
    case FrameStatus::Damaged: return "damaged";
    case FrameStatus::Failed: return "failed";
    case FrameStatus::Pending: return "pending";
  }
  return "";
}

namespace {

/// OUT/farm/farm.json when it belongs to the bake `name` ("" = any), else null.
json read_farm_record(const std::string& dir, const std::string& name) {
  const std::string path = (fs::path(dir) / "farm" / kFarmRecord).string();
  if (!fs::is_regular_file(path)) return nullptr;
  std::ifstream in(path);
  json r = json::parse(in, nullptr, false);
  const bool usable = !r.is_discarded() && r.is_object() && r.value("name", json()).is_string() &&
                      r.value("first", json()).is_number_integer() && r.value("last", json()).is_number_integer() &&
                      r.value("chunks", json()).is_array() && r.value("command", json()).is_array();
  if (!usable || (!name.empty() && r["name"] != name)) return nullptr;
  return r;
}

/// The status of frame `f` of bake `m`; `record` (maybe null) adds what the farm's job logs say.
/// "resolution 512, aov, exemplar 512636c0": what a rendered frame's record says.
std::string made_with(const RenderRecord& record) {
  const auto option = [&](const char* name) {
    const auto at = record.options.find(name);
    return at == record.options.end() ? std::string("?") : at->second;
  };
  return fmt::format("resolution {}{}, exemplar {}", option("resolution"), option("aov") == "true" ? ", aov" : "",
                     record.exemplar_digest.substr(0, 8));
}

/// The status of frame `f` of bake `m`; `record` (maybe null) adds what the farm's job logs say.
FarmFrameReport frame_report(const BakeManifest& m, const json& record, int f) {
  FarmFrameReport r{f, FrameStatus::Pending, "", ""};
  std::error_code ec;
  const std::string state = m.frame_file("state", f);
  const bool tracked = fs::exists(state, ec);
  if (fs::exists(m.frame_file("obj", f), ec)) {
    const std::string record_path = m.frame_file("render", f);
    r.status = FrameStatus::Rendered;
    if (!fs::exists(record_path, ec)) {
      r.detail = "no record";
      return r;
    }
    try {
      const RenderRecord rendered = read_render_record(record_path);
      if (rendered.name != m.name || rendered.frame != f)
        throw InputError(record_path, fmt::format("the record of {} frame {}", rendered.name, rendered.frame));
      r.detail = render_record_file_problem(m, rendered);
      if (!r.detail.empty()) r.status = FrameStatus::Damaged;
      else r.detail = made_with(rendered);
    } catch (const InputError& e) {
      r.status = FrameStatus::Damaged;
      r.detail = e.what();
    }
    return r;
  }
  if (tracked) {
    r.status = FrameStatus::Tracked;
    try {
      check_bake_state(read_bake_state(state), state, m, f);
    } catch (const InputError& e) {
      r.status = FrameStatus::Damaged;
      r.detail = e.what();
      return r;
    }
  }
  if (record.is_null()) return r;
  for (const json& j : record["chunks"]) {
    FarmChunk ch;
    ch.first = j.value("first", 0);
    ch.last = j.value("last", -1);
    if (f < ch.first || f > ch.last) continue;
    ch.render_script = j.value("render_script", "");
    // A job that ended with a non-zero exit code said so last in its log.
    if (tracked) {
      std::string log = j.value("render_log", "");
      if (const std::size_t at = log.rfind("%a"); at != std::string::npos)
        log.replace(at, 2, std::to_string(f - ch.first));
      const std::optional<int> code = logged_exit(log);
      if (code && *code != 0) r = {f, FrameStatus::Failed, render_rerun(ch, f), ""};
    } else {
      // The chain after a failed tracking job was cancelled: the whole farm command goes again.
      const std::optional<int> code = logged_exit(j.value("track_log", ""));
      if (code && *code != 0)
        r = {f, FrameStatus::Failed,
             "cd " + shell_quote(record.value("cwd", ".")) + " && " +
                 shell_words(record["command"].get<std::vector<std::string>>()),
             ""};
    }
  }
  return r;
}

}  // namespace

FarmStatus farm_status(const std::string& dir, const std::string& name_in) {
  const json record = read_farm_record(dir, name_in);
  const std::string name = !name_in.empty() || record.is_null() ? name_in : record["name"].get<std::string>();
  BakeManifest m;
  if (!record.is_null() && !fs::is_regular_file(bake_manifest_path(dir, name))) {
    // Submitted, but the first tracking job has not written the manifest yet.
    m.name = name;
    m.dir = fs::absolute(dir).lexically_normal().string();
    for (int f = record["first"].get<int>(); f <= record["last"].get<int>(); ++f) m.frames.push_back(f);
  } else {
    m = read_bake_manifest(dir, name);
  }

  FarmStatus s;
  std::vector<FarmFrameReport>& frames = s.frames;
  std::map<FrameStatus, int>& counts = s.counts;
  // Every state is read through (its CRC): frames on their own tasks.
  frames.resize(m.frames.size());
  parallel_for(m.frames.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) frames[i] = frame_report(m, record, m.frames[i]);
  }, 1);
  for (const FarmFrameReport& r : frames) ++counts[r.status];
  s.manifest = std::move(m);
  return s;
}
}  // namespace lapflow
