// The detail-accuracy experiment's baseline regressors (pipeline/training/patch_baselines.h).
#include "pipeline/training/patch_baselines.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "core/error.h"
#include "pipeline/training/detail_model.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Random patches and coefficients that are an exact affine function of the
// mean-removed patch.
void LinearData(int N, int n, int D, Eigen::MatrixXf* T, Eigen::MatrixXf* C, Eigen::MatrixXf* W) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  T->resize(N, n);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < n; ++j) (*T)(i, j) = u(rng);
  W->resize(D, n + 1);
  for (int i = 0; i < D; ++i)
    for (int j = 0; j <= n; ++j) (*W)(i, j) = u(rng) - 0.5f;
  Eigen::MatrixXf X = *T;
  X.colwise() -= X.rowwise().mean();
  *C = (X * W->leftCols(n).transpose()).rowwise() + W->col(n).transpose();
}

TEST(PatchBaselines, RidgeRecoversALinearMap) {
  Eigen::MatrixXf T, C, W;
  LinearData(400, 16, 3, &T, &C, &W);
  PatchBaselineOptions o;
  o.regressor = PatchRegressor::kRidge;
  o.ridge_lambda = 1e-6;
  const PatchBaseline b = FitPatchBaseline(T, C, o);
  b.Check("ridge");
  const RowMajor P = T.topRows(10);
  RowMajor c(10, 3);
  b.PredictBatch(P.data(), 10, c.data());
  EXPECT_LT((Eigen::MatrixXf(c) - C.topRows(10)).cwiseAbs().maxCoeff(), 1e-3);
  // A brightness offset does not change the prediction (the patch mean is removed).
  const RowMajor P2 = P.array() + 0.2f;
  RowMajor c2(10, 3);
  b.PredictBatch(P2.data(), 10, c2.data());
  EXPECT_LT((c2 - c).cwiseAbs().maxCoeff(), 1e-4);
}

TEST(PatchBaselines, NearestReturnsTheClosestExample) {
  Eigen::MatrixXf T, C, W;
  LinearData(50, 16, 2, &T, &C, &W);
  PatchBaselineOptions o;
  o.regressor = PatchRegressor::kNearest;
  const PatchBaseline b = FitPatchBaseline(T, C, o);
  ASSERT_EQ(b.examples.rows(), 50);
  // A training patch, slightly perturbed, finds itself.
  RowMajor P = T.row(17);
  P(0, 3) += 0.01f;
  RowMajor c(1, 2);
  b.PredictBatch(P.data(), 1, c.data());
  EXPECT_EQ(Eigen::MatrixXf(c), Eigen::MatrixXf(C.row(17)));
  // Subsampling keeps nearest_max_examples evenly spread examples.
  o.nearest_max_examples = 10;
  EXPECT_EQ(FitPatchBaseline(T, C, o).examples.rows(), 10);
  EXPECT_ERROR_HAS(SetOptionsFromJson(R"({"regressor": "cubic"})", "test", &o),
                   "test: option 'regressor' must be one of: ferns, ridge, nearest, got \"cubic\"");
}

}  // namespace
}  // namespace crease
