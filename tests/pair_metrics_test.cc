// Rung R0 of the detail ladder (eval/pair_metrics.h): a model's patch regression on
// pairs it learned from and on pairs whose displacements have nothing to do with
// their textures; and pair files joined for a leave-one-actor-out test.
#include "eval/pair_metrics.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/rng.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/pca.h"

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
  const auto dir = std::filesystem::path(::testing::TempDir()) / ("pair_metrics_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
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

}  // namespace
}  // namespace crease
