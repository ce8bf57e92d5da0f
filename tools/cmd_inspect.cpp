// placeholder until the 'inspect' command lands
#include "cli_common.hpp"
#include "lapflow/errors.hpp"
namespace lapflow::cli {
void add_inspect_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("inspect", "(not built yet)");
  add_global_options(*cmd);
  cmd->callback([] { throw lapflow::UsageError("'inspect' is not built yet"); });
}
}  // namespace lapflow::cli
