// placeholder until the 'patches' command lands
#include "cli_common.hpp"
#include "lapflow/errors.hpp"
namespace lapflow::cli {
void add_patches_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("patches", "(not built yet)");
  add_global_options(*cmd);
  cmd->callback([] { throw lapflow::UsageError("'patches' is not built yet"); });
}
}  // namespace lapflow::cli
