#include "core/painted_regions.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "tests/test_util.h"

#include "core/image_io.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using testing::TestDir;
using testing::WriteText;

FaceRig RigWithForehead() {
  FaceRig rig;
  rig.regions = {{"forehead", cv::Mat::zeros(8, 8, CV_8UC1)}};
  return rig;
}

TEST(PaintedRegions, PicturesReplaceOrAddRegionsByName) {
  const fs::path dir = TestDir() / "regions";
  fs::create_directories(dir);
  cv::Mat left = cv::Mat::zeros(16, 16, CV_32FC3);
  left(cv::Rect(0, 0, 8, 16)).setTo(cv::Scalar(1.0, 0.0, 0.0));  // only the first channel counts
  WriteImage(dir / "forehead.png", left, {.srgb = false});
  cv::Mat top = cv::Mat::zeros(16, 16, CV_32FC1);
  top(cv::Rect(0, 0, 16, 4)) = 1.0f;
  WriteImage(dir / "chin.png", top, {.srgb = false});
  WriteText(dir / "notes.txt", "not a region");
  FaceRig rig = RigWithForehead();
  const std::vector<fs::path> used = AddPaintedRegions(dir, &rig);
  EXPECT_EQ(used.size(), 2u);
  ASSERT_EQ(rig.regions.size(), 2u);
  const RegionMask* forehead = rig.FindRegion("forehead");
  const RegionMask* chin = rig.FindRegion("chin");
  ASSERT_TRUE(forehead && chin);
  EXPECT_EQ(forehead->mask.size(), cv::Size(16, 16));
  EXPECT_EQ(cv::countNonZero(forehead->mask), 8 * 16);
  EXPECT_TRUE(rig.InRegion("forehead", {0.2, 0.9}));
  EXPECT_FALSE(rig.InRegion("forehead", {0.8, 0.1}));
  EXPECT_EQ(cv::countNonZero(chin->mask), 16 * 4);
  EXPECT_TRUE(AddPaintedRegions(TestDir() / "absent", &rig).empty());
}

TEST(PaintedRegions, NonSquarePicturesAreRefusedByName) {
  FaceRig rig = RigWithForehead();
  EXPECT_ERROR_HAS(SetRegionFromPicture("cheek", cv::Mat::zeros(8, 16, CV_32FC1), "cheek.png", &rig),
                   "cheek.png: region masks must be square");
  EXPECT_EQ(rig.regions.size(), 1u);
}

}  // namespace
}  // namespace crease
