#include "apps/crease/track_util.h"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/dataset_info.h"
#include "core/error.h"
#include "core/json_io.h"
#include "core/options.h"
#include "eval/rig_correspondence.h"
#include "eval/tracking_metrics.h"

namespace crease::app {

void AddTrackingFlags(CLI::App* cmd, TrackingFlags* f) {
  cmd->add_option("--input,-i", f->input, "Video file, image folder or crease sequence dataset")->required();
  cmd->add_option("--rig", f->rig_path, "Rig (.crig); default: the dataset's rig.crig");
  cmd->add_option("--landmarks", f->landmarks, "Landmark source: dlib or regressor")->capture_default_str();
  cmd->add_option("--tracker", f->tracker_model, "Regressor model (from `crease train-tracker`); implies --landmarks regressor");
  cmd->add_option("--camera", f->camera_path, "Camera JSON (intrinsics); default: the dataset's, else --fov");
  cmd->add_option("--fov", f->fov, "Horizontal field of view, degrees, when there is no calibration")
      ->capture_default_str();
  cmd->add_option("--max-frames", f->max_frames, "Stop after this many frames");
  cmd->add_flag("--ground-truth-prior", f->gt_prior,
                "Experimental control: fit the rig to the dataset's ground-truth landmarks (+ --noise), "
                "to isolate later stages; never a default");
  cmd->add_option("--noise", f->noise, "Ground-truth-prior landmark noise, px (σ)")->capture_default_str();
  cmd->add_option("--seed", f->seed, "Seed of the ground-truth-prior noise")->capture_default_str();
}

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
                           const TrackingFlags& flags, const std::filesystem::path& dataset)
    : rig_(rig), dataset_(dataset) {
  Require(!(flags.gt_prior && flags.gt_fit), "--ground-truth-prior and --ground-truth-fit exclude each other");
  if (flags.gt_prior || flags.gt_fit) {
    Require(!dataset.empty(), fmt::format("--ground-truth-{} needs a crease sequence dataset as input",
                                          flags.gt_prior ? "prior" : "fit"));
  }
  if (flags.gt_fit) {
    // The truth's expression weights mean the same shapes only on the truth's rig.
    const FaceRig truth_rig = ReadRig(dataset / "rig.crig");
    Require(CorrespondRigs(rig, truth_rig).same_uv,
            fmt::format("--ground-truth-fit: the rig ({}) is not {}/rig.crig or a part of it; the truth's expression "
                        "weights would mean other shapes",
                        rig.source, dataset.string()));
    gt_fit_ = true;
    source_ = "ground-truth-fit";
  } else if (flags.gt_prior) {
    GroundTruthPriorOptions go;
    go.gt_prior_noise_px = flags.noise;
    go.gt_prior_noise_seed = flags.seed;
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

std::string TrackingRigPath(const std::string& rig_flag, const FrameSourceInfo& info) {
  if (!rig_flag.empty()) return rig_flag;
  Require(info.kind == "dataset", "--rig is required unless the input is a crease dataset");
  return DatasetTrackingRig(info.path);
}

}  // namespace crease::app
