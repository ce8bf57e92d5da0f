#pragma once
// Shared pieces of the lapflow command line: global options, exit codes,
// progress reporting, logging.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

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
/// Applies --threads (call at the start of every command's callback).
void apply_global_options();

/// Message to stderr unless --quiet.
template <typename... Args>
void info(fmt::format_string<Args...> f, Args&&... args) {
  if (!globals().quiet) fmt::print(stderr, "{}\n", fmt::format(f, std::forward<Args>(args)...));
}
/// Warning to stderr (printed even with --quiet).
template <typename... Args>
void warn(fmt::format_string<Args...> f, Args&&... args) {
  fmt::print(stderr, "warning: {}\n", fmt::format(f, std::forward<Args>(args)...));
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

/// Each command file adds its subcommand with one of these.
void add_inspect_command(CLI::App& app);
void add_demo_command(CLI::App& app);
void add_atlas_command(CLI::App& app);
void add_patches_command(CLI::App& app);
void add_bake_command(CLI::App& app);

}  // namespace lapflow::cli
