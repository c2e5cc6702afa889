// Tests of the displacement-patch PCA (pipeline/training/pca.h, paper Sec. 4.3).
#include "pipeline/training/pca.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <limits>

#include "core/options.h"
#include "core/rng.h"
#include "test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

// N patches of w×w: a mean bump plus `modes` smooth random patterns with
// decreasing standard deviations, plus small white noise.
Eigen::MatrixXf MakePatches(int N, int w, int modes, double noise, uint64_t seed) {
  Rng rng(seed);
  const int n = w * w;
  Eigen::MatrixXf patterns(modes, n);
  for (int m = 0; m < modes; ++m) {
    const double fx = rng.Uniform(0.5, 3.0), fy = rng.Uniform(0.5, 3.0), ph = rng.Uniform(0.0, 6.0);
    for (int y = 0; y < w; ++y)
      for (int x = 0; x < w; ++x)
        patterns(m, y * w + x) = static_cast<float>(std::sin(fx * x / w * 6.28 + fy * y / w * 6.28 + ph));
  }
  Eigen::MatrixXf patches(N, n);
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < n; ++j) patches(i, j) = 0.3f + static_cast<float>(noise * rng.Normal());
    for (int m = 0; m < modes; ++m) patches.row(i) += static_cast<float>(rng.Normal() / (1 + m)) * patterns.row(m);
  }
  return patches;
}

TEST(PcaTest, FullBasisReconstructsTrainingPatchExactly) {
  const int w = 8, n = w * w;
  const Eigen::MatrixXf patches = MakePatches(300, w, 6, 0.05, 1);
  PcaOptions options;
  options.dimensions = n;
  const PatchPca pca = FitPatchPca(patches, options);
  ASSERT_EQ(pca.dimensions(), n);
  ASSERT_EQ(pca.patch_pixels(), n);
  // Orthonormal basis.
  const Eigen::MatrixXf gram = pca.basis.transpose() * pca.basis;
  EXPECT_LT((gram - Eigen::MatrixXf::Identity(n, n)).cwiseAbs().maxCoeff(), 1e-5f);
  for (int row : {0, 17, 299}) {
    const Eigen::VectorXf patch = patches.row(row).transpose();
    Eigen::VectorXf c(n), back(n);
    pca.Project(patch.data(), c.data());
    pca.Reconstruct(c.data(), back.data());
    const float scale = patch.cwiseAbs().maxCoeff();
    EXPECT_LT((back - patch).cwiseAbs().maxCoeff(), 1e-5f * scale) << "row " << row;
  }
}

TEST(PcaTest, EnergyIsMonotoneAndEndsAtOne) {
  const Eigen::MatrixXf patches = MakePatches(200, 6, 4, 0.02, 2);
  const PatchPca pca = FitPatchPca(patches, PcaOptions{});
  const int n = 36;
  ASSERT_EQ(static_cast<int>(pca.energy.size()), n);
  ASSERT_EQ(pca.variances.size(), n);
  EXPECT_EQ(pca.energy.back(), 1.0);
  EXPECT_GT(pca.energy.front(), 0.0);
  for (int k = 1; k < n; ++k) {
    EXPECT_GE(pca.energy[k], pca.energy[k - 1]) << k;
    EXPECT_LE(pca.variances[k], pca.variances[k - 1]) << k;
    EXPECT_GE(pca.variances[k], 0.0) << k;
  }
  // energy[k] is the variance fraction of the leading k + 1 dimensions.
  EXPECT_NEAR(pca.energy[2], pca.variances.head(3).sum() / pca.variances.sum(), 1e-12);
  EXPECT_EQ(pca.DimensionsForEnergy(1.0), pca.DimensionsForEnergy(pca.energy.back()));
  EXPECT_EQ(pca.DimensionsForEnergy(pca.energy[4]), 5);
}

TEST(PcaTest, RecoversPlantedSubspaceAndVariances) {
  // Three orthonormal patterns with standard deviations 3, 2, 1 and no noise:
  // three dimensions hold all the energy, with variances 9, 4, 1.
  const int w = 4, n = w * w, N = 4000;
  Eigen::MatrixXf patterns = Eigen::MatrixXf::Zero(3, n);
  for (int j = 0; j < n; ++j) {
    patterns(0, j) = 0.25f;                      // constant
    patterns(1, j) = (j % w < w / 2) ? 0.25f : -0.25f;  // left / right
    patterns(2, j) = (j / w < w / 2) ? 0.25f : -0.25f;  // top / bottom
  }
  Rng rng(3);
  Eigen::MatrixXf patches(N, n);
  for (int i = 0; i < N; ++i)
    patches.row(i) = 3.f * static_cast<float>(rng.Normal()) * patterns.row(0) +
                     2.f * static_cast<float>(rng.Normal()) * patterns.row(1) +
                     1.f * static_cast<float>(rng.Normal()) * patterns.row(2);
  PcaOptions options;
  options.dimensions = 3;
  const PatchPca pca = FitPatchPca(patches, options);
  EXPECT_NEAR(pca.energy[2], 1.0, 1e-9);
  EXPECT_EQ(pca.DimensionsForEnergy(0.999), 3);
  EXPECT_NEAR(pca.variances[0], 9.0, 0.6);
  EXPECT_NEAR(pca.variances[1], 4.0, 0.3);
  EXPECT_NEAR(pca.variances[2], 1.0, 0.1);
  // Each basis vector is (up to sign convention) the planted pattern.
  for (int m = 0; m < 3; ++m) EXPECT_NEAR(std::abs(pca.basis.col(m).dot(patterns.row(m).transpose())), 1.0, 1e-3) << m;
}

TEST(PcaTest, ProjectPatchesMatchesProjectAndIsDeterministic) {
  const Eigen::MatrixXf patches = MakePatches(2500, 8, 5, 0.05, 4);  // > one covariance block
  PcaOptions options;
  options.dimensions = 7;
  PatchPca one, two;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = FitPatchPca(patches, options);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    two = FitPatchPca(patches, options);
  }
  EXPECT_TRUE(one == two) << "PCA differs between 1 and 2 threads";
  const Eigen::MatrixXf coefficients = one.ProjectPatches(patches);
  ASSERT_EQ(coefficients.rows(), 2500);
  ASSERT_EQ(coefficients.cols(), 7);
  for (int row : {0, 1234, 2499}) {
    const Eigen::VectorXf patch = patches.row(row).transpose();
    Eigen::VectorXf c(7);
    one.Project(patch.data(), c.data());
    EXPECT_LT((c - coefficients.row(row).transpose()).cwiseAbs().maxCoeff(), 1e-4f) << row;
  }
  // Projected coefficients are centred, with the PCA variances.
  const Eigen::VectorXf coefficient_mean = coefficients.colwise().mean();
  EXPECT_LT(coefficient_mean.cwiseAbs().maxCoeff(), 1e-3f);
  const double var0 = (coefficients.col(0).cast<double>().array().square().sum()) / (2500 - 1);
  EXPECT_NEAR(var0, one.variances[0], 1e-3 * one.variances[0]);
}

TEST(PcaTest, BadInputIsAClearError) {
  const Eigen::MatrixXf patches = MakePatches(10, 4, 2, 0.1, 5);
  EXPECT_NE(ErrorOf([&] { FitPatchPca(patches.topRows(1), PcaOptions{}); }).find("at least 2 patches"),
            std::string::npos);
  PcaOptions too_many;
  too_many.dimensions = 17;
  EXPECT_NE(ErrorOf([&] { FitPatchPca(patches, too_many); }).find("dimensions = 17"), std::string::npos);
  PcaOptions zero;
  zero.dimensions = 0;
  EXPECT_NE(ErrorOf([&] { FitPatchPca(patches, zero); }).find("PcaOptions.dimensions"), std::string::npos);
  Eigen::MatrixXf with_nan = patches;
  with_nan(6, 3) = std::numeric_limits<float>::quiet_NaN();
  const std::string message = ErrorOf([&] { FitPatchPca(with_nan, PcaOptions{}); });
  EXPECT_NE(message.find("row 6"), std::string::npos) << message;
  EXPECT_NE(message.find("pixel 3"), std::string::npos) << message;
  const PatchPca pca = FitPatchPca(patches, PcaOptions{});
  EXPECT_FALSE(ErrorOf([&] { pca.ProjectPatches(Eigen::MatrixXf::Zero(2, 5)); }).empty());
  EXPECT_FALSE(ErrorOf([&] { pca.DimensionsForEnergy(0.0); }).empty());
  EXPECT_FALSE(ErrorOf([&] { EigenPatchMosaic(pca, 4, 5); }).empty());
}

TEST(PcaTest, OptionsFromJson) {
  PcaOptions options;
  SetOptionsFromJson(R"({"dimensions": 24})", "test", &options);
  EXPECT_EQ(options.dimensions, 24);
  EXPECT_FALSE(ErrorOf([&] { SetOptionsFromJson(R"({"dimensions": -1})", "test", &options); }).empty());
}

TEST(PcaTest, EigenPatchMosaicLayout) {
  const int w = 6;
  const Eigen::MatrixXf patches = MakePatches(100, w, 4, 0.05, 6);
  PcaOptions options;
  options.dimensions = 5;
  const PatchPca pca = FitPatchPca(patches, options);
  const cv::Mat mosaic = EigenPatchMosaic(pca, 16, w);  // clamped to 5 eigen-patches
  EXPECT_EQ(mosaic.type(), CV_32FC3);
  EXPECT_EQ(mosaic.rows, w);
  EXPECT_EQ(mosaic.cols, 6 * w + 5);
  // Gaps are white; each tile is normalised, so its largest magnitude reaches the
  // saturated end of the colour map (a channel well below white).
  EXPECT_EQ(mosaic.at<cv::Vec3f>(0, w), cv::Vec3f(1, 1, 1));
  for (int tile = 0; tile <= 5; ++tile) {
    float darkest = 1.f;
    for (int y = 0; y < w; ++y)
      for (int x = 0; x < w; ++x) {
        const cv::Vec3f v = mosaic.at<cv::Vec3f>(y, tile * (w + 1) + x);
        darkest = std::min({darkest, v[0], v[1], v[2]});
        for (int c = 0; c < 3; ++c) ASSERT_TRUE(v[c] >= 0.f && v[c] <= 1.f);
      }
    EXPECT_LT(darkest, 0.1f) << "tile " << tile;
  }
}

}  // namespace
}  // namespace crease
