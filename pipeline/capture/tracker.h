// The global face tracker (paper Sec. 5; the paper uses DDE, Cao et al. 2014):
// every frame, 2D landmarks from a landmark source (dlib's shape predictor or
// crease's own cascaded regressor), the rig fitted to them (landmark_fit.h), a
// confidence, and recovery after a loss.
//
// Loss and recovery: a frame is lost when the source finds no face, or when the
// fitted rig explains the landmarks badly (confidence below min_confidence, see
// TrackedFrame::confidence). Then the source and the fitter are reset, so the next
// frame runs the face detector again and re-initialises the pose; the identity,
// once fixed, is kept.
//
// Differences from the paper: DDE regresses the rig parameters (with displaced
// dynamic expressions) directly from the image; here landmarks are regressed and
// the rig is fitted to them, which keeps the landmark source pluggable.
#pragma once

#include <array>
#include <memory>
#include <string>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "pipeline/capture/landmark_fit.h"
#include "pipeline/capture/landmarks.h"

namespace crease {

class OptionVisitor;

// TrackerOptions::landmark_source (see there).
enum class LandmarkSourceKind { kDlib, kRegressor };
constexpr std::array<const char*, 2> OptionEnumNames(LandmarkSourceKind) { return {"dlib", "regressor"}; }

struct TrackerOptions {
  // "dlib" or "regressor" (crease's own, trained by `crease train-tracker`).
  LandmarkSourceKind landmark_source = LandmarkSourceKind::kDlib;
  // The regressor's model file (landmark_source = "regressor").
  std::string tracker_model;
  // A frame whose confidence is below this counts as lost (the tracker re-detects).
  double min_confidence = 0.05;
  // σ of the confidence, as a fraction of the inter-ocular distance:
  // confidence = exp(−½ (rms / (σ · IOD))²), rms the fit's landmark residual.
  double confidence_scale_iod = 0.1;
  // Start the landmark regressor on the next frame from the rig fit's projected
  // landmarks rather than its own output (as DDE starts from the fitted model), so
  // its per-landmark errors do not accumulate from frame to frame. dlib ignores it.
  bool init_from_fit = true;
  LandmarkFitOptions fit;
  DlibLandmarkOptions dlib;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct TrackedFrame {
  int frame = 0;
  bool tracked = false;   // a face was found and the fit accepted
  bool detected = false;  // the face detector ran on this frame (start or recovery)
  double confidence = 0.0;  // in [0, 1]; 0 when no face was found
  MatX2d landmarks;         // 68×2 px from the source (empty when none)
  LandmarkFrameFit fit;     // valid when tracked
  double landmarks_ms = 0.0, fit_ms = 0.0;
};

// The landmark source named by the options. Throws Error for an unknown name or a
// missing model file.
std::unique_ptr<LandmarkSource> MakeLandmarkSource(const TrackerOptions& options);

class FaceTracker {
 public:
  // `intrinsics`: the camera of the video (calibrated, or from a field of view).
  FaceTracker(const FaceRig& rig, const CameraIntrinsics& intrinsics, std::unique_ptr<LandmarkSource> source,
              const TrackerOptions& options);
  // The next frame (linear float RGB or gray, or 8-bit).
  TrackedFrame Track(const cv::Mat& frame);
  // Restart as if from the first frame (the identity is kept once fixed).
  void Reset();

  const LandmarkRigFitter& fitter() const { return fitter_; }
  const LandmarkSource& source() const { return *source_; }

 private:
  TrackerOptions options_;
  std::unique_ptr<LandmarkSource> source_;
  LandmarkRigFitter fitter_;
  int next_frame_ = 0;
};

}  // namespace crease
