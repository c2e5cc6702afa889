#include "eval/pair_metrics.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace crease {

PairRegressionMetrics EvaluatePairs(const DetailModel& model, const TrainingPairs& pairs, const std::string& what) {
  const PatchPca& pca = model.pca;
  const int n = pca.patch_pixels(), N = static_cast<int>(pairs.texture.rows());
  Require(pairs.texture.cols() == n && pairs.displacement.cols() == n && pairs.displacement.rows() == N,
          fmt::format("{}: patches of {} and {} pixels, the model's have {}", what, pairs.texture.cols(),
                      pairs.displacement.cols(), n));
  using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  RowMatrixXf t = pairs.texture;
  RowMatrixXf c(N, pca.dimensions());
  model.RegressBatch(t.data(), N, c.data());
  const Eigen::MatrixXf predicted = (c * pca.basis.transpose()).rowwise() + pca.mean.transpose();
  const Eigen::MatrixXf projected = pca.ProjectPatches(pairs.displacement);
  const Eigen::MatrixXf ceiling = (projected * pca.basis.transpose()).rowwise() + pca.mean.transpose();
  MapMoments pred, ceil, mean;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < N; ++i) {
      const double d = pairs.displacement(i, j);
      pred.AddValue(predicted(i, j), d);
      ceil.AddValue(ceiling(i, j), d);
      mean.AddValue(pca.mean[j], d);
    }
  }
  PairRegressionMetrics m;
  m.pairs = N;
  m.prediction = pred.Result();
  m.pca_ceiling = ceil.Result();
  m.mean_patch = mean.Result();
  m.regressor = model.baseline.empty() ? "ferns" : model.baseline.kind;
  return m;
}

std::string PairRegressionMetrics::ToTable() const {
  std::string o = fmt::format("{} pairs, regressor {}\n{:<14} {:>10} {:>12} {:>10} {:>10}\n", pairs, regressor, "",
                              "RMSE, mm", "correlation", "RMS, mm", "true RMS");
  for (const auto& [name, c] : {std::pair<const char*, const MapComparison&>{"prediction", prediction},
                                {"PCA ceiling", pca_ceiling},
                                {"mean patch", mean_patch}}) {
    o += fmt::format("{:<14} {:>10.4f} {:>12.3f} {:>10.4f} {:>10.4f}\n", name, c.rmse_mm, c.correlation,
                     c.extracted_rms_mm, c.reference_rms_mm);
  }
  return o;
}

std::string PairRegressionMetrics::ToJson() const {
  return nlohmann::json{{"pairs", pairs},
                        {"regressor", regressor},
                        {"prediction", MapComparisonJson(prediction)},
                        {"pca_ceiling", MapComparisonJson(pca_ceiling)},
                        {"mean_patch", MapComparisonJson(mean_patch)}}
      .dump(1);
}

}  // namespace crease
