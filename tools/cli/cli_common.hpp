#pragma once
// Shared pieces of the lapflow command line: global options, exit codes,
// progress reporting, logging.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "lapflow/bake/bake.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/core/interrupt.hpp"
#include "lapflow/core/vec.hpp"

namespace lapflow::cli {

enum ExitCode { kOk = 0, kInternal = 1, kBadInput = 2 };

/// Options every command takes.
struct GlobalOptions {
  int threads = 0;     ///< 0 = all cores
  uint64_t seed = 1;
  bool quiet = false;
};
GlobalOptions& globals();
/// Adds --threads, --seed and --quiet to a subcommand.
void add_global_options(CLI::App& cmd);

/// `--max-memory SIZE` (16G, 500M, bytes; default 80% of physical memory)
/// into `bytes`, with `what` saying what the command refuses beyond it.
CLI::Option* add_max_memory_option(CLI::App& cmd, std::size_t& bytes, const std::string& what);

/// While it lives, SIGINT / SIGTERM stop a bake or render between frames
/// (exit 130 / 143), a second one at once (install_stop_handlers); the
/// default handlers come back after it, so that a command going on to other
/// work (`lapflow demo` renders previews) stops on Ctrl-C as usual.
struct StopHandlersScope {
  StopHandlersScope() { lapflow::install_stop_handlers(); }
  ~StopHandlersScope() { lapflow::restore_stop_handlers(); }
  StopHandlersScope(const StopHandlersScope&) = delete;
  StopHandlersScope& operator=(const StopHandlersScope&) = delete;
};

/// `--remesher lattice|isotropic|cgal` (the old names `grid` and `fast` are
/// accepted too), shared by bake and patches.
CLI::Option* add_remesher_option(CLI::App& cmd, lapflow::Remesher& remesher);
/// Applies --threads (call at the start of every command's callback).
void apply_global_options();

/// Message to stderr unless --quiet.
template <typename... Args>
void info(fmt::format_string<Args...> f, Args&&... args) {
  if (!globals().quiet) fmt::print(stderr, "{}\n", fmt::format(f, std::forward<Args>(args)...));
}
/// "error: MESSAGE" on stderr, one printable line of at most about 300
/// characters (lapflow::printable_line), whatever the message holds; a
/// `hint` after it is never cut away.
void print_error(const std::string& message, const std::string& hint = "");
/// Warning to stderr (printed even with --quiet), one printable line.
template <typename... Args>
void warn(fmt::format_string<Args...> f, Args&&... args) {
  fmt::print(stderr, "warning: {}\n", lapflow::printable_line(fmt::format(f, std::forward<Args>(args)...)));
}

/// Frame progress: a bar with count and ETA on a terminal, plain lines
/// otherwise, nothing with --quiet.
class Progress {
 public:
  Progress(std::string label, std::size_t total);
  ~Progress();
  /// One unit done; `note` is shown after the bar (e.g. "frame 12: 5123 patches").
  void step(const std::string& note = "");
  void finish();

 private:
  std::string label_;
  std::size_t total_, done_ = 0;
  bool tty_, finished_ = false;
  std::chrono::steady_clock::time_point start_;
};

/// Fills the feature and displacement paths of an exemplar: `color` may be a
/// shipped exemplar's name (`pebbles`) or a file `NAME.color.EXT`; missing
/// maps default to `NAME.feature.*` / `NAME.disp.*` beside it when present.
/// Throws InputError when no feature map can be found.
void resolve_exemplar_paths(std::string& color, std::string& feature, std::string& displacement);
/// Folder of the shipped exemplars.
std::string exemplar_dir();
/// "random" -> false; "world:x,y,z" -> true and the direction. Throws UsageError.
bool parse_orientation(const std::string& text, lapflow::Vec3& direction);
/// "2" or "all (2)".
std::string thread_count_label();

/// Resolves automatic options, bakes with a progress bar, prints a summary.
void bake_with_progress(lapflow::BakeOptions& options);

/// Each command file adds its subcommand with one of these.
void add_inspect_command(CLI::App& app);
void add_demo_command(CLI::App& app);
void add_atlas_command(CLI::App& app);
void add_patches_command(CLI::App& app);
void add_bake_command(CLI::App& app);
void add_track_command(CLI::App& app);
void add_options_command(CLI::App& app);
void add_render_command(CLI::App& app);
void add_eval_command(CLI::App& app);
/// `lapflow preview DIR --width W --height H` with every other option at its default.
void preview_bake(const std::string& dir, int width, int height);
void add_preview_command(CLI::App& app);
void add_feature_map_command(CLI::App& app);
/// `lapflow farm slurm|status` (cmd_farm.cpp).
void add_farm_command(CLI::App& app);

}  // namespace lapflow::cli
