#include "eval/frame_tracker.h"

#include <chrono>

#include <fmt/format.h>

#include "core/dataset_info.h"
#include "core/error.h"
#include "eval/rig_correspondence.h"
#include "eval/tracking_metrics.h"

namespace crease {

CameraIntrinsics ResolveIntrinsics(const std::string& camera_path, const FrameSourceInfo& info, double fov_deg) {
  CameraIntrinsics K;
  if (!camera_path.empty()) {
    K = ReadCamera(camera_path).intrinsics;
  } else if (info.camera) {
    K = info.camera->intrinsics;
  } else {
    K = CameraIntrinsics::FromFov(fov_deg, info.width, info.height);
  }
  Require(K.width == info.width && K.height == info.height,
          fmt::format("the camera is {}×{} but the frames are {}×{}", K.width, K.height, info.width, info.height));
  return K;
}

FrameTracker::FrameTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics, const TrackerOptions& options,
                           const TrackingControl& control, const std::filesystem::path& dataset)
    : rig_(rig), dataset_(dataset) {
  Require(!(control.ground_truth_prior && control.ground_truth_fit), "--ground-truth-prior and --ground-truth-fit exclude each other");
  if (control.ground_truth_prior || control.ground_truth_fit) {
    Require(!dataset.empty(), fmt::format("--ground-truth-{} needs a crease sequence dataset as input",
                                          control.ground_truth_prior ? "prior" : "fit"));
  }
  if (control.ground_truth_fit) {
    // The truth's expression weights mean the same shapes only on the truth's rig.
    const FaceRig truth_rig = ReadRig(dataset / "rig.crig");
    Require(CorrespondRigs(rig, truth_rig).same_uv,
            fmt::format("--ground-truth-fit: the rig ({}) is not {}/rig.crig or a part of it; the truth's expression "
                        "weights would mean other shapes",
                        rig.source, dataset.string()));
    gt_fit_ = true;
    source_ = "ground-truth-fit";
  } else if (control.ground_truth_prior) {
    GroundTruthPriorOptions go;
    go.gt_prior_noise_px = control.noise_px;
    go.gt_prior_noise_seed = control.seed;
    gt_ = std::make_unique<GroundTruthPriorFitter>(rig, intrinsics, options.fit, go);
    source_ = "ground-truth-prior";
  } else {
    tracker_ = std::make_unique<FaceTracker>(rig, intrinsics, MakeLandmarkSource(options), options);
    source_ = ToString(options.landmark_source);
  }
}

TrackedFrame FrameTracker::Track(const cv::Mat& image, int index) {
  if (tracker_) {
    TrackedFrame t = tracker_->Track(image);
    t.frame = index;
    return t;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const FrameTruth truth = ReadFrameTruth(dataset_, index, -1);
  TrackedFrame t;
  if (gt_fit_) {
    t = TruthAsTrackedFrame(rig_, truth, index);
    if (truth_identity_.size() == 0) truth_identity_ = TruthIdentity(rig_, truth);
  } else {
    t.frame = index;
    t.fit = gt_->Fit(truth.landmarks);
    t.landmarks = gt_->last_landmarks();
    t.tracked = true;
    t.confidence = 1.0;
  }
  t.fit_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  t.detected = gt_count_++ == 0;
  return t;
}

const LandmarkRigFitter& FrameTracker::fitter() const {
  Require(!gt_fit_, "the ground-truth-fit control has no landmark fitter");
  return tracker_ ? tracker_->fitter() : gt_->fitter();
}

Eigen::VectorXd FrameTracker::identity() const {
  if (gt_fit_) return truth_identity_.size() ? truth_identity_ : Eigen::VectorXd::Zero(rig_.num_identity());
  return tracker_ ? tracker_->fitter().identity() : gt_->fitter().identity();
}

std::string FrameTracker::source_name() const { return source_; }

std::string DatasetTrackingRig(const std::filesystem::path& dataset) {
  return ReadSequenceDatasetInfo(dataset).TrackingRigPath().string();
}

std::string TrackingRigPath(const std::string& rig_path, const FrameSourceInfo& info) {
  if (!rig_path.empty()) return rig_path;
  Require(info.kind == "dataset", "--rig is required unless the input is a crease dataset");
  return DatasetTrackingRig(info.path);
}

}  // namespace crease
