// Tests of the boosted random-fern cascade (pipeline/training/fern_cascade.h,
// paper Sec. 4.3 Eqs. 2–4 and Sec. 5.2 Eq. 6).
#include "pipeline/training/fern_cascade.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <set>

#include "core/error.h"
#include "core/options.h"
#include "core/rng.h"
#include "test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

// Random patches in [0, 1] (N × n).
Eigen::MatrixXf RandomPatches(int N, int n, uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXf patches(N, n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < N; ++i) patches(i, j) = static_cast<float>(rng.Uniform());
  return patches;
}

// A known function of pixel differences: three coefficients.
Eigen::MatrixXf KnownTargets(const Eigen::MatrixXf& t) {
  Eigen::MatrixXf c(t.rows(), 3);
  for (Eigen::Index i = 0; i < t.rows(); ++i) {
    c(i, 0) = std::tanh(4.f * (t(i, 5) - t(i, 20)));
    c(i, 1) = t(i, 10) - t(i, 40) > 0.f ? 0.5f : -0.5f;
    c(i, 2) = 0.5f * (t(i, 1) - t(i, 2)) + 0.2f;
  }
  return c;
}

FernOptions SmallOptions() {
  FernOptions o;
  o.num_ferns = 150;
  o.fern_depth = 5;
  o.num_sampled_pixels = 64;
  o.shrinkage = 50.0;
  o.fern_seed = 7;
  return o;
}

double Rms(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b) {
  return std::sqrt((a - b).cast<double>().array().square().mean());
}

std::vector<float> PredictAllBatch(const FernCascade& fc, const Eigen::MatrixXf& patches) {
  const RowMatrixXf rows = patches;
  std::vector<float> out(static_cast<size_t>(rows.rows()) * fc.dimensions);
  fc.PredictBatch(rows.data(), static_cast<int>(rows.rows()), out.data());
  return out;
}

std::vector<float> PredictAllSingle(const FernCascade& fc, const Eigen::MatrixXf& patches) {
  const RowMatrixXf rows = patches;
  std::vector<float> out(static_cast<size_t>(rows.rows()) * fc.dimensions);
  for (Eigen::Index i = 0; i < rows.rows(); ++i) fc.Predict(rows.row(i).data(), out.data() + i * fc.dimensions);
  return out;
}

bool SameBytes(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// The features' input normalisation (fern_texture_normalization): "gain" cancels a
// factor on the patch (an actor's albedo, the exposure), "standardize" any affine
// change of the gray levels; "none" leaves the paper's raw gray levels.
TEST(FernCascadeTest, TextureNormalisationCancelsAlbedoAndContrast) {
  std::vector<float> p(16), q(16), r(16);
  for (int i = 0; i < 16; ++i) p[i] = 0.3f + 0.02f * static_cast<float>(i % 4) - 0.05f * static_cast<float>(i == 5);
  for (int i = 0; i < 16; ++i) q[i] = 1.7f * p[i];
  for (int i = 0; i < 16; ++i) r[i] = 0.4f * p[i] + 0.1f;
  auto normalised = [](std::vector<float> v, TextureNormalization mode) {
    NormalizeTexturePatch(v.data(), static_cast<int>(v.size()), mode);
    return v;
  };
  const auto pg = normalised(p, TextureNormalization::kGain), qg = normalised(q, TextureNormalization::kGain),
             rg = normalised(r, TextureNormalization::kGain);
  const auto ps = normalised(p, TextureNormalization::kStandardize),
             rs = normalised(r, TextureNormalization::kStandardize);
  double mean = 0, var = 0;
  for (int i = 0; i < 16; ++i) mean += ps[i] / 16.0;
  for (int i = 0; i < 16; ++i) var += (ps[i] - mean) * (ps[i] - mean) / 16.0;
  EXPECT_NEAR(mean, 0.0, 1e-6);
  EXPECT_NEAR(var, 1.0, 1e-5);
  double gain_vs_offset = 0;
  for (int i = 0; i < 16; ++i) {
    EXPECT_NEAR(pg[i], qg[i], 1e-6);  // a factor cancels
    EXPECT_NEAR(ps[i], rs[i], 1e-5);  // an affine change cancels
    gain_vs_offset = std::max(gain_vs_offset, static_cast<double>(std::abs(pg[i] - rg[i])));
  }
  EXPECT_GT(gain_vs_offset, 0.01);  // "gain" does not cancel an offset
  EXPECT_EQ(normalised(p, TextureNormalization::kNone), p);
  EXPECT_EQ(normalised(std::vector<float>(16, 0.0f), TextureNormalization::kGain), std::vector<float>(16, 0.0f));
  FernOptions o;
  EXPECT_THROW(SetOptionsFromJson(R"({"texture_normalization": "bogus"})", "f.json", &o), Error);
}

TEST(FernCascadeTest, BinOutputsFollowEq4OnHandMadeBins) {
  // Bins: 0 ← samples {0, 1}, 1 ← {2}, 2 ← {3, 4, 5}, 3 empty.
  const std::vector<int> bins = {0, 0, 1, 2, 2, 2};
  RowMatrixXf eps(6, 2);
  eps << 1, 2,  //
      3, 4,     //
      -5, 0.5,  //
      1, 1,     //
      2, 2,     //
      3, -9;
  const double beta = 2.0;
  const Eigen::MatrixXf out = FernBinOutputs(bins, eps, 4, beta);
  ASSERT_EQ(out.rows(), 4);
  ASSERT_EQ(out.cols(), 2);
  EXPECT_FLOAT_EQ(out(0, 0), (1 + 3) / (2 + beta));
  EXPECT_FLOAT_EQ(out(0, 1), (2 + 4) / (2 + beta));
  EXPECT_FLOAT_EQ(out(1, 0), -5 / (1 + beta));
  EXPECT_FLOAT_EQ(out(1, 1), 0.5 / (1 + beta));
  EXPECT_FLOAT_EQ(out(2, 0), (1 + 2 + 3) / (3 + beta));
  EXPECT_FLOAT_EQ(out(2, 1), (1 + 2 - 9) / (3 + beta));
  EXPECT_EQ(out(3, 0), 0.f);
  EXPECT_EQ(out(3, 1), 0.f);
  // β = 0: the plain bin mean.
  const Eigen::MatrixXf mean = FernBinOutputs(bins, eps, 4, 0.0);
  EXPECT_FLOAT_EQ(mean(2, 1), -2.f);
  EXPECT_EQ(mean(3, 0), 0.f);
}

TEST(FernCascadeTest, TrainedFernOutputsAreEq4OfItsBins) {
  // One fern: its outputs are Σ(ĉ_i − c̄)/(|Ω_b| + β) over the samples that fall in b.
  const Eigen::MatrixXf patches = RandomPatches(500, 16, 11);
  Eigen::MatrixXf targets(500, 2);
  Rng rng(12);
  for (int i = 0; i < 500; ++i) targets.row(i) << static_cast<float>(rng.Normal()), patches(i, 3) * 2.f;
  FernOptions o;
  o.num_ferns = 1;
  o.fern_depth = 3;
  o.num_sampled_pixels = 8;
  o.shrinkage = 37.0;
  const FernCascade fc = TrainFernCascade(patches, targets, o).cascade;
  fc.Check();
  const RowMatrixXf rows = patches;
  Eigen::MatrixXd sums = Eigen::MatrixXd::Zero(8, 2);
  Eigen::VectorXd counts = Eigen::VectorXd::Zero(8);
  for (int i = 0; i < 500; ++i) {
    const int b = fc.BinIndex(0, rows.row(i).data());
    for (int d = 0; d < 2; ++d) sums(b, d) += targets(i, d) - fc.mean[d];
    counts[b] += 1;
  }
  for (int b = 0; b < 8; ++b)
    for (int d = 0; d < 2; ++d) EXPECT_NEAR(fc.BinOutput(0, b)[d], sums(b, d) / (counts[b] + 37.0), 1e-5) << b;
}

TEST(FernCascadeTest, CorrelationSelectionPicksTheInformativePair) {
  // y = p2 − p5 exactly; the other pixels are independent noise.
  const int N = 2000, P = 8;
  const Eigen::MatrixXf p = RandomPatches(N, P, 21);
  Eigen::VectorXd y(N);
  for (int i = 0; i < N; ++i) y[i] = p(i, 2) - p(i, 5);
  Eigen::MatrixXd pc = p.cast<double>();
  pc.rowwise() -= pc.colwise().mean();
  const Eigen::VectorXd yc = y.array() - y.mean();
  const PixelPair pair = SelectCorrelatedPair(pc.transpose() * pc, pc.transpose() * yc, yc.squaredNorm());
  EXPECT_EQ(pair.m, 2);
  EXPECT_EQ(pair.n, 5);
  EXPECT_NEAR(pair.correlation, 1.0, 1e-9);

  // Through training: a single target determined by t[3] − t[7]; with P = n every
  // pixel is a candidate, so every feature of the fern must use that pair.
  const Eigen::MatrixXf patches = RandomPatches(3000, 12, 22);
  Eigen::MatrixXf targets(3000, 1);
  for (int i = 0; i < 3000; ++i) targets(i, 0) = patches(i, 3) - patches(i, 7);
  FernOptions o;
  o.num_ferns = 1;
  o.fern_depth = 4;
  o.num_sampled_pixels = 12;
  const FernTrainingResult r = TrainFernCascade(patches, targets, o);
  for (int f = 0; f < 4; ++f) {
    const std::set<int> chosen = {r.cascade.pixel_a[f], r.cascade.pixel_b[f]};
    EXPECT_EQ(chosen, (std::set<int>{3, 7})) << "feature " << f;
  }
  EXPECT_GT(r.report.mean_abs_correlation, 0.999);
}

TEST(FernCascadeTest, LargePatchesSelectPairsFromPerFernCovariance) {
  // n = 48² > 2048: the trainer computes each fern's P × P covariance directly
  // instead of slicing one n × n scatter. Pixel j repeats base value j mod 8, so
  // pairs of equal residue are constant (zero variance, never chosen) and the
  // informative pairs are those with residues {1, 5}.
  const int N = 500, n = 48 * 48;
  const Eigen::MatrixXf base = RandomPatches(N, 8, 91);
  Eigen::MatrixXf patches(N, n);
  for (int j = 0; j < n; ++j) patches.col(j) = base.col(j % 8);
  Eigen::MatrixXf targets(N, 1);
  targets.col(0) = base.col(1) - base.col(5);
  FernOptions o;
  o.num_ferns = 3;
  o.fern_depth = 3;
  o.num_sampled_pixels = 40;
  const FernTrainingResult r = TrainFernCascade(patches, targets, o);
  for (int i = 0; i < 9; ++i) {
    const std::set<int> residues = {r.cascade.pixel_a[i] % 8, r.cascade.pixel_b[i] % 8};
    EXPECT_EQ(residues, (std::set<int>{1, 5})) << "feature " << i;
  }
  EXPECT_GT(r.report.mean_abs_correlation, 0.999);
}

TEST(FernCascadeTest, FitsAKnownFunctionOfPixelDifferences) {
  const int n = 64;
  const Eigen::MatrixXf train = RandomPatches(8000, n, 31);
  const Eigen::MatrixXf test = RandomPatches(1000, n, 32);
  const Eigen::MatrixXf train_targets = KnownTargets(train);
  const Eigen::MatrixXf test_targets = KnownTargets(test);
  const FernTrainingResult r = TrainFernCascade(train, train_targets, SmallOptions());
  const FernTrainingReport& report = r.report;
  ASSERT_EQ(report.checkpoint_ferns.size(), 11u);
  ASSERT_EQ(report.train_rmse.size(), 11u);
  EXPECT_EQ(report.checkpoint_ferns.front(), 0);
  EXPECT_EQ(report.checkpoint_ferns.back(), 150);
  for (size_t j = 1; j < report.train_rmse.size(); ++j)
    EXPECT_LT(report.train_rmse[j], report.train_rmse[j - 1]) << "checkpoint " << j;
  // k = 0 is c̄ alone.
  const Eigen::MatrixXf mean_only = Eigen::VectorXf::Map(r.cascade.mean.data(), 3).transpose().replicate(8000, 1);
  EXPECT_NEAR(report.train_rmse[0], Rms(mean_only, train_targets), 1e-6);
  EXPECT_LT(report.train_rmse.back(), 0.35 * report.train_rmse.front());  // measured 0.25

  const Eigen::MatrixXf predicted = r.cascade.PredictMatrix(test);
  const Eigen::MatrixXf test_mean_only = mean_only.topRows(1000);
  const double held_out = Rms(predicted, test_targets);
  // Held-out RMSE against predicting c̄ alone (measured 0.16 vs 0.54): the cascade
  // generalises, not only memorises.
  EXPECT_LT(held_out, 0.4 * Rms(test_mean_only, test_targets)) << "held-out RMSE " << held_out;
  // Final training estimates c_i^K equal Predict(t_i): the report's RMSE is reproduced.
  EXPECT_NEAR(Rms(r.cascade.PredictMatrix(train), train_targets), report.train_rmse.back(),
              1e-12 * report.train_rmse.back());
}

TEST(FernCascadeTest, AlternativeRulesAlsoLearn) {
  const Eigen::MatrixXf train = RandomPatches(2000, 64, 41);
  const Eigen::MatrixXf targets = KnownTargets(train);
  for (const auto& [threshold_rule, pair_selection] :
       std::vector<std::pair<std::string, std::string>>{{"range", "correlation"}, {"sample", "random"}}) {
    FernOptions o = SmallOptions();
    o.num_ferns = 100;
    o.fern_threshold_rule = FromString<FernThresholdRule>(threshold_rule, "threshold_rule");
    o.fern_pair_selection = FromString<FernPairSelection>(pair_selection, "pair_selection");
    const FernTrainingReport report = TrainFernCascade(train, targets, o).report;
    EXPECT_LT(report.train_rmse.back(), 0.9 * report.train_rmse.front()) << threshold_rule << "/" << pair_selection;
  }
}

TEST(FernCascadeTest, SameSeedSameBytesAndThreadCountIndependent) {
  const Eigen::MatrixXf train = RandomPatches(5000, 64, 51);  // > 2 reduction blocks
  const Eigen::MatrixXf targets = KnownTargets(train);
  FernOptions o = SmallOptions();
  o.num_ferns = 60;
  FernTrainingResult one, two, again;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = TrainFernCascade(train, targets, o);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    two = TrainFernCascade(train, targets, o);
    again = TrainFernCascade(train, targets, o);
  }
  EXPECT_TRUE(one.cascade == two.cascade) << "cascade differs between 1 and 2 threads";
  EXPECT_TRUE(two.cascade == again.cascade);
  EXPECT_EQ(one.report.train_rmse, two.report.train_rmse);

  const Eigen::MatrixXf test = RandomPatches(700, 64, 52);
  std::vector<float> p1, p2;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    p1 = PredictAllBatch(one.cascade, test);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    p2 = PredictAllBatch(two.cascade, test);
  }
  EXPECT_TRUE(SameBytes(p1, p2));

  FernOptions other = o;
  other.fern_seed = 8;
  EXPECT_FALSE(TrainFernCascade(train, targets, other).cascade == one.cascade);
}

TEST(FernCascadeTest, PredictEqualsPredictBatchByteForByte) {
  // D = 16 (the specialised path) and D = 3 (generic), counts not a multiple of the block.
  const Eigen::MatrixXf train = RandomPatches(1500, 100, 61);
  const Eigen::MatrixXf test = RandomPatches(301, 100, 62);
  Rng rng(63);
  Eigen::MatrixXf targets16(1500, 16);
  for (int i = 0; i < 1500; ++i)
    for (int d = 0; d < 16; ++d)
      targets16(i, d) = train(i, d) - train(i, 99 - d) + 0.1f * static_cast<float>(rng.Normal());
  FernOptions o = SmallOptions();
  o.num_ferns = 43;  // not a multiple of the fern group
  for (const Eigen::MatrixXf& targets : {targets16, Eigen::MatrixXf(KnownTargets(train))}) {
    const FernCascade fc = TrainFernCascade(train, targets, o).cascade;
    EXPECT_TRUE(SameBytes(PredictAllSingle(fc, test), PredictAllBatch(fc, test))) << "D = " << fc.dimensions;
    internal::SetFernAvx2Allowed(false);  // the generic kernel gives the same bytes
    EXPECT_TRUE(SameBytes(PredictAllSingle(fc, test), PredictAllBatch(fc, test))) << "generic, D = " << fc.dimensions;
    internal::SetFernAvx2Allowed(true);
    for (int count : {1, 5, 128, 129}) {
      const RowMatrixXf rows = test.topRows(count);
      std::vector<float> batch(static_cast<size_t>(count) * fc.dimensions);
      fc.PredictBatch(rows.data(), count, batch.data());
      const std::vector<float> all = PredictAllSingle(fc, test.topRows(count));
      EXPECT_TRUE(SameBytes(all, batch)) << "count " << count;
    }
  }
}

TEST(FernCascadeTest, ShorterCascadeIsAPrefix) {
  const Eigen::MatrixXf train = RandomPatches(1000, 64, 71);
  const Eigen::MatrixXf targets = KnownTargets(train);
  FernOptions o = SmallOptions();
  o.num_ferns = 50;
  const FernCascade long_cascade = TrainFernCascade(train, targets, o).cascade;
  o.num_ferns = 20;
  const FernCascade short_cascade = TrainFernCascade(train, targets, o).cascade;
  EXPECT_TRUE(long_cascade.Truncated(20) == short_cascade);
}

TEST(FernCascadeTest, BadInputIsAClearError) {
  const Eigen::MatrixXf patches = RandomPatches(50, 16, 81);
  const Eigen::MatrixXf targets = Eigen::MatrixXf::Ones(50, 2);
  FernOptions o;
  o.num_ferns = 2;
  o.num_sampled_pixels = 8;
  auto error = [&](const Eigen::MatrixXf& t, const Eigen::MatrixXf& c, const FernOptions& options) {
    return ErrorOf([&] { TrainFernCascade(t, c, options); });
  };
  EXPECT_NE(error(patches, targets.topRows(49), o).find("49 target rows"), std::string::npos);
  EXPECT_NE(error(patches.topRows(0), targets.topRows(0), o).find("empty"), std::string::npos);
  Eigen::MatrixXf bad_targets = targets;
  bad_targets(13, 1) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(error(patches, bad_targets, o).find("target row 13"), std::string::npos);
  Eigen::MatrixXf bad_patches = patches;
  bad_patches(27, 4) = std::numeric_limits<float>::infinity();
  const std::string pixel_message = error(bad_patches, targets, o);
  EXPECT_NE(pixel_message.find("patch row 27"), std::string::npos) << pixel_message;
  EXPECT_NE(pixel_message.find("pixel 4"), std::string::npos) << pixel_message;
  FernOptions too_many = o;
  too_many.num_sampled_pixels = 17;
  EXPECT_NE(error(patches, targets, too_many).find("num_sampled_pixels"), std::string::npos);
  FernOptions bad_beta = o;
  bad_beta.shrinkage = -1;
  EXPECT_NE(error(patches, targets, bad_beta).find("shrinkage"), std::string::npos);

  // A corrupted cascade (e.g. from a damaged model file) is rejected by Check.
  FernCascade fc = TrainFernCascade(patches, targets, o).cascade;
  EXPECT_TRUE(ErrorOf([&] { fc.Check("model.bin"); }).empty());
  FernCascade bad_pixel = fc;
  bad_pixel.pixel_b[3] = 16;
  EXPECT_NE(ErrorOf([&] { bad_pixel.Check("model.bin"); }).find("model.bin"), std::string::npos);
  FernCascade short_table = fc;
  short_table.outputs.pop_back();
  EXPECT_NE(ErrorOf([&] { short_table.Check("model.bin"); }).find("outputs"), std::string::npos);
  EXPECT_FALSE(ErrorOf([&] { fc.Truncated(3); }).empty());
}

TEST(FernCascadeTest, OptionsHaveUniqueReadableKeys) {
  FernOptions o;
  SetOptionsFromJson(
      R"({"num_ferns": 640, "depth": 4, "num_sampled_pixels": 30, "shrinkage": 250, "seed": 9,
          "threshold_rule": "range", "threshold_range": 0.5, "pair_selection": "random"})",
      "test", &o);
  EXPECT_EQ(o.num_ferns, 640);
  EXPECT_EQ(o.fern_depth, 4);
  EXPECT_EQ(o.num_sampled_pixels, 30);
  EXPECT_EQ(o.shrinkage, 250.0);
  EXPECT_EQ(o.fern_seed, 9u);
  EXPECT_EQ(o.fern_threshold_rule, FernThresholdRule::kRange);
  EXPECT_EQ(o.fern_threshold_range, 0.5);
  EXPECT_EQ(o.fern_pair_selection, FernPairSelection::kRandom);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"depth": 17})", "test", &o); }).find("fern_depth"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"fern_seed": 1})", "test", &o); }).find("it is now 'seed'"),
            std::string::npos);
  // A mode outside its enum is refused listing the allowed values (issue 18).
  EXPECT_NE(ErrorOf([&] { SetOptionsFromJson(R"({"threshold_rule": "median"})", "f.json", &o); })
                .find("f.json: option 'threshold_rule' must be one of: sample, range, got \"median\""),
            std::string::npos);
}

}  // namespace
}  // namespace crease
