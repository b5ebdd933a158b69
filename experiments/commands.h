// Subcommands of the `artex` executable. Each Register* adds its subcommand(s) to the app;
// the callbacks throw artex::Error on bad input, which main() prints before exiting with 1.
#pragma once

#include <string>

namespace CLI {
class App;
}

namespace artex {

void RegisterTemplateCommands(CLI::App* app);  // artex template make|info|pose
void RegisterSynthCommand(CLI::App* app);      // artex synth
void RegisterTrackCommand(CLI::App* app);      // artex track
void RegisterRenderCommand(CLI::App* app);     // artex render
void RegisterExperimentCommand(CLI::App* app); // artex experiment
void RegisterImportCommand(CLI::App* app);     // artex import
void RegisterOverlayCommand(CLI::App* app);    // artex overlay
// artex experiment collect|status OUT and the Slurm tasks' hidden entry points
// (slurm_command.cc); `experiment` is the experiment subcommand.
void RegisterSlurmSubcommands(CLI::App* app, CLI::App* experiment);
// Runs scripts/plot_results.py on an experiment's output folder (prints a hint when python3
// with matplotlib is missing).
void MakeExperimentPlots(const std::string& out);
void RegisterStreamCommands(CLI::App* app);    // artex stream encode|play
void RegisterStreamServeCommand(CLI::App* stream);  // artex stream serve (the browser viewer)

}  // namespace artex
