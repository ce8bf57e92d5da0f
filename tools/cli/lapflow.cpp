// lapflow: deformable lapped textures on animated liquid surfaces.
// The command line: parse, validate, call the library. Exit codes: 0 ok,
// 2 bad input, usage or an output problem, 130 / 143 stopped by SIGINT /
// SIGTERM, 1 internal error.
#include <algorithm>
#include <exception>
#include <string>
#include <vector>
#include <new>

#include "cli_common.hpp"
#include "scene_file.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/bake/bake.hpp"

int main(int argc, char** argv) {
  using namespace lapflow;
  keep_freed_memory_for_reuse();  // freed frame buffers are reused (bake.hpp); large ones by large_block_new.cpp
  CLI::App app{
      "lapflow covers an animated liquid surface (a new mesh every frame plus a velocity field) with small\n"
      "deformable texture patches that ride the flow, erodes each patch where it gets too distorted, and\n"
      "bakes every frame into an EXR colour + displacement atlas and a UV mesh any renderer can load.\n"
      "Method: Gagnon, Guzman, Mould, Paquette, \"Patch Erosion for Deformable Lapped Textures on 3D\n"
      "Fluids\" (2021).",
      "lapflow"};
  app.require_subcommand(1);
  app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  app.set_version_flag("--version", "lapflow 0.1.0");
  app.footer(
      "Run 'lapflow <command> --help' for a command's options.\nExit codes: 0 ok, 2 bad input, usage or output "
      "problem (a folder or file that cannot be written, disk full), 130/143 a bake stopped by SIGINT/SIGTERM, "
      "1 internal error.");
  cli::add_demo_command(app);
  cli::add_inspect_command(app);
  cli::add_atlas_command(app);
  cli::add_patches_command(app);
  cli::add_bake_command(app);
  cli::add_track_command(app);
  cli::add_options_command(app);
  cli::add_render_command(app);
  cli::add_eval_command(app);
  cli::add_preview_command(app);
  cli::add_feature_map_command(app);
  cli::add_farm_command(app);
  if (argc == 1) {
    // A bare `lapflow`: what it is and its commands, one line each.
    fmt::print("lapflow: deformable lapped textures on animated liquid surfaces.\n\nCommands:\n");
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) {
      // The description's first clause, on one line.
      std::string d = sub->get_description();
      std::replace(d.begin(), d.end(), '\n', ' ');
      std::size_t end = d.size();
      for (const char* stop : {". ", ": ", "; "}) end = std::min(end, d.find(stop));
      d = d.substr(0, end);
      if (d.size() > 100) d = d.substr(0, std::min(d.find(" ("), d.rfind(", ", 100)));
      if (!d.empty() && d.back() == '.') d.pop_back();
      fmt::print("  {:<12} {}\n", sub->get_name(), d);
    }
    fmt::print("\nRun 'lapflow <command> --help' for a command's options, 'lapflow --help' for more.\n");
    return cli::kOk;
  }
  try {
    // `lapflow bake scene.toml [options]`: the file's keys become options
    // placed before the user's, so the command line overrides the file.
    // `lapflow farm slurm scene.toml ...` hands the scene file on to its
    // jobs as it is, and reads it itself (cmd_farm.cpp).
    std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty() || args[0] != "farm") cli::expand_scene_files(args);
    std::reverse(args.begin(), args.end());  // CLI11 takes the vector in reverse order
    app.parse(args);
  } catch (const CLI::ParseError& e) {
    // --help and --version print as CLI11 does; a parse error is one line
    // like every other error (CLI11 adds a second, and echoes the argument
    // in full, whatever its length or bytes).
    if (e.get_exit_code() == 0) return app.exit(e) == 0 ? cli::kOk : cli::kBadInput;
    cli::print_error(e.what(), " (--help lists the options)");
    return cli::kBadInput;
  } catch (const InputError& e) {
    cli::print_error(e.what());
    return cli::kBadInput;
  } catch (const UsageError& e) {
    cli::print_error(e.what());
    return cli::kBadInput;
  } catch (const OutputError& e) {
    cli::print_error(e.what());
    return cli::kBadInput;
  } catch (const Interrupted& e) {
    fmt::print(stderr, "lapflow: {}\n", printable_line(e.what()));
    return 128 + e.signal();
  } catch (const std::bad_alloc&) {
    cli::print_error("out of memory");
    return cli::kInternal;
  } catch (const std::exception& e) {
    cli::print_error(e.what());
    return cli::kInternal;
  }
  return cli::kOk;
}
