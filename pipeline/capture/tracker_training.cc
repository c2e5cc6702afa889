#include "pipeline/capture/tracker_training.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <fmt/format.h>

#include "core/error.h"
#include "core/timer.h"

namespace crease {

namespace fs = std::filesystem;

void TrackerTrainingOptions::VisitFields(OptionVisitor& v) {
  v.Field("train_actors", train_actors);
  v.Field("test_actors", test_actors);
  v.Field("renders_per_actor", renders_per_actor);
  v.Field("data_seed", data_seed);
  v.Field("width", width);
  v.Field("height", height);
  v.Field("fov_deg", fov_deg);
  v.Field("max_yaw_deg", max_yaw_deg);
  v.Field("max_pitch_deg", max_pitch_deg);
  v.Field("max_roll_deg", max_roll_deg);
  v.Field("max_shift_mm", max_shift_mm);
  v.Field("max_depth_mm", max_depth_mm);
  v.Field("max_active_expressions", max_active_expressions);
  v.Field("extreme_probability", extreme_probability);
  v.Field("lights", lights);
  v.Field("exposure_min", exposure_min);
  v.Field("exposure_max", exposure_max);
  v.Field("full_well_min", full_well_min);
  v.Field("full_well_max", full_well_max);
  v.Field("jpeg_probability", jpeg_probability);
  v.Field("actor_resolution", actor_resolution);
  v.Field("test_fraction", test_fraction);
  v.Field("max_detector_tests", max_detector_tests);
  v.Section("regressor", regressor);
}

void TrackerTrainingOptions::Check() const {
  const char* o = "TrackerTrainingOptions";
  CheckGe(o, "train_actors", train_actors, 1);
  CheckGe(o, "test_actors", test_actors, 1);
  CheckGe(o, "renders_per_actor", renders_per_actor, 1);
  CheckGe(o, "width", width, 32);
  CheckGe(o, "height", height, 32);
  CheckGt(o, "fov_deg", fov_deg, 1.0);
  CheckLt(o, "fov_deg", fov_deg, 170.0);
  CheckGe(o, "max_yaw_deg", max_yaw_deg, 0.0);
  CheckLe(o, "max_yaw_deg", max_yaw_deg, 80.0);
  CheckGe(o, "max_pitch_deg", max_pitch_deg, 0.0);
  CheckLe(o, "max_pitch_deg", max_pitch_deg, 60.0);
  CheckGe(o, "max_roll_deg", max_roll_deg, 0.0);
  CheckLe(o, "max_roll_deg", max_roll_deg, 90.0);
  CheckGe(o, "max_shift_mm", max_shift_mm, 0.0);
  CheckGe(o, "max_depth_mm", max_depth_mm, 0.0);
  CheckLt(o, "max_depth_mm", max_depth_mm, 300.0);
  CheckGe(o, "max_active_expressions", max_active_expressions, 0);
  CheckGe(o, "extreme_probability", extreme_probability, 0.0);
  CheckLe(o, "extreme_probability", extreme_probability, 1.0);
  Require(!lights.empty(), "TrackerTrainingOptions.lights must not be empty");
  CheckGt(o, "exposure_min", exposure_min, 0.0);
  CheckGe(o, "exposure_max", exposure_max, exposure_min);
  CheckGt(o, "full_well_min", full_well_min, 0.0);
  CheckGe(o, "full_well_max", full_well_max, full_well_min);
  CheckGe(o, "jpeg_probability", jpeg_probability, 0.0);
  CheckLe(o, "jpeg_probability", jpeg_probability, 1.0);
  CheckGe(o, "actor_resolution", actor_resolution, 64);
  CheckGt(o, "test_fraction", test_fraction, 0.0);
  CheckLt(o, "test_fraction", test_fraction, 1.0);
  CheckGe(o, "max_detector_tests", max_detector_tests, 0);
  regressor.Check();
}

TrainedTracker TrainTrackerOnFaces(const std::vector<LabelledFace>& train, const TrackerTrainingOptions& options) {
  options.Check();
  Require(!train.empty(), "tracker training: the training set must not be empty");
  const ScopedTimer timer(nullptr, "");
  std::vector<cv::Mat> images;
  std::vector<MatX2d> shapes;
  for (const LabelledFace& f : train) {
    images.push_back(f.image);
    shapes.push_back(f.landmarks);
  }
  ShapeRegressorTrainingResult trained = TrainShapeRegressor(images, shapes, options.regressor);
  TrainedTracker out;
  out.regressor = std::move(trained.regressor);
  out.summary.train_images = static_cast<int>(train.size());
  out.summary.regressor = trained.report;
  out.summary.detector_calibration_faces = CalibrateDetectorBox(&out.regressor, images, shapes);
  out.summary.detector_box = out.regressor.detector_box;
  out.summary.seconds = timer.Elapsed();
  return out;
}

LabelledSplit ReadLabelledSplit(const fs::path& folder, double test_fraction) {
  LabelledSplit split;
  if (fs::is_directory(folder / "train") && fs::is_directory(folder / "test")) {
    split.train = ReadLabelledFaces(folder / "train");
    split.test = ReadLabelledFaces(folder / "test");
    return split;
  }
  std::vector<LabelledFace> all = ReadLabelledFaces(folder);
  Require(all.size() >= 2, fmt::format("{}: need at least two labelled faces to hold some out", folder.string()));
  const size_t n_test =
      std::clamp<size_t>(static_cast<size_t>(std::lround(test_fraction * all.size())), 1, all.size() - 1);
  split.test.assign(std::make_move_iterator(all.end() - n_test), std::make_move_iterator(all.end()));
  all.resize(all.size() - n_test);
  split.train = std::move(all);
  return split;
}

TrackerTrainingResult TrainAndEvaluateTracker(const std::vector<LabelledFace>& train,
                                              const std::vector<LabelledFace>& test,
                                              const TrackerTrainingOptions& options) {
  options.Check();
  Require(!train.empty() && !test.empty(), "tracker training: the training and held-out sets must not be empty");
  const ScopedTimer timer(nullptr, "");
  TrainedTracker trained = TrainTrackerOnFaces(train, options);
  TrackerTrainingResult result;
  result.regressor = std::move(trained.regressor);
  result.report.train_images = static_cast<int>(train.size());
  result.report.test_images = static_cast<int>(test.size());
  result.report.training = trained.summary;
  result.report.held_out =
      EvaluateShapeRegressor(result.regressor, test, options.data_seed + 7777, options.max_detector_tests);
  result.report.seconds = timer.Elapsed();
  return result;
}

TrackerTrainingResult TrainTrackerOnFolder(const fs::path& folder, const TrackerTrainingOptions& options) {
  options.Check();
  const ScopedTimer timer(nullptr, "");
  const LabelledSplit split = ReadLabelledSplit(folder, options.test_fraction);
  const double data_s = timer.Elapsed();
  TrackerTrainingResult r = TrainAndEvaluateTracker(split.train, split.test, options);
  r.report.data_seconds = data_s;
  r.report.seconds = timer.Elapsed();
  return r;
}

fs::path TrackerReportPath(const fs::path& out, const fs::path& report) {
  return report.empty() ? out.parent_path() / (out.stem().string() + "_report.json") : report;
}

LandmarkEvaluationReport EvaluateLandmarks(const std::vector<LabelledFace>& faces, const std::string& data, bool dlib,
                                           const ShapeRegressor* regressor, uint64_t seed) {
  LandmarkEvaluationReport r;
  r.data = data;
  r.faces = static_cast<int>(faces.size());
  if (dlib) {
    DlibLandmarkSource source;
    r.sources.push_back(EvaluateLandmarkSource(source, faces));
  }
  if (regressor) {
    RegressorLandmarkSource source(*regressor);
    r.sources.push_back(EvaluateLandmarkSource(source, faces));
    // Without the detector: from the truth under a random similarity (a tracker's
    // previous frame) and from the mean shape in the truth's jittered box.
    r.has_regressor = true;
    r.regressor = EvaluateShapeRegressor(*regressor, faces, seed, /*detector_frames=*/0);
  }
  return r;
}

}  // namespace crease
