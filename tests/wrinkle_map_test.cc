// Tests of the wrinkle map (paper Sec. 4.2): DoG sign and band-pass, the
// coverage-normalised convolution, the thresholded average, the orientation of
// lines, region masks and errors.
#include "pipeline/training/wrinkle_map.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <limits>
#include <numbers>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/options.h"
#include "test_util.h"
#include "wrinkle_test_util.h"

namespace crease {
namespace {

constexpr double kPi = std::numbers::pi;

using testing::AngleDiffMod180;
using testing::LineTexture;
using testing::TexelOptions;

TEST(WrinkleMapOptionsTest, DefaultsArePaperValues) {
  const WrinkleMapOptions o;
  EXPECT_EQ(o.dog_small_sigma, 6.0);
  EXPECT_EQ(o.dog_large_sigma, 8.0);
  EXPECT_EQ(o.dog_reference_resolution, 1024);
  EXPECT_EQ(o.wrinkle_threshold, 0.005);
  EXPECT_EQ(o.patch_regions,
            (std::vector<std::string>{"forehead", "glabella", "left_eye", "right_eye", "left_cheek", "right_cheek"}));
  EXPECT_TRUE(o.patch_exclude_regions.empty());  // Difference 5 is opt-in
  o.Check();
  EXPECT_DOUBLE_EQ(SigmaScale(o, 1024), 1.0);
  EXPECT_DOUBLE_EQ(SigmaScale(o, 512), 0.5);
  EXPECT_DOUBLE_EQ(SigmaScale(TexelOptions(), 512), 1.0);
}

TEST(WrinkleMapOptionsTest, SetByNameAndChecked) {
  WrinkleMapOptions o;
  SetOptionsFromJson(R"({"dog_small_sigma": 3, "dog_large_sigma": 4, "patch_regions": ["forehead"]})", "--set", &o);
  EXPECT_EQ(o.dog_small_sigma, 3.0);
  EXPECT_EQ(o.patch_regions, std::vector<std::string>{"forehead"});
  WrinkleMapOptions bad;
  bad.dog_large_sigma = 5.0;
  EXPECT_ERROR_HAS(bad.Check(), "dog_large_sigma");
  bad = WrinkleMapOptions();
  bad.wrinkle_threshold = -1.0;
  EXPECT_ERROR_HAS(bad.Check(), "wrinkle_threshold");
  bad = WrinkleMapOptions();
  bad.patch_regions = {""};
  EXPECT_ERROR_HAS(bad.Check(), "patch_regions[0]");
}

TEST(DogResponseTest, PositiveOnDarkLineZeroAway) {
  const cv::Mat t = LineTexture(128, 90.0);  // vertical line at x = 63.5
  const cv::Mat r = DogResponse(t, TexelOptions());
  ASSERT_EQ(r.type(), CV_32FC1);
  const float centre = 0.5f * (r.at<float>(64, 63) + r.at<float>(64, 64));
  EXPECT_GT(centre, 0.005f) << "dark line must give a positive response above alpha";
  // Far from the line (> 4 σ_large) the response vanishes.
  EXPECT_NEAR(r.at<float>(64, 10), 0.0f, 1e-4f);
  // A bright line gives the opposite sign.
  const cv::Mat bright = 1.0 - t;
  const cv::Mat rb = DogResponse(bright, TexelOptions());
  EXPECT_LT(rb.at<float>(64, 63), -0.005f);
}

TEST(DogResponseTest, SigmasScaleWithMapResolution) {
  // A 256² map with σ given at 1024² filters with σ / 4 (Difference 1).
  const cv::Mat t = LineTexture(256, 40.0, 0.2, 0.5);
  WrinkleMapOptions at1024;
  WrinkleMapOptions texels = TexelOptions();
  texels.dog_small_sigma = 1.5;
  texels.dog_large_sigma = 2.0;
  EXPECT_EQ(cv::norm(DogResponse(t, at1024), DogResponse(t, texels), cv::NORM_INF), 0.0);
}

TEST(DogResponseTest, BandPassIgnoresPoresScaleNoise) {
  // A fine checkerboard (period 2 texels, "pores") of amplitude 0.05 gives almost
  // no response at σ = 6 / 8, a dark line of the same depth does.
  cv::Mat t(128, 128, CV_32F);
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x) t.at<float>(y, x) = ((x + y) % 2) ? 0.55f : 0.45f;
  const cv::Mat r = DogResponse(t, TexelOptions());
  double lo, hi;
  cv::minMaxLoc(r(cv::Rect(32, 32, 64, 64)), &lo, &hi);
  EXPECT_LT(std::max(std::abs(lo), std::abs(hi)), 1e-4);
}

TEST(DogResponseTest, ZeroOnConstantAndLinearRamp) {
  const int S = 128;
  cv::Mat constant(S, S, CV_32F, cv::Scalar(0.4));
  cv::Mat ramp(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) ramp.at<float>(y, x) = 0.2f + 0.25f * x / S + 0.05f * y / S;  // 0.002 / texel: steep shading
  const cv::Mat rc = DogResponse(constant, TexelOptions());
  double lo, hi;
  cv::minMaxLoc(rc, &lo, &hi);
  EXPECT_LT(std::max(std::abs(lo), std::abs(hi)), 1e-6);
  const cv::Mat rr = DogResponse(ramp, TexelOptions());
  cv::minMaxLoc(rr(cv::Rect(40, 40, S - 80, S - 80)), &lo, &hi);  // 5 σ_large from the border: exact
  EXPECT_LT(std::max(std::abs(lo), std::abs(hi)), 1e-5);
  cv::minMaxLoc(rr, &lo, &hi);  // near the border: a small bias, far below α
  EXPECT_LT(hi, 0.005);
}

TEST(DogResponseTest, NoFalseWrinkleAtCoverageBoundary) {
  const int S = 128;
  cv::Mat coverage(S, S, CV_8U, cv::Scalar(0));
  cv::circle(coverage, cv::Point(64, 64), 40, cv::Scalar(255), cv::FILLED);
  cv::Mat t(S, S, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  t.setTo(cv::Scalar(0.6), coverage);  // skin inside, undefined (NaN) outside
  const cv::Mat r = DogResponse(t, TexelOptions(), coverage);
  double lo, hi;
  cv::minMaxLoc(r, &lo, &hi);
  EXPECT_LT(std::max(std::abs(lo), std::abs(hi)), 1e-5) << "the boundary must not look like a wrinkle";
  EXPECT_EQ(cv::countNonZero((r != 0) & (coverage == 0)), 0) << "0 outside coverage";
  // Without the coverage (outside = black), the boundary is a strong false edge.
  cv::Mat black(S, S, CV_32F, cv::Scalar(0));
  black.setTo(cv::Scalar(0.6), coverage);
  cv::minMaxLoc(DogResponse(black, TexelOptions()), &lo, &hi);
  EXPECT_GT(hi, 4 * 0.005);
}

TEST(WrinkleProbabilityTest, AveragesOnlyContributionsAboveAlpha) {
  // Three textures, four texels; α = 0.005.
  auto row = [](std::initializer_list<float> v) {
    cv::Mat m(1, static_cast<int>(v.size()), CV_32F);
    int i = 0;
    for (float x : v) m.at<float>(0, i++) = x;
    return m;
  };
  const std::vector<cv::Mat> r = {row({0.010f, 0.004f, 0.020f, 0.030f}), row({0.003f, 0.006f, 0.020f, 0.030f}),
                                  row({0.000f, -0.2f, -0.1f, 0.030f})};
  const cv::Mat w = WrinkleProbability(r, cv::Mat(), 0.005);
  EXPECT_FLOAT_EQ(w.at<float>(0, 0), 0.010f / 3);  // only the first counts, divided by J = 3
  EXPECT_FLOAT_EQ(w.at<float>(0, 1), 0.006f / 3);  // 0.004 is below α; negatives never count
  EXPECT_FLOAT_EQ(w.at<float>(0, 2), 0.040f / 3);
  EXPECT_FLOAT_EQ(w.at<float>(0, 3), 0.090f / 3);
  cv::Mat valid(1, 4, CV_8U, cv::Scalar(255));
  valid.at<uint8_t>(0, 2) = 0;
  const cv::Mat wv = WrinkleProbability(r, valid, 0.005);
  EXPECT_EQ(wv.at<float>(0, 2), 0.0f);
  EXPECT_FLOAT_EQ(wv.at<float>(0, 3), 0.090f / 3);
  // A response exactly at α does not count (strictly above).
  EXPECT_EQ(WrinkleProbability({row({0.005f})}, cv::Mat(), 0.005f).at<float>(0, 0), 0.0f);
}

TEST(WrinkleMapTest, BuilderMatchesDefinitionAndAngleFollowsLines) {
  const int S = 128;
  const WrinkleMapOptions o = TexelOptions();
  for (double line_deg : {0.0, 30.0, 75.0, 90.0, 135.0, 170.0}) {
    SCOPED_TRACE(line_deg);
    const std::vector<cv::Mat> textures = {LineTexture(S, line_deg), LineTexture(S, line_deg, 0.1),
                                           cv::Mat(S, S, CV_32F, cv::Scalar(0.5))};
    std::vector<cv::Mat> responses;
    const WrinkleMap map = ComputeWrinkleMap(textures, cv::Mat(), {}, o, &responses);
    ASSERT_EQ(responses.size(), 3u);
    EXPECT_EQ(map.num_textures, 3);
    // W is the thresholded mean of the returned responses.
    const cv::Mat w = WrinkleProbability(responses, map.valid, o.wrinkle_threshold);
    EXPECT_EQ(cv::norm(w, map.probability, cv::NORM_INF), 0.0);
    // At the line centre: W > 0, two contributing textures, angle ⟂ line.
    const int c = S / 2;
    EXPECT_GT(map.probability.at<float>(c, c), 0.0f);
    EXPECT_EQ(map.contributions.at<int>(c, c), 2);
    const double angle_deg = map.angle.at<float>(c, c) * 180.0 / kPi;
    EXPECT_GE(angle_deg, 0.0);
    EXPECT_LT(angle_deg, 180.0);
    EXPECT_LT(AngleDiffMod180(angle_deg, line_deg + 90.0), 2.0) << "angle " << angle_deg;
  }
}

// orientation_reference_deg (Difference 7): the same axis across the line, its sign
// chosen so that e1 has a non-negative component along φ_0; 90° is the default's
// θ ∈ [0°, 180°) to the bit.
TEST(WrinkleMapTest, OrientationReferenceChoosesTheSignOfE1) {
  const int S = 128, c = S / 2;
  for (double line_deg : {0.0, 30.0, 75.0, 135.0, 170.0}) {
    SCOPED_TRACE(line_deg);
    const std::vector<cv::Mat> textures = {LineTexture(S, line_deg)};
    WrinkleMapOptions o = TexelOptions();
    const WrinkleMap base = ComputeWrinkleMap(textures, cv::Mat(), {}, o);
    o.orientation_reference_deg = 90.0;
    EXPECT_EQ(cv::norm(ComputeWrinkleMap(textures, cv::Mat(), {}, o).angle, base.angle, cv::NORM_INF), 0.0);
    for (double phi : {0.0, 45.0, 135.0, -100.0}) {
      o.orientation_reference_deg = phi;
      const double a = ComputeWrinkleMap(textures, cv::Mat(), {}, o).angle.at<float>(c, c);
      EXPECT_GE(a, 0.0);
      EXPECT_LT(a, 2.0 * kPi);
      EXPECT_LT(AngleDiffMod180(a * 180.0 / kPi, base.angle.at<float>(c, c) * 180.0 / kPi), 1e-3);
      EXPECT_GE(std::cos(a - phi * kPi / 180.0), -1e-6) << "phi " << phi << " angle " << a * 180.0 / kPi;
    }
  }
}

// orient_patches = false (Difference 8): one frame for every patch, e1 along φ_0,
// whatever the lines' orientation; the map itself does not change.
TEST(WrinkleMapTest, UnorientedPatchesKeepTheReferenceFrame) {
  const int S = 96;
  const std::vector<cv::Mat> textures = {LineTexture(S, 30.0), LineTexture(S, 120.0)};
  WrinkleMapOptions o = TexelOptions();
  const WrinkleMap oriented = ComputeWrinkleMap(textures, cv::Mat(), {}, o);
  o.orient_patches = false;
  for (double phi : {90.0, 20.0, 300.0}) {
    o.orientation_reference_deg = phi;
    const WrinkleMap fixed = ComputeWrinkleMap(textures, cv::Mat(), {}, o);
    EXPECT_EQ(cv::norm(fixed.probability, oriented.probability, cv::NORM_INF), 0.0);
    double lo = 0.0, hi = 0.0;
    cv::minMaxLoc(fixed.angle, &lo, &hi);
    const double want = std::fmod(phi + 360.0, 360.0) * kPi / 180.0;
    EXPECT_NEAR(lo, want, 1e-5) << "phi " << phi;
    EXPECT_NEAR(hi, want, 1e-5) << "phi " << phi;
  }
}

TEST(WrinkleMapTest, CurvedLineOrientationAlongItsLength) {
  // A dark circle of radius 40: at every point of it the angle is radial.
  const int S = 128;
  cv::Mat t(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) {
      const double d = std::hypot(x - 64.0, y - 64.0) - 40.0;
      t.at<float>(y, x) = static_cast<float>(0.5 - 0.2 * std::exp(-d * d / 8.0));
    }
  const WrinkleMap map = ComputeWrinkleMap({t}, cv::Mat(), {}, TexelOptions());
  for (int k = 0; k < 12; ++k) {
    const double a = k * kPi / 6 + 0.1;
    const int x = static_cast<int>(std::lround(64 + 40 * std::cos(a))), y = static_cast<int>(std::lround(64 + 40 * std::sin(a)));
    const double radial = std::atan2(y - 64.0, x - 64.0) * 180 / kPi;
    EXPECT_LT(AngleDiffMod180(map.angle.at<float>(y, x) * 180 / kPi, radial), 4.0) << "at " << x << "," << y;
  }
}

TEST(WrinkleMapTest, AwayFromRimsKeepsTheChartOutsideAMarginAlongItsOpenEdges) {
  // A chart of 100² texels inside a 120² raster with a slit (a mouth) 4 texels tall.
  cv::Mat coverage(120, 120, CV_8U, cv::Scalar(0));
  coverage(cv::Rect(10, 10, 100, 100)).setTo(1);  // any non-zero counts
  coverage(cv::Rect(40, 58, 40, 4)).setTo(0);
  EXPECT_EQ(cv::countNonZero(AwayFromRims(coverage, 0.0)), cv::countNonZero(coverage));
  const cv::Mat away = AwayFromRims(coverage, 5.0);
  EXPECT_EQ(away.at<uint8_t>(30, 30), 255);    // far from every edge
  EXPECT_EQ(away.at<uint8_t>(53, 60), 255);    // 5 texels above the slit
  EXPECT_EQ(away.at<uint8_t>(55, 60), 0);      // 3 texels above it
  EXPECT_EQ(away.at<uint8_t>(64, 60), 0);      // 3 below
  EXPECT_EQ(away.at<uint8_t>(60, 12), 0);      // 3 from the outer rim
  EXPECT_EQ(away.at<uint8_t>(60, 5), 0);       // outside the chart
  // A chart touching the raster's border has a rim there too.
  const cv::Mat full(50, 50, CV_8U, cv::Scalar(255));
  const cv::Mat inner = AwayFromRims(full, 3.0);
  EXPECT_EQ(inner.at<uint8_t>(0, 25), 0);
  EXPECT_EQ(inner.at<uint8_t>(25, 25), 255);
  EXPECT_THROW(AwayFromRims(cv::Mat(4, 4, CV_32F, cv::Scalar(1)), 1.0), Error);
}

TEST(WrinkleMapTest, RegionsRestrictTheMapAndResample) {
  const int S = 128;
  // Regions at 32² (another resolution than the maps): left and right halves.
  RegionMask left{"forehead", cv::Mat(32, 32, CV_8U, cv::Scalar(0))};
  left.mask(cv::Rect(0, 0, 16, 32)).setTo(255);
  RegionMask right{"nose", cv::Mat(32, 32, CV_8U, cv::Scalar(0))};
  right.mask(cv::Rect(16, 0, 16, 32)).setTo(255);
  const std::vector<RegionMask> regions = {left, right};
  const cv::Mat valid = ValidRegionMask(regions, {"forehead"}, S);
  EXPECT_EQ(cv::countNonZero(valid), S * S / 2);
  EXPECT_EQ(valid.at<uint8_t>(10, 63), 255);
  EXPECT_EQ(valid.at<uint8_t>(10, 64), 0);
  EXPECT_EQ(cv::countNonZero(ValidRegionMask(regions, {"forehead", "nose"}, S)), S * S);
  cv::Mat coverage(S, S, CV_8U, cv::Scalar(0));
  coverage(cv::Rect(0, 0, S, 32)).setTo(1);  // any non-zero counts
  EXPECT_EQ(cv::countNonZero(ValidRegionMask(regions, {"forehead"}, S, coverage)), 32 * 64);
  EXPECT_EQ(cv::countNonZero(ValidRegionMask(regions, {}, S, coverage)), 32 * S);

  WrinkleMapOptions o = TexelOptions();
  o.patch_regions = {"forehead"};
  const WrinkleMap map = ComputeWrinkleMap({LineTexture(S, 0.0)}, cv::Mat(), regions, o);  // horizontal line
  EXPECT_GT(map.probability.at<float>(64, 20), 0.0f);
  EXPECT_EQ(map.probability.at<float>(64, 100), 0.0f);
  EXPECT_EQ(cv::countNonZero((map.probability > 0) & (map.valid == 0)), 0);
}

TEST(WrinkleMapTest, ExcludedRegionsAreCutOutWithTheirMargin) {
  const int S = 128;
  RegionMask forehead{"forehead", cv::Mat(64, 64, CV_8U, cv::Scalar(255))};
  RegionMask brow{"brow_left", cv::Mat(64, 64, CV_8U, cv::Scalar(0))};
  brow.mask(cv::Rect(16, 30, 32, 4)).setTo(255);  // a bar: texels x 32…95, y 60…67 of the map
  WrinkleMapOptions o = TexelOptions();
  o.patch_regions = {"forehead"};
  o.patch_exclude_regions = {"brow_left", "brow_right"};  // the rig has no brow_right: skipped
  o.patch_exclude_margin = 5.0;
  const cv::Mat valid = PatchRegionMask({forehead, brow}, o, S);
  EXPECT_EQ(valid.at<uint8_t>(64, 64), 0);     // on the brow
  EXPECT_EQ(valid.at<uint8_t>(55, 64), 0);     // 5 texels above it: inside the margin
  EXPECT_EQ(valid.at<uint8_t>(53, 64), 255);   // 7 texels above: outside
  EXPECT_EQ(valid.at<uint8_t>(64, 20), 255);   // beside the bar's end, beyond the margin
  // The 64 × 8 bar grown by a disk of radius 5: 512 + 2·72·5 + π·25 ≈ 1310 texels.
  EXPECT_NEAR(S * S - cv::countNonZero(valid), 1310, 30);
  // Without brows in the rig, or with no exclusions, the valid region is the named one.
  EXPECT_EQ(cv::countNonZero(PatchRegionMask({forehead}, o, S)), S * S);
  o.patch_exclude_regions.clear();
  EXPECT_EQ(cv::countNonZero(PatchRegionMask({forehead, brow}, o, S)), S * S);
  // A line on the brow leaves no wrinkle map there.
  o.patch_exclude_regions = {"brow_left"};
  const WrinkleMap map = ComputeWrinkleMap({LineTexture(S, 0.0)}, cv::Mat(), {forehead, brow}, o);
  EXPECT_EQ(cv::countNonZero((map.probability > 0) & (valid == 0)), 0);
}

TEST(WrinkleMapTest, BuilderAddsFramesOneByOne) {
  // Capture (Sec. 5.2) adds the first N frames one at a time; same bytes as all at once.
  const int S = 96;
  const std::vector<cv::Mat> frames = {LineTexture(S, 10.0), LineTexture(S, 100.0), LineTexture(S, 50.0, 0.1)};
  WrinkleMapBuilder builder(S, cv::Mat(), {}, TexelOptions());
  std::vector<cv::Mat> r_one;
  for (const cv::Mat& f : frames) r_one.push_back(builder.Add(f));
  EXPECT_EQ(builder.num_textures(), 3);
  const WrinkleMap a = builder.Finish();
  std::vector<cv::Mat> r_all;
  const WrinkleMap b = ComputeWrinkleMap(frames, cv::Mat(), {}, TexelOptions(), &r_all);
  EXPECT_EQ(cv::norm(a.probability, b.probability, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.angle, b.angle, cv::NORM_INF), 0.0);
  for (int j = 0; j < 3; ++j) EXPECT_EQ(cv::norm(r_one[j], r_all[j], cv::NORM_INF), 0.0);
  // Finish does not consume: more frames can follow.
  builder.Add(frames[0]);
  EXPECT_EQ(builder.Finish().num_textures, 4);
}

TEST(WrinkleMapTest, FlatteningByAReferenceCancelsAlbedoAndKeepsShading) {
  // T = albedo · shading; the reference has the same albedo and shading 1.
  cv::Mat albedo(8, 8, CV_32F), shading(8, 8, CV_32F, cv::Scalar(1.0f));
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) albedo.at<float>(y, x) = 0.1f + 0.05f * x;  // a brow-to-skin ramp
  shading.row(3).setTo(0.5f);                                              // a wrinkle's shadow
  const cv::Mat T = albedo.mul(shading), ref = albedo.clone();
  cv::Mat coverage(8, 8, CV_8U, cv::Scalar(255));
  coverage.at<uint8_t>(0, 0) = 0;
  const cv::Mat F = FlattenByReference(T, ref, coverage, TextureReference::kRatio);
  const double m = cv::mean(ref, coverage)[0];
  EXPECT_EQ(F.at<float>(0, 0), 0.0f);  // outside the coverage
  EXPECT_NEAR(F.at<float>(2, 5), m, 1e-6);
  EXPECT_NEAR(F.at<float>(3, 1), 0.5 * m, 1e-6);
  EXPECT_NEAR(F.at<float>(3, 7), 0.5 * m, 1e-6);
  EXPECT_NEAR(FlattenByReference(T, ref, coverage, TextureReference::kRatio, 2.0).at<float>(3, 2), 1.0, 1e-6);
  // The difference keeps the albedo's scaling of the shadow: T − T_ref + m.
  const cv::Mat G = FlattenByReference(T, ref, coverage, TextureReference::kDifference);
  EXPECT_NEAR(G.at<float>(2, 5), m, 1e-6);
  EXPECT_NEAR(G.at<float>(3, 7), m - 0.5 * albedo.at<float>(3, 7), 1e-6);
  EXPECT_THROW(FlattenByReference(T, ref, coverage, TextureReference::kNone), Error);
  // The median of the frames that saw each texel.
  std::vector<cv::Mat> frames = {cv::Mat(2, 2, CV_32F, cv::Scalar(1.0f)), cv::Mat(2, 2, CV_32F, cv::Scalar(5.0f)),
                                 cv::Mat(2, 2, CV_32F, cv::Scalar(3.0f))};
  std::vector<cv::Mat> seen = {cv::Mat(2, 2, CV_8U, cv::Scalar(1)), cv::Mat(2, 2, CV_8U, cv::Scalar(1)),
                               cv::Mat(2, 2, CV_8U, cv::Scalar(1))};
  seen[2].at<uint8_t>(1, 1) = 0;
  const cv::Mat med = MedianTexture(frames, seen);
  EXPECT_EQ(med.at<float>(0, 0), 3.0f);
  EXPECT_EQ(med.at<float>(1, 1), 5.0f);  // upper median of {1, 5}
  EXPECT_THROW(FlattenByReference(T, cv::Mat(4, 4, CV_32F), cv::Mat(), TextureReference::kRatio), Error);
  EXPECT_THROW(MedianTexture({}, {}), Error);
}

TEST(WrinkleMapTest, Errors) {
  const WrinkleMapOptions o = TexelOptions();
  const cv::Mat t(64, 64, CV_32F, cv::Scalar(0.5));
  EXPECT_ERROR_HAS(ComputeWrinkleMap({}, cv::Mat(), {}, o), "no textures");
  EXPECT_ERROR_HAS(ComputeWrinkleMap({t, cv::Mat(32, 32, CV_32F, cv::Scalar(0.5))}, cv::Mat(), {}, o),
                   "texture 1: texture is 32x32, expected 64x64");
  EXPECT_ERROR_HAS(DogResponse(cv::Mat(64, 64, CV_32FC3), o), "CV_32FC1");
  EXPECT_ERROR_HAS(DogResponse(cv::Mat(), o), "empty");
  EXPECT_ERROR_HAS(DogResponse(t, o, cv::Mat(32, 32, CV_8U, cv::Scalar(255))), "coverage mask is 32x32");
  cv::Mat nan = t.clone();
  nan.at<float>(3, 4) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_ERROR_HAS(DogResponse(nan, o, cv::Mat(), "expr_07"), "expr_07: 1 covered texels are not finite");
  const std::vector<RegionMask> regions = {{"forehead", cv::Mat(16, 16, CV_8U, cv::Scalar(255))},
                                           {"nose", cv::Mat(16, 16, CV_8U, cv::Scalar(255))}};
  EXPECT_ERROR_HAS(ValidRegionMask(regions, {"forehead", "left_ear"}, 64), "unknown region 'left_ear'");
  EXPECT_ERROR_HAS(ValidRegionMask(regions, {"left_ear"}, 64), "forehead, nose");
  EXPECT_ERROR_HAS(WrinkleMapBuilder(64, cv::Mat(), {}, WrinkleMapOptions()), "unknown region 'forehead'");
  WrinkleMapBuilder builder(64, cv::Mat(), {}, o);
  EXPECT_ERROR_HAS(builder.Finish(), "no textures were added");
  EXPECT_ERROR_HAS(WrinkleProbability({t, cv::Mat(64, 32, CV_32F)}, cv::Mat(), 0.005), "response 1 is 32x64");
}

TEST(WrinkleMapTest, SameBytesForOneAndTwoThreads) {
  const int S = 128;
  cv::Mat coverage(S, S, CV_8U, cv::Scalar(0));
  cv::circle(coverage, cv::Point(60, 66), 55, cv::Scalar(255), cv::FILLED);
  const std::vector<cv::Mat> textures = {LineTexture(S, 20.0), LineTexture(S, 110.0, 0.15, 3.0)};
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return ComputeWrinkleMap(textures, coverage, {}, TexelOptions());
  };
  const WrinkleMap a = run(1), b = run(2);
  auto same = [](const cv::Mat& x, const cv::Mat& y) {
    return x.size() == y.size() && x.type() == y.type() &&
           std::equal(x.datastart, x.dataend, y.datastart);
  };
  EXPECT_TRUE(same(a.probability, b.probability));
  EXPECT_TRUE(same(a.orientation, b.orientation));
  EXPECT_TRUE(same(a.angle, b.angle));
}

}  // namespace
}  // namespace crease
