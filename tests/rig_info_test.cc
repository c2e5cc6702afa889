#include "core/rig_info.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "tests/test_util.h"

#include "core/mesh_primitives.h"

namespace crease {
namespace {

// A 4×4-cell grid, 40 mm square, UVs on [0, 1]² in steps of 0.25, with two 8×8
// region masks that overlap in the top-left quadrant of UV: "forehead" the top
// half (v < 0.5), "nose" the left half (u < 0.5); landmark "tip" at UV (0.25, 0.75).
FaceRig QuadrantRig() {
  FaceRig rig;
  rig.neutral = MakeGrid(4, 4, 40.0, 40.0);
  rig.expression_names = {"jawOpen", "eyeBlink_L"};
  cv::Mat top = cv::Mat::zeros(8, 8, CV_8UC1), left = cv::Mat::zeros(8, 8, CV_8UC1);
  top(cv::Rect(0, 0, 8, 4)) = 255;
  left(cv::Rect(0, 0, 4, 8)) = 255;
  rig.regions = {{"forehead", top}, {"nose", left}};
  rig.landmarks = {{"tip", 3 * 5 + 1}};
  return rig;
}

// The vertex of QuadrantRig at UV (i/4, j/4).
int GridVertex(int i, int j) { return j * 5 + i; }

TEST(RigInfo, MissingStandardRegionsAreTheOthersInOrder) {
  const FaceRig rig = QuadrantRig();
  const std::vector<std::string> missing = MissingStandardRegions(rig);
  std::vector<std::string> expected;
  for (const auto& n : StandardRegionNames()) {
    if (n != "forehead" && n != "nose") expected.push_back(n);
  }
  EXPECT_EQ(missing, expected);
  EXPECT_EQ(missing.size(), StandardRegionNames().size() - 2);
}

TEST(RigInfo, JsonDescribesSizesCoverageAndLandmarks) {
  const FaceRig rig = QuadrantRig();
  const nlohmann::json j = RigInfoJson(rig, "q.crig");
  EXPECT_EQ(j["file"], "q.crig");
  EXPECT_EQ(j["vertices"], 25);
  EXPECT_EQ(j["triangles"], 32);
  EXPECT_EQ(j["extent_mm"], nlohmann::json({40.0, 40.0, 0.0}));
  EXPECT_EQ(j["expressions"], nlohmann::json({"jawOpen", "eyeBlink_L"}));
  EXPECT_EQ(j["landmarks"]["tip"], 16);
  EXPECT_EQ(j["regions"]["forehead"]["size"], 8);
  EXPECT_DOUBLE_EQ(j["regions"]["nose"]["coverage"].get<double>(), 0.5);
  EXPECT_EQ(j["missing_standard_regions"], nlohmann::json(MissingStandardRegions(rig)));
}

TEST(RigInfo, VertexRegionIsTheFirstRegionContainingItsUv) {
  const FaceRig rig = QuadrantRig();
  const Eigen::MatrixXd region = VertexRegionIndices(rig, rig.neutral);
  ASSERT_EQ(region.rows(), rig.num_vertices());
  ASSERT_EQ(region.cols(), 1);
  EXPECT_EQ(region(GridVertex(1, 1), 0), 0.0);   // in both: forehead comes first
  EXPECT_EQ(region(GridVertex(3, 1), 0), 0.0);   // forehead only
  EXPECT_EQ(region(GridVertex(1, 3), 0), 1.0);   // nose only
  EXPECT_EQ(region(GridVertex(3, 3), 0), -1.0);  // neither
  EXPECT_EQ(region(GridVertex(4, 0), 0), -1.0);  // u = 1 lies outside the masks
}

TEST(RigInfo, RegionPictureTintsMasksDrawsEdgesAndLandmarks) {
  const FaceRig rig = QuadrantRig();
  const int size = 64;  // cells of 16 px; sample texels 4+ px from every edge and diagonal
  const cv::Mat img = RegionPicture(rig, size);
  ASSERT_EQ(img.type(), CV_32FC3);
  ASSERT_EQ(img.rows, size);
  ASSERT_EQ(img.cols, size);
  const auto at = [&](int x, int y) { return img.at<cv::Vec3f>(y, x); };
  const cv::Vec3f forehead = at(44, 6), nose = at(12, 38), both = at(12, 6), none = at(44, 38);
  EXPECT_EQ(none, cv::Vec3f(0.05f, 0.05f, 0.05f));
  EXPECT_NE(forehead, none);
  EXPECT_NE(forehead, nose);
  EXPECT_EQ(both, nose);  // a later region paints over an earlier one
  EXPECT_NE(forehead[0], forehead[1]);  // tinted, not grey
  // An edge of the layout (u = 0.5) is grey, the landmark's dot white.
  EXPECT_NEAR(at(32, 40)[0], at(32, 40)[1], 1e-6);
  EXPECT_GT(at(32, 40)[0], none[0]);
  EXPECT_EQ(at(16, 48), cv::Vec3f(1.0f, 1.0f, 1.0f));
}

TEST(RigInfo, NamedCoefficientsByNameOrIndexWithNamedErrors) {
  const std::vector<std::string> names = {"jawOpen", "eyeBlink_L", "eyeBlink_R"};
  const Eigen::VectorXd w = ParseNamedCoefficients({"eyeBlink_L=0.5", "0=2", "eyeBlink_L=0.25"}, names, "expression");
  ASSERT_EQ(w.size(), 3);
  EXPECT_EQ(w[0], 2.0);
  EXPECT_EQ(w[1], 0.25);  // the last item for a name wins
  EXPECT_EQ(w[2], 0.0);
  EXPECT_EQ(ParseNamedCoefficients({}, names, "expression"), Eigen::VectorXd::Zero(3));
  EXPECT_ERROR_HAS(ParseNamedCoefficients({"smile=1"}, names, "expression"),
                   "--expression: the rig has no expression named 'smile' (it has: jawOpen, eyeBlink_L, eyeBlink_R)");
  EXPECT_ERROR_HAS(ParseNamedCoefficients({"3=1"}, names, "identity"), "the rig has no identity named '3'");
  EXPECT_ERROR_HAS(ParseNamedCoefficients({"jawOpen=lots"}, names, "expression"),
                   "--expression 'jawOpen=lots': 'lots' is not a number");
  EXPECT_ERROR_HAS(ParseNamedCoefficients({"jawOpen"}, names, "expression"),
                   "--expression 'jawOpen': expected NAME=VALUE");
}

}  // namespace
}  // namespace crease
