#include "pipeline/training/pca.h"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>

#include "core/color.h"
#include "core/error.h"
#include "core/options.h"

namespace crease {
namespace {

// Rows per covariance block and columns per covariance tile. Fixed, so the
// summation order (and the result) does not depend on the thread count.
constexpr int kRowBlock = 1024;
constexpr int kTile = 128;

// Throws naming the first non-finite entry (patch row and pixel).
void RequireFinite(const Eigen::MatrixXf& patches) {
  if (patches.allFinite()) return;
  for (Eigen::Index i = 0; i < patches.rows(); ++i) {
    for (Eigen::Index j = 0; j < patches.cols(); ++j) {
      if (!std::isfinite(patches(i, j))) {
        throw Error(fmt::format("FitPatchPca: patch row {} has a non-finite value ({}) at pixel {}", i,
                                patches(i, j), j));
      }
    }
  }
}

// Σ_i (d_i − mean)(d_i − mean)ᵀ over all rows, in double: blocks of kRowBlock
// centred rows are converted to double and multiplied tile by tile (upper
// triangle only, Eigen GEMM per tile). Tiles run in parallel; each tile adds its
// row blocks in order, so the sum is the same for any number of threads.
Eigen::MatrixXd CentredScatter(const Eigen::MatrixXf& patches, const Eigen::VectorXd& mean) {
  const int N = static_cast<int>(patches.rows());
  const int n = static_cast<int>(patches.cols());
  const int tiles = (n + kTile - 1) / kTile;
  std::vector<std::pair<int, int>> tile_pairs;
  for (int I = 0; I < tiles; ++I)
    for (int J = I; J < tiles; ++J) tile_pairs.emplace_back(I, J);

  Eigen::MatrixXd scatter = Eigen::MatrixXd::Zero(n, n);
  Eigen::MatrixXd block;
  for (int r0 = 0; r0 < N; r0 += kRowBlock) {
    const int rows = std::min(kRowBlock, N - r0);
    block = patches.middleRows(r0, rows).cast<double>();
    block.rowwise() -= mean.transpose();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tile_pairs.size(), 1),
                      [&](const tbb::blocked_range<size_t>& range) {
                        for (size_t t = range.begin(); t != range.end(); ++t) {
                          const int i0 = tile_pairs[t].first * kTile;
                          const int j0 = tile_pairs[t].second * kTile;
                          const int ni = std::min(kTile, n - i0);
                          const int nj = std::min(kTile, n - j0);
                          scatter.block(i0, j0, ni, nj).noalias() +=
                              block.middleCols(i0, ni).transpose() * block.middleCols(j0, nj);
                        }
                      });
  }
  return scatter.selfadjointView<Eigen::Upper>();
}

// Diverging colour map (sRGB endpoints of Moreland's cool-warm map, white at 0),
// returned as linear RGB. v in [−1, 1].
cv::Vec3f Diverging(float v) {
  static const float kBlue[3] = {59.f / 255.f, 76.f / 255.f, 192.f / 255.f};
  static const float kRed[3] = {180.f / 255.f, 4.f / 255.f, 38.f / 255.f};
  const float t = std::clamp(std::abs(v), 0.f, 1.f);
  const float* end = v < 0.f ? kBlue : kRed;
  cv::Vec3f rgb;
  for (int c = 0; c < 3; ++c) rgb[c] = SrgbToLinear(1.f + t * (end[c] - 1.f));
  return rgb;
}

}  // namespace

void PcaOptions::VisitFields(OptionVisitor& v) { v.Field("dimensions", dimensions); }

void PcaOptions::Check() const { CheckGe("PcaOptions", "dimensions", dimensions, 1); }

void PatchPca::Project(const float* patch, float* coefficients) const {
  const int n = patch_pixels();
  const int D = dimensions();
  for (int d = 0; d < D; ++d) {
    const float* b = basis.col(d).data();
    double sum = 0.0;
    for (int j = 0; j < n; ++j) sum += static_cast<double>(b[j]) * (patch[j] - mean[j]);
    coefficients[d] = static_cast<float>(sum);
  }
}

void PatchPca::Reconstruct(const float* coefficients, float* patch) const {
  Eigen::Map<Eigen::VectorXf> out(patch, patch_pixels());
  out.noalias() = basis * Eigen::Map<const Eigen::VectorXf>(coefficients, dimensions());
  out += mean;
}

Eigen::MatrixXf PatchPca::ProjectPatches(const Eigen::MatrixXf& patches) const {
  Require(patches.cols() == patch_pixels(),
          fmt::format("PatchPca::ProjectPatches: patches have {} pixels, the PCA {}", patches.cols(),
                      patch_pixels()));
  Eigen::MatrixXf coefficients(patches.rows(), dimensions());
  Eigen::MatrixXf block;
  for (Eigen::Index r0 = 0; r0 < patches.rows(); r0 += kRowBlock) {
    const Eigen::Index rows = std::min<Eigen::Index>(kRowBlock, patches.rows() - r0);
    block = patches.middleRows(r0, rows);
    block.rowwise() -= mean.transpose();
    coefficients.middleRows(r0, rows).noalias() = block * basis;
  }
  return coefficients;
}

int PatchPca::DimensionsForEnergy(double fraction) const {
  Require(fraction > 0.0 && fraction <= 1.0,
          fmt::format("PatchPca::DimensionsForEnergy: fraction = {} must be in (0, 1]", fraction));
  Require(!energy.empty(), "PatchPca::DimensionsForEnergy: the PCA has no energy table");
  const auto it = std::lower_bound(energy.begin(), energy.end(), fraction);
  if (it == energy.end()) return static_cast<int>(energy.size());
  return static_cast<int>(it - energy.begin()) + 1;
}

bool PatchPca::operator==(const PatchPca& o) const {
  return mean.size() == o.mean.size() && mean == o.mean && basis.rows() == o.basis.rows() &&
         basis.cols() == o.basis.cols() && basis == o.basis && variances.size() == o.variances.size() &&
         variances == o.variances && energy == o.energy;
}

PatchPca FitPatchPca(const Eigen::MatrixXf& patches, const PcaOptions& options) {
  options.Check();
  const Eigen::Index N = patches.rows();
  const Eigen::Index n = patches.cols();
  Require(n >= 1, "FitPatchPca: patches have no pixels (0 columns)");
  Require(N >= 2, fmt::format("FitPatchPca: needs at least 2 patches to estimate a covariance, got {}", N));
  Require(options.dimensions <= n,
          fmt::format("PcaOptions.dimensions = {} must be <= the patch pixel count n = {}", options.dimensions,
                      n));
  RequireFinite(patches);

  // Mean patch, summed in double.
  Eigen::VectorXd mean = patches.cast<double>().colwise().sum().transpose() / static_cast<double>(N);

  const Eigen::MatrixXd covariance = CentredScatter(patches, mean) / static_cast<double>(N - 1);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(covariance);
  Require(solver.info() == Eigen::Success, "FitPatchPca: the eigen decomposition of the covariance failed");

  // Eigen returns increasing eigenvalues; reverse to decreasing variance.
  PatchPca pca;
  pca.mean = mean.cast<float>();
  pca.variances.resize(n);
  Eigen::MatrixXd vectors(n, n);
  for (Eigen::Index k = 0; k < n; ++k) {
    pca.variances[k] = std::max(0.0, solver.eigenvalues()[n - 1 - k]);
    vectors.col(k) = solver.eigenvectors().col(n - 1 - k);
    // Sign convention: the entry of largest magnitude is positive.
    Eigen::Index arg = 0;
    vectors.col(k).cwiseAbs().maxCoeff(&arg);
    if (vectors(arg, k) < 0.0) vectors.col(k) = -vectors.col(k);
  }
  pca.basis = vectors.leftCols(options.dimensions).cast<float>();

  const double total = pca.variances.sum();
  pca.energy.resize(n);
  double cumulative = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) {
    cumulative += pca.variances[k];
    pca.energy[k] = total > 0.0 ? std::min(1.0, cumulative / total) : 1.0;
  }
  pca.energy.back() = 1.0;
  return pca;
}

cv::Mat EigenPatchMosaic(const PatchPca& pca, int count, int patch_size) {
  Require(patch_size >= 1 && patch_size * patch_size == pca.patch_pixels(),
          fmt::format("EigenPatchMosaic: patch_size = {} does not match the PCA's {} pixels (w² expected)",
                      patch_size, pca.patch_pixels()));
  Require(count >= 0, fmt::format("EigenPatchMosaic: count = {} must be >= 0", count));
  count = std::min(count, pca.dimensions());
  const int w = patch_size;
  cv::Mat mosaic(w, (count + 1) * w + count, CV_32FC3, cv::Scalar(1, 1, 1));
  for (int tile = 0; tile <= count; ++tile) {
    const float* values = tile == 0 ? pca.mean.data() : pca.basis.col(tile - 1).data();
    float scale = 0.f;
    for (int j = 0; j < w * w; ++j) scale = std::max(scale, std::abs(values[j]));
    const float inv = scale > 0.f ? 1.f / scale : 0.f;
    const int x0 = tile * (w + 1);
    for (int y = 0; y < w; ++y) {
      auto* row = mosaic.ptr<cv::Vec3f>(y);
      for (int x = 0; x < w; ++x) row[x0 + x] = Diverging(values[y * w + x] * inv);
    }
  }
  return mosaic;
}

}  // namespace crease
