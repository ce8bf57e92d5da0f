// `lapflow render`: atlases and UV meshes from the patch states of a tracked
// folder, any frame on its own (docs/farm.md).
#include "cli_common.hpp"
#include "option_flags.hpp"
#include "lapflow/bake/render.hpp"
#include "lapflow/core/interrupt.hpp"

namespace lapflow::cli {
namespace {

struct RenderCli {
  RenderOptions o;
  std::string frames;
  std::string exemplar, feature, displacement;
  std::vector<std::string> layers;
  bool aov = false, no_aov = false;
  bool usd = false, no_usd = false;
};

void run_render(RenderCli& c) {
  apply_global_options();
  RenderOptions& o = c.o;
  if (!c.frames.empty()) o.frames = parse_frame_range(c.frames);
  if (!c.exemplar.empty()) {
    o.exemplar_color = c.exemplar;
    o.exemplar_feature = c.feature;
    o.exemplar_displacement = c.displacement;
    resolve_exemplar_paths(o.exemplar_color, o.exemplar_feature, o.exemplar_displacement);
  } else if (!c.feature.empty() || !c.displacement.empty()) {
    throw UsageError("--feature and --displacement go with --exemplar");
  }
  for (const std::string& text : c.layers) {
    BakeOptions scratch = default_bake_options();
    set_bake_option(scratch, *find_bake_option("layer"), text);
    for (ExemplarLayer& layer : scratch.layers) {
      resolve_exemplar_paths(layer.color, layer.feature, layer.displacement);
      o.layers.push_back(layer);
    }
  }
  if (c.aov) o.aov = true;
  if (c.no_aov) o.aov = false;
  if (c.usd) o.usd = true;
  if (c.no_usd) o.usd = false;
  const StopHandlersScope stop_handlers;
  std::size_t rendered = 0, skipped = 0;
  double seconds = 0;
  render(o, [&](const RenderedFrame& f) {
    if (f.skipped) {
      ++skipped;
      info("frame {}: already rendered, skipped", f.frame);
      return;
    }
    ++rendered;
    seconds += f.stats.seconds_total;
    if (!f.reason.empty()) info("frame {}: rendered again: {}", f.frame, f.reason);
    const FrameStats& s = f.stats;
    info("frame {}: {} tris, {} patches, {}x{} atlas, coverage {:.2f}% ({} texels closed by neighbours, {} forced), "
         "{:.2f}s",
         s.frame, s.triangles, s.patches_alive, f.resolution, f.resolution, 100 * s.coverage,
         s.closed_texels, s.forced_texels, s.seconds_total);
  });
  info("done: {} frames rendered in {:.1f} s{}, peak memory {:.0f} MiB", rendered, seconds,
       skipped ? fmt::format(", {} already there", skipped) : "", peak_rss_mb());
}

}  // namespace

void add_render_command(CLI::App& app) {
  static RenderCli c;
  CLI::App* cmd = app.add_subcommand("render", "Atlases and UV meshes from the patch states of a tracked folder");
  cmd->description(
      "Renders frames of a folder that `lapflow track` (or `lapflow bake`) wrote: for each frame asked for whose\n"
      "NAME.state.N.bin exists, reads its mesh again, builds its atlas and rasterizes the frame's patches into\n"
      "NAME.color.N.exr, NAME.disp.N.exr (NAME.aov.N.exr with --aov) and NAME.N.obj + .mtl, renamed into place\n"
      "together, the OBJ last. Frames are independent: run any range anywhere, in any order, at once. No patch is\n"
      "born: holes finer than a tracking texel are closed by their neighbours (counted). The output options\n"
      "default to the manifest's; another --resolution gives the same patches, and another --exemplar with the\n"
      "same feature map the same animation. Each frame's NAME.render.N.json records what it was made with; the\n"
      "tracked NAME.bake.json is never rewritten (another --out gets a copy). A frame is written under its lock\n"
      "(.NAME.N.lock): renders of the same options share a range, one with other options is refused.\n\n"
      "Exit codes: 0 ok, 2 bad input (the message names the file: a missing or damaged state, a feature map\n"
      "other than the tracked one), usage or output problem, 130 / 143 stopped by SIGINT / SIGTERM, 1 internal.");
  cmd->add_option("dir", c.o.dir, "The tracked folder (NAME.bake.json and NAME.state.N.bin)")->required();
  cmd->add_option("--name", c.o.name, "The bake's NAME when the folder holds several")->group("Input");
  cmd->add_option("--frames", c.frames, "Frame range C-D (default: every frame of the manifest)")->group("Input");
  // The output options of the bake's table, defaulting to the manifest's.
  add_table_flag(*cmd, "resolution", [](const std::string& t) { c.o.resolution = std::stoi(t); },
                 "(default: the manifest's)")
      ->check(CLI::Range(16, 32768));
  add_table_flag(*cmd, "exemplar", [](const std::string& t) { c.exemplar = t; },
                 "(default: the manifest's). Its feature map must be the tracked one");
  add_table_flag(*cmd, "feature", [](const std::string& t) { c.feature = t; }, "(with --exemplar)");
  cmd->add_option("--layer", c.layers,
                  "A tracked layer's exemplar swapped, NAME=COLOR[,FEATURE[,DISP]] (repeatable; its feature map "
                  "must be the tracked one)")
      ->type_name("NAME=FILES")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->allow_extra_args(false)
      ->group("Exemplar");
  add_table_flag(*cmd, "displacement", [](const std::string& t) { c.displacement = t; }, "(with --exemplar)");
  cmd->add_option("--out", c.o.out_dir, "Output folder (default: the tracked folder)")->group("Output");
  add_table_flag(*cmd, "aov", [](const std::string& t) { c.aov = t == "true"; }, "(default: as the manifest says)");
  cmd->add_flag("--no-aov", c.no_aov, "Do not write NAME.aov.N.exr")->group("Output");
  add_table_flag(*cmd, "texture", [](const std::string& t) { c.o.texture = t; }, "(default: the manifest's)");
  add_table_flag(*cmd, "usd", [](const std::string& t) { c.usd = t == "true"; }, "(default: as the manifest says)");
  cmd->add_flag("--no-usd", c.no_usd, "Do not write the USD layers and stage")->group("Output");
  add_table_flag(*cmd, "up-axis", [](const std::string& t) { c.o.up_axis = t == "y" ? 'Y' : 'Z'; },
                 "(default: the manifest's)");
  cmd->add_flag("--skip-done", c.o.skip_done,
                "Skip a frame already in --out whose NAME.render.N.json says it was made from the same patches with "
                "the same options and whose files are whole (a re-submitted farm job); render any other again, "
                "saying why")
      ->group("Output");
  cmd->add_flag("--no-rerender", c.o.refuse_other_options,
                "With --skip-done: a frame already there made with other options is an error (exit 2), not "
                "rendered again")
      ->group("Output");
  cmd->add_flag("--allow-changed-input", c.o.allow_changed_input,
                "Render a frame whose mesh file changed since it was tracked (its size or CRC-32 is not its "
                "state's); by default that is an error naming the mesh")
      ->group("Input");
  add_max_memory_option(*cmd, c.o.max_memory, "The render's memory estimate must fit")->group("Limits");
  add_global_options(*cmd);
  cmd->callback([] { run_render(c); });
}

}  // namespace lapflow::cli
