#include "pipeline/capture/landmarks.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

TEST(Landmarks, GrayConversionEncodesSrgb) {
  cv::Mat rgb(2, 2, CV_32FC3, cv::Scalar(0.0, 0.0, 0.0));
  rgb.at<cv::Vec3f>(0, 1) = cv::Vec3f(1, 1, 1);
  rgb.at<cv::Vec3f>(1, 0) = cv::Vec3f(0.214f, 0.214f, 0.214f);  // linear 0.214 ≈ sRGB 0.5
  rgb.at<cv::Vec3f>(1, 1) = cv::Vec3f(std::nanf(""), 2.0f, -1.0f);
  const cv::Mat g = ToGray8(rgb);
  ASSERT_EQ(g.type(), CV_8UC1);
  EXPECT_EQ(g.at<uint8_t>(0, 0), 0);
  EXPECT_EQ(g.at<uint8_t>(0, 1), 255);
  EXPECT_NEAR(g.at<uint8_t>(1, 0), 128, 1);
  EXPECT_NO_THROW(ToGray8(cv::Mat(3, 3, CV_8UC3, cv::Scalar(1, 2, 3))));
  EXPECT_NE(ErrorOf([] { ToGray8(cv::Mat()); }).find("empty image"), std::string::npos);
}

TEST(Landmarks, BoxOfPoints) {
  MatX2d p(3, 2);
  p << 10, 20, 30, 60, 20, 40;
  const FaceBox b = BoxOfPoints(p, 2.0);
  EXPECT_DOUBLE_EQ(b.x, 0.0);
  EXPECT_DOUBLE_EQ(b.y, 0.0);
  EXPECT_DOUBLE_EQ(b.width, 40.0);
  EXPECT_DOUBLE_EQ(b.height, 80.0);
}

TEST(Landmarks, DlibFindsNoFaceInNoiseAndNamesAMissingModel) {
  DlibLandmarkOptions bad;
  bad.model_path = "/nonexistent/model.dat";
  EXPECT_NE(ErrorOf([&] { DlibLandmarkSource s(bad); }).find("libdlib-data"), std::string::npos);
  DlibLandmarkSource source;
  cv::Mat noise(240, 320, CV_32FC1);
  cv::randu(noise, 0.0f, 1.0f);
  const LandmarkResult r = source.Track(noise);
  EXPECT_FALSE(r.found);
  EXPECT_TRUE(r.detected);
}

}  // namespace
}  // namespace crease
