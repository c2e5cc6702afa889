// Rung R0 of the detail ladder (eval/pair_metrics.h): a model's patch regression on
// pairs it learned from and on pairs whose displacements have nothing to do with
// their textures; and pair files joined for a leave-one-actor-out test.
#include "eval/pair_metrics.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/rng.h"
#include "pipeline/training/trainer.h"
#include <nlohmann/json.hpp>
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/pca.h"
#include "test_util.h"

namespace crease {
namespace {

constexpr int kW = 6, kN = kW * kW;

// Textures: a random ramp per patch; displacements: a groove whose depth is the
// ramp's slope (learnable from t).
TrainingPairs RampPairs(int count, uint64_t seed) {
  Rng rng(seed);
  TrainingPairs p;
  p.texture.resize(count, kN);
  p.displacement.resize(count, kN);
  for (int i = 0; i < count; ++i) {
    const double slope = rng.Uniform(-1.0, 1.0), offset = rng.Uniform(0.2, 0.8);
    for (int y = 0; y < kW; ++y)
      for (int x = 0; x < kW; ++x) {
        p.texture(i, y * kW + x) = static_cast<float>(offset + 0.05 * slope * x + 0.01 * rng.Normal());
        p.displacement(i, y * kW + x) = static_cast<float>(-0.1 * slope * std::exp(-0.5 * (y - 2.5) * (y - 2.5)));
      }
  }
  p.options_json = "{}";
  return p;
}

DetailModel FitModel(const TrainingPairs& p) {
  DetailModel m;
  PcaOptions po;
  po.dimensions = 4;
  m.pca = FitPatchPca(p.displacement, po);
  FernOptions fo;
  fo.num_ferns = 200;
  fo.num_sampled_pixels = 12;
  fo.shrinkage = 5;
  m.cascade = TrainFernCascade(p.texture, m.pca.ProjectPatches(p.displacement), fo).cascade;
  return m;
}

TEST(PairMetrics, LearnablePairsAreRegressedUnrelatedOnesAreNot) {
  const TrainingPairs train = RampPairs(600, 1);
  const DetailModel m = FitModel(train);
  const PairRegressionMetrics seen = EvaluatePairs(m, train);
  const PairRegressionMetrics held_out = EvaluatePairs(m, RampPairs(300, 2));
  EXPECT_EQ(seen.pairs, 600);
  EXPECT_GT(seen.pca_ceiling.correlation, 0.999);  // one mode explains the grooves
  EXPECT_GT(seen.prediction.correlation, 0.9);
  EXPECT_GT(held_out.prediction.correlation, 0.8);
  EXPECT_LT(held_out.prediction.rmse_mm, 0.6 * held_out.mean_patch.rmse_mm);
  // The same displacements under other patches' textures: nothing to learn from t.
  TrainingPairs shuffled = RampPairs(300, 2);
  shuffled.texture = RampPairs(300, 3).texture;
  EXPECT_LT(std::abs(EvaluatePairs(m, shuffled).prediction.correlation), 0.2);
  TrainingPairs wrong = train;
  wrong.texture.conservativeResize(Eigen::NoChange, kN - 1);
  wrong.displacement.conservativeResize(Eigen::NoChange, kN - 1);
  EXPECT_THROW(EvaluatePairs(m, wrong, "wrong.cpr"), Error);
}

TEST(PairMetrics, PairFilesJoinWhenTheirExtractionAgrees) {
  const auto dir = testing::TestDir();
  TrainingPairs a = RampPairs(10, 1), b = RampPairs(7, 2), c = RampPairs(5, 3);
  a.actors = b.actors = c.actors = 1;
  c.options_json = R"({"patch_size": 8})";
  WriteTrainingPairs(dir / "a.cpr", a);
  WriteTrainingPairs(dir / "b.cpr", b);
  WriteTrainingPairs(dir / "c.cpr", c);
  const TrainingPairs ab = ReadTrainingPairs(std::vector<std::filesystem::path>{dir / "a.cpr", dir / "b.cpr"});
  ASSERT_EQ(ab.texture.rows(), 17);
  EXPECT_EQ(ab.actors, 2);
  EXPECT_EQ(ab.texture.row(12), b.texture.row(2));
  EXPECT_EQ(ab.displacement.row(3), a.displacement.row(3));
  try {
    ReadTrainingPairs(std::vector<std::filesystem::path>{dir / "a.cpr", dir / "c.cpr"});
    FAIL() << "pairs of other options were joined";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("c.cpr"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// Pair sets of `actors` actors of `per_actor` ramp pairs each; actor `flipped` (if
// ≥ 0) has the opposite relation between texture and displacement.
TrainingPairs ActorPairs(int actors, int per_actor, int flipped) {
  TrainingPairs all;
  all.options_json = "{}";
  all.texture.resize(actors * per_actor, kN);
  all.displacement.resize(actors * per_actor, kN);
  for (int a = 0; a < actors; ++a) {
    const TrainingPairs p = RampPairs(per_actor, 10 + a);
    all.texture.middleRows(a * per_actor, per_actor) = p.texture;
    all.displacement.middleRows(a * per_actor, per_actor) = (a == flipped ? -1.0f : 1.0f) * p.displacement;
    all.actor.insert(all.actor.end(), per_actor, a);
    all.actor_names.push_back("actor_" + std::to_string(a));
  }
  all.actors = actors;
  return all;
}

TrainingOptions SmallRegression() {
  TrainingOptions o;
  o.patch.patch_size = kW;
  o.pca.dimensions = 4;
  o.ferns.num_ferns = 200;
  o.ferns.num_sampled_pixels = 12;
  o.ferns.shrinkage = 5;
  return o;
}

TEST(PairMetrics, LeaveOneActorOutScoresEachActorOnAModelThatNeverSawIt) {
  // Three actors with the same relation: every held-out actor is predicted.
  const LeaveOneActorOutResult same =
      EvaluateLeaveOneActorOut(ActorPairs(3, 300, -1), SmallRegression(), {"ferns", "ridge"});
  ASSERT_EQ(same.folds.size(), 3u);
  for (const auto& f : same.folds) {
    EXPECT_EQ(f.training_pairs, 600);
    ASSERT_EQ(f.held_out.size(), 2u);
    EXPECT_EQ(f.held_out[0].pairs, 300);
    EXPECT_EQ(f.held_out[0].regressor, "ferns");
    EXPECT_EQ(f.held_out[1].regressor, "ridge");
    EXPECT_GT(f.held_out[0].prediction.correlation, 0.8) << f.actor;
    EXPECT_GT(f.held_out[1].prediction.correlation, 0.8) << f.actor;
    EXPECT_GT(f.seen.prediction.correlation, 0.8) << f.actor;
  }
  // The third actor's displacements are the negative of the others': held out, it
  // is predicted with the others' relation (negative correlation), which it would
  // not be if its own pairs had leaked into its fold's training.
  const LeaveOneActorOutResult flipped =
      EvaluateLeaveOneActorOut(ActorPairs(3, 300, 2), SmallRegression(), {"ferns"});
  ASSERT_EQ(flipped.folds.size(), 3u);
  EXPECT_EQ(flipped.folds[2].actor, "actor_2");
  EXPECT_LT(flipped.folds[2].held_out[0].prediction.correlation, -0.5);
  const nlohmann::json j = nlohmann::json::parse(flipped.ToJson());
  EXPECT_NEAR(j["mean"]["held_out"]["ferns"]["correlation_min"].get<double>(),
              flipped.folds[2].held_out[0].prediction.correlation, 1e-9);
  // Pairs without actor ids (files before 0.4.1) or of one actor cannot be split.
  TrainingPairs anonymous = ActorPairs(3, 50, -1);
  anonymous.actor.clear();
  EXPECT_THROW(EvaluateLeaveOneActorOut(anonymous, SmallRegression(), {"ferns"}, "old.cpr"), Error);
  EXPECT_THROW(EvaluateLeaveOneActorOut(ActorPairs(1, 50, -1), SmallRegression(), {"ferns"}), Error);
  EXPECT_THROW(EvaluateLeaveOneActorOut(ActorPairs(3, 50, -1), SmallRegression(), {"lasso"}), Error);
}

TEST(PairMetrics, ActorIdsSurviveFilesJoinsAndRowSelections) {
  const auto dir = testing::TestDir();
  const TrainingPairs a = ActorPairs(2, 4, -1), b = ActorPairs(3, 2, -1);
  WriteTrainingPairs(dir / "a.cpr", a);
  WriteTrainingPairs(dir / "b.cpr", b);
  const TrainingPairs read = ReadTrainingPairs(dir / "a.cpr");
  EXPECT_EQ(read.actor, a.actor);
  EXPECT_EQ(read.actor_names, a.actor_names);
  const TrainingPairs ab = ReadTrainingPairs(std::vector<std::filesystem::path>{dir / "a.cpr", dir / "b.cpr"});
  ASSERT_EQ(ab.actor.size(), 14u);
  EXPECT_EQ(ab.actor_names.size(), 5u);
  EXPECT_EQ(ab.actor[8], 2);   // b's first actor follows a's two
  EXPECT_EQ(ab.actor[13], 4);
  const TrainingPairs rows = ab.Rows({13, 0});
  EXPECT_EQ(rows.actor, (std::vector<int32_t>{4, 0}));
  EXPECT_EQ(rows.actors, 2);
  EXPECT_EQ(rows.texture.row(0), ab.texture.row(13));
  EXPECT_EQ(rows.displacement.row(1), ab.displacement.row(0));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace crease
