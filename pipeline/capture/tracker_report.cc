// TrackerTrainingReport's and LandmarkEvaluationReport's text and JSON
// (pipeline/capture/tracker_training.h): formatting only, kept apart from the
// training and the evaluation.
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "pipeline/capture/tracker_training.h"

namespace crease {

namespace {

// One row of the held-out table.
std::string StatsRow(const char* label, const LandmarkErrorStats& e) {
  return fmt::format("  {:<34} {:>10.4f} {:>10.4f} {:>10.2f} {:>10.2f}\n", label, e.initial_iod, e.final_iod,
                     e.initial_px, e.final_px);
}

nlohmann::json StatsJson(const LandmarkErrorStats& e) {
  return nlohmann::json{{"frames", e.frames},         {"initial_iod", e.initial_iod}, {"final_iod", e.final_iod},
                        {"initial_px", e.initial_px}, {"final_px", e.final_px}};
}

}  // namespace

std::string TrackerTrainingReport::ToText() const {
  const ShapeRegressorTrainingReport& t = training.regressor;
  const LandmarkSourceEvaluation& d = held_out.detector;
  std::string s;
  s += fmt::format("training: {} images, {} samples (with augmentation), {:.1f} s; data {:.1f} s\n", train_images,
                   t.num_samples, t.seconds, data_seconds);
  s += "training error / IOD by stage:";
  for (double e : t.train_error_iod) s += fmt::format(" {:.3f}", e);
  s += fmt::format("\nmean |corr| of selected pixel pairs: {:.3f}\n", t.mean_abs_correlation);
  s += fmt::format("held-out ({} images), mean point-to-point error over 68 points:\n", test_images);
  s += fmt::format("  {:<34} {:>10} {:>10} {:>10} {:>10}\n", "initialisation", "init/IOD", "final/IOD", "init px",
                   "final px");
  s += StatsRow("tracking (perturbed truth)", held_out.tracking);
  s += StatsRow("box (mean shape in jittered box)", held_out.box);
  if (d.faces > 0) {
    s += fmt::format("  detector start (HOG box + cascade): found {}/{}, error {:.4f} IOD, {:.2f} px\n", d.found,
                     d.faces, d.error_iod, d.error_px);
  }
  const Eigen::Vector3d& b = training.detector_box;
  s += fmt::format("detector box → landmark box, from {} training detections: centre {:+.3f}, {:+.3f} sides, side × {:.3f}\n",
                   training.detector_calibration_faces, b.x(), b.y(), b.z());
  if (sequence.frames > 0) {
    s += fmt::format("sequence ({} frames, tracked from the previous frame): found {}, detector runs {}, error {:.4f} "
                     "IOD, {:.2f} px, {:.3f} ms per tracked frame\n",
                     sequence.frames, sequence.found, sequence.detections, sequence.error_iod, sequence.error_px,
                     sequence.track_ms);
  }
  s += fmt::format("Predict: {:.3f} ms per image (one thread); total {:.1f} s\n", held_out.predict_ms, seconds);
  return s;
}

std::string TrackerTrainingReport::ToJson() const {
  const ShapeRegressorTrainingReport& t = training.regressor;
  const LandmarkSourceEvaluation& d = held_out.detector;
  nlohmann::json j;
  j["train_images"] = train_images;
  j["test_images"] = test_images;
  j["train_samples"] = t.num_samples;
  j["train_error_iod_by_stage"] = t.train_error_iod;
  j["mean_abs_correlation"] = t.mean_abs_correlation;
  j["train_seconds"] = t.seconds;
  j["data_seconds"] = data_seconds;
  j["held_out_tracking"] = StatsJson(held_out.tracking);
  j["held_out_box"] = StatsJson(held_out.box);
  j["held_out_detector"] = {{"frames", d.faces}, {"found", d.found}, {"error_iod", d.error_iod}, {"error_px", d.error_px}};
  j["predict_ms"] = held_out.predict_ms;
  j["detector_box"] = {{"faces", training.detector_calibration_faces},
                       {"offset_x", training.detector_box.x()},
                       {"offset_y", training.detector_box.y()},
                       {"side_ratio", training.detector_box.z()}};
  if (sequence.frames > 0) {
    j["sequence"] = {{"frames", sequence.frames},         {"found", sequence.found},
                     {"detections", sequence.detections}, {"error_iod", sequence.error_iod},
                     {"error_px", sequence.error_px},     {"track_ms", sequence.track_ms}};
  }
  j["seconds"] = seconds;
  return j.dump(2);
}

namespace {

// The initial and final errors of one initialisation (without the frame count).
nlohmann::json InitJson(const LandmarkErrorStats& e) {
  return nlohmann::json{{"initial_iod", e.initial_iod}, {"final_iod", e.final_iod}, {"initial_px", e.initial_px},
                        {"final_px", e.final_px}};
}

}  // namespace

std::string LandmarkEvaluationReport::ToText() const {
  std::string s;
  for (const LandmarkSourceEvaluation& e : sources) {
    s += fmt::format("{:<10} cold start (detector, then landmarks): found {} of {} faces; error {:.3f} IOD ({:.2f} px) "
                     "on those; {:.1f} ms per face\n",
                     e.source, e.found, e.faces, e.error_iod, e.error_px, e.ms_per_face);
  }
  if (has_regressor) {
    const LandmarkErrorStats &t = regressor.tracking, &b = regressor.box;
    s += fmt::format("regressor  from the perturbed truth: {:.3f} -> {:.3f} IOD ({:.2f} -> {:.2f} px); from a jittered "
                     "box: {:.3f} -> {:.3f} IOD ({:.2f} -> {:.2f} px)\n",
                     t.initial_iod, t.final_iod, t.initial_px, t.final_px, b.initial_iod, b.final_iod, b.initial_px,
                     b.final_px);
  }
  return s;
}

std::string LandmarkEvaluationReport::ToJson() const {
  nlohmann::json j;
  j["data"] = data;
  j["faces"] = faces;
  for (const LandmarkSourceEvaluation& e : sources) {
    j[e.source] = {{"faces", e.faces},       {"found", e.found},          {"error_iod", e.error_iod},
                   {"error_px", e.error_px}, {"ms_per_face", e.ms_per_face}};
  }
  if (has_regressor) {
    j["regressor_tracking_init"] = InitJson(regressor.tracking);
    j["regressor_box_init"] = InitJson(regressor.box);
  }
  return j.dump(2);
}

}  // namespace crease
