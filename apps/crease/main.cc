// crease — real-time high-fidelity facial performance capture (Cao et al. 2015),
// the synthetic studio and the evaluator, as one program with subcommands.
#include <cstdio>
#include <exception>
#include <fmt/format.h>

#include "apps/crease/commands.h"
#include "core/allocator.h"
#include "core/error.h"

int main(int argc, char** argv) {
  crease::KeepLargeBlocksInHeap();  // fewer page faults in frame loops (core/allocator.h)
  CLI::App app{"crease — a research harness for real-time high-fidelity facial performance capture\n"
               "(Cao, Bradley, Zhou and Beeler, SIGGRAPH 2015). Units are millimetres."};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Show help for all subcommands");
  crease::app::AddVersionCommand(app);
  crease::app::AddMeshCommands(app);
  crease::app::AddRigCommands(app);
  crease::app::AddSynthCommands(app);
  crease::app::AddSynthDatasetCommands(app);
  crease::app::AddTrainCommands(app);
  crease::app::AddTrackCommand(app);
  crease::app::AddTrainTrackerCommand(app);
  crease::app::AddEvalLandmarksCommand(app);
  crease::app::AddCaptureCommands(app);
  crease::app::AddExperimentCommands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const crease::Error& e) {
    std::fprintf(stderr, "crease: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "crease: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
