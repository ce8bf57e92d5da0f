#include "cli_common.hpp"

#include <unistd.h>

#include <cstdio>

#include "lapflow/parallel.hpp"

namespace lapflow::cli {

GlobalOptions& globals() {
  static GlobalOptions g;
  return g;
}

void add_global_options(CLI::App& cmd) {
  GlobalOptions& g = globals();
  cmd.add_option("--threads", g.threads, "Worker threads; 0 = all cores. Results do not depend on it.")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd.add_option("--seed", g.seed, "Random seed: same inputs and seed give the same output")->capture_default_str();
  cmd.add_flag("--quiet,-q", g.quiet, "Print only warnings and errors");
}

void apply_global_options() { set_thread_count(globals().threads); }

Progress::Progress(std::string label, std::size_t total)
    : label_(std::move(label)), total_(total), tty_(::isatty(STDERR_FILENO)), start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { finish(); }

static std::string format_seconds(double s) {
  if (s < 60) return fmt::format("{:.0f}s", s);
  if (s < 3600) return fmt::format("{}m{:02d}s", int(s / 60), int(s) % 60);
  return fmt::format("{}h{:02d}m", int(s / 3600), (int(s) / 60) % 60);
}

void Progress::step(const std::string& note) {
  ++done_;
  if (globals().quiet) return;
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double eta = done_ > 0 ? elapsed / double(done_) * double(total_ - std::min(done_, total_)) : 0;
  if (tty_) {
    const int width = 28;
    const int filled = total_ ? int(double(width) * double(done_) / double(total_)) : width;
    fmt::print(stderr, "\r\033[K{} [{}{}] {}/{}  {} elapsed, ETA {}  {}", label_, std::string(filled, '#'),
               std::string(width - filled, '.'), done_, total_, format_seconds(elapsed), format_seconds(eta), note);
    std::fflush(stderr);
  } else {
    fmt::print(stderr, "{} {}/{} ({} elapsed, ETA {}) {}\n", label_, done_, total_, format_seconds(elapsed),
               format_seconds(eta), note);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (tty_ && !globals().quiet && done_ > 0) fmt::print(stderr, "\n");
}

}  // namespace lapflow::cli
