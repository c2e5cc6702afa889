#include "eval/pair_metrics.h"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/options.h"

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

namespace crease {
namespace {

// Mean over the folds of one comparison's correlation, RMSE and amplitude ratio.
nlohmann::json MeanOverFolds(const std::vector<const MapComparison*>& cs) {
  double corr = 0, rmse = 0, amp = 0;
  double lo = 1, hi = -1;
  for (const MapComparison* c : cs) {
    corr += c->correlation;
    rmse += c->rmse_mm;
    amp += c->reference_rms_mm > 0 ? c->extracted_rms_mm / c->reference_rms_mm : 0.0;
    lo = std::min(lo, c->correlation);
    hi = std::max(hi, c->correlation);
  }
  const double n = std::max<double>(1, cs.size());
  return {{"correlation", corr / n}, {"correlation_min", lo}, {"correlation_max", hi},
          {"rmse_mm", rmse / n},     {"amplitude_ratio", amp / n}};
}

}  // namespace

LeaveOneActorOutResult EvaluateLeaveOneActorOut(const TrainingPairs& pairs, const TrainingOptions& options,
                                                const std::vector<std::string>& regressors, const std::string& what,
                                                const std::function<void(const std::string&)>& log) {
  Require(!pairs.actor.empty(), fmt::format("{}: the pairs carry no actor of each pair (written before crease 0.4.1: "
                                            "extract them again with crease train --scans … --save-pairs)",
                                            what));
  Require(pairs.actor_names.size() >= 2,
          fmt::format("{}: {} actor(s); leaving one out needs two or more", what, pairs.actor_names.size()));
  Require(!regressors.empty(), fmt::format("{}: no regressor to evaluate", what));
  std::vector<PatchRegressor> kinds;
  for (const auto& r : regressors) kinds.push_back(FromString<PatchRegressor>(r, "leave-one-actor-out.regressor"));
  LeaveOneActorOutResult result;
  result.regressors = regressors;
  for (int32_t a = 0; a < static_cast<int32_t>(pairs.actor_names.size()); ++a) {
    std::vector<int> train_rows, test_rows;
    for (int i = 0; i < static_cast<int>(pairs.actor.size()); ++i) (pairs.actor[i] == a ? test_rows : train_rows).push_back(i);
    if (test_rows.empty() || train_rows.size() < 2) continue;  // an actor without pairs holds nothing out
    const TrainingPairs train = pairs.Rows(train_rows), test = pairs.Rows(test_rows);
    TrainingOptions o = options;
    o.baseline.regressor = PatchRegressor::kFerns;
    DetailModel model = TrainDetailModelFromPairs(train, o, {}, nullptr);
    LeaveOneActorOutFold fold;
    fold.actor = pairs.actor_names[a];
    fold.training_pairs = static_cast<int>(train_rows.size());
    const std::string fold_what = fmt::format("{} without {}", what, fold.actor);
    // The baselines' inputs and targets, as TrainDetailModelFromPairs gives the cascade.
    const Eigen::MatrixXf features =
        NormalizeTexturePatches(train.texture, model.cascade.options.fern_texture_normalization);
    const Eigen::MatrixXf targets = model.pca.ProjectPatches(train.displacement);
    for (size_t r = 0; r < regressors.size(); ++r) {
      model.baseline = PatchBaseline();
      if (kinds[r] != PatchRegressor::kFerns) {
        PatchBaselineOptions b = options.baseline;
        b.regressor = kinds[r];
        model.baseline = FitPatchBaseline(features, targets, b);
      }
      fold.held_out.push_back(EvaluatePairs(model, test, fold_what));
      if (r == 0) fold.seen = EvaluatePairs(model, train, fold_what);
    }
    if (log)
      log(fmt::format("{} held out ({} pairs): correlation {:.3f} ({}), seen {:.3f}", fold.actor, test_rows.size(),
                      fold.held_out.front().prediction.correlation, regressors.front(), fold.seen.prediction.correlation));
    result.folds.push_back(std::move(fold));
  }
  Require(!result.folds.empty(), fmt::format("{}: no actor could be held out", what));
  return result;
}

std::string LeaveOneActorOutResult::ToTable() const {
  std::string o = fmt::format("{:<12} {:>8} {:>8}", "held out", "pairs", "seen");
  for (const auto& r : regressors) o += fmt::format(" {:>9}", r);
  o += fmt::format(" {:>9} {:>9}\n", "PCA ceil", "mean");
  for (const auto& f : folds) {
    o += fmt::format("{:<12} {:>8} {:>8.3f}", f.actor, f.held_out.front().pairs, f.seen.prediction.correlation);
    for (const auto& m : f.held_out) o += fmt::format(" {:>9.3f}", m.prediction.correlation);
    o += fmt::format(" {:>9.3f} {:>9.3f}\n", f.held_out.front().pca_ceiling.correlation,
                     f.held_out.front().mean_patch.correlation);
  }
  o += "(correlation of the predicted patch with d_i over all its pixels; seen: the first regressor on its own "
       "training pairs)\n";
  return o;
}

std::string LeaveOneActorOutResult::ToJson() const {
  nlohmann::json folds_json = nlohmann::json::array();
  std::vector<std::vector<const MapComparison*>> held(regressors.size());
  std::vector<const MapComparison*> seen, ceiling, mean_patch;
  for (const auto& f : folds) {
    nlohmann::json held_json = nlohmann::json::object();
    for (size_t r = 0; r < regressors.size(); ++r) {
      held_json[regressors[r]] = nlohmann::json::parse(f.held_out[r].ToJson());
      held[r].push_back(&f.held_out[r].prediction);
    }
    seen.push_back(&f.seen.prediction);
    ceiling.push_back(&f.held_out.front().pca_ceiling);
    mean_patch.push_back(&f.held_out.front().mean_patch);
    folds_json.push_back({{"actor", f.actor},
                          {"training_pairs", f.training_pairs},
                          {"held_out", held_json},
                          {"seen", nlohmann::json::parse(f.seen.ToJson())}});
  }
  nlohmann::json mean = {{"seen", MeanOverFolds(seen)},
                         {"pca_ceiling", MeanOverFolds(ceiling)},
                         {"mean_patch", MeanOverFolds(mean_patch)}};
  for (size_t r = 0; r < regressors.size(); ++r) mean["held_out"][regressors[r]] = MeanOverFolds(held[r]);
  return nlohmann::json{{"regressors", regressors}, {"folds", folds_json}, {"mean", mean}}.dump(1);
}

}  // namespace crease
