// placeholder until the 'atlas' command lands
#include "cli_common.hpp"
#include "lapflow/errors.hpp"
namespace lapflow::cli {
void add_atlas_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("atlas", "(not built yet)");
  add_global_options(*cmd);
  cmd->callback([] { throw lapflow::UsageError("'atlas' is not built yet"); });
}
}  // namespace lapflow::cli
