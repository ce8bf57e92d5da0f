#include "cli_common.hpp"

#include <unistd.h>

#include <cstdio>

#include <filesystem>
#include <regex>
#include <set>

#include "lapflow/core/errors.hpp"
#include "lapflow/core/memory.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/io/image.hpp"
#include "lapflow/io/mesh_io.hpp"

namespace lapflow::cli {

GlobalOptions& globals() {
  static GlobalOptions g;
  return g;
}

CLI::Option* add_remesher_option(CLI::App& cmd, lapflow::Remesher& remesher) {
  using lapflow::Remesher;
  const std::map<std::string, Remesher> names{{"lattice", Remesher::Lattice}, {"isotropic", Remesher::Isotropic},
                                              {"cgal", Remesher::CgalIsotropic}, {"grid", Remesher::Lattice},
                                              {"fast", Remesher::Isotropic}};
  return cmd
      .add_option("--remesher", remesher,
                  "How new patches get even triangles: lattice (tangent-plane lattice, isotropic where the cut is "
                  "not a height field), isotropic (remeshing), cgal (CGAL's isotropic remeshing, same algorithm); "
                  "grid and fast are the old names of lattice and isotropic")
      ->transform(CLI::CheckedTransformer(names).description(""))
      ->type_name("lattice|isotropic|cgal");
}

CLI::Option* add_max_memory_option(CLI::App& cmd, std::size_t& bytes, const std::string& what) {
  return cmd
      .add_option_function<std::string>(
          "--max-memory", [&bytes](const std::string& text) { bytes = lapflow::parse_memory_size(text); },
          fmt::format("Memory the command may use, e.g. 16G or 500M (default: 80% of physical memory, here {}). {}",
                      lapflow::format_bytes(double(lapflow::default_memory_budget())), what))
      ->type_name("SIZE");
}

void add_global_options(CLI::App& cmd) {
  GlobalOptions& g = globals();
  cmd.add_option("--threads", g.threads, "Worker threads; 0 = all cores. Results do not depend on it.")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd.add_option("--seed", g.seed, "Random seed: same inputs and seed give the same output")->capture_default_str();
  cmd.add_flag("--quiet,-q", g.quiet, "Print only warnings and errors");
}

void print_error(const std::string& message, const std::string& hint) {
  const std::size_t room = lapflow::kMaxMessageChars > hint.size() + 40 ? lapflow::kMaxMessageChars - hint.size() : 40;
  fmt::print(stderr, "error: {}{}\n", lapflow::printable_line(message, room), lapflow::printable_line(hint));
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

namespace fs = std::filesystem;

std::string exemplar_dir() {
  // Beside the binary's source tree (build/lapflow -> exemplars/), else the
  // folder compiled in.
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    for (fs::path p : {exe.parent_path().parent_path() / "exemplars", exe.parent_path() / "exemplars"})
      if (fs::is_directory(p)) return p.string();
  }
  return LAPFLOW_EXEMPLAR_DIR;
}

namespace {
std::string find_sibling(const fs::path& dir, const std::string& stem) {
  for (const char* ext : {".png", ".exr", ".tif", ".tiff", ".jpg", ".jpeg"}) {
    const fs::path p = dir / (stem + ext);
    if (fs::exists(p)) return p.string();
  }
  return "";
}

// An animated exemplar's folder: its NAME.color.NNNN.EXT frames as a pattern.
std::string sequence_in_folder(const fs::path& dir) {
  static const std::regex frame(R"((.+)\.color\.(\d+)\.(png|exr|tif|tiff|jpg|jpeg))", std::regex::icase);
  std::string name, ext;
  std::set<std::size_t> widths;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string file = it->path().filename().string();
    std::smatch m;
    if (!std::regex_match(file, m, frame)) continue;
    if (!name.empty() && (m[1].str() != name || m[3].str() != ext))
      throw InputError(dir.string(), "holds two exemplar sequences (" + name + ".color.*." + ext + " and " +
                                         m[1].str() + ".color.*." + m[3].str() + "); name one with a frame pattern");
    name = m[1].str(), ext = m[3].str();
    widths.insert(m[2].length());
  }
  if (name.empty())
    throw InputError(dir.string(), "a folder, but no animated exemplar's frames NAME.color.0001.png in it");
  const std::string token = widths.size() == 1 ? "%0" + std::to_string(*widths.begin()) + "d" : "%d";
  return (dir / (name + ".color." + token + "." + ext)).string();
}

// NAME.color.%04d.png -> NAME.KIND.%04d.EXT beside it, when its frames are on disk.
std::string sibling_sequence(const std::string& color, const std::string& kind) {
  const fs::path path(color);
  const std::string file = path.filename().string();
  const std::size_t at = file.find(".color.");
  if (at == std::string::npos) return "";
  const std::string rest = file.substr(at + 7);
  const std::size_t dot = rest.rfind('.');
  for (const char* ext : {".png", ".exr", ".tif", ".tiff", ".jpg", ".jpeg"}) {
    const std::string candidate =
        (path.parent_path() / (file.substr(0, at) + "." + kind + "." + rest.substr(0, dot) + ext)).string();
    if (!FramePattern(candidate).frames_on_disk().empty()) return candidate;
  }
  return "";
}

}  // namespace

void resolve_exemplar_paths(std::string& color, std::string& feature, std::string& displacement) {
  if (color.empty()) throw UsageError("--exemplar is required (a colour image or a shipped exemplar's name)");
  if (!fs::exists(color) && color.find('/') == std::string::npos && color.find('.') == std::string::npos) {
    std::string shipped = find_sibling(exemplar_dir(), color + ".color");
    if (shipped.empty() && fs::is_directory(fs::path(exemplar_dir()) / color))
      shipped = (fs::path(exemplar_dir()) / color).string();
    if (shipped.empty())
      throw InputError(color, "no such file, and no shipped exemplar of that name in " + exemplar_dir());
    color = shipped;
  }
  if (fs::is_directory(color)) color = sequence_in_folder(color);
  if (is_exemplar_sequence(color)) {
    exemplar_frame_files(color);  // throws when no frame is on disk
    if (feature.empty()) {
      feature = sibling_sequence(color, "feature");
      if (feature.empty())
        throw InputError(color, "no feature map given (--feature) and no NAME.feature.NNNN frames beside this "
                                "animated exemplar's NAME.color.NNNN frames");
    }
    if (displacement.empty()) displacement = sibling_sequence(color, "disp");
    return;
  }
  if (!fs::exists(color)) throw InputError(color, "exemplar image not found");
  // NAME.color.EXT -> NAME; otherwise the file's stem.
  const fs::path path(color);
  std::string stem = path.stem().string();
  if (stem.size() > 6 && stem.substr(stem.size() - 6) == ".color") stem = stem.substr(0, stem.size() - 6);
  if (feature.empty()) {
    feature = find_sibling(path.parent_path(), stem + ".feature");
    if (feature.empty())
      throw InputError(color, "no feature map given (--feature) and no " + stem +
                                  ".feature.png beside the exemplar; make one with any grey image in [0,1]");
  }
  if (displacement.empty()) displacement = find_sibling(path.parent_path(), stem + ".disp");
}

bool parse_orientation(const std::string& text, lapflow::Vec3& direction) {
  if (text == "random") return false;
  std::smatch m;
  static const std::regex world(R"(world:\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+))");
  if (!std::regex_match(text, m, world))
    throw UsageError("--orientation: expected 'random' or 'world:x,y,z', got '" + text + "'");
  direction = {std::stod(m[1]), std::stod(m[2]), std::stod(m[3])};
  if (!(lapflow::norm(direction) > 0)) throw UsageError("--orientation: the direction must not be zero");
  return true;
}

std::string thread_count_label() {
  return globals().threads > 0 ? std::to_string(globals().threads)
                               : "all (" + std::to_string(lapflow::thread_count()) + ")";
}

}  // namespace lapflow::cli
