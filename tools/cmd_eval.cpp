// `lapflow eval`: being written (issue 6). Not registered as done.
#include "cli_common.hpp"

namespace lapflow::cli {

void add_eval_command(CLI::App& app) { (void)app; }

}  // namespace lapflow::cli
