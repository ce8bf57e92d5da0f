// placeholder until the 'demo' command lands
#include "cli_common.hpp"
#include "lapflow/errors.hpp"
namespace lapflow::cli {
void add_demo_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "(not built yet)");
  add_global_options(*cmd);
  cmd->callback([] { throw lapflow::UsageError("'demo' is not built yet"); });
}
}  // namespace lapflow::cli
