// PCA of displacement patches (paper Sec. 4.3, Fig. 7).
//
// The N aligned displacement patches {d_i} (w×w each, n = w² values, row-major
// inside the patch: pixel (x, y) at index y·w + x) are reduced to their D = 16
// dimensions of largest variance; projecting a patch gives the regression target
// ĉ_i of the fern cascade (fern_cascade.h), and reconstructing the regressed
// coefficients gives the displacement patch back (Sec. 5.2, "From the regressed
// coefficients the local displacements can be reconstructed via the PCA basis").
//
//   PatchPca pca = FitPatchPca(displacement_patches, PcaOptions{});
//   Eigen::MatrixXf targets = pca.ProjectPatches(displacement_patches);  // {ĉ_i}
//
// Determinism: the covariance is summed in fixed blocks (independent of the TBB
// thread count) and every eigenvector's sign is fixed (its entry of largest
// magnitude is positive), so the same patches give the same bytes.
//
// Differences from the paper:
//   1. The paper does not say whether the patches are centred; we subtract the
//      mean patch (the "average" of Fig. 7) and reconstruct as mean + basis·c.
//   2. The covariance is normalised by N − 1 (sample covariance); this scales the
//      variances only, not the basis or the energy fractions.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

namespace crease {

class OptionVisitor;

struct PcaOptions {
  int dimensions = 16;  // D, Sec. 4.3 (option key "pca_dimensions"): PCA dimensions kept (≈85 % of the energy in the paper's data)

  void VisitFields(OptionVisitor& v);
  void Check() const;
  bool operator==(const PcaOptions&) const = default;
};

struct PatchPca {
  Eigen::VectorXf mean;       // n = w²: the mean patch (Fig. 7, left)
  Eigen::MatrixXf basis;      // n × D: orthonormal columns, in order of decreasing variance
  Eigen::VectorXd variances;  // n: all eigenvalues of the sample covariance, decreasing, ≥ 0
  // energy[k] = fraction of the total variance captured by the leading k + 1
  // dimensions, for k = 0 … n − 1 (monotone, energy.back() = 1).
  std::vector<double> energy;

  int dimensions() const { return static_cast<int>(basis.cols()); }
  int patch_pixels() const { return static_cast<int>(mean.size()); }

  // c = basisᵀ (patch − mean). patch: n floats; coefficients: D floats.
  void Project(const float* patch, float* coefficients) const;
  // patch = mean + basis · c. coefficients: D floats; patch: n floats.
  void Reconstruct(const float* coefficients, float* patch) const;
  // All rows at once: patches N × n → coefficients N × D (the targets {ĉ_i}).
  // Throws Error when patches.cols() != n.
  Eigen::MatrixXf ProjectPatches(const Eigen::MatrixXf& patches) const;
  // The smallest number of dimensions whose energy is ≥ fraction (0 < fraction ≤ 1);
  // e.g. DimensionsForEnergy(0.85) for the paper's "approximately 85 %".
  int DimensionsForEnergy(double fraction) const;

  bool operator==(const PatchPca&) const;
};

// Fits the PCA to N displacement patches (rows of `patches`, N × n, n = w²).
// The n × n covariance is accumulated in double with Eigen GEMM and decomposed
// with Eigen's SelfAdjointEigenSolver. Throws Error for N < 2, a non-finite value
// (naming the patch row and pixel), n < 1, or options.dimensions > n.
PatchPca FitPatchPca(const Eigen::MatrixXf& patches, const PcaOptions& options);

// The mean patch and the leading `count` eigen-patches side by side, like the
// paper's Fig. 7, for the training report: a CV_32FC3 image (linear RGB, crease's
// in-memory convention; write it with WriteImage) of height patch_size and width
// (count + 1)·patch_size + count (one-pixel white gaps). Each tile is normalised by
// its own largest magnitude and drawn with a diverging map (blue < 0, white = 0,
// red > 0). count is clamped to the available dimensions. Throws Error when
// patch_size² != n or count < 0.
cv::Mat EigenPatchMosaic(const PatchPca& pca, int count, int patch_size);

}  // namespace crease
