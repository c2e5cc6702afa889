// Baseline patch regressors for the detail-accuracy experiment (issue 7): what the
// fern cascade of Sec. 4.3 is compared against. Both map a texture patch t (w²
// pixels) to PCA coefficients c (D) like the cascade (Eq. 6), so the capture
// pipeline can swap them in (DetailModel::baseline):
//   ridge:   c = W [t − mean(t); 1], W by ridge regression (λ on W only, not the bias)
//            over the training pairs — a linear model of the shading.
//   nearest: c of the training patch closest to t in L2 after each patch's mean is
//            removed — a lookup with no learning beyond the examples.
// Not in the paper: it compares with no baseline.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "core/options.h"

namespace crease {

// PatchBaselineOptions::regressor (see there).
enum class PatchRegressor { kFerns, kRidge, kNearest };
constexpr std::array<const char*, 3> OptionEnumNames(PatchRegressor) { return {"ferns", "ridge", "nearest"}; }

struct PatchBaselineOptions {
  // Which regressor the model applies at capture time: "ferns" (the paper's cascade,
  // Sec. 4.3), "ridge" or "nearest" (baselines; the cascade is still trained).
  PatchRegressor regressor = PatchRegressor::kFerns;
  double ridge_lambda = 10.0;         // λ of the ridge penalty (features are gray levels in [0, 1])
  int nearest_max_examples = 4000;    // training patches kept for the lookup (evenly subsampled)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct PatchBaseline {
  std::string kind;             // "" (none: the cascade), "ridge" or "nearest"
  int patch_pixels = 0, dimensions = 0;
  Eigen::MatrixXf weights;      // ridge: D × (n + 1), the last column the bias
  Eigen::MatrixXf examples;     // nearest: M × n, mean-removed texture patches
  Eigen::MatrixXf coefficients; // nearest: M × D

  bool empty() const { return kind.empty(); }
  // patches: N × n row-major; c: N × D row-major (written).
  void PredictBatch(const float* patches, int N, float* c) const;
  // Throws Error starting with `what` when the arrays disagree with the sizes.
  void Check(const std::string& what) const;
};

// T: N × n texture patches, C: N × D target coefficients (rows pair up).
PatchBaseline FitPatchBaseline(const Eigen::MatrixXf& T, const Eigen::MatrixXf& C,
                               const PatchBaselineOptions& options);

}  // namespace crease
