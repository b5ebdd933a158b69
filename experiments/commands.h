// Subcommands of the `artex` executable. Each Register* adds its subcommand(s) to the app;
// the callbacks throw artex::Error on bad input, which main() prints before exiting with 1.
#pragma once

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
void RegisterStreamCommands(CLI::App* app);    // artex stream encode|play

}  // namespace artex
