// Shared by `crease track` and `crease capture`: the global tracker (or the
// ground-truth-prior control) behind one call and the camera resolution rules
// (the per-frame record and the preview drawing: pipeline/capture/tracking_record.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "pipeline/capture/capture_run.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/landmark_fit.h"
#include "pipeline/capture/tracker.h"

namespace crease::app {

// The input and global-tracker flags `crease track` and `crease capture` share.
struct TrackingFlags {
  std::string input, rig_path, landmarks = "dlib", tracker_model, camera_path;
  double fov = 50.0;
  int max_frames = -1;
  bool gt_prior = false;  // the ground-truth-prior control
  bool gt_fit = false;    // the ground-truth-fit control (the truth's pose and expression)
  double noise = 0.0;     // its landmark noise, px
  uint64_t seed = 1;      // its noise seed
};
// Adds --input, --rig, --landmarks, --tracker, --camera, --fov, --max-frames,
// --ground-truth-prior, --noise and --seed to `cmd` (`crease capture` adds
// --ground-truth-fit itself).
void AddTrackingFlags(CLI::App* cmd, TrackingFlags* flags);

// The intrinsics of the frames: --camera (a camera JSON), else the dataset's
// calibration, else a pinhole of `fov_deg` horizontal field of view. Throws Error
// when they disagree with the frame size.
CameraIntrinsics ResolveIntrinsics(const std::string& camera_path, const FrameSourceInfo& info, double fov_deg);

// The global tracker of the options, or one of two experimental controls on a
// crease sequence dataset: the rig fitted to the ground-truth landmark projections
// plus noise (issue 5), or the truth's own pose, expression weights and identity
// (issue 17: exact geometry up to the actor's personal deviations; needs the
// dataset's rig or a part of it, such as its tracking rig).
class FrameTracker : public GlobalTracker {
 public:
  // `flags`: gt_prior / gt_fit choose a control (not both); `dataset`: the sequence
  // dataset (needed for the controls). Throws Error naming what is missing.
  FrameTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics, const TrackerOptions& options,
               const TrackingFlags& flags, const std::filesystem::path& dataset);
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

// The rig to track with: `rig_flag` (--rig) when given, else the input dataset's
// tracking rig (DatasetTrackingRig); an error when neither exists.
std::string TrackingRigPath(const std::string& rig_flag, const FrameSourceInfo& info);

}  // namespace crease::app
