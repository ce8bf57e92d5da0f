// `lapflow eval`: quality metrics of a bake folder (docs/eval.md).
#include <filesystem>

#include "cli_common.hpp"
#include "lapflow/io/atomic_file.hpp"
#include "lapflow/bake/manifest.hpp"
#include "lapflow/addons/eval.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow::cli {

namespace {

struct EvalCli {
  std::string dir, exemplar, frames, json_path, plots_dir, maps_dir;
  double min_speed = -1;
  CLI::Option *json = nullptr, *plots = nullptr, *maps = nullptr;
};

void run_eval(EvalCli& c) {
  apply_global_options();
  EvalOptions o;
  o.seed = globals().seed;
  if (!c.frames.empty()) o.frames = parse_frame_range(c.frames);
  if (c.min_speed >= 0) o.min_speed = c.min_speed;
  if (!c.exemplar.empty()) {
    // A shipped exemplar's name or a file; only the colour image is needed.
    std::string feature = "-", displacement = "-";
    resolve_exemplar_paths(c.exemplar, feature, displacement);
    o.exemplar = c.exemplar;
  }
  const bool json_to_stdout = c.json->count() > 0 && c.json_path.empty();

  const BakeManifest manifest = read_bake_manifest(c.dir);
  if (c.maps->count() > 0)
    o.maps_dir = c.maps_dir.empty()
                     ? (std::filesystem::path(manifest.dir.empty() ? c.dir : manifest.dir) / (manifest.name + ".eval_maps")).string()
                     : c.maps_dir;
  std::size_t frames = 0;
  for (int f : manifest.frames) frames += !o.frames || (f >= o.frames->first && f <= o.frames->last);
  info("lapflow eval: {} ({} mode), {} frames | {} threads", manifest.dir, raster_mode_name(manifest.options.raster.mode), frames, thread_count_label());
  Progress progress("eval", frames);
  EvalReport report = evaluate_bake(c.dir, o, [&](const FrameMetrics& m) {
    progress.step(fmt::format("frame {}: coverage {:.2f}%, contrast {:.3f}, {:.2f}s", m.frame, 100 * m.coverage,
                               m.contrast, m.seconds));
  });
  progress.finish();

  if (json_to_stdout) {
    fmt::print("{}", eval_report_json(report));
  } else {
    fmt::print("{}", eval_report_table(report));
    if (!c.json_path.empty()) {
      write_text_atomically(c.json_path, eval_report_json(report));
      info("wrote {}", c.json_path);
    }
  }
  if (!report.maps.empty()) info("wrote {} popping maps in {}", report.maps.size(), o.maps_dir);
  if (c.plots->count() > 0) {
    const std::string dir =
        c.plots_dir.empty() ? (std::filesystem::path(report.dir) / (report.name + ".eval_plots")).string() : c.plots_dir;
    const auto files = write_eval_plots(report, dir);
    info("wrote {} plots in {}", files.size(), dir);
  }
}

}  // namespace

void add_eval_command(CLI::App& app) {
  static EvalCli c;
  CLI::App* cmd = app.add_subcommand("eval", "Measure the quality of a bake: coverage, ghosting, fidelity, flow, popping");
  cmd->description(
      "Measure the quality of a bake (made with --aov) per frame and over the sequence.\n\n"
      "  coverage     share of chart texels that a patch covers\n"
      "  contrast     area-weighted luminance std on the surface / the exemplar's (blending lowers it: ghosting)\n"
      "  hist W1, SW  distance of the surface's colours (per channel) and 5x5 luminance windows (sliced\n"
      "               Wasserstein) to the exemplar's, at the atlas texel scale\n"
      "  flow50/90    |displacement - v dt| / (|v| dt) of texels matched to the previous frame by (patch, u, v)\n"
      "  pop%         surface whose patch changed since the previous frame (back-advected); born / died patches\n"
      "  drift%       texels at rest (|v| <= --min-speed) whose texture changed since the previous frame\n"
      "  delta        distortion max(s1, 1/s2) of the patch map: median, 90th percentile, max\n"
      "A bake with exemplar layers (--layer) is compared layer by layer with each layer's exemplar (the frame's\n"
      "contrast and fidelity are the texel-weighted means), and a second table gives per frame:\n"
      "  agree%       texels showing the layer the rules choose at their surface point (the input mesh's\n"
      "               attributes); inner%: the same where the fluid triangle's vertices all choose one layer\n"
      "  share%, pop% per layer: its share of the covered texels, and the popping of its texels\n"
      "Reads NAME.bake.json in DIR and the input meshes (for velocities) it names. docs/eval.md has the details.\n\n"
      "Exit codes: 0 ok, 2 bad input or usage (the message names the file), 1 internal error.");
  cmd->add_option("dir", c.dir, "Bake folder (holding NAME.bake.json) or the manifest file")->required();
  cmd->add_option("--exemplar", c.exemplar,
                  "Exemplar to compare with: an image or a shipped exemplar's name (default: the bake's; not with "
                  "exemplar layers)");
  cmd->add_option("--frames", c.frames, "Frame range A-B (default: every frame of the bake)");
  c.json = cmd->add_option("--json", c.json_path,
                           "Print JSON (per frame + summary) instead of the table, or with FILE write it there")
               ->expected(0, 1);
  c.plots = cmd->add_option("--plots", c.plots_dir,
                            "Write one PNG per metric over the frames with gnuplot into DIR (default: "
                            "DIR/NAME.eval_plots)")
                ->expected(0, 1);
  c.maps = cmd->add_option("--maps", c.maps_dir,
                           "Write a popping map per frame into DIR (default: DIR/NAME.eval_maps): NAME.popping.N.exr "
                           "in the frame's atlas layout, R popped to a newborn patch, G popped to an existing patch, B "
                           "kept, A compared")
               ->expected(0, 1);
  cmd->add_option("--min-speed", c.min_speed, "Rest threshold in m/s for drift (default: the bake's --min-speed)");
  add_global_options(*cmd);
  cmd->callback([] { run_eval(c); });
}

}  // namespace lapflow::cli
