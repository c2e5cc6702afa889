// Landmark sources for the global tracker (paper Sec. 5: the DDE-style global
// tracker, Cao et al. 2014). A source gives, per frame, the face box and the 68
// iBUG landmarks in pixels (OpenCV convention: pixel (x, y) has its centre at
// (x, y)); point i is iBUG point i + 1 (points 37–42, 0-based 36–41, are the
// subject's right eye).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/options.h"
#include "core/types.h"

namespace crease {

struct FaceBox {
  double x = 0, y = 0, width = 0, height = 0;  // pixels, top-left corner and size
  double score = 0;                            // detector score (HOG SVM margin); 0 when not detected
};

struct LandmarkResult {
  bool found = false;
  bool detected = false;  // true when the face detector ran on this frame (start or recovery)
  FaceBox box;
  MatX2d points;  // 68×2 pixels (empty when not found)
};

class LandmarkSource {
 public:
  virtual ~LandmarkSource() = default;
  // Landmarks on the next frame of a sequence (state carries over between calls).
  // `image`: linear float RGB (CV_32FC3) or gray (CV_32FC1) in [0, 1], or 8-bit.
  virtual LandmarkResult Track(const cv::Mat& image) = 0;
  // Forgets the previous frame (next Track detects again).
  virtual void Reset() = 0;
  // The shape the next frame starts from, when the source tracks from the previous
  // frame (68×2 px): the tracker passes the rig fit's landmarks (DDE). Default: ignored.
  virtual void SetNextInitialisation(const MatX2d& /*shape*/) {}
  virtual std::string name() const = 0;
};

// dlib's HOG frontal face detector (Dalal–Triggs features, no model file): the
// detection both landmark sources run at the start and after a loss.
class HogFaceDetector {
 public:
  // `upsample`: image doublings before detecting (1 finds faces down to ~40 px);
  // `threshold`: SVM score threshold.
  explicit HogFaceDetector(int upsample = 0, double threshold = 0.0);
  ~HogFaceDetector();
  HogFaceDetector(HogFaceDetector&&) noexcept;
  HogFaceDetector& operator=(HogFaceDetector&&) noexcept;
  // All faces in the image (linear float or 8-bit, RGB or gray), best first.
  std::vector<FaceBox> Detect(const cv::Mat& image) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct DlibLandmarkOptions {
  // dlib's 68-point model (Debian package libdlib-data; trained on iBUG 300-W, whose
  // terms exclude commercial use).
  std::string model_path = "/usr/share/dlib/shape_predictor_68_face_landmarks.dat";
  int upsample = 0;                 // HOG pyramid upsampling steps (1 finds faces down to ~40 px)
  double detection_threshold = 0.0; // HOG SVM score threshold
  // Tracking: the face box of the next frame is placed on the previous frame's eye
  // and nose landmarks as the detector's box was on the last detection, and the
  // detector runs only at the start and after a loss. The face counts as lost
  // when the outer eye corners' distance changes by more than this factor between
  // frames or the landmarks leave the image.
  double max_scale_change = 1.5;
  // Every this many tracked frames the detector runs again and the track is kept
  // only if a detected face overlaps it (intersection over union > 0.3); otherwise
  // the face counts as lost and the detection restarts the track. This is how the
  // tracker leaves an occluder or a drifted track. 0 = never (fastest).
  int redetect_interval = 30;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// dlib's HOG face detector and 68-point shape predictor (Kazemi and Sullivan 2014).
class DlibLandmarkSource final : public LandmarkSource {
 public:
  // Loads the model; an Error names the path and the package when it is missing.
  explicit DlibLandmarkSource(const DlibLandmarkOptions& options = {});
  ~DlibLandmarkSource() override;

  LandmarkResult Track(const cv::Mat& image) override;
  void Reset() override;
  std::string name() const override { return "dlib"; }

  // All faces the HOG detector finds, best first.
  std::vector<FaceBox> Detect(const cv::Mat& image) const;
  // The 68 landmarks inside a given face box.
  MatX2d Landmarks(const cv::Mat& image, const FaceBox& box) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Linear float (or 8-bit) RGB/gray → 8-bit sRGB-encoded gray, what image-trained
// detectors expect.
cv::Mat ToGray8(const cv::Mat& image);

// The tight box around a set of 2D points, expanded by `scale` about its centre.
FaceBox BoxOfPoints(const MatX2d& points, double scale = 1.0);

}  // namespace crease
