// crease train-tracker — trains crease's landmark regressor (issue 5, part 1;
// pipeline/capture/shape_regressor.h, Cao et al. 2012 explicit shape regression as
// the landmark stage of the DDE-style tracker) on studio renders generated on the fly
// or read from a folder, and reports its error on held-out renders
// (eval/tracker_training.h).
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/options.h"
#include "eval/tracker_training.h"

namespace crease::app {
namespace fs = std::filesystem;

void AddTrainTrackerCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "train-tracker", "Train the landmark regressor of the global tracker (68 iBUG points) on studio renders");
  static std::string rig_path, out, data, save_data, config, report, size, sequence;
  static std::vector<std::string> sets;
  static int actors = -1, test_actors = -1, renders = -1;
  static uint64_t seed = 1;
  cmd->add_option("--rig", rig_path, "Rig (.crig) whose actors are rendered (needed unless --data is given)");
  cmd->add_option("--out,-o", out, "Tracker model file to write (.ctrk)")->required();
  cmd->add_option("--data", data,
                  "Train from a folder of NAME.png + NAME.pts (iBUG format) instead of rendering; train/ and test/ "
                  "subfolders are the split, else the last test_fraction of the names is held out");
  cmd->add_option("--save-data", save_data, "Also write the generated renders (train/, test/) to this folder");
  cmd->add_option("--sequence", sequence,
                  "Also track a labelled folder as a video (frames in name order) and report the error");
  cmd->add_option("--actors", actors, "Training actors (default 12)");
  cmd->add_option("--test-actors", test_actors, "Held-out actors (default 3)");
  cmd->add_option("--renders", renders, "Renders per actor (default 40)");
  cmd->add_option("--size", size, "Image size WIDTHxHEIGHT (default 320x240)");
  cmd->add_option("--seed", seed, "Seed of actors, renders, augmentation and features")->capture_default_str();
  cmd->add_option("--config", config,
                  "Options (YAML; keys: eval/tracker_training.h TrackerTrainingOptions and "
                  "pipeline/capture/shape_regressor.h ShapeRegressorOptions)");
  cmd->add_option("--set", sets, "Option KEY=VALUE (repeatable), e.g. num_stages=6 num_ferns=50 lights=[\"front\"]");
  cmd->add_option("--report", report, "Report (JSON; default: <out without extension>_report.json)");
  cmd->callback([] {
    TrackerTrainingOptions options;
    options.data_seed = seed;
    options.regressor.seed = seed;
    if (actors >= 0) options.train_actors = actors;
    if (test_actors >= 0) options.test_actors = test_actors;
    if (renders >= 0) options.renders_per_actor = renders;
    if (!size.empty()) {
      const auto x = size.find('x');
      try {
        if (x == std::string::npos) throw std::invalid_argument("no x");
        options.width = std::stoi(size.substr(0, x));
        options.height = std::stoi(size.substr(x + 1));
      } catch (const std::exception&) {
        throw Error(fmt::format("--size '{}': expected WIDTHxHEIGHT, e.g. 320x240", size));
      }
    }
    if (!config.empty()) SetOptionsFromYaml(ReadFileToString(config), config, &options);
    if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &options);
    options.Check();
    TrackerTrainingResult result;
    if (!data.empty()) {
      std::printf("training the landmark regressor on %s\n", data.c_str());
      result = TrainTrackerOnFolder(data, options);
    } else {
      Require(!rig_path.empty(), "train-tracker: give --rig (to render training faces) or --data (a folder)");
      const FaceRig rig = ReadRig(rig_path);
      std::printf("rendering %d training and %d held-out actors × %d renders at %dx%d, then training\n",
                  options.train_actors, options.test_actors, options.renders_per_actor, options.width,
                  options.height);
      std::fflush(stdout);
      result = TrainTrackerOnRenders(rig, options, save_data);
    }
    if (!sequence.empty()) EvaluateSequenceTracking(result.regressor, ReadLabelledFaces(sequence), &result.report);
    SaveShapeRegressor(out, result.regressor);
    const fs::path out_path(out);
    const fs::path report_path =
        report.empty() ? out_path.parent_path() / (out_path.stem().string() + "_report.json") : fs::path(report);
    WriteFileAtomic(report_path, [&](std::ostream& o) { o << result.report.ToJson() << "\n"; });
    std::printf("%s", result.report.ToText().c_str());
    std::printf("wrote %s and %s\n", out.c_str(), report_path.string().c_str());
  });
}

}  // namespace crease::app
