// `lapflow feature-map`: being written (issue 6). Not registered as done.
#include "cli_common.hpp"

namespace lapflow::cli {

void add_feature_map_command(CLI::App& app) { (void)app; }

}  // namespace lapflow::cli
