// Expression wrinkles of the studio's actors (synth/wrinkles.h): the depth response
// to compression, the family names, the random layout on the procedural head, and
// the displacement field of one line under a known strain.
#include "synth/wrinkles.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include <opencv2/core.hpp>

#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::ProceduralRig;

constexpr WrinkleFamily kFamilies[] = {WrinkleFamily::kForehead,   WrinkleFamily::kGlabella,
                                       WrinkleFamily::kCrowsFeet,  WrinkleFamily::kNasolabial,
                                       WrinkleFamily::kUnderEye,   WrinkleFamily::kBunny};

TEST(Wrinkles, CompressionResponseIsZeroAtRestMonotoneAndSaturating) {
  EXPECT_EQ(CompressionResponse(0.0, 0.1), 0.0);
  EXPECT_EQ(CompressionResponse(-0.3, 0.1), 0.0);
  EXPECT_EQ(CompressionResponse(std::nan(""), 0.1), 0.0);
  EXPECT_NEAR(CompressionResponse(0.1, 0.1), 1.0 - std::exp(-1.0), 1e-12);  // f(c_sat) = 1 − 1/e
  double prev = 0.0;
  for (double c = 0.005; c <= 0.4; c += 0.005) {
    const double f = CompressionResponse(c, 0.1);
    EXPECT_GT(f, prev) << c;
    EXPECT_LE(f, 1.0) << c;
    prev = f;
  }
  EXPECT_GT(CompressionResponse(0.6, 0.1), 1.0 - 1e-12);
  // f'(0) = 0: at a tenth of the saturation the response is about (1/10)², not 1/10.
  EXPECT_NEAR(CompressionResponse(0.01, 0.1), 0.01, 1e-4);
}

TEST(Wrinkles, DepthGrowsFromStaticToMaxAndStretchFlattensStaticLines) {
  WrinkleLine line;
  line.max_depth_mm = 0.6;
  line.static_depth_mm = 0.2;
  line.saturation = 0.08;
  EXPECT_DOUBLE_EQ(WrinkleDepth(line, 0.0), 0.2);  // visible at neutral
  double prev = 0.2;
  for (double c = 0.01; c < 0.4; c += 0.01) {
    const double d = WrinkleDepth(line, c);
    EXPECT_GT(d, prev) << c;
    EXPECT_LE(d, line.max_depth_mm) << c;
    prev = d;
  }
  EXPECT_NEAR(WrinkleDepth(line, 0.4), 0.6, 1e-9);
  // Stretch: shallower than static, never below half of it.
  prev = 0.2;
  for (double c = -0.01; c > -0.4; c -= 0.01) {
    const double d = WrinkleDepth(line, c);
    EXPECT_LT(d, prev) << c;
    EXPECT_GE(d, 0.1 - 1e-12) << c;
    prev = d;
  }
  EXPECT_NEAR(WrinkleDepth(line, -0.4), 0.1, 1e-9);
  // An expression-only line: nothing at neutral or under stretch.
  line.static_depth_mm = 0.0;
  EXPECT_EQ(WrinkleDepth(line, 0.0), 0.0);
  EXPECT_EQ(WrinkleDepth(line, -0.2), 0.0);
}

TEST(Wrinkles, FamilyNamesRoundTripAndUnknownNamesAreRefused) {
  for (WrinkleFamily f : kFamilies) {
    EXPECT_EQ(WrinkleFamilyFromString(ToString(f)), f) << ToString(f);
    EXPECT_FALSE(WrinkleFamilyRegions(f).empty()) << ToString(f);
  }
  EXPECT_EQ(ToString(WrinkleFamily::kCrowsFeet), "crows_feet");
  const std::string e = ErrorOf([] { WrinkleFamilyFromString("dimple"); });
  EXPECT_NE(e.find("unknown wrinkle family 'dimple'"), std::string::npos) << e;
  EXPECT_NE(ErrorOf([] { WrinkleFamilyFromString("Forehead"); }).find("'Forehead'"), std::string::npos);
}

std::vector<WrinkleLine> Layout(const FaceAnchors& a, double age, uint64_t seed) {
  Rng rng(seed);
  return GenerateWrinkleLayout(a, {.age = age, .shape = 0.0, .static_lines = true}, rng);
}

TEST(Wrinkles, LayoutIsDeterministicPerSeedAndGrowsWithAge) {
  const FaceAnchors a = ComputeFaceAnchors(ProceduralRig());
  const std::vector<WrinkleLine> x = Layout(a, 0.8, 4), y = Layout(a, 0.8, 4), z = Layout(a, 0.8, 5);
  ASSERT_EQ(x.size(), y.size());
  for (size_t i = 0; i < x.size(); ++i) {
    EXPECT_EQ(x[i].family, y[i].family);
    EXPECT_EQ(x[i].points, y[i].points);
    EXPECT_EQ(x[i].strength, y[i].strength);
    EXPECT_EQ(x[i].max_depth_mm, y[i].max_depth_mm);
  }
  EXPECT_TRUE(z.size() != x.size() || z[0].points != x[0].points);
  size_t young = 0, old = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    young += Layout(a, 0.0, seed).size();
    old += Layout(a, 1.0, seed).size();
    for (const WrinkleLine& l : Layout(a, 0.0, seed)) EXPECT_EQ(l.static_depth_mm, 0.0);  // young: no static lines
  }
  EXPECT_LT(2 * young, old);
  Rng rng(1);
  EXPECT_NE(ErrorOf([&] { GenerateWrinkleLayout(a, {.age = 1.5}, rng); }).find("WrinkleStyle.age = 1.5"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { GenerateWrinkleLayout(a, {.shape = -2.0}, rng); }).find("WrinkleStyle.shape"),
            std::string::npos);
}

// Of the two sides' anchors, the one nearer to `p`.
int NearerSide(const Eigen::Vector2d (&anchor)[2], const Eigen::Vector2d& p) {
  return (p - anchor[0]).norm() < (p - anchor[1]).norm() ? 0 : 1;
}

// Each line's middle lies where its family belongs relative to the face's anchors
// (mm), and inside the soft union of its family's rig regions.
TEST(Wrinkles, LinesLieInTheirFamilysRegions) {
  const FaceRig& rig = ProceduralRig();
  const FaceAnchors a = ComputeFaceAnchors(rig);
  const double s = a.mm_per_uv;
  Eigen::Vector2d brow_mean = Eigen::Vector2d::Zero();
  for (int k = 0; k < 2; ++k)
    for (const auto& p : a.brow[k]) brow_mean += p / static_cast<double>(a.brow[0].size() + a.brow[1].size());
  const Eigen::Vector2d glabella = 0.5 * (a.brow[0].back() + a.brow[1].back());
  constexpr int kSize = 128;
  std::vector<cv::Mat> weights;
  for (WrinkleFamily f : kFamilies) weights.push_back(SoftRegionWeight(rig, WrinkleFamilyRegions(f), kSize, 3.0, s));
  int lines = 0, inside = 0;
  std::set<WrinkleFamily> seen;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    for (const WrinkleLine& l : Layout(a, 1.0, seed)) {
      const Eigen::Vector2d m = l.points[l.points.size() / 2];
      seen.insert(l.family);
      const std::string what = ToString(l.family) + " seed " + std::to_string(seed);
      switch (l.family) {
        case WrinkleFamily::kForehead: EXPECT_GT((m - brow_mean).dot(a.up) * s, 4.0) << what; break;
        case WrinkleFamily::kGlabella: EXPECT_LT(std::abs((m - glabella).dot(a.lateral)) * s, 20.0) << what; break;
        case WrinkleFamily::kCrowsFeet: {
          const int side = NearerSide(a.eye_outer, m);
          EXPECT_GT((m - a.eye_outer[side]).dot(a.Outward(side)) * s, 1.0) << what;
          break;
        }
        case WrinkleFamily::kNasolabial: {
          const int side = NearerSide(a.nose_wing, m);
          EXPECT_GT((m - a.nose_wing[side]).dot(a.Outward(side)) * s, 0.0) << what;
          break;
        }
        case WrinkleFamily::kUnderEye: {
          const int side = NearerSide(a.lower_lid, m);
          EXPECT_LT((m - a.lower_lid[side]).dot(a.up) * s, 0.0) << what;
          break;
        }
        case WrinkleFamily::kBunny:
          EXPECT_GT(std::abs((m - a.nose_bridge_top).dot(a.lateral)) * s, 1.0) << what;
          break;
      }
      const cv::Mat& w = weights[static_cast<int>(l.family)];
      const int i = std::clamp(static_cast<int>(m.x() * kSize), 0, kSize - 1);
      const int j = std::clamp(static_cast<int>(m.y() * kSize), 0, kSize - 1);
      inside += w.at<float>(j, i) > 0.05f;
      ++lines;
    }
  }
  EXPECT_EQ(seen.size(), 6u);
  EXPECT_GE(inside, lines * 9 / 10) << inside << " of " << lines << " line middles in their family's regions";
}

// A metric map (CV_32FC3: C_uu, C_uv, C_vv) that is the same everywhere.
cv::Mat UniformMetric(int size, double c_uu, double c_uv, double c_vv) {
  return cv::Mat(size, size, CV_32FC3, cv::Scalar(c_uu, c_uv, c_vv));
}

// One straight horizontal line on a flat chart of 100 mm per UV unit: compressing
// the skin across it (v) by λ = 0.8 carves WrinkleDepth(line, 0.2) into its centre,
// compressing along it (u) carves nothing, and the neutral metric nothing.
TEST(Wrinkles, FieldCarvesTheLineWhereTheSkinIsCompressedAcrossIt) {
  constexpr int R = 64;
  constexpr double kMmPerUv = 100.0;
  const double v = (32 + 0.5) / R;  // through texel centres of row 32
  WrinkleLine line;
  line.family = WrinkleFamily::kForehead;
  for (int k = 0; k <= 10; ++k) {
    line.points.emplace_back(0.2 + 0.06 * k, v);
    line.strength.push_back(1.0);
  }
  line.max_depth_mm = 0.5;
  line.width_mm = 1.0;
  line.saturation = 0.1;
  const std::vector<cv::Mat> ones(6, cv::Mat(R, R, CV_32F, cv::Scalar(1.0f)));
  const double c0 = kMmPerUv * kMmPerUv;
  const WrinkleField field({line}, R, kMmPerUv, ones, UniformMetric(R, c0, 0, c0));
  ASSERT_FALSE(field.samples().empty());
  const cv::Mat across = UniformMetric(R, c0, 0, 0.64 * c0), along = UniformMetric(R, 0.64 * c0, 0, c0);
  EXPECT_NEAR(field.CompressionAt(across, 0, 32, 32), 0.2, 1e-6);
  EXPECT_NEAR(field.CompressionAt(along, 0, 32, 32), 0.0, 1e-6);
  EXPECT_TRUE(std::isnan(field.CompressionAt(across, 0, 32, 5)));  // beyond the line's reach
  const cv::Mat D = field.Displacement(across);
  EXPECT_NEAR(D.at<float>(32, 32), -WrinkleDepth(line, 0.2), 1e-5);  // into the skin
  EXPECT_GT(D.at<float>(33, 32), D.at<float>(32, 32));  // the valley is deepest on the line
  EXPECT_EQ(D.at<float>(5, 32), 0.0f);
  EXPECT_LT(cv::norm(field.Displacement(along), cv::NORM_INF), 1e-6);
  EXPECT_LT(cv::norm(field.Displacement(UniformMetric(R, c0, 0, c0)), cv::NORM_INF), 1e-6);
}

TEST(Wrinkles, SampleMetricInterpolatesBilinearlyAndClampsAtTheBorder) {
  cv::Mat m(2, 2, CV_32FC3);
  m.at<cv::Vec3f>(0, 0) = {0, 0, 0};
  m.at<cv::Vec3f>(0, 1) = {4, 1, 0};
  m.at<cv::Vec3f>(1, 0) = {0, 1, 8};
  m.at<cv::Vec3f>(1, 1) = {4, 2, 8};
  const Eigen::Vector3d mid = SampleMetric(m, 0.5, 0.5);
  EXPECT_NEAR(mid[0], 2.0, 1e-9);
  EXPECT_NEAR(mid[1], 1.0, 1e-9);
  EXPECT_NEAR(mid[2], 4.0, 1e-9);
  const Eigen::Vector3d corner = SampleMetric(m, -1.0, 2.0);  // clamped to texel (0, 1)
  EXPECT_NEAR(corner[0], 0.0, 1e-9);
  EXPECT_NEAR(corner[2], 8.0, 1e-9);
}

}  // namespace
}  // namespace crease
