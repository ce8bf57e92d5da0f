// placeholder until the 'bake' command lands
#include "cli_common.hpp"
#include "lapflow/errors.hpp"
namespace lapflow::cli {
void add_bake_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("bake", "(not built yet)");
  add_global_options(*cmd);
  cmd->callback([] { throw lapflow::UsageError("'bake' is not built yet"); });
}
}  // namespace lapflow::cli
