// Subcommands of the `crease` program. Each Add*Commands registers its
// subcommands on the app; flags are parsed here only and turned into the
// libraries' Options structs (libraries never see argv).
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace crease::app {

// "KEY=VALUE" pairs (from repeatable --set flags) → a JSON object for
// SetOptionsFromJson; VALUE is parsed as JSON (numbers, booleans, lists) and
// otherwise taken as a string.
std::string SetPairsToJson(const std::vector<std::string>& pairs);

// "a,b,,c" → {"a", "b", "c"} (empty items dropped).
std::vector<std::string> SplitComma(const std::string& s);

// "WIDTHxHEIGHT" (a --size flag) → *width, *height; "" leaves them as they are.
// Errors show `example`, e.g. "640x480".
void ParseSizeFlag(const std::string& size, const std::string& example, int* width, int* height);

void AddVersionCommand(CLI::App& app);
void AddMeshCommands(CLI::App& app);
void AddRigCommands(CLI::App& app);
void AddSynthCommands(CLI::App& app);
// Adds actor, render, sequence, scans, mesh and check to the "synth" subcommand.
void AddSynthDatasetCommands(CLI::App& app);
// train (Sec. 4) and model info.
void AddTrainCommands(CLI::App& app);
// track (issue 5: the global face tracker).
void AddTrackCommand(CLI::App& app);
void AddTrainTrackerCommand(CLI::App& app);
// eval-landmarks: a landmark source against labelled faces (real photographs, renders).
void AddEvalLandmarksCommand(CLI::App& app);
// capture (Sec. 5: online capture) and eval (its metrics against ground truth), issue 6.
void AddCaptureCommands(CLI::App& app);
// experiment list|run (the runner, eval/experiment.h) and report (reports/), issue 7.
void AddExperimentCommands(CLI::App& app);

}  // namespace crease::app
