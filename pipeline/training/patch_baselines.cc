#include "pipeline/training/patch_baselines.h"

#include <algorithm>
#include <limits>

#include <Eigen/Cholesky>
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "core/error.h"

namespace crease {

void PatchBaselineOptions::VisitFields(OptionVisitor& v) {
  v.Field("regressor", regressor);
  v.Field("ridge_lambda", ridge_lambda);
  v.Field("nearest_max_examples", nearest_max_examples);
}

void PatchBaselineOptions::Check() const {
  CheckGe("PatchBaselineOptions", "ridge_lambda", ridge_lambda, 0.0);
  CheckGe("PatchBaselineOptions", "nearest_max_examples", nearest_max_examples, 1);
}

namespace {

using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Each row minus its mean (the cascade's pixel differences ignore the offset too).
Eigen::MatrixXf CenterRows(const Eigen::MatrixXf& T) {
  Eigen::MatrixXf X = T;
  X.colwise() -= X.rowwise().mean();
  return X;
}

}  // namespace

PatchBaseline FitPatchBaseline(const Eigen::MatrixXf& T, const Eigen::MatrixXf& C,
                               const PatchBaselineOptions& options) {
  options.Check();
  Require(T.rows() == C.rows() && T.rows() >= 1,
          fmt::format("patch baseline: {} texture patches but {} coefficient rows", T.rows(), C.rows()));
  PatchBaseline b;
  b.kind = options.regressor == PatchRegressor::kFerns ? "" : ToString(options.regressor);
  b.patch_pixels = static_cast<int>(T.cols());
  b.dimensions = static_cast<int>(C.cols());
  const int n = b.patch_pixels;
  if (b.kind == "ridge") {
    // [X 1]ᵀ[X 1] + λ diag(1…1, 0): the bias is not penalised.
    Eigen::MatrixXd X(T.rows(), n + 1);
    X.leftCols(n) = CenterRows(T).cast<double>();
    X.col(n).setOnes();
    Eigen::MatrixXd A = X.transpose() * X;
    A.diagonal().head(n).array() += options.ridge_lambda;
    const Eigen::MatrixXd rhs = X.transpose() * C.cast<double>();
    Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
    Require(ldlt.info() == Eigen::Success, "patch baseline: the ridge system is singular (ridge_lambda = 0?)");
    b.weights = ldlt.solve(rhs).transpose().cast<float>();  // D × (n + 1)
  } else if (b.kind == "nearest") {
    const int64_t N = T.rows();
    const int64_t M = std::min<int64_t>(N, options.nearest_max_examples);
    b.examples.resize(M, n);
    b.coefficients.resize(M, C.cols());
    const Eigen::MatrixXf X = CenterRows(T);
    for (int64_t i = 0; i < M; ++i) {  // evenly spread over the pairs (deterministic)
      const int64_t src = M == N ? i : i * N / M;
      b.examples.row(i) = X.row(src);
      b.coefficients.row(i) = C.row(src);
    }
  }
  return b;
}

void PatchBaseline::PredictBatch(const float* patches, int N, float* c) const {
  const int n = patch_pixels, D = dimensions;
  const Eigen::Map<const RowMajor> P(patches, N, n);
  Eigen::Map<RowMajor> out(c, N, D);
  Eigen::MatrixXf X = P;
  X.colwise() -= X.rowwise().mean();
  if (kind == "ridge") {
    out = (X * weights.leftCols(n).transpose()).rowwise() + weights.col(n).transpose();
  } else if (kind == "nearest") {
    // ‖x − e‖² = ‖x‖² − 2 x·e + ‖e‖²: one matrix product for all pairs.
    const Eigen::VectorXf e2 = examples.rowwise().squaredNorm();
    tbb::parallel_for(0, N, 64, [&](int begin) {
      const int end = std::min(N, begin + 64);
      const Eigen::MatrixXf dots = X.middleRows(begin, end - begin) * examples.transpose();
      for (int i = begin; i < end; ++i) {
        Eigen::Index best = 0;
        (e2.transpose() - 2.0f * dots.row(i - begin)).minCoeff(&best);
        out.row(i) = coefficients.row(best);
      }
    });
  } else {
    throw Error("patch baseline: no baseline to predict with");
  }
}

void PatchBaseline::Check(const std::string& what) const {
  if (kind.empty()) return;
  Require(kind == "ridge" || kind == "nearest", fmt::format("{}: unknown baseline '{}'", what, kind));
  Require(patch_pixels > 0 && dimensions > 0, fmt::format("{}: baseline without sizes", what));
  if (kind == "ridge") {
    Require(weights.rows() == dimensions && weights.cols() == patch_pixels + 1,
            fmt::format("{}: ridge weights are {}×{}, expected {}×{}", what, weights.rows(), weights.cols(), dimensions,
                        patch_pixels + 1));
  } else {
    Require(examples.cols() == patch_pixels && coefficients.cols() == dimensions &&
                examples.rows() == coefficients.rows() && examples.rows() > 0,
            fmt::format("{}: nearest-neighbour examples {}×{} and coefficients {}×{} do not match", what,
                        examples.rows(), examples.cols(), coefficients.rows(), coefficients.cols()));
  }
  Require(weights.allFinite() && examples.allFinite() && coefficients.allFinite(),
          fmt::format("{}: baseline holds a non-finite value", what));
}

}  // namespace crease
