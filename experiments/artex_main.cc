// The `artex` command-line tool: one subcommand per pipeline stage.
#include <cstdio>
#include <exception>
#include <functional>
#include <string>

#include <CLI/CLI.hpp>

#include "experiments/commands.h"
#include "experiments/heap_retention.h"
#include "experiments/runner.h"
#include "models/error.h"

int main(int argc, char** argv) {
  artex::RememberProgramArguments(argv);  // pipeline.huge_pages (experiments/heap_retention.h)
  CLI::App app{"artex: articulated 3D model tracking with on-the-fly texturing"};
  app.require_subcommand(1);
  // "artex 0.1.0 (<git revision of the source tree>)"; --version works without a subcommand.
  // Asked of git only when --version is given (every other start would run it, twice when
  // `artex track` restarts itself for pipeline.huge_pages).
  app.set_version_flag(
      "--version",
      std::function<std::string()>([] {
        return std::string("artex ") + ARTEX_VERSION + " (" + artex::SourceRevision() + ")";
      }),
      "print the version and the source revision, then exit");
  artex::RegisterTemplateCommands(&app);
  artex::RegisterSynthCommand(&app);
  artex::RegisterTrackCommand(&app);
  artex::RegisterRenderCommand(&app);
  artex::RegisterExperimentCommand(&app);
  artex::RegisterImportCommand(&app);
  artex::RegisterOverlayCommand(&app);
  artex::RegisterStreamCommands(&app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const artex::Error& e) {
    std::fprintf(stderr, "artex: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "artex: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
