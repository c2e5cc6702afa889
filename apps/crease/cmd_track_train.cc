// crease train-tracker — trains crease's landmark regressor (issue 5, part 1;
// pipeline/capture/shape_regressor.h, Cao et al. 2012 explicit shape regression as
// the landmark stage of the DDE-style tracker) on studio renders generated on the fly
// or read from a folder, and reports its error on held-out renders
// (eval/tracker_training.h).
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/options.h"
#include "core/json_io.h"
#include "eval/tracker_training.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease::app {
namespace fs = std::filesystem;

void AddTrainTrackerCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "train-tracker", "Train the landmark regressor of the global tracker (68 iBUG points) on studio renders");
  static std::string rig_path, out, data, extra_data, save_data, config, report, size, sequence;
  static std::vector<std::string> sets;
  static int actors = -1, test_actors = -1, renders = -1;
  static uint64_t seed = 1;
  cmd->add_option("--rig", rig_path, "Rig (.crig) whose actors are rendered (needed unless --data is given)");
  cmd->add_option("--out,-o", out, "Tracker model file to write (.ctrk)")->required();
  cmd->add_option("--data", data,
                  "Train from a folder of NAME.png + NAME.pts (iBUG format) instead of rendering; train/ and test/ "
                  "subfolders are the split, else the last test_fraction of the names is held out");
  cmd->add_option("--extra-data", extra_data,
                  "With --rig: labelled faces (a folder of NAME.png + NAME.pts, its train/ subfolder if it has one, "
                  "or a dlib XML file) added to the training renders, e.g. photographs");
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
  cmd->add_option("--set", sets, "Option KEY=VALUE (repeatable), e.g. regressor.num_stages=6 regressor.num_ferns=50 lights=[\"front\"]");
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
      Require(extra_data.empty(), "train-tracker: --extra-data adds to the studio renders (--rig), not to --data");
      std::printf("training the landmark regressor on %s\n", data.c_str());
      result = TrainTrackerOnFolder(data, options);
    } else {
      Require(!rig_path.empty(), "train-tracker: give --rig (to render training faces) or --data (a folder)");
      const FaceRig rig = ReadRig(rig_path);
      std::printf("rendering %d training and %d held-out actors × %d renders at %dx%d, then training\n",
                  options.train_actors, options.test_actors, options.renders_per_actor, options.width,
                  options.height);
      std::fflush(stdout);
      std::vector<LabelledFace> extra;
      if (!extra_data.empty()) {
        const fs::path e(extra_data);
        extra = ReadLabelledFaces(fs::is_directory(e / "train") ? e / "train" : e);
        std::printf("adding %zu labelled faces from %s to the training renders\n", extra.size(), extra_data.c_str());
      }
      result = TrainTrackerOnRenders(rig, options, save_data, extra);
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

void AddEvalLandmarksCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "eval-landmarks",
      "Landmark error of dlib and/or a trained regressor on labelled faces (real photographs or renders)");
  static std::string data, tracker, json_path, save_crops;
  static bool use_dlib = false;
  static double crop_scale = 2.5;
  static int box_px = 100;
  static uint64_t seed = 1;
  cmd->add_option("--data", data,
                  "Labelled faces: a folder of NAME.png + NAME.pts (iBUG format) or a dlib XML file "
                  "(imglab; dlib's 300-W release and example faces)")
      ->required();
  cmd->add_option("--tracker", tracker, "Regressor model (from `crease train-tracker`)");
  cmd->add_flag("--dlib", use_dlib, "Also evaluate dlib's HOG detector + 68-point model");
  cmd->add_option("--crop-scale", crop_scale, "XML: crop side over the box's larger side")->capture_default_str();
  cmd->add_option("--box-px", box_px, "XML: the box's larger side in the crop, pixels")->capture_default_str();
  cmd->add_option("--seed", seed, "Seed of the regressor's perturbed initialisations")->capture_default_str();
  cmd->add_option("--save-crops", save_crops, "Also write the faces as read (NAME.png + NAME.pts) to this folder");
  cmd->add_option("--json", json_path, "Write the results (JSON)");
  cmd->callback([] {
    Require(use_dlib || !tracker.empty(), "eval-landmarks: give --tracker T.ctrk and/or --dlib");
    const fs::path path(data);
    const std::vector<LabelledFace> faces = fs::is_regular_file(path) && path.extension() == ".xml"
                                                ? ReadDlibXmlFaces(path, {crop_scale, box_px})
                                                : ReadLabelledFaces(path);
    std::printf("%zu labelled faces from %s\n", faces.size(), data.c_str());
    if (!save_crops.empty()) WriteLabelledFaces(save_crops, faces);
    nlohmann::json out;
    out["data"] = data;
    out["faces"] = faces.size();
    auto report = [&](const LandmarkSourceEvaluation& e) {
      std::printf("%-10s cold start (detector, then landmarks): found %d of %d faces; error %.3f IOD (%.2f px) on "
                  "those; %.1f ms per face\n",
                  e.source.c_str(), e.found, e.faces, e.error_iod, e.error_px, e.ms_per_face);
      out[e.source] = {{"faces", e.faces},         {"found", e.found},          {"error_iod", e.error_iod},
                       {"error_px", e.error_px}, {"ms_per_face", e.ms_per_face}};
    };
    if (use_dlib) {
      DlibLandmarkSource dlib;
      report(EvaluateLandmarkSource(dlib, faces));
    }
    if (!tracker.empty()) {
      const ShapeRegressor regressor = LoadShapeRegressor(tracker);
      RegressorLandmarkSource source(regressor);
      report(EvaluateLandmarkSource(source, faces));
      // Without the detector: from the truth under a random similarity (a tracker's
      // previous frame) and from the mean shape in the truth's jittered box.
      TrackerTrainingReport r;
      EvaluateShapeRegressor(regressor, faces, seed, /*detector_frames=*/0, &r);
      std::printf("regressor  from the perturbed truth: %.3f -> %.3f IOD (%.2f -> %.2f px); from a jittered box: "
                  "%.3f -> %.3f IOD (%.2f -> %.2f px)\n",
                  r.tracking.initial_iod, r.tracking.final_iod, r.tracking.initial_px, r.tracking.final_px,
                  r.box.initial_iod, r.box.final_iod, r.box.initial_px, r.box.final_px);
      out["regressor_tracking_init"] = {{"initial_iod", r.tracking.initial_iod}, {"final_iod", r.tracking.final_iod},
                                        {"initial_px", r.tracking.initial_px}, {"final_px", r.tracking.final_px}};
      out["regressor_box_init"] = {{"initial_iod", r.box.initial_iod}, {"final_iod", r.box.final_iod},
                                   {"initial_px", r.box.initial_px}, {"final_px", r.box.final_px}};
    }
    if (!json_path.empty()) {
      WriteJsonFile(json_path, out);
      std::printf("wrote %s\n", json_path.c_str());
    }
  });
}

}  // namespace crease::app
