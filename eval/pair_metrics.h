// Rung R0 of the detail ladder (issue 17): a detail model's patch regression
// (Sec. 4.3, Eq. 6) on training pairs (t_i, d_i) of Sec. 4.2, seen in training or
// held out (another actor's pairs: leave-one-actor-out). Every patch's prediction
// d̂_i = mean + basis · c(t_i), with c the model's regressor (the cascade or its
// baseline), is compared with d_i over all its pixels, pooled over the pairs, beside
// two references: the PCA ceiling (d_i projected onto the model's basis and back:
// the best any regressor of these coefficients can do) and the mean patch (what a
// regressor that ignores t predicts).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "pipeline/training/detail_extraction.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/trainer.h"

namespace crease {

struct PairRegressionMetrics {
  int pairs = 0;
  MapComparison prediction;   // d̂_i against d_i
  MapComparison pca_ceiling;  // PCA⁻¹(PCA(d_i)) against d_i
  MapComparison mean_patch;   // the PCA mean against d_i
  std::string regressor;      // "ferns", "ridge" or "nearest"
  std::string ToTable() const;
  std::string ToJson() const;
};

// Throws Error (naming `what`) when the pairs' patch size differs from the model's.
PairRegressionMetrics EvaluatePairs(const DetailModel& model, const TrainingPairs& pairs,
                                    const std::string& what = "training pairs");

// Leave one actor out (rung R0): for each actor of `pairs`, a model is trained
// (Sec. 4.3: PCA and cascade, `options`' regression fields) on the other actors'
// pairs and scored on the held-out actor's, by each regressor of `regressors`
// ("ferns", "ridge", "nearest"; the baselines fitted to the same PCA
// coefficients), and — the generalisation gap — on its own training pairs.
struct LeaveOneActorOutFold {
  std::string actor;       // the held-out actor
  int training_pairs = 0;  // the other actors' pairs
  std::vector<PairRegressionMetrics> held_out;  // one per regressor, in order
  PairRegressionMetrics seen;                   // the first regressor on its training pairs
};
struct LeaveOneActorOutResult {
  std::vector<std::string> regressors;
  std::vector<LeaveOneActorOutFold> folds;
  std::string ToTable() const;
  // {regressors, folds: [...], mean: {held_out: {REGRESSOR: {correlation, rmse_mm,
  // amplitude_ratio}}, seen, pca_ceiling, mean_patch}} — means over the folds.
  std::string ToJson() const;
};

// Throws Error (naming `what`) when the pairs carry no actor ids or fewer than two actors.
LeaveOneActorOutResult EvaluateLeaveOneActorOut(const TrainingPairs& pairs, const TrainingOptions& options,
                                                const std::vector<std::string>& regressors,
                                                const std::string& what = "training pairs",
                                                const std::function<void(const std::string&)>& log = {});

}  // namespace crease
