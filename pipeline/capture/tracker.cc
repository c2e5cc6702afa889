#include "pipeline/capture/tracker.h"

#include <chrono>
#include <cmath>
#include <fmt/format.h>

#include "core/error.h"
#include "core/ibug.h"
#include "core/options.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease {

void TrackerOptions::VisitFields(OptionVisitor& v) {
  v.Field("landmark_source", landmark_source);
  v.Field("tracker_model", tracker_model);
  v.Field("min_confidence", min_confidence);
  v.Field("confidence_scale_iod", confidence_scale_iod);
  v.Field("init_from_fit", init_from_fit);
  v.Section("fit", fit);
  v.Section("dlib", dlib);
}

void TrackerOptions::Check() const {
  const char* o = "TrackerOptions";
  CheckGe(o, "min_confidence", min_confidence, 0.0);
  CheckLt(o, "min_confidence", min_confidence, 1.0);
  CheckGt(o, "confidence_scale_iod", confidence_scale_iod, 0.0);
  Require(landmark_source != LandmarkSourceKind::kRegressor || !tracker_model.empty(),
          "TrackerOptions.tracker_model: the regressor needs a model file (`crease train-tracker`)");
  fit.Check();
  dlib.Check();
}

std::unique_ptr<LandmarkSource> MakeLandmarkSource(const TrackerOptions& options) {
  options.Check();
  if (options.landmark_source == LandmarkSourceKind::kDlib) return std::make_unique<DlibLandmarkSource>(options.dlib);
  return std::make_unique<RegressorLandmarkSource>(LoadShapeRegressor(options.tracker_model));
}

FaceTracker::FaceTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics,
                         std::unique_ptr<LandmarkSource> source, const TrackerOptions& options)
    : options_(options), source_(std::move(source)), fitter_(rig, intrinsics, options.fit) {
  options_.Check();
  Require(source_ != nullptr, "FaceTracker: no landmark source");
}

void FaceTracker::Reset() {
  source_->Reset();
  fitter_.Reset();
}

TrackedFrame FaceTracker::Track(const cv::Mat& frame) {
  using Clock = std::chrono::steady_clock;
  TrackedFrame out;
  out.frame = next_frame_++;
  const auto t0 = Clock::now();
  const LandmarkResult lm = source_->Track(frame);
  const auto t1 = Clock::now();
  out.landmarks_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  out.detected = lm.detected;
  if (!lm.found || lm.points.rows() != LandmarkRigFitter::kNumLandmarks) {
    fitter_.Reset();  // lost: the next found face re-initialises the pose
    return out;
  }
  out.landmarks = lm.points;
  out.fit = fitter_.Fit(lm.points);
  out.fit_ms = std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
  // Confidence from how well the rig explains the landmarks, relative to the
  // face's size (inter-ocular distance: outer eye corners, iBUG 37 and 46).
  const double iod = InterOcularDistance(lm.points);
  const double s = options_.confidence_scale_iod * std::max(iod, 1.0);
  out.confidence = std::exp(-0.5 * (out.fit.rms_px / s) * (out.fit.rms_px / s));
  out.tracked = out.confidence >= options_.min_confidence;
  if (!out.tracked) {
    Reset();  // re-detect on the next frame
  } else if (options_.init_from_fit) {
    source_->SetNextInitialisation(fitter_.ProjectLandmarks(out.fit));
  }
  return out;
}

}  // namespace crease
