// The global tracker a capture or a tracking run calls per frame (L^t, paper Sec. 5),
// or one of two experimental controls that read a crease sequence dataset's ground
// truth instead of the image; and the rules for the camera and the rig a run tracks
// with. Shared by `crease track` (eval/track_run.h) and `crease capture`
// (pipeline/capture/capture_run.h). It lives in eval because the controls read the
// studio's truth.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "pipeline/capture/capture_run.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/landmark_fit.h"
#include "pipeline/capture/tracker.h"

namespace crease {

// Experimental controls on a crease sequence dataset (never a default). At most one.
struct TrackingControl {
  // The rig fitted to the ground-truth landmark projections plus Gaussian noise of
  // noise_px (σ, seeded by seed): isolates the stages after the landmarks (issue 5).
  bool ground_truth_prior = false;
  // The truth's own pose, expression weights and identity: exact geometry up to the
  // actor's personal deviations (issue 17); needs the dataset's rig or a part of it.
  bool ground_truth_fit = false;
  // The ground-truth fit on the actor's own expression shapes (ControlRig): L^t is
  // the true coarse surface, deviations included (issue 17's exact-geometry rungs).
  bool ground_truth_surface = false;
  double noise_px = 0.0;
  uint64_t seed = 1;
};

// The rig a run under `control` tracks with: `rig` itself, except under the
// ground-truth-surface control, where its expression shapes become the actor's own
// (PersonalRig of the dataset's rig.crig and actor.json, synth/actor.h, taken at
// `rig`'s vertices and matched by expression name), so that the truth's weights give
// the true coarse surface. `rig` must be the dataset's rig or a part of it. Under the
// plain ground-truth fit these personal deviations stay as model error: 0.17 px on
// average, but about 3 px at the brows of a brow raise (8 texels of a 1024² texture
// where the wrinkles are), which cut D^t's correlation with D* in the wrinkle band
// from 0.51 to 0.35 on a quick-profile novel actor.
FaceRig ControlRig(const FaceRig& rig, const TrackingControl& control, const std::filesystem::path& dataset);

// The intrinsics of the frames: `camera_path` (a camera JSON) when given, else the
// dataset's calibration, else a pinhole of `fov_deg` horizontal field of view. Throws
// Error when they disagree with the frame size.
CameraIntrinsics ResolveIntrinsics(const std::string& camera_path, const FrameSourceInfo& info, double fov_deg);

// The global tracker of the options (FaceTracker: landmarks, then the rig fit of
// Sec. 5.1), or a TrackingControl.
class FrameTracker : public GlobalTracker {
 public:
  // `dataset`: the sequence dataset the frames come from (needed for the controls;
  // empty otherwise). Throws Error naming what is missing or inconsistent.
  FrameTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics, const TrackerOptions& options,
               const TrackingControl& control, const std::filesystem::path& dataset);
  // Tracks `image` (linear RGB), frame number `index`.
  TrackedFrame Track(const cv::Mat& image, int index) override;
  // The identity α the frames were tracked with (the truth's under the ground-truth fit).
  Eigen::VectorXd identity() const override;
  // The landmark fitter (throws Error under the ground-truth fit, which has none).
  const LandmarkRigFitter& fitter() const;
  std::string source_name() const override;

 private:
  const FaceRig& rig_;
  std::filesystem::path dataset_;
  std::string source_;
  std::unique_ptr<FaceTracker> tracker_;
  std::unique_ptr<GroundTruthPriorFitter> gt_;
  bool gt_fit_ = false;
  Eigen::VectorXd truth_identity_;
  int gt_count_ = 0;
};

// The rig a dataset is tracked with by default: its tracking_rig.crig when
// dataset.json lists one (the generic rig without the parts a tracker never fits),
// else its rig.crig.
std::string DatasetTrackingRig(const std::filesystem::path& dataset);

// The rig to track with: `rig_path` when given, else the input dataset's tracking rig
// (DatasetTrackingRig); an Error when neither exists.
std::string TrackingRigPath(const std::string& rig_path, const FrameSourceInfo& info);

}  // namespace crease
