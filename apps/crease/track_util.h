// Shared by `crease track` and `crease capture`: the global tracker (or the
// ground-truth-prior control) behind one call, the camera resolution rules, and
// the preview drawing.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
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
  double noise = 0.0;     // its landmark noise, px
  uint64_t seed = 1;      // its noise seed
};
// Adds --input, --rig, --landmarks, --tracker, --camera, --fov, --max-frames,
// --ground-truth-prior, --noise and --seed to `cmd`.
void AddTrackingFlags(CLI::App* cmd, TrackingFlags* flags);

// The intrinsics of the frames: --camera (a camera JSON), else the dataset's
// calibration, else a pinhole of `fov_deg` horizontal field of view. Throws Error
// when they disagree with the frame size.
CameraIntrinsics ResolveIntrinsics(const std::string& camera_path, const FrameSourceInfo& info, double fov_deg);

// The global tracker of the options, or — the experimental control of issue 5 —
// the rig fitted to a dataset's ground-truth landmark projections plus noise.
class FrameTracker {
 public:
  // `dataset`: the sequence dataset (needed for the ground-truth prior).
  FrameTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics, const TrackerOptions& options,
               bool ground_truth_prior, double noise_px, uint64_t seed, const std::filesystem::path& dataset);
  // Tracks `image` (linear RGB), frame number `index`.
  TrackedFrame Track(const cv::Mat& image, int index);
  const LandmarkRigFitter& fitter() const;
  std::string source_name() const;

 private:
  const FaceRig& rig_;
  std::filesystem::path dataset_;
  std::string source_;
  std::unique_ptr<FaceTracker> tracker_;
  std::unique_ptr<GroundTruthPriorFitter> gt_;
  int gt_count_ = 0;
};

nlohmann::json PoseJson(const Rigid3d& pose);

// The per-frame record both commands write: frame, tracked, detected, confidence,
// landmarks (px) and, when tracked, cam_from_head, expression weights by name and rms_px.
nlohmann::json TrackedFrameJson(const TrackedFrame& t, const FaceRig& rig);

// The rig's mesh (topology, UVs) with vertices V and no normals, for writing.
TriMesh RigMeshWithVertices(const FaceRig& rig, const MatX3d& V);

// Linear float RGB → 8-bit sRGB BGR (for previews).
cv::Mat PreviewBgr(const cv::Mat& linear_rgb);
// Draws the landmarks (green), a faint wireframe of `projected` (#V×2 px) over the
// face chart triangles, and the tracking state onto `bgr`.
void DrawTracking(const TrackedFrame& t, const MatX2d& projected, const MatX3i& face_F, cv::Mat* bgr);

// The rig a dataset is tracked with by default: its tracking_rig.crig when
// dataset.json lists one (the generic rig without the parts a tracker never fits),
// else its rig.crig.
std::string DatasetTrackingRig(const std::filesystem::path& dataset);

}  // namespace crease::app
