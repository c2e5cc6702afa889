// crease train-tracker — trains crease's landmark regressor (issue 5, part 1;
// pipeline/capture/shape_regressor.h, Cao et al. 2012 explicit shape regression as
// the landmark stage of the DDE-style tracker) on studio renders generated on the fly
// or read from a folder, and reports its error on held-out renders
// (pipeline/capture/tracker_training.h; the renders: eval/tracker_renders.h).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/options.h"
#include "eval/tracker_renders.h"
#include "pipeline/capture/labelled_faces.h"
#include "pipeline/capture/landmark_evaluation.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/capture/shape_regressor.h"
#include "pipeline/capture/tracker_training.h"

namespace crease::app {
namespace fs = std::filesystem;

void AddTrainTrackerCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "train-tracker", "Train the landmark regressor of the global tracker (68 iBUG points) on studio renders");
  struct Args {
    std::string rig_path, out, data, extra_data, save_data, config, report, size, sequence;
    std::vector<std::string> sets;
    int actors = -1, test_actors = -1, renders = -1;
    uint64_t seed = 1;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig) whose actors are rendered (needed unless --data is given)");
  cmd->add_option("--out,-o", a->out, "Tracker model file to write (.ctrk)")->required();
  cmd->add_option("--data", a->data,
                  "Train from a folder of NAME.png + NAME.pts (iBUG format) instead of rendering; train/ and test/ "
                  "subfolders are the split, else the last test_fraction of the names is held out");
  cmd->add_option("--extra-data", a->extra_data,
                  "With --rig: labelled faces (a folder of NAME.png + NAME.pts, its train/ subfolder if it has one, "
                  "or a dlib XML file) added to the training renders, e.g. photographs");
  cmd->add_option("--save-data", a->save_data, "Also write the generated renders (train/, test/) to this folder");
  cmd->add_option("--sequence", a->sequence,
                  "Also track a labelled folder as a video (frames in name order) and report the error");
  const TrackerTrainingOptions defaults;  // the help states the defaults it does not repeat
  cmd->add_option("--actors", a->actors, fmt::format("Training actors (default {})", defaults.train_actors));
  cmd->add_option("--test-actors", a->test_actors, fmt::format("Held-out actors (default {})", defaults.test_actors));
  cmd->add_option("--renders", a->renders, fmt::format("Renders per actor (default {})", defaults.renders_per_actor));
  cmd->add_option("--size", a->size,
                  fmt::format("Image size WIDTHxHEIGHT (default {}x{})", defaults.width, defaults.height));
  cmd->add_option("--seed", a->seed, "Seed of actors, renders, augmentation and features")->capture_default_str();
  cmd->add_option("--config", a->config,
                  "Options (YAML; keys: pipeline/capture/tracker_training.h TrackerTrainingOptions and "
                  "pipeline/capture/shape_regressor.h ShapeRegressorOptions)");
  cmd->add_option("--set", a->sets,
                  "Option KEY=VALUE (repeatable), e.g. regressor.num_stages=6 regressor.num_ferns=50 "
                  "lights=[\"front\"]");
  cmd->add_option("--report", a->report, "Report (JSON; default: <out without extension>_report.json)");
  cmd->callback([a] {
    TrackerTrainingOptions options;
    options.data_seed = a->seed;
    options.regressor.seed = a->seed;
    if (a->actors >= 0) options.train_actors = a->actors;
    if (a->test_actors >= 0) options.test_actors = a->test_actors;
    if (a->renders >= 0) options.renders_per_actor = a->renders;
    ParseSizeFlag(a->size, "320x240", &options.width, &options.height);
    if (!a->config.empty()) SetOptionsFromYaml(ReadFileToString(a->config), a->config, &options);
    if (!a->sets.empty()) SetOptionsFromJson(SetPairsToJson(a->sets), "--set", &options);
    options.Check();
    TrackerTrainingResult result;
    if (!a->data.empty()) {
      Require(a->extra_data.empty(), "train-tracker: --extra-data adds to the studio renders (--rig), not to --data");
      std::printf("training the landmark regressor on %s\n", a->data.c_str());
      result = TrainTrackerOnFolder(a->data, options);
    } else {
      Require(!a->rig_path.empty(), "train-tracker: give --rig (to render training faces) or --data (a folder)");
      const FaceRig rig = ReadRig(a->rig_path);
      std::printf("rendering %d training and %d held-out actors × %d renders at %dx%d, then training\n",
                  options.train_actors, options.test_actors, options.renders_per_actor, options.width,
                  options.height);
      std::fflush(stdout);
      std::vector<LabelledFace> extra;
      if (!a->extra_data.empty()) {
        const fs::path e(a->extra_data);
        extra = ReadLabelledFaces(fs::is_directory(e / "train") ? e / "train" : e);
        std::printf("adding %zu labelled faces from %s to the training renders\n", extra.size(), a->extra_data.c_str());
      }
      result = TrainTrackerOnRenders(rig, options, a->save_data, extra);
    }
    if (!a->sequence.empty()) {
      result.report.sequence = EvaluateSequenceTracking(result.regressor, ReadLabelledFaces(a->sequence));
    }
    SaveShapeRegressor(a->out, result.regressor);
    const fs::path report_path = TrackerReportPath(a->out, a->report);
    WriteFileAtomic(report_path, [&](std::ostream& o) { o << result.report.ToJson() << "\n"; });
    std::printf("%s", result.report.ToText().c_str());
    std::printf("wrote %s and %s\n", a->out.c_str(), report_path.string().c_str());
  });
}

void AddEvalLandmarksCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "eval-landmarks",
      "Landmark error of dlib and/or a trained regressor on labelled faces (real photographs or renders)");
  struct Args {
    std::string data, tracker, json_path, save_crops;
    bool use_dlib = false;
    double crop_scale = 2.5;
    int box_px = 100;
    uint64_t seed = 1;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--data", a->data,
                  "Labelled faces: a folder of NAME.png + NAME.pts (iBUG format) or a dlib XML file "
                  "(imglab; dlib's 300-W release and example faces)")
      ->required();
  cmd->add_option("--tracker", a->tracker, "Regressor model (from `crease train-tracker`)");
  cmd->add_flag("--dlib", a->use_dlib, "Also evaluate dlib's HOG detector + 68-point model");
  cmd->add_option("--crop-scale", a->crop_scale, "XML: crop side over the box's larger side")->capture_default_str();
  cmd->add_option("--box-px", a->box_px, "XML: the box's larger side in the crop, pixels")->capture_default_str();
  cmd->add_option("--seed", a->seed, "Seed of the regressor's perturbed initialisations")->capture_default_str();
  cmd->add_option("--save-crops", a->save_crops, "Also write the faces as read (NAME.png + NAME.pts) to this folder");
  cmd->add_option("--json", a->json_path, "Write the results (JSON)");
  cmd->callback([a] {
    Require(a->use_dlib || !a->tracker.empty(), "eval-landmarks: give --tracker T.ctrk and/or --dlib");
    const fs::path path(a->data);
    const std::vector<LabelledFace> faces = fs::is_regular_file(path) && path.extension() == ".xml"
                                                ? ReadDlibXmlFaces(path, {a->crop_scale, a->box_px})
                                                : ReadLabelledFaces(path);
    std::printf("%zu labelled faces from %s\n", faces.size(), a->data.c_str());
    if (!a->save_crops.empty()) WriteLabelledFaces(a->save_crops, faces);
    std::optional<ShapeRegressor> regressor;
    if (!a->tracker.empty()) regressor = LoadShapeRegressor(a->tracker);
    const LandmarkEvaluationReport r =
        EvaluateLandmarks(faces, a->data, a->use_dlib, regressor ? &*regressor : nullptr, a->seed);
    std::printf("%s", r.ToText().c_str());
    if (!a->json_path.empty()) {
      WriteFileAtomic(a->json_path, [&](std::ostream& o) { o << r.ToJson() << "\n"; });
      std::printf("wrote %s\n", a->json_path.c_str());
    }
  });
}

}  // namespace crease::app
