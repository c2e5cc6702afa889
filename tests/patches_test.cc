// Tests of the local wrinkle patches (paper Sec. 4.2) and their merge (Sec. 5.2):
// orientation, greedy placement properties, exact bilinear sampling, splatting,
// training pairs, determinism and errors.
#include "pipeline/training/patches.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numbers>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/options.h"
#include "core/rng.h"
#include "test_util.h"
#include "wrinkle_test_util.h"

namespace crease {
namespace {

constexpr double kPi = std::numbers::pi;

using testing::AngleDiffMod180;
using testing::LineTexture;
using testing::TexelOptions;

bool SameBytes(const cv::Mat& x, const cv::Mat& y) {
  return x.size() == y.size() && x.type() == y.type() && std::equal(x.datastart, x.dataend, y.datastart);
}

// A smooth positive "wrinkle map" with random angles, for placement properties.
struct SyntheticMap {
  cv::Mat probability, angle, coverage;
};
SyntheticMap MakeSyntheticMap(int S, uint64_t seed) {
  Rng rng(seed);
  SyntheticMap m;
  cv::Mat noise(S, S, CV_32F);
  m.angle = cv::Mat(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) {
      noise.at<float>(y, x) = static_cast<float>(rng.Uniform(0.0, 1.0));
      m.angle.at<float>(y, x) = static_cast<float>(rng.Uniform(0.0, kPi));
    }
  cv::GaussianBlur(noise, m.probability, cv::Size(0, 0), 3.0);
  m.probability -= 0.5;
  m.probability = cv::max(m.probability, 0.0f);  // W > 0 on blobs only
  m.coverage = cv::Mat(S, S, CV_8U, cv::Scalar(0));
  cv::circle(m.coverage, cv::Point(S / 2, S / 2), S / 2 - 6, cv::Scalar(255), cv::FILLED);
  return m;
}

TEST(PatchLayoutOptionsTest, DefaultsAndChecks) {
  PatchLayoutOptions o;
  EXPECT_EQ(o.patch_size, 32);
  EXPECT_EQ(o.patch_density, 0.5);
  EXPECT_EQ(o.patch_max_outside_fraction, 0.0);
  o.Check();
  SetOptionsFromJson(R"({"size": 16, "density": 0.25})", "--set", &o);
  EXPECT_EQ(o.patch_size, 16);
  o.patch_density = 0.0;
  EXPECT_ERROR_HAS(o.Check(), "patch_density");
  o = PatchLayoutOptions();
  o.patch_max_outside_fraction = 1.5;
  EXPECT_ERROR_HAS(o.Check(), "patch_max_outside_fraction");
}

TEST(PatchesTest, PatchOrientationFollowsALine) {
  const int S = 128;
  for (double line_deg : {0.0, 25.0, 60.0, 90.0, 145.0}) {
    SCOPED_TRACE(line_deg);
    const cv::Mat t = LineTexture(S, line_deg);
    const WrinkleMap map = ComputeWrinkleMap({t}, cv::Mat(), {}, TexelOptions());
    PatchLayoutOptions po;
    po.patch_size = 24;
    const PatchLayout layout = PlacePatches(map, po);
    ASSERT_GT(layout.num_patches(), 0);
    for (const PatchFrame& f : layout.patches) {
      EXPECT_LT(AngleDiffMod180(f.angle * 180 / kPi, line_deg + 90.0), 2.0)
          << "patch at " << f.center_texel.transpose() << " angle " << f.angle * 180 / kPi;
    }
    // The first patch sits on the line and shows it as the middle column(s).
    const PatchFrame& f = layout.patches[0];
    const int w = layout.patch_size;
    std::vector<float> patch(w * w);
    SamplePatch(t, f, w, patch.data());
    for (int b = 0; b < w; ++b) {
      int darkest = 0;
      for (int a = 1; a < w; ++a)
        if (patch[b * w + a] < patch[b * w + darkest]) darkest = a;
      EXPECT_NEAR(darkest, 0.5 * (w - 1), 1.0) << "row " << b;
    }
  }
}

TEST(PatchesTest, GreedyPlacementProperties) {
  const int S = 160;
  const SyntheticMap m = MakeSyntheticMap(S, 7);
  PatchLayoutOptions o;
  o.patch_size = 16;
  PatchLayoutReport report;
  const PatchLayout layout = PlacePatches(m.probability, m.angle, cv::Mat(), m.coverage, o, &report);
  ASSERT_GT(layout.num_patches(), 5);
  EXPECT_EQ(report.placed, layout.num_patches());
  EXPECT_GT(report.skipped_outside, 0) << "the disc boundary must reject some candidates";
  EXPECT_EQ(layout.map_size, S);
  EXPECT_EQ(layout.patch_size, 16);

  // Candidates are taken by decreasing W, so patches come in non-increasing W
  // (the global maximum itself may not fit inside the disc; the next test checks
  // it with full coverage).
  auto w_at = [&](const PatchFrame& f) {
    return m.probability.at<float>(static_cast<int>(f.center_texel.y()), static_cast<int>(f.center_texel.x()));
  };
  for (int i = 1; i < layout.num_patches(); ++i) EXPECT_LE(w_at(layout.patches[i]), w_at(layout.patches[i - 1]));

  // No later centre lies strictly inside an earlier patch's oriented ρw sub-rectangle.
  const float h = 0.5f * static_cast<float>(o.patch_density * o.patch_size);
  for (int i = 0; i < layout.num_patches(); ++i) {
    const PatchFrame& p = layout.patches[i];
    const float c = std::cos(p.angle), s = std::sin(p.angle);
    for (int j = i + 1; j < layout.num_patches(); ++j) {
      const Eigen::Vector2f d = layout.patches[j].center_texel - p.center_texel;
      const float a1 = d.x() * c + d.y() * s, a2 = -d.x() * s + d.y() * c;
      EXPECT_FALSE(std::abs(a1) < h - 1e-3f && std::abs(a2) < h - 1e-3f) << "patches " << i << " and " << j;
      EXPECT_GE(d.norm(), h - 1e-3f);
    }
  }

  // Patches stay inside coverage: sampling a map that is hugely negative outside
  // the coverage never picks up any of it.
  cv::Mat indicator(S, S, CV_32F, cv::Scalar(-1e6));
  indicator.setTo(cv::Scalar(0), m.coverage);
  std::vector<float> patch(o.patch_size * o.patch_size);
  for (const PatchFrame& f : layout.patches) {
    SamplePatch(indicator, f, o.patch_size, patch.data());
    EXPECT_GE(*std::min_element(patch.begin(), patch.end()), -1e-3f) << f.center_texel.transpose();
  }
}

TEST(PatchesTest, FirstPatchAtMaximumAndListExhausted) {
  // Full coverage: the first patch is the global maximum (lowest index among
  // ties) and every candidate ends inside some placed patch's sub-rectangle.
  const int S = 96;
  SyntheticMap m = MakeSyntheticMap(S, 11);
  cv::Mat valid(S, S, CV_8U, cv::Scalar(255));
  valid(cv::Rect(0, 0, S, 20)).setTo(0);
  PatchLayoutOptions o;
  o.patch_size = 12;
  o.patch_max_outside_fraction = 1.0;  // allow patches over the border
  PatchLayoutReport report;
  const PatchLayout layout = PlacePatches(m.probability, m.angle, valid, cv::Mat(), o, &report);
  EXPECT_EQ(report.skipped_outside, 0);
  cv::Point best;
  cv::minMaxLoc(m.probability, nullptr, nullptr, nullptr, &best, valid);
  EXPECT_EQ(layout.patches[0].center_texel, Eigen::Vector2f(best.x, best.y));
  EXPECT_FLOAT_EQ(layout.patches[0].angle, m.angle.at<float>(best.y, best.x));
  const float h = 0.5f * static_cast<float>(o.patch_density * o.patch_size);
  int candidates = 0;
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) {
      if (!(m.probability.at<float>(y, x) > 0 && valid.at<uint8_t>(y, x))) continue;
      ++candidates;
      bool covered = false;
      for (const PatchFrame& f : layout.patches) {
        const float c = std::cos(f.angle), s = std::sin(f.angle);
        const float dx = x - f.center_texel.x(), dy = y - f.center_texel.y();
        if (std::abs(dx * c + dy * s) < h + 1e-3f && std::abs(-dx * s + dy * c) < h + 1e-3f) covered = true;
      }
      EXPECT_TRUE(covered) << "candidate " << x << "," << y << " left in the list";
      if (!covered) return;
    }
  EXPECT_EQ(report.candidates, candidates);
  for (const PatchFrame& f : layout.patches) EXPECT_GE(f.center_texel.y(), 20.0f) << "outside valid";
}

TEST(PatchesTest, SamplePatchOfLinearFunctionIsExact) {
  const int S = 64;
  cv::Mat f(S, S, CV_32F);
  auto lin = [](double x, double y) { return 0.3 + 0.01 * x - 0.02 * y; };
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) f.at<float>(y, x) = static_cast<float>(lin(x, y));
  Rng rng(3);
  const int w = 9;
  std::vector<float> patch(w * w);
  for (int trial = 0; trial < 20; ++trial) {
    PatchFrame frame;
    frame.center_texel = Eigen::Vector2f(static_cast<float>(rng.Uniform(15, 48)), static_cast<float>(rng.Uniform(15, 48)));
    frame.angle = static_cast<float>(rng.Uniform(0, kPi));
    SamplePatch(f, frame, w, patch.data());
    const double c = std::cos(frame.angle), s = std::sin(frame.angle);
    for (int b = 0; b < w; ++b)
      for (int a = 0; a < w; ++a) {
        const double sa = a - 0.5 * (w - 1), sb = b - 0.5 * (w - 1);
        const double x = frame.center_texel.x() + sa * c - sb * s, y = frame.center_texel.y() + sa * s + sb * c;
        EXPECT_NEAR(patch[b * w + a], lin(x, y), 2e-6) << a << "," << b;
      }
  }
  // Axis-aligned at a texel centre: samples are texels.
  PatchFrame axis{Eigen::Vector2f(20, 30), 0.0f};
  SamplePatch(f, axis, 3, patch.data());
  EXPECT_EQ(patch[0], f.at<float>(29, 19));
  EXPECT_EQ(patch[5], f.at<float>(30, 21));
}

// The pair augmentation's copies: the same patch moved across its line (along e1) by
// ±k · shift; a copy's sample equals the original's sample shifted by k · shift texels
// along its x axis; copies leaving the map are skipped.
TEST(PatchesTest, ShiftedLayoutMovesCopiesAcrossTheLine) {
  const int S = 64, w = 9;
  PatchLayout layout;
  layout.map_size = S;
  layout.patch_size = w;
  layout.patches = {{Eigen::Vector2f(30, 32), 0.4f}, {Eigen::Vector2f(1.5f, 20), 0.0f}};
  EXPECT_EQ(ShiftedLayout(layout, 2.0, 0).num_patches(), 2);
  const PatchLayout shifted = ShiftedLayout(layout, 2.0, 2);
  // 2 originals, then k = −2, −1, 1, 2 of each; the second patch's k = −1, −2 copies
  // (x = −0.5, −2.5) leave the map.
  ASSERT_EQ(shifted.num_patches(), 2 + 4 + 2);
  shifted.Validate("shifted");
  cv::Mat f(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) f.at<float>(y, x) = static_cast<float>(0.3 + 0.01 * x - 0.02 * y);
  std::vector<float> original(w * w), copy(w * w);
  SamplePatch(f, layout.patches[0], w, original.data());
  // Order: the originals, then per k = −2, −1, 1, 2 the copies that stay on the map:
  // [p0], [p0], [p0, p1], [p0, p1]; k = 2 of the first patch is the 7th.
  const PatchFrame& plus2 = shifted.patches[6];
  EXPECT_FLOAT_EQ(plus2.angle, 0.4f);
  SamplePatch(f, plus2, w, copy.data());
  // f is linear: moving by 4 texels along e1 adds 4 · (0.01 cos θ − 0.02 sin θ).
  const double step = 4 * (0.01 * std::cos(0.4) - 0.02 * std::sin(0.4));
  for (int i = 0; i < w * w; ++i) EXPECT_NEAR(copy[i] - original[i], step, 1e-5) << i;
  EXPECT_THROW(ShiftedLayout(layout, 0.0, 1), Error);
  EXPECT_THROW(ShiftedLayout(layout, 2.0, -1), Error);
}

TEST(PatchesTest, SamplerMatchesSamplePatchAndSplatReproducesSmoothMaps) {
  const int S = 128;
  const SyntheticMap m = MakeSyntheticMap(S, 5);
  PatchLayoutOptions o;
  o.patch_size = 16;
  const PatchLayout layout = PlacePatches(m.probability, m.angle, cv::Mat(), m.coverage, o);
  ASSERT_GT(layout.num_patches(), 3);
  const PatchSampler sampler(layout);
  EXPECT_EQ(sampler.num_patches(), layout.num_patches());
  cv::Mat smooth(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) smooth.at<float>(y, x) = static_cast<float>(std::sin(x / 20.0) * std::cos(y / 25.0));
  const Eigen::MatrixXf patches = sampler.Sample(smooth);
  ASSERT_EQ(patches.rows(), layout.num_patches());
  ASSERT_EQ(patches.cols(), 256);
  std::vector<float> one(256);
  for (int k = 0; k < layout.num_patches(); ++k) {
    SamplePatch(smooth, layout.patches[k], 16, one.data());
    for (int s = 0; s < 256; ++s) ASSERT_EQ(patches(k, s), one[s]) << "patch " << k << " sample " << s;
  }
  // Splat back: where covered, the map is reproduced up to its smoothness. The
  // merged value is f at the weighted centroid of the samples around a texel,
  // which lies within a texel of it (about half a texel at patch edges, ~0 inside);
  // |∇f| ≤ gmax = 0.064 / texel here.
  const cv::Mat back = sampler.Splat(patches);
  const cv::Mat& weight = sampler.splat_weight();
  const double gmax = 1.0 / 20 + 1.0 / 25;
  int covered = 0;
  double sum_error = 0.0;
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) {
      if (weight.at<float>(y, x) > 0) {
        ++covered;
        const double e = std::abs(back.at<float>(y, x) - smooth.at<float>(y, x));
        EXPECT_LE(e, gmax) << x << "," << y;
        sum_error += e;
      } else {
        EXPECT_EQ(back.at<float>(y, x), 0.0f);
      }
    }
  EXPECT_GT(covered, 16 * 16);
  EXPECT_LT(sum_error / covered, 0.1 * gmax) << "mean error";
  // A constant map comes back exactly (up to rounding) everywhere covered.
  const cv::Mat constant(S, S, CV_32F, cv::Scalar(0.7));
  const cv::Mat back_c = sampler.Splat(sampler.Sample(constant));
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x)
      if (weight.at<float>(y, x) > 0) {
        ASSERT_NEAR(back_c.at<float>(y, x), 0.7f, 1e-5f);
      }
}

// The per-frame path of the capture's re-centring (SamplePatches / SplatPatches) agrees
// with the precomputed sampler on the same frames: the same samples to the bit, weight
// = splat_weight, value / weight = Splat (up to the summation order), and the gains
// weigh whole patches.
TEST(PatchesTest, PerFrameSamplingAndSplatAgreeWithTheSampler) {
  const int S = 128, w = 16;
  const SyntheticMap m = MakeSyntheticMap(S, 5);
  PatchLayoutOptions o;
  o.patch_size = w;
  const PatchLayout layout = PlacePatches(m.probability, m.angle, cv::Mat(), m.coverage, o);
  const int N = layout.num_patches();
  ASSERT_GT(N, 3);
  const PatchSampler sampler(layout);
  cv::Mat smooth(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) smooth.at<float>(y, x) = static_cast<float>(std::sin(x / 20.0) * std::cos(y / 25.0));
  const Eigen::MatrixXf reference = sampler.Sample(smooth);
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows(N, w * w);
  SamplePatches(smooth, layout.patches, w, rows.data());
  ASSERT_TRUE(rows == reference);
  const cv::Mat merged = sampler.Splat(reference);
  const SplatSums sums = SplatPatches(layout.patches, w, S, rows.data(), std::vector<float>(N, 1.0f));
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) {
      const float weight = sums.weight.at<float>(y, x);
      ASSERT_NEAR(weight, sampler.splat_weight().at<float>(y, x), 1e-4f) << x << "," << y;
      ASSERT_EQ(sums.gain.at<float>(y, x), weight) << x << "," << y;
      if (weight > 0) {
        ASSERT_NEAR(sums.value.at<float>(y, x) / weight, merged.at<float>(y, x), 1e-5f) << x << "," << y;
      }
    }
  // A gain of 0 on patch 0 leaves only the other patches' weight in `gain`.
  std::vector<float> gain(N, 1.0f);
  gain[0] = 0.0f;
  const SplatSums without = SplatPatches(layout.patches, w, S, rows.data(), gain);
  const cv::Point c(static_cast<int>(std::lround(layout.patches[0].center_texel.x())),
                    static_cast<int>(std::lround(layout.patches[0].center_texel.y())));
  EXPECT_LT(without.gain.at<float>(c), without.weight.at<float>(c) - 0.5f);
  EXPECT_ERROR_HAS(SplatPatches(layout.patches, w, S, rows.data(), std::vector<float>(N - 1, 1.0f)),
                   "gains for");
}

TEST(PatchesTest, TrainingPairsOnlyAboveAlpha) {
  const int S = 64;
  PatchLayout layout;
  layout.map_size = S;
  layout.patch_size = 8;
  layout.patches = {{Eigen::Vector2f(20, 20), 0.3f}, {Eigen::Vector2f(40, 30), 1.2f}, {Eigen::Vector2f(30, 45), 2.5f}};
  const int J = 3;
  std::vector<cv::Mat> textures, responses, displacements;
  Rng rng(1);
  for (int j = 0; j < J; ++j) {
    cv::Mat t(S, S, CV_32F), d(S, S, CV_32F);
    for (int y = 0; y < S; ++y)
      for (int x = 0; x < S; ++x) {
        t.at<float>(y, x) = static_cast<float>(rng.Uniform(0, 1));
        d.at<float>(y, x) = static_cast<float>(rng.Uniform(-1, 1));
      }
    textures.push_back(t);
    displacements.push_back(d);
    responses.push_back(cv::Mat(S, S, CV_32F, cv::Scalar(0.001)));
  }
  // r_j at the centres: patch 0 ← expressions 0 and 2; patch 1 ← none; patch 2 ← 1.
  responses[0].at<float>(20, 20) = 0.02f;
  responses[2].at<float>(20, 20) = 0.0051f;
  responses[1].at<float>(30, 40) = 0.005f;  // exactly α: not above
  responses[1].at<float>(45, 30) = 0.01f;
  responses[0].at<float>(46, 30) = 0.5f;  // next to a centre: irrelevant
  const TrainingPatches pairs = ExtractTrainingPatches(layout, textures, responses, displacements, WrinkleMapOptions());
  ASSERT_EQ(pairs.size(), 3);
  EXPECT_EQ(pairs.patch_index, (std::vector<int>{0, 0, 2}));
  EXPECT_EQ(pairs.expression_index, (std::vector<int>{0, 2, 1}));
  ASSERT_EQ(pairs.texture.rows(), 3);
  ASSERT_EQ(pairs.texture.cols(), 64);
  std::vector<float> t(64), d(64);
  for (int i = 0; i < pairs.size(); ++i) {
    SamplePatch(textures[pairs.expression_index[i]], layout.patches[pairs.patch_index[i]], 8, t.data());
    SamplePatch(displacements[pairs.expression_index[i]], layout.patches[pairs.patch_index[i]], 8, d.data());
    for (int s = 0; s < 64; ++s) {
      ASSERT_EQ(pairs.texture(i, s), t[s]);
      ASSERT_EQ(pairs.displacement(i, s), d[s]);
    }
  }
  // Errors name what mismatches.
  EXPECT_ERROR_HAS(ExtractTrainingPatches(layout, textures, {responses[0]}, displacements, WrinkleMapOptions()),
                   "1 responses for 3 textures");
  std::vector<cv::Mat> small = displacements;
  small[2] = cv::Mat(32, 32, CV_32F);
  EXPECT_ERROR_HAS(ExtractTrainingPatches(layout, textures, responses, small, WrinkleMapOptions()),
                   "displacement map 2 (layout map size): is 32x32, expected 64x64");
  EXPECT_ERROR_HAS(ExtractTrainingPatches(layout, {}, {}, {}, WrinkleMapOptions()), "no textures");
}

TEST(PatchesTest, SameBytesForOneAndTwoThreads) {
  const int S = 128;
  const SyntheticMap m = MakeSyntheticMap(S, 9);
  cv::Mat map(S, S, CV_32F);
  Rng rng(2);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) map.at<float>(y, x) = static_cast<float>(rng.Uniform(0, 1));
  auto run = [&](int threads, cv::Mat* back, Eigen::MatrixXf* patches) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    PatchLayoutOptions o;
    o.patch_size = 16;
    const PatchLayout layout = PlacePatches(m.probability, m.angle, cv::Mat(), m.coverage, o);
    const PatchSampler sampler(layout);
    *patches = sampler.Sample(map);
    *back = sampler.Splat(*patches * 1.5f);
    return layout;
  };
  cv::Mat back1, back2;
  Eigen::MatrixXf p1, p2;
  const PatchLayout l1 = run(1, &back1, &p1), l2 = run(2, &back2, &p2);
  ASSERT_EQ(l1.num_patches(), l2.num_patches());
  for (int k = 0; k < l1.num_patches(); ++k) {
    EXPECT_EQ(l1.patches[k].center_texel, l2.patches[k].center_texel);
    EXPECT_EQ(l1.patches[k].angle, l2.patches[k].angle);
  }
  ASSERT_EQ(p1.size(), p2.size());
  EXPECT_TRUE(std::equal(p1.data(), p1.data() + p1.size(), p2.data()));
  EXPECT_TRUE(SameBytes(back1, back2));
}

TEST(PatchesTest, Errors) {
  const cv::Mat w(32, 32, CV_32F, cv::Scalar(0.1)), a(32, 32, CV_32F, cv::Scalar(0));
  EXPECT_ERROR_HAS(PlacePatches(w, cv::Mat(16, 16, CV_32F), cv::Mat(), cv::Mat(), PatchLayoutOptions()),
                   "angle map (same size as the wrinkle map): is 16x16, expected 32x32");
  EXPECT_ERROR_HAS(PlacePatches(cv::Mat(), a, cv::Mat(), cv::Mat(), PatchLayoutOptions()), "empty wrinkle map");
  EXPECT_ERROR_HAS(PlacePatches(w, a, cv::Mat(32, 32, CV_32F), cv::Mat(), PatchLayoutOptions()), "valid mask");
  EXPECT_ERROR_HAS(PlacePatches(w, a, cv::Mat(), cv::Mat(8, 8, CV_8U), PatchLayoutOptions()), "coverage mask");
  PatchLayout layout;
  layout.map_size = 32;
  layout.patch_size = 8;
  layout.patches = {{Eigen::Vector2f(10, 10), 0.0f}};
  const PatchSampler sampler(layout);
  EXPECT_ERROR_HAS(sampler.Sample(cv::Mat(64, 64, CV_32F)), "is 64x64, expected 32x32");
  EXPECT_ERROR_HAS(sampler.Sample(cv::Mat()), "empty map");
  EXPECT_ERROR_HAS(sampler.Splat(Eigen::MatrixXf(2, 64)), "patches are 2x64, expected 1x64");
  float out[4];
  EXPECT_ERROR_HAS(SamplePatch(cv::Mat(8, 8, CV_64F), layout.patches[0], 2, out), "CV_32FC1");
  layout.patches.push_back({Eigen::Vector2f(40, 10), 0.0f});
  EXPECT_ERROR_HAS(PatchSampler{layout}, "patch 1 centre (40, 10) lies outside the 32x32 map");
}

TEST(PatchesTest, DrawPatchLayout) {
  const int S = 128;
  const cv::Mat t = LineTexture(S, 30.0);
  const WrinkleMap map = ComputeWrinkleMap({t}, cv::Mat(), {}, TexelOptions());
  PatchLayoutOptions o;
  o.patch_size = 16;
  const PatchLayout layout = PlacePatches(map, o);
  const cv::Mat picture = DrawPatchLayout(map.probability, layout, map.valid);
  EXPECT_EQ(picture.type(), CV_8UC3);
  EXPECT_EQ(picture.rows, 512);  // small maps are enlarged (×4)
  // The rectangles (cyan: R, G, B = 0, 255, 255) are drawn, in R, G, B order.
  cv::Mat cyan, yellow;
  cv::inRange(picture, cv::Scalar(0, 200, 200), cv::Scalar(60, 255, 255), cyan);
  EXPECT_GT(cv::countNonZero(cyan), 100);
  cv::inRange(picture, cv::Scalar(200, 200, 0), cv::Scalar(255, 255, 60), yellow);  // cyan as B, G, R
  EXPECT_LT(cv::countNonZero(yellow), cv::countNonZero(cyan) / 4);
}

// Pairs side by side: a dark texture column is drawn dark, a groove blue and a ridge
// red (R, G, B), one cell per pair, evenly spread over the rows.
TEST(PatchesTest, PairMosaicDrawsTexturesBesideTheirDisplacements) {
  const int w = 4, n = w * w;
  Eigen::MatrixXf t = Eigen::MatrixXf::Constant(3, n, 0.5f), d = Eigen::MatrixXf::Zero(3, n);
  for (int r = 0; r < 3; ++r)
    for (int y = 0; y < w; ++y) t(r, y * w) = 0.1f;  // left column dark
  d.row(0).setConstant(-0.2f);  // a groove
  d.row(2).setConstant(0.3f);   // a ridge
  const cv::Mat m = PairMosaic(t, d, w, 2, /*scale=*/1);
  ASSERT_EQ(m.type(), CV_8UC3);
  EXPECT_EQ(m.rows, w + 2);
  EXPECT_EQ(m.at<cv::Vec3b>(1, 0), cv::Vec3b(0, 0, 0));        // dark texel, stretched to black
  EXPECT_EQ(m.at<cv::Vec3b>(1, 2), cv::Vec3b(255, 255, 255));  // bright texel
  EXPECT_EQ(m.at<cv::Vec3b>(1, w + 1), cv::Vec3b(0, 0, 255));  // pair 0: groove, blue
  // The second cell shows row 1 of 3 (rows 0 and 1 of 2 shown: k·N/count): flat, white.
  EXPECT_EQ(m.at<cv::Vec3b>(1, 2 * w + 2 + w + 1), cv::Vec3b(255, 255, 255));
  EXPECT_THROW(PairMosaic(t, d, w + 1, 2), Error);
}

}  // namespace
}  // namespace crease
