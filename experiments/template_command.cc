// placeholder until the subcommand is implemented
#include <CLI/CLI.hpp>

#include "experiments/commands.h"

namespace artex {
void RegisterTemplateCommands(CLI::App* app) { (void)app; }
}  // namespace artex
