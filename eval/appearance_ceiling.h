// The appearance ceiling (issue 17's detail ladder, rung A): how much of the true
// detail D* one linear filter of the capture's own textures explains. Not a method,
// and despite the name not a bound. It is an index of how visible the studio's
// detail is under a light at an image resolution, measured before every other rung
// of the ladder. A low index says the texture shows little of D*.
//
// The cascade can exceed it. One filter serves every texel of the wrinkle regions,
// whatever the local orientation of a line or the direction of the light. Sec. 4.3's
// patches are instead oriented along the lines and regressed non-linearly. At the
// paper scale under "raking-above" (R2, a novel actor), the cascade's D^t correlates
// 0.42 with the lines where this index is 0.16.
//
// Per capture, with the truth:
//   reference   T_ref = the per-texel median of the textures of the
//               reference_frames frames whose true expression |β| is smallest
//               (MedianTexture, wrinkle_map.h)
//   contrast    r = T / T_ref − 1 where both are seen (FlattenByReference, "ratio"),
//               0 elsewhere, clamped to [−1, 1], blurred by σ = window_step / 2
//               (the samples below are window_step apart)
//   features    x(p) = r at the window × window grid of texels p + window_step·(i, j),
//               |i|, |j| ≤ window / 2, for every stride-th texel p of the wrinkle
//               regions seen in both T and T_ref
//   target      y(p) = the truth at p (D*, and the wrinkle layer minus that of the
//               frame with the smallest |β|, so its static lines drop out)
//   fit         ridge regression y ≈ wᵀx + b on the frames of one half (frames
//               alternate between the halves in blocks of `block` consecutive
//               frames), scored by the Pearson correlation of wᵀx + b with y on the
//               other half; both ways round, and the mean of the two.
// Only sufficient statistics are kept (Σxxᵀ, Σxy, Σx, Σy, Σy² per half), so a frame
// is read once and memory does not grow with the sequence.
//
// Measured (crease 0.4.2, 640×480, wrinkle regions; the correlation with D* / with the
// wrinkle lines):
//   * a lined training actor's 241-frame wrinkle-workout, ground-truth fit, the
//     default "studio" light: 0.44 / 0.13 (the cascade's D^t: 0.10 / 0.00);
//   * the detail ladder's lights profile (a novel actor, 40 frames, rung R2):
//     studio 0.46 / 0.24, overcast 0.54 / 0.28, raking-above 0.44 / 0.39; at R3 (the
//     quick tracker, 5.7–9.8 px off) 0.35, 0.30 and 0.26 against D*.
//   * paper scale under "raking-above" (R2, 2 novel actors, 241 frames): 0.34 / 0.24
//     and 0.20 / 0.16; the cascade's D^t 0.18 / 0.27 and 0.17 / 0.42.
//   A python prototype of the same fit on the forehead alone (15 × 15 window at step 3)
//   gave 0.27 against D* under "studio", the same without sensor noise and at
//   1280×720, 0.43 under "overcast" and 0.61 under "raking-above".
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

namespace crease {

class OptionVisitor;

struct AppearanceCeilingOptions {
  bool enabled = true;      // measure it (crease eval: when the truth D* is known)
  int window = 11;          // samples per side of the window (odd)
  int window_step = 4;      // texels between the window's samples
  int stride = 4;           // texels between sampled centres
  double ridge = 1e-3;      // λ, relative to the mean variance of the features
  int reference_frames = 8;  // T_ref: median of the frames with the smallest true |β|
  int block = 3;             // frames alternate between the two halves in blocks of this many

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct AppearanceCeiling {
  int frames[2] = {0, 0};       // frames in each half
  int64_t samples[2] = {0, 0};  // texels in each half
  // Per target: the mean over the two ways round of the held-out correlation.
  std::vector<double> correlation;
  bool measured() const { return frames[0] > 0 && frames[1] > 0 && !correlation.empty(); }
};

class AppearanceCeilingMeter {
 public:
  // reference: T_ref (CV_32F R×R, 0 where unseen); mask: CV_8U R×R, the texels to
  // sample (the wrinkle regions); num_targets ≥ 1 maps per frame. Throws Error on
  // a size or type mismatch or bad options.
  AppearanceCeilingMeter(const cv::Mat& reference, const cv::Mat& mask, int num_targets,
                         const AppearanceCeilingOptions& options);

  // Adds frame `frame`'s texture T^t (CV_32F R×R, linear, 0 unseen) and its targets
  // (num_targets CV_32F R×R maps) to the half of its block. Non-finite target
  // texels are skipped.
  void Add(int frame, const cv::Mat& texture, const std::vector<cv::Mat>& targets);

  AppearanceCeiling Result() const;

 private:
  struct Half {
    Eigen::MatrixXd xx, xy;  // Σ x xᵀ (n×n, lower triangle), Σ x yᵀ (n×T)
    Eigen::VectorXd x, y, yy;
    int64_t count = 0;
    int frames = 0;
  };
  // The held-out correlations of fitting on `fit` and scoring on `score`.
  std::vector<double> FitAndScore(const Half& fit, const Half& score) const;

  cv::Mat reference_, mask_;
  int num_targets_ = 0;
  AppearanceCeilingOptions options_;
  std::vector<cv::Point> offsets_;  // window sample offsets, texels
  Half half_[2];
};

}  // namespace crease
