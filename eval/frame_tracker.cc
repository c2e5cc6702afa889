#include "eval/frame_tracker.h"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "core/dataset_info.h"
#include "core/error.h"
#include "eval/rig_correspondence.h"
#include "eval/tracking_metrics.h"
#include "synth/actor.h"

namespace crease {

namespace {

// The control's command-line name ("" for none); throws Error when several are set.
std::string ControlName(const TrackingControl& control) {
  std::vector<std::string> names;
  if (control.ground_truth_prior) names.push_back("ground-truth-prior");
  if (control.ground_truth_fit) names.push_back("ground-truth-fit");
  if (control.ground_truth_surface) names.push_back("ground-truth-surface");
  Require(names.size() <= 1, fmt::format("--{} exclude each other", fmt::join(names, " and --")));
  return names.empty() ? std::string() : names[0];
}

// The expression basis (3#V × #E) as #V × 3#E rows, one per vertex, and back.
Eigen::MatrixXd BasisRows(const FaceRig& rig, int b) {
  Eigen::MatrixXd rows(rig.num_vertices(), 3);
  for (int v = 0; v < rig.num_vertices(); ++v) rows.row(v) = rig.expression_basis.block(3 * v, b, 3, 1).cast<double>().transpose();
  return rows;
}

}  // namespace

FaceRig ControlRig(const FaceRig& rig, const TrackingControl& control, const std::filesystem::path& dataset) {
  if (!control.ground_truth_surface) return rig;
  const FaceRig truth_rig = ReadRig(dataset / "rig.crig");
  const RigCorrespondence corr = CorrespondRigs(rig, truth_rig);
  Require(corr.same_uv, fmt::format("--ground-truth-surface: the rig ({}) is not {}/rig.crig or a part of it",
                                    rig.source, dataset.string()));
  const FaceRig personal = PersonalRig(truth_rig, ReadActor(dataset / "actor.json"));
  FaceRig out = rig;
  for (int b = 0; b < rig.num_expressions(); ++b) {
    const auto& names = truth_rig.expression_names;
    const auto it = std::find(names.begin(), names.end(), rig.expression_names[b]);
    Require(it != names.end(), fmt::format("--ground-truth-surface: the rig's expression {} is not in {}/rig.crig",
                                           rig.expression_names[b], dataset.string()));
    const Eigen::MatrixXd rows = corr.Map(BasisRows(personal, static_cast<int>(it - names.begin())));
    for (int v = 0; v < rig.num_vertices(); ++v) out.expression_basis.block(3 * v, b, 3, 1) = rows.row(v).transpose().cast<float>();
  }
  out.source += "; the actor's own expression shapes (--ground-truth-surface)";
  return out;
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
                           const TrackingControl& control, const std::filesystem::path& dataset)
    : rig_(rig), dataset_(dataset) {
  const std::string name = ControlName(control);
  if (!name.empty()) Require(!dataset.empty(), fmt::format("--{} needs a crease sequence dataset as input", name));
  if (control.ground_truth_fit || control.ground_truth_surface) {
    // The truth's expression weights mean the same shapes only on the truth's rig.
    const FaceRig truth_rig = ReadRig(dataset / "rig.crig");
    Require(CorrespondRigs(rig, truth_rig).same_uv,
            fmt::format("--{}: the rig ({}) is not {}/rig.crig or a part of it; the truth's expression "
                        "weights would mean other shapes",
                        name, rig.source, dataset.string()));
    gt_fit_ = true;
    source_ = name;
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
