// Tests of the online detail regression (pipeline/capture/detail_regression.h,
// paper Sec. 5.2) on a tiny model trained in-process (Sec. 4.2–4.3) on synthetic
// line textures (dark lines = wrinkle shadows) and their displacement maps
// (grooves along the lines).
#include "pipeline/capture/detail_regression.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "core/rng.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/pca.h"
#include "tests/test_util.h"
#include "tests/detail_model_test_util.h"
#include "tests/wrinkle_test_util.h"

namespace crease {
namespace {

constexpr int kS = 128;  // map size

// The user's wrinkle lines: centre (x, y) and direction (degrees).
struct Line {
  double cx, cy, deg;
};
const std::vector<Line>& Lines() {
  static const std::vector<Line> lines = {{64, 40, 5}, {60, 58, -8}, {40, 90, 60}, {90, 92, 120}};
  return lines;
}

// A texture with the lines at `depth` (0 = no lines) and its displacement map:
// a groove of `depth` mm per unit of shadow depth along each line (D < 0 on lines),
// lines limited to a 50-texel segment around their centre.
void Frame(double depth, cv::Mat* texture, cv::Mat* displacement, double shift = 0.0) {
  *texture = cv::Mat(kS, kS, CV_32F, cv::Scalar(0.5f));
  *displacement = cv::Mat(kS, kS, CV_32F, cv::Scalar(0.0f));
  for (const Line& l : Lines()) {
    const double phi = l.deg * std::numbers::pi / 180.0;
    const double tx = std::cos(phi), ty = std::sin(phi), nx = -ty, ny = tx;
    for (int y = 0; y < kS; ++y) {
      for (int x = 0; x < kS; ++x) {
        const double along = (x - l.cx) * tx + (y - l.cy) * ty;
        const double across = (x - l.cx) * nx + (y - l.cy) * ny - shift;
        const double fade = std::exp(-std::pow(std::max(0.0, std::abs(along) - 25.0) / 4.0, 2));
        const double g = std::exp(-across * across / (2 * 2.0 * 2.0)) * fade;
        texture->at<float>(y, x) -= static_cast<float>(depth * g);
        displacement->at<float>(y, x) -= static_cast<float>(0.5 * depth * g);
      }
    }
  }
}

cv::Mat Chart() {
  cv::Mat c(kS, kS, CV_8U, cv::Scalar(0));
  cv::circle(c, cv::Point(kS / 2, kS / 2), 62, cv::Scalar(255), cv::FILLED);
  return c;
}

// The tiny model: Sec. 4.2 wrinkle map and layout on training textures with the
// lines at several depths and small shifts, Sec. 4.3 PCA and fern cascade.
const DetailModel& TinyModel() {
  static const DetailModel model = [] {
    DetailModel m;
    m.map_resolution = kS;
    m.wrinkle = testing::TexelOptions();  // σ in texels, no regions
    m.wrinkle.dog_small_sigma = 3.0;
    m.wrinkle.dog_large_sigma = 4.0;
    m.patch.patch_size = 16;
    std::vector<cv::Mat> textures, displacements;
    Rng rng(5);
    for (int j = 0; j < 24; ++j) {
      cv::Mat t, d;
      const double shift = rng.Uniform(-1.5, 1.5);  // one draw per statement
      Frame(0.05 + 0.25 * rng.Uniform(), &t, &d, shift);
      textures.push_back(t);
      displacements.push_back(d);
    }
    std::vector<cv::Mat> responses;
    const WrinkleMap wmap = ComputeWrinkleMap(textures, Chart(), {}, m.wrinkle, &responses);
    const PatchLayout layout = PlacePatches(wmap, m.patch);
    testing::FitTinyRegressor(layout, textures, responses, displacements, /*pca_dimensions=*/4, /*num_ferns=*/120,
                              &m);
    return m;
  }();
  return model;
}

DetailRegressionOptions SmallOptions() {
  DetailRegressionOptions o;
  o.wrinkle_frames = 4;
  o.fill.fill_resolution = 64;  // s = 2 on the 128² maps
  return o;
}

// A regressor whose wrinkle map comes from four frames of the user's wrinkles.
DetailRegressor FixedRegressor(const DetailRegressionOptions& options = SmallOptions()) {
  DetailRegressor r(TinyModel(), {}, Chart(), options);
  for (double depth : {0.1, 0.2, 0.0, 0.15}) {
    cv::Mat t, d;
    Frame(depth, &t, &d);
    r.AddWrinkleFrame(t, cv::Mat());
  }
  EXPECT_FALSE(r.NeedsWrinkleFrames());
  r.FixLayout();
  return r;
}

double Correlation(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
  int n = 0;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x)
      if (mask.at<uint8_t>(y, x)) {
        const double u = a.at<float>(y, x), v = b.at<float>(y, x);
        sa += u, sb += v, saa += u * u, sbb += v * v, sab += u * v, ++n;
      }
  const double cov = sab / n - sa / n * sb / n;
  return cov / std::sqrt((saa / n - sa * sa / n / n) * (sbb / n - sb * sb / n / n));
}

TEST(DetailRegression, PredictsGroovesWhereTheTextureShowsLines) {
  const DetailRegressor r = FixedRegressor();
  ASSERT_GT(r.layout().num_patches(), 5);
  cv::Mat t, truth;
  Frame(0.18, &t, &truth);
  DetailTiming timing;
  const cv::Mat D = r.Regress(t, cv::Mat(), &timing);
  ASSERT_EQ(D.type(), CV_32FC1);
  ASSERT_EQ(D.rows, kS);
  const double corr = Correlation(D, truth, Chart());
  double lo, hi;
  cv::minMaxLoc(D, &lo, &hi);
  std::printf("%d patches; D^t vs truth over the chart: correlation %.3f; D in [%.3f, %.3f] mm, truth min %.3f; "
              "%.2f ms\n",
              r.layout().num_patches(), corr, lo, hi, -0.5 * 0.18, timing.total_ms());
  EXPECT_GT(corr, 0.5);
  EXPECT_LT(lo, -0.03);
  // 0 outside the chart; finite everywhere.
  const cv::Mat chart = Chart();
  for (int y = 0; y < kS; ++y)
    for (int x = 0; x < kS; ++x) {
      ASSERT_TRUE(std::isfinite(D.at<float>(y, x)));
      if (!chart.at<uint8_t>(y, x)) {
        ASSERT_EQ(D.at<float>(y, x), 0.0f);
      }
    }
}

TEST(DetailRegression, SameBytesForAnyThreadCountAndCall) {
  const DetailRegressor r = FixedRegressor();
  cv::Mat t, truth;
  Frame(0.2, &t, &truth);
  cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
  seen(cv::Rect(0, 70, 60, 58)).setTo(0);  // some patches dropped
  cv::Mat one, two, again;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = r.Regress(t, seen);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = r.Regress(t, seen);
    again = r.Regress(t, seen);
  }
  EXPECT_EQ(std::memcmp(one.data, two.data, one.total() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(two.data, again.data, two.total() * sizeof(float)), 0);
}

TEST(DetailRegression, UnseenPatchesAreDroppedAndLeaveNoGroove) {
  const DetailRegressor r = FixedRegressor();
  cv::Mat t, truth;
  Frame(0.2, &t, &truth);
  // The lower-left line (40, 90) is occluded: its texels are unseen (and 0 in T^t).
  cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
  const cv::Rect occluded(0, 66, 62, 62);
  seen(occluded).setTo(0);
  t.setTo(0.0f, seen == 0);
  DetailTiming timing;
  const cv::Mat D = r.Regress(t, seen, &timing);
  EXPECT_GT(timing.dropped, 0);
  double lo, hi;
  cv::minMaxLoc(D(cv::Rect(10, 76, 42, 42)), &lo, &hi);
  std::printf("%d of %d patches dropped; D in the occluded square: [%.4f, %.4f] mm\n", timing.dropped,
              timing.patches, lo, hi);
  EXPECT_GT(lo, -0.02);  // no groove where nothing was seen (the fill only)
  // The seen lines keep their grooves.
  EXPECT_GT(Correlation(D, truth, Chart() & (seen != 0)), 0.5);
}

// Rung R2-oracle: the truth's own patches, projected onto the PCA and merged as the
// regressed ones are, match the truth better than the regression does; the drops
// apply to them as to the regression (an occluded line leaves no groove), and the
// oracle is built from the truth map, not from the texture.
TEST(DetailRegression, TheTruthsOwnPatchesBoundTheRegression) {
  const DetailRegressor r = FixedRegressor();
  cv::Mat t, truth;
  Frame(0.18, &t, &truth);
  const cv::Mat chart = Chart();
  const double regressed = Correlation(r.Regress(t, cv::Mat()), truth, chart);
  DetailTiming timing;
  const cv::Mat oracle = r.AssembleFromTruth(t, cv::Mat(), truth, &timing);
  const double assembled = Correlation(oracle, truth, chart);
  std::printf("over the chart: regressed %.3f, the truth's own patches %.3f\n", regressed, assembled);
  EXPECT_GT(assembled, 0.9);
  EXPECT_GE(assembled, regressed);
  EXPECT_EQ(timing.patches, r.layout().num_patches());
  // The grooves follow the truth map: half as deep for half the truth.
  const cv::Mat half = r.AssembleFromTruth(t, cv::Mat(), 0.5 * truth);
  double lo_full, lo_half;
  cv::minMaxLoc(oracle, &lo_full);
  cv::minMaxLoc(half, &lo_half);
  EXPECT_LT(lo_full, 1.6 * lo_half);
  EXPECT_GT(lo_full, 2.4 * lo_half);
  // Drops as in Regress: the occluded line's patches drop out of the oracle too.
  cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
  seen(cv::Rect(0, 66, 62, 62)).setTo(0);
  cv::Mat t_occluded = t.clone();
  t_occluded.setTo(0.0f, seen == 0);
  DetailTiming occluded;
  const cv::Mat D = r.AssembleFromTruth(t_occluded, seen, truth, &occluded);
  EXPECT_GT(occluded.dropped, 0);
  double lo, hi;
  cv::minMaxLoc(D(cv::Rect(10, 76, 42, 42)), &lo, &hi);
  EXPECT_GT(lo, -0.02);
  // A truth map of the wrong size or with NaNs is refused.
  EXPECT_THROW(r.AssembleFromTruth(t, cv::Mat(), cv::Mat(64, 64, CV_32F, cv::Scalar(0))), Error);
  cv::Mat nan = truth.clone();
  nan.at<float>(40, 64) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(r.AssembleFromTruth(t, cv::Mat(), nan), Error);
}

// Rung R2-pairs: a frame's pairs are the kept patches (the drops of Regress), their
// texture rows the patches the regressor reads and their displacement rows the same
// patches of the truth map; the model scores the pairs as it scores the map.
TEST(DetailRegression, TheVideosPairsAreTheKeptPatchesOfTheTextureAndTheTruth) {
  const DetailRegressor r = FixedRegressor();
  cv::Mat t, truth;
  Frame(0.18, &t, &truth);
  cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
  seen(cv::Rect(0, 66, 62, 62)).setTo(0);
  t.setTo(0.0f, seen == 0);
  Eigen::MatrixXf T, D;
  std::vector<int> kept;
  r.CutPairs(t, seen, truth, &T, &D, &kept);
  const std::vector<uint8_t> drop = r.DroppedPatches(t, seen);
  std::vector<int> expected;
  for (int k = 0; k < static_cast<int>(drop.size()); ++k)
    if (!drop[k]) expected.push_back(k);
  ASSERT_GT(expected.size(), 3u);
  ASSERT_LT(expected.size(), drop.size());  // the occluded line's patches dropped out
  EXPECT_EQ(kept, expected);
  const int n = r.layout().patch_size * r.layout().patch_size;
  ASSERT_EQ(T.rows(), static_cast<Eigen::Index>(kept.size()));
  ASSERT_EQ(T.cols(), n);
  ASSERT_EQ(D.rows(), T.rows());
  // Both sides are sampled alike: the texture cut as its own truth gives equal rows.
  Eigen::MatrixXf T2, D2;
  r.CutPairs(t, seen, t, &T2, &D2);
  EXPECT_EQ(T2, T);
  EXPECT_EQ(D2, T);
  // The regression of the rows predicts the truth's rows (as Regress predicts the map).
  const DetailModel& m = TinyModel();
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = T;
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c(T.rows(), m.pca.dimensions());
  m.RegressBatch(rows.data(), static_cast<int>(T.rows()), c.data());
  const Eigen::MatrixXf predicted = (c * m.pca.basis.transpose()).rowwise() + m.pca.mean.transpose();
  const Eigen::ArrayXf p = Eigen::Map<const Eigen::ArrayXf>(predicted.data(), predicted.size());
  const Eigen::ArrayXf d = Eigen::Map<const Eigen::ArrayXf>(D.data(), D.size());
  const double corr = ((p - p.mean()) * (d - d.mean())).mean() /
                      std::sqrt((p - p.mean()).square().mean() * (d - d.mean()).square().mean());
  std::printf("%zu of %zu patches kept; predicted vs true rows: correlation %.3f\n", kept.size(), drop.size(), corr);
  EXPECT_GT(corr, 0.5);
  EXPECT_THROW(r.CutPairs(t, seen, cv::Mat(64, 64, CV_32F, cv::Scalar(0)), &T, &D), Error);
}

// Steps 1–4 against a reference built from the training blocks directly: on every
// covered texel D^t is the bilinear-weighted average of the reconstructed patches
// that did not drop out (Splat of the kept patches over Splat of their indicator).
TEST(DetailRegression, MergeAveragesTheKeptPatches) {
  const DetailRegressor r = FixedRegressor();
  cv::Mat t, truth;
  Frame(0.2, &t, &truth);
  cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
  seen(cv::Rect(0, 66, 62, 62)).setTo(0);
  t.setTo(0.0f, seen == 0);
  const cv::Mat D = r.Regress(t, seen);
  const std::vector<uint8_t> drop = r.DroppedPatches(t, seen);
  const PatchSampler sampler(r.layout());
  const int N = sampler.num_patches(), n = sampler.patch_size() * sampler.patch_size();
  ASSERT_EQ(static_cast<int>(drop.size()), N);
  const DetailModel& model = TinyModel();
  const Eigen::MatrixXf c = model.cascade.PredictMatrix(sampler.Sample(t));  // Eq. 6
  Eigen::MatrixXf d = (c * model.pca.basis.transpose()).rowwise() + model.pca.mean.transpose();
  Eigen::MatrixXf kept = Eigen::MatrixXf::Ones(N, n);
  int dropped = 0;
  for (int k = 0; k < N; ++k)
    if (drop[k]) {
      d.row(k).setZero();
      kept.row(k).setZero();
      ++dropped;
    }
  ASSERT_GT(dropped, 0);
  ASSERT_LT(dropped, N);
  const cv::Mat num = sampler.Splat(d), share = sampler.Splat(kept);
  double worst = 0.0;
  int compared = 0;
  for (int y = 0; y < kS; ++y)
    for (int x = 0; x < kS; ++x) {
      if (sampler.splat_weight().at<float>(y, x) <= 0.0f || !Chart().at<uint8_t>(y, x)) continue;
      const float s = share.at<float>(y, x);
      const double ref = s > 1e-4f ? num.at<float>(y, x) / s : 0.0;
      worst = std::max(worst, std::abs(ref - D.at<float>(y, x)));
      ++compared;
    }
  std::printf("%d of %d patches dropped; merge vs reference over %d texels: max |diff| %.2e mm\n", dropped, N,
              compared, worst);
  EXPECT_LT(worst, 1e-5);
}

TEST(DetailRegression, GateLeavesAFrameWithoutLinesFlat) {
  DetailRegressionOptions o = SmallOptions();
  o.gate_by_response = true;
  const DetailRegressor gated = FixedRegressor(o);
  const DetailRegressor plain = FixedRegressor();
  cv::Mat flat, truth;
  Frame(0.0, &flat, &truth);
  DetailTiming tg;
  const cv::Mat Dg = gated.Regress(flat, cv::Mat(), &tg);
  const cv::Mat Dp = plain.Regress(flat, cv::Mat());
  EXPECT_EQ(tg.dropped, tg.patches);
  EXPECT_EQ(cv::countNonZero(Dg != 0), 0);
  std::printf("flat frame: max |D| %.4f mm without the gate, %.4f with it\n", cv::norm(Dp, cv::NORM_INF),
              cv::norm(Dg, cv::NORM_INF));
  // With lines the gate keeps the patches on them.
  cv::Mat t;
  Frame(0.2, &t, &truth);
  DetailTiming tl;
  const cv::Mat D = gated.Regress(t, cv::Mat(), &tl);
  EXPECT_LT(tl.dropped, tl.patches / 2);
  EXPECT_GT(Correlation(D, truth, Chart()), 0.5);
}

// The soft gate (gate_softness), apart from the cascade: the truth's own patches
// assembled through the gate (AssembleFromTruth) while the texture's lines deepen by
// small steps, so that the patches' DoG responses cross α. The hard gate switches
// the patches on at once and D^t jumps; the soft gate's ramp turns them on over a
// range of depths. Both leave a frame without lines flat and, with deep lines, keep
// the patches on them.
TEST(DetailRegression, TheSoftGateTurnsPatchesOnGradually) {
  DetailRegressionOptions o = SmallOptions();
  o.gate_by_response = true;
  o.gate_softness = 0.0;
  const DetailRegressor hard = FixedRegressor(o);
  o.gate_softness = 0.75;
  const DetailRegressor soft = FixedRegressor(o);
  cv::Mat t, truth, unused;
  Frame(0.2, &unused, &truth);
  auto largest_step = [&](const DetailRegressor& r) {
    double worst = 0.0;
    cv::Mat previous;
    for (int i = 0; i <= 60; ++i) {
      Frame(0.0025 * i, &t, &unused);
      const cv::Mat D = r.AssembleFromTruth(t, cv::Mat(), truth);
      if (!previous.empty()) worst = std::max(worst, cv::norm(D, previous, cv::NORM_INF));
      previous = D;
    }
    return worst;
  };
  const double hard_step = largest_step(hard), soft_step = largest_step(soft);
  std::printf("largest change of D^t between lines 0.0025 apart in depth: hard gate %.4f mm, soft %.4f mm\n",
              hard_step, soft_step);
  EXPECT_LT(soft_step, 0.5 * hard_step);
  Frame(0.0, &t, &unused);
  EXPECT_EQ(cv::countNonZero(soft.AssembleFromTruth(t, cv::Mat(), truth) != 0), 0);
  Frame(0.2, &t, &unused);
  EXPECT_GT(Correlation(soft.Regress(t, cv::Mat()), truth, Chart()), 0.5);
}

// Difference 7 (recentre_radius): the lines move across themselves by 4 texels after
// the wrinkle frames laid the patches on them (the tracker's drift). With the gate the
// fixed patches lose them: their centres' DoG response falls. Patches that move to
// their line's response in each frame keep the grooves where the frame shows them, in
// the truth's own patches (AssembleFromTruth) and in the regression, the same bytes
// for any thread count; on a frame whose lines did not move they cost nothing.
TEST(DetailRegression, RecentredPatchesFollowLinesThatMoved) {
  DetailRegressionOptions o = SmallOptions();
  o.gate_by_response = true;
  const DetailRegressor fixed = FixedRegressor(o);
  o.recentre_radius = 6.0;
  const DetailRegressor moving = FixedRegressor(o);
  cv::Mat t, truth;
  Frame(0.2, &t, &truth, /*shift=*/4.0);
  const double oracle_fixed = Correlation(fixed.AssembleFromTruth(t, cv::Mat(), truth), truth, Chart());
  const double oracle_moving = Correlation(moving.AssembleFromTruth(t, cv::Mat(), truth), truth, Chart());
  const double fixed_corr = Correlation(fixed.Regress(t, cv::Mat()), truth, Chart());
  cv::Mat one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = moving.Regress(t, cv::Mat());
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = moving.Regress(t, cv::Mat());
  }
  const double moving_corr = Correlation(two, truth, Chart());
  std::printf("lines moved 4 texels: oracle %.3f fixed / %.3f re-centred; regression %.3f / %.3f\n", oracle_fixed,
              oracle_moving, fixed_corr, moving_corr);
  EXPECT_GT(oracle_moving, oracle_fixed + 0.1);
  EXPECT_GT(moving_corr, fixed_corr + 0.1);
  EXPECT_GT(moving_corr, 0.5);
  EXPECT_EQ(std::memcmp(one.data, two.data, one.total() * sizeof(float)), 0);
  Frame(0.2, &t, &truth);
  const double still_fixed = Correlation(fixed.Regress(t, cv::Mat()), truth, Chart());
  const double still_moving = Correlation(moving.Regress(t, cv::Mat()), truth, Chart());
  std::printf("lines in place: regression %.3f fixed / %.3f re-centred\n", still_fixed, still_moving);
  EXPECT_GT(still_moving, still_fixed - 0.05);
}

// A static dark stripe (a brow painted in the albedo) in every frame, beside the
// lines that come and go: read raw, the wrinkle map puts patches on it; flattened by
// the most neutral wrinkle frame (texture_reference = difference, Difference 6) it
// cancels, and the lines still make patches and grooves.
TEST(DetailRegression, AReferenceTextureCancelsStaticFeaturesButKeepsWrinkles) {
  auto frame = [](double depth, cv::Mat* t, cv::Mat* d) {
    Frame(depth, t, d);
    (*t)(cv::Rect(34, 18, 60, 5)) -= 0.25f;
  };
  auto near_stripe = [](const DetailRegressor& r) {
    int n = 0;
    for (const auto& p : r.layout().patches) n += std::abs(p.center_texel.y() - 20.0f) < 6.0f;
    return n;
  };
  DetailModel flat_model = TinyModel();
  flat_model.wrinkle.texture_reference = TextureReference::kDifference;
  DetailRegressionOptions o = SmallOptions();
  o.wrinkle_frames = 5;
  DetailRegressor raw(TinyModel(), {}, Chart(), o), flat(flat_model, {}, Chart(), o);
  // Lines in most wrinkle frames: the reference is the frame closest to the neutral
  // (expression = the line depth here), not their median, which holds the lines.
  for (double depth : {0.2, 0.15, 0.0, 0.18, 0.1}) {
    cv::Mat t, d;
    frame(depth, &t, &d);
    raw.AddWrinkleFrame(t, cv::Mat(), depth);
    flat.AddWrinkleFrame(t, cv::Mat(), depth);
  }
  raw.FixLayout();
  flat.FixLayout();
  EXPECT_GT(near_stripe(raw), 0);
  EXPECT_EQ(near_stripe(flat), 0);
  ASSERT_GT(flat.layout().num_patches(), 3);
  cv::Mat t, truth;
  frame(0.18, &t, &truth);
  EXPECT_GT(Correlation(flat.Regress(t, cv::Mat()), truth, Chart()), 0.5);
}

// The same lines on a skin five times darker (albedo × 0.2: the lines' shading scales
// with it). Flattened to the reference's own mean (the default) the absolute α finds
// fewer of them; flattened to a fixed gray level (texture_reference_level) the darker
// skin gives the same wrinkle map and layout, patch for patch.
TEST(DetailRegression, AFixedReferenceLevelMakesTheLayoutIndependentOfTheSkinTone) {
  auto layout = [](double level, float albedo) {
    DetailModel model = TinyModel();
    model.wrinkle.texture_reference = TextureReference::kRatio;
    model.wrinkle.texture_reference_level = level;
    DetailRegressionOptions o = SmallOptions();
    o.wrinkle_frames = 5;
    DetailRegressor r(model, {}, Chart(), o);
    for (double depth : {0.2, 0.15, 0.0, 0.18, 0.1}) {
      cv::Mat t, d;
      Frame(depth, &t, &d);
      r.AddWrinkleFrame(t * albedo, cv::Mat(), depth);
    }
    r.FixLayout();
    return r.layout();
  };
  const PatchLayout own_bright = layout(0.0, 1.0f), own_dark = layout(0.0, 0.2f);
  ASSERT_GT(own_bright.num_patches(), 3);
  EXPECT_LT(own_dark.num_patches(), own_bright.num_patches() / 2);
  const PatchLayout fixed_bright = layout(0.5, 1.0f), fixed_dark = layout(0.5, 0.2f);
  ASSERT_EQ(fixed_dark.num_patches(), fixed_bright.num_patches());
  EXPECT_EQ(fixed_bright.num_patches(), own_bright.num_patches());  // the bright skin's mean is 0.5
  for (int k = 0; k < fixed_bright.num_patches(); ++k) {
    EXPECT_NEAR(fixed_dark.patches[k].center_texel.x(), fixed_bright.patches[k].center_texel.x(), 1e-3f);
    EXPECT_NEAR(fixed_dark.patches[k].center_texel.y(), fixed_bright.patches[k].center_texel.y(), 1e-3f);
  }
}

TEST(DetailRegression, AReferenceLevelWithoutAReferenceIsRefused) {
  WrinkleMapOptions o;
  o.texture_reference_level = 0.5;
  EXPECT_THROW(o.Check(), Error);
  o.texture_reference = TextureReference::kDifference;
  EXPECT_NO_THROW(o.Check());
  o.texture_reference_level = -1.0;
  EXPECT_THROW(o.Check(), Error);
}

// The tracker slides the texture over the face by a few texels in an expression: with
// reference_alignment.warp_texture, T^t is resampled onto the most neutral frames'
// registration, and D^t lands where the lines are in that registration.
TEST(DetailRegression, WarpingTheTextureOntoTheReferenceUndoesASlide) {
  cv::Mat skin(kS, kS, CV_32F);
  Rng rng(11);
  for (int y = 0; y < kS; ++y)
    for (int x = 0; x < kS; ++x) skin.at<float>(y, x) = static_cast<float>(rng.Uniform(-1.0, 1.0));
  cv::GaussianBlur(skin, skin, cv::Size(0, 0), 2.0);
  skin *= 0.03 / cv::norm(skin, cv::NORM_INF);
  // The frame with lines at `depth`, all of it slid down by `slide` texels.
  auto frame = [&](double depth, double slide, cv::Mat* t, cv::Mat* d) {
    Frame(depth, t, d);
    *t += skin;
    const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, 0, 0, 1, slide);
    cv::warpAffine(*t, *t, m, t->size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  };
  DetailRegressionOptions o = SmallOptions();
  o.reference_alignment.resolution = 64;
  o.reference_alignment.highpass_sigma = 4.0;
  o.reference_alignment.smoothing_sigma = 3.0;
  DetailRegressionOptions aligned_options = o;
  aligned_options.reference_alignment.enabled = true;
  aligned_options.reference_alignment.warp_texture = true;
  DetailRegressor plain(TinyModel(), {}, Chart(), o), aligned(TinyModel(), {}, Chart(), aligned_options);
  for (double depth : {0.0, 0.2, 0.15, 0.1}) {
    cv::Mat t, d;
    frame(depth, 0.0, &t, &d);
    plain.AddWrinkleFrame(t, cv::Mat(), depth);
    aligned.AddWrinkleFrame(t, cv::Mat(), depth);
  }
  plain.FixLayout();
  aligned.FixLayout();
  cv::Mat t, truth;
  frame(0.18, 4.0, &t, &truth);
  DetailTiming timing;
  const double c_plain = Correlation(plain.Regress(t, cv::Mat()), truth, Chart());
  const double c_aligned = Correlation(aligned.Regress(t, cv::Mat(), &timing), truth, Chart());
  EXPECT_GT(c_aligned, 0.5);
  EXPECT_GT(c_aligned, c_plain + 0.2) << "plain " << c_plain;
  EXPECT_NEAR(timing.reference_shift, 2.0, 0.5);  // 4 texels on the 64² flow grid of a 128² map
}

TEST(DetailRegression, WrinkleMapIgnoresOcclusionBorders) {
  // Frames with no lines; in two of them one half of the chart is unseen (0 in T^t).
  // Every texel is seen in at least 3 of 4 frames, so only the extension of the seen
  // texels keeps the occlusion borders from reading as dark lines (no patches).
  DetailRegressor r(TinyModel(), {}, Chart(), SmallOptions());
  cv::Mat t, d;
  Frame(0.0, &t, &d);
  for (int i = 0; i < 4; ++i) {
    cv::Mat seen(kS, kS, CV_8U, cv::Scalar(255));
    if (i == 0) seen(cv::Rect(0, 0, 64, 128)).setTo(0);
    if (i == 1) seen(cv::Rect(64, 0, 64, 128)).setTo(0);
    cv::Mat ti = t.clone();
    ti.setTo(0.0f, seen == 0);
    r.AddWrinkleFrame(ti, seen);
  }
  r.FixLayout();
  double w_max;
  cv::minMaxLoc(r.wrinkle_map().probability, nullptr, &w_max);
  std::printf("occlusion borders: max W %.5f, %d patches\n", w_max, r.layout().num_patches());
  EXPECT_EQ(r.layout().num_patches(), 0);
  EXPECT_EQ(cv::countNonZero(r.Regress(t, cv::Mat()) != 0), 0);
}

TEST(DetailRegression, ASeenMarginKeepsTheSilhouettesSeamOutOfTheWrinkleMap) {
  // No lines; the skin darkens gently towards a silhouette (the right fifth of the
  // chart, never seen), as a cheek turning away does. The seam between the seen texels and their
  // smooth extension reads as a line unless texels near it do not count
  // (wrinkle_seen_margin_sigmas, header "Unseen texels"; the tiny model's large σ is 4).
  cv::Mat t(kS, kS, CV_32F), seen(kS, kS, CV_8U, cv::Scalar(255));
  const int edge = kS * 4 / 5;
  for (int y = 0; y < kS; ++y) {
    for (int x = 0; x < kS; ++x) t.at<float>(y, x) = static_cast<float>(0.5 - 0.3 * std::pow(x / double(edge), 2));
  }
  seen.colRange(edge, kS).setTo(0);
  t.setTo(0.0f, seen == 0);
  auto patches_near_the_seam = [&](double margin) {
    DetailRegressionOptions o = SmallOptions();
    o.wrinkle_seen_margin_sigmas = margin;
    DetailRegressor r(TinyModel(), {}, Chart(), o);
    for (int i = 0; i < 4; ++i) r.AddWrinkleFrame(t, seen);
    r.FixLayout();
    int near = 0;
    for (const PatchFrame& f : r.layout().patches) near += f.center_texel.x() > edge - 12;
    std::printf("seen margin %.1f σ: %d patches, %d within 12 texels of the seam\n", margin, r.layout().num_patches(),
                near);
    return near;
  };
  EXPECT_GT(patches_near_the_seam(0.0), 0);  // the seam reads as a line
  EXPECT_EQ(patches_near_the_seam(DetailRegressionOptions().wrinkle_seen_margin_sigmas), 0);
}

TEST(DetailRegression, MisuseIsAClearError) {
  DetailRegressor r(TinyModel(), {}, Chart(), SmallOptions());
  cv::Mat t, d;
  Frame(0.1, &t, &d);
  EXPECT_ERROR_HAS(r.Regress(t, cv::Mat()), "layout is not fixed");
  EXPECT_ERROR_HAS(r.FixLayout(), "no wrinkle frames");
  EXPECT_ERROR_HAS(r.AddWrinkleFrame(cv::Mat(64, 64, CV_32F, cv::Scalar(0)), cv::Mat()), "expected 128x128");
  EXPECT_ERROR_HAS(r.AddWrinkleFrame(cv::Mat(kS, kS, CV_8U, cv::Scalar(0)), cv::Mat()), "CV_32FC1");
  EXPECT_ERROR_HAS(r.AddWrinkleFrame(t, cv::Mat(kS, kS, CV_32F, cv::Scalar(0))), "seen mask must be CV_8UC1");
  r.AddWrinkleFrame(t, cv::Mat());
  EXPECT_TRUE(r.NeedsWrinkleFrames());
  r.FixLayout();
  EXPECT_ERROR_HAS(r.AddWrinkleFrame(t, cv::Mat()), "already fixed");
  EXPECT_ERROR_HAS(r.FixLayout(), "already fixed");
  EXPECT_ERROR_HAS(DetailRegressor(TinyModel(), {}, cv::Mat(64, 64, CV_8U, cv::Scalar(255)), SmallOptions()),
                   "coverage is 64x64, expected 128x128");
  DetailRegressionOptions bad = SmallOptions();
  bad.wrinkle_frames = 0;
  EXPECT_ERROR_HAS(DetailRegressor(TinyModel(), {}, Chart(), bad), "wrinkle_frames");
  DetailModel regions = TinyModel();
  regions.wrinkle.patch_regions = {"forehead"};
  EXPECT_ERROR_HAS(DetailRegressor(regions, {}, Chart(), SmallOptions()), "unknown region 'forehead'");
}

}  // namespace
}  // namespace crease
