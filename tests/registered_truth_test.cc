// The truth registered through the image (eval/registered_truth.h): maps of the
// UV coordinates themselves, so the registered map says which true texel each
// tracked texel sees.
#include "eval/registered_truth.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/uv_raster.h"
#include "pipeline/training/detail_extraction.h"
#include "tests/synth_test_util.h"

namespace crease {
namespace {

constexpr int kR = 512;

const FaceRig& Rig() { return testing::ProceduralRig(); }

struct Scene {
  CameraIntrinsics K = CameraIntrinsics::FromFov(50.0, 640, 480);
  MatX3d cam;  // the rig's neutral in the camera frame
};

Scene FrontalScene() {
  Scene s;
  const MatX3d& V = Rig().neutral.V;
  const Eigen::Vector3d centre = V.colwise().mean().transpose();
  const Camera camera = LookAtCamera(s.K, centre + Eigen::Vector3d(0, 0, 450), centre, Eigen::Vector3d::UnitY());
  s.cam.resize(V.rows(), 3);
  for (int v = 0; v < V.rows(); ++v) s.cam.row(v) = (camera.cam_from_head * Eigen::Vector3d(V.row(v).transpose())).transpose();
  return s;
}

// u (channel 0) or v (channel 1) of each texel centre, in texels.
cv::Mat CoordinateMap(int channel) {
  cv::Mat m(kR, kR, CV_32F);
  for (int j = 0; j < kR; ++j) {
    for (int i = 0; i < kR; ++i) m.at<float>(j, i) = static_cast<float>(channel == 0 ? i + 0.5 : j + 0.5);
  }
  return m;
}

FrameTextureOptions Options() {
  FrameTextureOptions o;
  o.map_resolution = kR;
  return o;
}

// Mean of (registered − own coordinate) over the finite texels of the forehead, and their count.
double MeanShift(const cv::Mat& registered, const cv::Mat& own, int* count) {
  const cv::Mat forehead = ResampleSquareMap(Rig().FindRegion("forehead")->mask, kR) > 127;
  double sum = 0;
  *count = 0;
  for (int j = 0; j < kR; ++j) {
    for (int i = 0; i < kR; ++i) {
      const float r = registered.at<float>(j, i);
      if (!forehead.at<uint8_t>(j, i) || !std::isfinite(r)) continue;
      sum += r - own.at<float>(j, i);
      ++*count;
    }
  }
  return *count ? sum / *count : 0.0;
}

TEST(TruthRegistration, TrackedEqualToTruthSeesEachTexelItself) {
  const Scene s = FrontalScene();
  const TruthRegistration reg(Rig(), s.K, Options());
  const cv::Mat u = CoordinateMap(0), v = CoordinateMap(1);
  const std::vector<cv::Mat> out = reg.Register(s.cam, s.cam, {u, v});
  ASSERT_EQ(out.size(), 2u);
  int n = 0;
  // The splat and the bilinear resampling are unbiased: the mean shift is a small
  // fraction of a pixel (a pixel is about 1.5 texels here).
  EXPECT_NEAR(MeanShift(out[0], u, &n), 0.0, 0.3);
  EXPECT_GT(n, 2000);
  EXPECT_NEAR(MeanShift(out[1], v, &n), 0.0, 0.3);
  const cv::Mat forehead = ResampleSquareMap(Rig().FindRegion("forehead")->mask, kR) > 127;
  EXPECT_GT(CompareMaps(out[0], u, forehead).correlation, 0.99);
}

TEST(TruthRegistration, ShiftedTrackedMeshSeesTheTruthBesideIt) {
  // L~^t 3 mm to the camera's right of the truth: texel u of L~^t projects to the
  // pixel where the truth shows the surface 3 mm to the right of u on the
  // (near-frontal) forehead, so the registered u coordinate grows by 3 mm of texels
  // (the chart's u runs with the camera's x for a frontal face).
  const Scene s = FrontalScene();
  MatX3d shifted = s.cam;
  shifted.col(0).array() += 3.0;
  const TruthRegistration reg(Rig(), s.K, Options());
  const cv::Mat u = CoordinateMap(0), v = CoordinateMap(1);
  const std::vector<cv::Mat> out = reg.Register(s.cam, shifted, {u, v});
  // The forehead's own scale: camera x per texel of u there.
  const cv::Mat P = InterpolateToUv(reg.extractor().raster(), reg.extractor().chart_mesh(), s.cam);
  cv::Mat x_of_u(kR, kR, CV_32F, cv::Scalar(std::nanf("")));
  for (int j = 0; j < kR; ++j) {
    for (int i = 1; i + 1 < kR; ++i) {
      const float a = P.at<cv::Vec3f>(j, i - 1)[0], b = P.at<cv::Vec3f>(j, i + 1)[0];
      if (a != 0.0f && b != 0.0f) x_of_u.at<float>(j, i) = 0.5f * (b - a);
    }
  }
  int n = 0;
  const double mm_per_texel = MeanShift(x_of_u, cv::Mat::zeros(kR, kR, CV_32F), &n);
  ASSERT_GT(std::abs(mm_per_texel), 0.05);
  const double du = MeanShift(out[0], u, &n) * mm_per_texel;
  EXPECT_GT(n, 2000);
  EXPECT_NEAR(du, 3.0, 0.3) << "u shift " << du << " mm";
  EXPECT_NEAR(MeanShift(out[1], v, &n) * std::abs(mm_per_texel), 0.0, 0.5);
}

TEST(TruthRegistration, RejectsMapsOfAnotherSize) {
  const Scene s = FrontalScene();
  const TruthRegistration reg(Rig(), s.K, Options());
  EXPECT_THROW(reg.Register(s.cam, s.cam, {cv::Mat::zeros(kR / 2, kR / 2, CV_32F)}), Error);
  EXPECT_THROW(reg.Register(s.cam, s.cam, {cv::Mat::zeros(kR, kR, CV_64F)}), Error);
}

}  // namespace
}  // namespace crease
