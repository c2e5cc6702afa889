// crease's own cascaded shape regressor for the 68 iBUG landmarks (issue 5, part 1):
// the landmark stage of the DDE-style global tracker (paper Sec. 5, Cao et al. 2014,
// "Displaced dynamic expression regression for real-time facial tracking"), built as
// the explicit shape regression of Cao, Wei, Wen and Sun 2012, "Face alignment by
// explicit shape regression" (ESR):
//
//   S^t = S^{t−1} + M_{t−1}^{−1} ∘ R^t(I, S^{t−1}),   t = 1 … T        (two-level boosting)
//   R^t = Σ_{k=1…K} r^{t,k}: K random ferns fitted one after another to the residuals
//
// Shapes S are 68×2 pixel positions. M_S is the similarity transform that maps the
// current shape S onto the mean shape S̄ (least squares, ESR Sec. 2.2); regression
// targets and fern outputs live in that normalised frame, so one regressor serves all
// face sizes and in-plane rotations.
//
// Shape-indexed features (ESR Sec. 2.3): stage t samples P pixels once. Pixel p is
// indexed by its nearest landmark l_p of the mean shape and an offset d_p in the
// normalised frame; in an image with current shape S it is read at
//   x_p = S_{l_p} + M_S^{−1}(d_p)   (rotation and scale only),
// nearest pixel, as the sRGB-encoded grey value (what ToGray8 gives, / 255). A fern
// feature is the difference of two of the P pixels compared with a threshold; the
// pair is chosen by the correlation-based selection of ESR Sec. 2.4 — the pair
// (m, n) maximising |corr(Y·v, x_m − x_n)| for a random unit direction v in the
// 136-dimensional target space — shared with the detail regressor
// (SelectCorrelatedPair in pipeline/training/fern_cascade.h). Bin outputs are the
// shrunk mean residuals of ESR Eq. 7 / paper Eq. 4, δS_b = Σ_{i∈Ω_b} Y_i / (|Ω_b| + β)
// (FernBinOutputs, shared as well).
//
// Training data augmentation (ESR Sec. 2.5 and DDE's perturbed previous frames):
// each image gets `augmentation` initial shapes, a `tracking_fraction` of them the
// ground truth under a random similarity perturbation (what a tracker initialised
// from the previous frame sees), the rest another training sample's ground truth,
// fitted by similarity into this sample's (jittered) face box (what a tracker
// starting from a detector box sees).
//
// Differences from the papers:
//   1. Landmarks only: DDE (Cao et al. 2014) regresses the displaced dynamic
//      expression (rigid pose, blendshape weights and 2D displacements) against a
//      user-specific blendshape model; here the regressor predicts the 68 landmarks
//      and the rig fit is a separate stage (pipeline/capture/landmark_fit.h).
//   2. Feature locality: ESR samples pixels uniformly in the face and favours close
//      pairs by a prior exp(−λ‖u − v‖) during selection. Here stage t draws each pixel
//      around a uniformly random mean-shape landmark, uniformly in a disk whose
//      radius falls linearly from feature_radius_first to feature_radius_last
//      (units of the mean shape's inter-ocular distance) over the stages, then
//      indexes it by its nearest landmark; the selection itself is unchanged.
//   3. Thresholds are the feature value of a random training sample (as the detail
//      regressor's default "sample" rule); ESR draws them uniformly in the range.
//   4. One initial shape at test time (ESR takes the median over several); tracking
//      from the previous frame makes that unnecessary after the first frame.
//   5. Detector boxes are not used in training: the detection-like initial shapes are
//      placed in the square box of the truth landmarks with jitter
//      (box_jitter_*), and at test time the mean shape is placed into the HOG box by
//      the same square-box convention (dlib's HOG boxes are close to the square box
//      of the landmarks, cf. DlibLandmarkSource::Track).
//   6. Defaults are scaled from ESR's T = 10, K = 500, F = 5, P = 400, β = 1000, 20
//      initialisations per image to be trainable in minutes on two cores.
//
// Speed (bench/shape_regressor_bench, 2-vCPU Sapphire Rapids shared with other jobs, one
// thread, 640×480): Predict with the defaults (T = 10, K = 100, P = 400) 0.18 ms when
// consecutive calls hit the same bins (tracking), 0.53 ms when every call sees another
// image (the 17 MB bin table then misses cache); ESR's K = 500: 1.0 ms. Training on
// 480 renders × 10 initialisations (4800 samples): 15–33 s on two cores.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "core/ibug.h"
#include "core/options.h"
#include "core/types.h"
#include "pipeline/capture/landmarks.h"

namespace crease {

struct ShapeRegressorOptions {
  int num_stages = 10;              // T, ESR Sec. 2.1: outer stages (features re-indexed per stage)
  int num_ferns = 100;              // K, ESR Sec. 2.2: ferns per stage (ESR: 500)
  int fern_depth = 5;               // F, ESR Sec. 2.4: features per fern (2^F bins), 1 … 10
  int num_sampled_pixels = 400;     // P, ESR Sec. 2.3: shape-indexed pixels per stage (P² candidate pairs), 2 … 65535
  double shrinkage = 250.0;         // β, ESR Eq. 7: bin-output shrinkage (samples), ≥ 0 (ESR: 1000 for ~40k samples)
  double feature_radius_first = 0.6;  // pixel-offset radius at stage 1, units of the mean inter-ocular distance, > 0
  double feature_radius_last = 0.15;  // … at stage T (linear in between), > 0
  int augmentation = 10;            // initial shapes per training image (ESR Sec. 2.5: 20), ≥ 1
  double tracking_fraction = 0.5;   // fraction of them perturbed ground truth (the rest: other samples' shapes), [0, 1]
  // Tracking-like perturbations: frame-to-frame motion left after the previous frame's
  // landmarks. Smaller σ tracks video better, larger σ recovers better from a detector
  // start (measured: σ 0.15 / 6° / 0.06 gave 0.067 IOD on a held-out 640×480 video,
  // 0.10 / 5° / 0.05 gave 0.041; cold detector starts 0.064 vs 0.103 IOD).
  double perturb_translation = 0.10;  // σ of the tracking-like shift, units of the truth's inter-ocular distance, ≥ 0
  double perturb_rotation_deg = 5.0;  // σ of the tracking-like in-plane rotation, degrees, ≥ 0
  double perturb_scale = 0.05;      // σ of the tracking-like log scale, ≥ 0
  double box_jitter_translation = 0.08;  // detection-like: σ of the box shift, fraction of the box size, ≥ 0
  double box_jitter_scale = 0.08;   // detection-like: σ of the box log scale, ≥ 0
  uint64_t seed = 1;                // feature, direction, threshold and augmentation draws

  void VisitFields(OptionVisitor& v);
  void Check() const;
  bool operator==(const ShapeRegressorOptions&) const = default;
};

// The trained regressor: plain data (serialised member by member).
// L landmarks (68), T stages, K ferns per stage, F depth, P pixels per stage, B = 2^F.
struct ShapeRegressor {
  ShapeRegressorOptions options;   // the options it was trained with (T, K, F, P read from here)
  int num_landmarks = 0;           // L
  // S̄: L×2, the mean shape in the normalised frame (centroid 0, inter-ocular distance 1,
  // eyes horizontal); point i is iBUG point i + 1.
  MatX2d mean_shape;
  std::vector<uint16_t> pixel_landmark;  // T·P: l_p, the nearest mean-shape landmark of pixel p of stage t
  std::vector<float> pixel_offset;       // T·P·2: d_p in the normalised frame
  std::vector<uint16_t> fern_pixel_a;    // T·K·F: feature f of fern k is x[a] − x[b] (indices < P)
  std::vector<uint16_t> fern_pixel_b;    // T·K·F
  std::vector<float> fern_threshold;     // T·K·F: bit f = (x[a] − x[b] > θ)
  std::vector<float> fern_output;        // T·K·B·2L: δS_b of fern k of stage t, normalised frame, row-major L×2
  // Where a face's square landmark box (MeanShapeInBox's) lies relative to the HOG
  // detector's box: centre offset (x, y) in units of the detector box's side, and the
  // ratio of the sides; fitted on the training images (CalibrateDetectorBox).
  // (0, 0, 1) = the detector's box as is (models saved before it existed).
  Eigen::Vector3d detector_box{0.0, 0.0, 1.0};

  int num_stages() const { return options.num_stages; }
  int num_ferns() const { return options.num_ferns; }
  int depth() const { return options.fern_depth; }
  int num_pixels() const { return options.num_sampled_pixels; }

  // Runs the cascade from `initial_shape` (L×2 pixels) on `image` (linear float RGB or
  // gray in [0, 1], or 8-bit sRGB; OpenCV pixel-centre convention). Returns L×2 pixels.
  MatX2d Predict(const cv::Mat& image, const MatX2d& initial_shape) const;
  // The mean shape placed in a face box: scaled and centred so that the square box of
  // its points (side = max(width, height)) equals the square box about the box centre.
  MatX2d MeanShapeInBox(const FaceBox& box) const;
  // The landmark box expected for a HOG detection (detector_box applied).
  FaceBox FromDetectorBox(const FaceBox& detection) const;
  // Throws Error (message starts with `what`) unless the arrays have the sizes above,
  // indices are in range and all values are finite.
  void Check(const std::string& what = "shape regressor") const;

  bool operator==(const ShapeRegressor&) const = default;
};

struct ShapeRegressorTrainingReport {
  int num_images = 0;
  int num_samples = 0;             // images × augmentation
  // Mean point-to-point error over the training samples / the truth's inter-ocular
  // distance, at the initial shapes (index 0) and after each stage (index t).
  std::vector<double> train_error_iod;
  double mean_abs_correlation = 0.0;  // mean |corr| of the selected pairs
  double seconds = 0.0;
};

struct ShapeRegressorTrainingResult {
  ShapeRegressor regressor;
  ShapeRegressorTrainingReport report;
};

// Trains the regressor (ESR Alg. 1 with the augmentation above). `images` and
// `shapes` (L×2 truth pixels, L the same for all, outer eye corners at iBUG 37 and 46
// when L = 68) correspond one to one. Deterministic: the same inputs and options give
// an identical regressor for any thread count. Throws Error for invalid options,
// no images, mismatched counts or landmark counts, empty images or non-finite shapes.
ShapeRegressorTrainingResult TrainShapeRegressor(const std::vector<cv::Mat>& images,
                                                 const std::vector<MatX2d>& shapes,
                                                 const ShapeRegressorOptions& options);

// The mean shape of a set of shapes in the normalised frame (centroid 0,
// inter-ocular distance 1, eyes horizontal), by iterated similarity alignment.
// `left_eye`, `right_eye`: the landmark indices whose distance is the inter-ocular
// distance, `left_eye` on the image's left in a frontal view; by default the 68 iBUG
// points' outer eye corners (core/ibug.h), i.e. the subject's right eye, then the left.
MatX2d MeanShapeOf(const std::vector<MatX2d>& shapes, int left_eye = kIbugRightEyeOuter,
                   int right_eye = kIbugLeftEyeOuter);

// Model file: magic "CREASTRK", version kShapeRegressorFileVersion (core/array_file.h).
// Fits regressor->detector_box: runs dlib's HOG detector (`upsample`, `threshold` as
// RegressorLandmarkOptions) on the images and takes, over the detections that overlap
// their shape's square box (intersection over union > 0.3), the median centre offset
// and side ratio. Without it the mean shape starts where the detector's box is, which
// for a turned head is off the face: on 180 `fast-motion` frames the regressor's cold
// start was at 0.125 IOD against 0.050 from a box around the truth. Returns the
// detections used; with none, detector_box is left as it was.
int CalibrateDetectorBox(ShapeRegressor* regressor, const std::vector<cv::Mat>& images,
                         const std::vector<MatX2d>& shapes, int upsample = 0, double threshold = 0.0);

// Loading a file of another kind or version throws Error naming the file and both versions.
inline constexpr uint32_t kShapeRegressorFileVersion = 1;
void SaveShapeRegressor(const std::filesystem::path& path, const ShapeRegressor& regressor);
ShapeRegressor LoadShapeRegressor(const std::filesystem::path& path);

struct RegressorLandmarkOptions {
  int upsample = 0;                  // HOG pyramid upsampling steps for detection (as DlibLandmarkOptions)
  double detection_threshold = 0.0;  // HOG SVM score threshold
  // Refinement passes of the cascade right after a detection (the mean shape in the
  // box is far from the face; a second pass starts from the first's result), ≥ 1.
  int detection_passes = 2;
  // Initial shapes after a detection (Cao et al. 2012, Sec. 4: several starts, the
  // median of their results): the mean shape in the box, then shifted sideways by
  // ±12 % and scaled by 0.9 and 1.1 of the box, … (1, 3 or 5 of these). The median
  // per coordinate survives a start that converges elsewhere (a turned head whose
  // box is off-centre). ≥ 1.
  int detection_initialisations = 5;
  // Loss: the face counts as lost when its landmarks' box changes size by more than
  // this factor between frames, …
  double max_scale_change = 1.5;
  // … leaves the image by more than this fraction of its size, …
  double max_outside_fraction = 0.25;
  // … or the shape degenerates: its RMS distance to the mean shape after similarity
  // alignment exceeds this (units of the inter-ocular distance), or the inter-ocular
  // distance is below min_interocular_px.
  double max_shape_deviation = 0.5;
  double min_interocular_px = 8.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// LandmarkSource of crease's own regressor: dlib's HOG face detector at the start and
// after a loss, the mean shape placed in the box as the initial shape; later frames
// start from the previous frame's landmarks (DDE, Cao et al. 2014 Sec. 5).
class RegressorLandmarkSource final : public LandmarkSource {
 public:
  explicit RegressorLandmarkSource(ShapeRegressor regressor, const RegressorLandmarkOptions& options = {});
  ~RegressorLandmarkSource() override;

  LandmarkResult Track(const cv::Mat& image) override;
  void Reset() override;
  void SetNextInitialisation(const MatX2d& shape) override;
  std::string name() const override { return "regressor"; }

  const ShapeRegressor& regressor() const;
  // True when `shape` (L×2 pixels) in an image of this size counts as a loss.
  bool IsLost(const MatX2d& shape, const cv::Size& image_size, const MatX2d* previous) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
