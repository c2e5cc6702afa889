// The wrinkle offset of eval/capture_metrics.h (the slide of the paper's Fig. 14),
// and the refinement-step errors at the flow points with their file round trip.
#include "eval/capture_metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/ray_caster.h"
#include "tests/test_util.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/capture/flow_refinement.h"
#include "pipeline/capture/frame_texture.h"

namespace crease {
namespace {

// Horizontal grooves (a forehead's lines) every 23 texels, plus a weak ramp.
cv::Mat Grooves(int size, int shift_up) {
  cv::Mat m(size, size, CV_32F);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const double v = y + shift_up;  // a feature at y0 in G appears at y0 − shift_up here
      m.at<float>(y, x) = static_cast<float>(-0.05 * std::exp(-std::pow(std::fmod(v + 1000.0, 23.0) - 11.5, 2) / 4.0) +
                                             1e-5 * x);
    }
  return m;
}

TEST(CaptureMetrics, WrinkleOffsetFindsAKnownShift) {
  const int n = 128;
  cv::Mat mask = cv::Mat::zeros(n, n, CV_8U);
  mask(cv::Rect(10, 20, 100, 80)).setTo(1);
  const cv::Mat G = Grooves(n, 0);
  for (int s : {-6, 0, 4, 9}) {
    int found = 100;
    double r = 0;
    ASSERT_TRUE(BestVerticalOffset(Grooves(n, s), G, mask, 10, &found, &r)) << s;
    // D's lines lie s texels higher (smaller y) when D(y) = G(y + s).
    EXPECT_EQ(found, s);
    EXPECT_GT(r, 0.95);
  }
  // Outside the search range the best in-range shift is not the true one.
  int found = 0;
  double r = 0;
  BestVerticalOffset(Grooves(n, 9), G, mask, 3, &found, &r);
  EXPECT_LE(std::abs(found), 3);
  EXPECT_LT(r, 0.95);
  // Nothing to correlate: a flat map.
  EXPECT_FALSE(BestVerticalOffset(cv::Mat::zeros(n, n, CV_32F), G, mask, 5, &found, &r));
}

// Four flow points with known errors per step: the statuses split the means, the
// invisible point and the point off the evaluated set do not count, and the
// arrays survive the capture's frame file.
TEST(CaptureMetrics, FlowStagesSplitTheErrorByStep) {
  const CameraIntrinsics K = CameraIntrinsics::FromFov(50.0, 640, 480);
  const Camera cam(K, Rigid3d());
  const int V = 6;
  MatX2d truth(V, 2);
  CaptureFrameArrays a;
  a.frame = 7;
  a.tracked = true;
  a.coarse.resize(V, 3);
  a.refined.resize(V, 3);
  for (int v = 0; v < V; ++v) {
    const Eigen::Vector3d X(10.0 * v - 25.0, 5.0 * v, 500.0);
    a.coarse.row(v) = X.transpose();
    a.refined.row(v) = X.transpose();
    truth.row(v) = cam.ProjectCamPoint(X).transpose();
  }
  // L~^t is 1 px off in x at every vertex (moved by 1 px · z / f in camera x).
  for (int v = 0; v < V; ++v) a.refined(v, 0) += a.refined(v, 2) / K.fx;
  a.flow_vertex = {0, 1, 2, 3, 4};
  a.flow_status = {static_cast<uint8_t>(FlowPointStatus::kTrusted), static_cast<uint8_t>(FlowPointStatus::kTrusted),
                   static_cast<uint8_t>(FlowPointStatus::kRecovered), static_cast<uint8_t>(FlowPointStatus::kInvisible),
                   static_cast<uint8_t>(FlowPointStatus::kReset)};
  a.flow_projected = truth.topRows(5);
  a.flow_projected.col(1).array() += 2.0;  // u^t: 2 px off everywhere
  a.flow_positions = truth.topRows(5);
  a.flow_positions.col(0).array() += Eigen::Array<double, 5, 1>(1.0, 3.0, 4.0, 9.0, 0.0);
  a.flow_positions(4, 1) += 2.0;  // the reset point sits at u^t
  a.flow_fitted = truth.topRows(5);
  a.flow_fitted.col(1).array() += 0.5;
  const std::vector<char> visible(V, 1);
  std::vector<char> evaluated(V, 1);
  evaluated[1] = 0;  // a trusted point off the evaluated vertices
  const FlowStageErrors e = MeasureFlowStages(a, cam, truth, visible, evaluated);
  EXPECT_EQ(e.points, 3);
  EXPECT_EQ(e.trusted, 1);
  EXPECT_EQ(e.recovered, 1);
  EXPECT_EQ(e.reset, 1);
  EXPECT_NEAR(e.coarse_px, 2.0, 1e-9);
  EXPECT_NEAR(e.trusted_px, 1.0, 1e-9);
  EXPECT_NEAR(e.trusted_coarse_px, 2.0, 1e-9);
  EXPECT_NEAR(e.recovered_px, 4.0, 1e-9);
  EXPECT_NEAR(e.reset_px, 2.0, 1e-9);
  EXPECT_NEAR(e.flow_px, (1.0 + 4.0 + 2.0) / 3.0, 1e-9);
  EXPECT_NEAR(e.fit_px, 0.5, 1e-9);
  EXPECT_NEAR(e.refined_px, 1.0, 1e-6);

  const std::filesystem::path path = std::filesystem::temp_directory_path() / "crease_flow_stages.cfr";
  WriteCaptureFrameArrays(path, a);
  const CaptureFrameArrays b = ReadCaptureFrameArrays(path);
  std::filesystem::remove(path);
  EXPECT_EQ(b.flow_vertex, a.flow_vertex);
  EXPECT_EQ(b.flow_status, a.flow_status);
  EXPECT_LT((b.flow_positions - a.flow_positions).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LT((b.flow_fitted - a.flow_fitted).cwiseAbs().maxCoeff(), 1e-3);
  const FlowStageErrors e2 = MeasureFlowStages(b, cam, truth, visible, evaluated);
  EXPECT_NEAR(e2.recovered_px, 4.0, 1e-3);
  // A frame without flow points (an older file, an unrefined frame) has none after the round trip.
  a.flow_vertex.clear();
  WriteCaptureFrameArrays(path, a);
  EXPECT_TRUE(ReadCaptureFrameArrays(path).flow_vertex.empty());
  std::filesystem::remove(path);
}

// A flat true surface (z = 0) and H^t a grid 0.1 mm above it whose normals tilt by
// 20° where u < 0.5: the whole-face angle is the average, the wrinkle-region one
// (the region: u < 0.5) is 20°.
TEST(CaptureMetrics, SurfaceErrorInTheWrinkleRegionsCountsOnlyTheirVertices) {
  const int n = 11;
  TriMesh plane, h;
  plane.V.resize(4, 3);
  plane.V << -10, -10, 0, 10, -10, 0, 10, 10, 0, -10, 10, 0;
  plane.F.resize(2, 3);
  plane.F << 0, 1, 2, 0, 2, 3;
  h.V.resize(n * n, 3);
  h.N.resize(n * n, 3);
  h.UV.resize(n * n, 2);
  const double tilt = 20.0 * M_PI / 180.0;
  int left = 0;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const int i = y * n + x;
      const double u = (x + 0.25) / n, v = (y + 0.5) / n;
      h.V.row(i) << -5 + x, -5 + y, 0.1;
      h.UV.row(i) << u, v;
      const bool in = u < 0.5;
      left += in;
      // Pointing into the surface (-z), as the ray along the normal must hit it.
      h.N.row(i) << (in ? std::sin(tilt) : 0.0), 0.0, -(in ? std::cos(tilt) : 1.0);
    }
  h.F.resize(0, 3);
  const RayCaster caster(plane);
  cv::Mat region = cv::Mat::zeros(64, 64, CV_8U);
  region(cv::Rect(0, 0, 32, 64)).setTo(1);
  const SurfaceError e = MeasureSurface(h, caster, 5.0, region);
  EXPECT_EQ(e.samples, n * n);
  EXPECT_EQ(e.wrinkle_samples, left);
  EXPECT_NEAR(e.wrinkle_normal_deg, 20.0, 1e-3);
  EXPECT_NEAR(e.normal_deg, 20.0 * left / (n * n), 1e-3);
  // Along the normal: 0.1 mm straight down, 0.1 / cos 20° along a tilted one.
  EXPECT_NEAR(e.wrinkle_distance_mm, 0.1 / std::cos(tilt), 1e-5);
  EXPECT_NEAR(e.distance_mm, (left * 0.1 / std::cos(tilt) + (n * n - left) * 0.1) / (n * n), 1e-5);
  EXPECT_EQ(MeasureSurface(h, caster, 5.0, cv::Mat()).wrinkle_samples, 0);
}

// The band normal error (issue 17): on ramps (planes) the angle between the normals
// is exact, atan(s) − atan(s / 2) for slopes s and s / 2 along one direction; the
// truth scores 0; only masked texels count; NaNs are skipped, never averaged in.
TEST(CaptureMetrics, BandNormalErrorIsTheAngleBetweenTheHeightFieldsNormals) {
  const int n = 32;
  const double mm = 0.2, slope = 0.3;  // texel size, mm; the truth's slope (dz/dx)
  cv::Mat truth(n, n, CV_32F), half(n, n, CV_32F), flat = cv::Mat::zeros(n, n, CV_32F);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      truth.at<float>(y, x) = static_cast<float>(slope * mm * x);
      half.at<float>(y, x) = static_cast<float>(0.5 * slope * mm * x);
    }
  const cv::Mat all = cv::Mat::ones(n, n, CV_8U);
  const double deg = 180.0 / M_PI;
  EXPECT_NEAR(BandNormalError(truth, truth, all, mm), 0.0, 1e-9);
  EXPECT_NEAR(BandNormalError(flat, truth, all, mm), std::atan(slope) * deg, 1e-3);
  EXPECT_NEAR(BandNormalError(half, truth, all, mm), (std::atan(slope) - std::atan(0.5 * slope)) * deg, 1e-3);
  // A groove on the right half only: the left half (a flat truth there) scores 0.
  cv::Mat groove = flat.clone();
  for (int y = 0; y < n; ++y)
    for (int x = n / 2; x < n; ++x) groove.at<float>(y, x) = static_cast<float>(slope * mm * (x - n / 2));
  cv::Mat left = cv::Mat::zeros(n, n, CV_8U);
  left(cv::Rect(0, 0, n / 2 - 1, n)).setTo(1);
  EXPECT_NEAR(BandNormalError(flat, groove, left, mm), 0.0, 1e-9);
  EXPECT_GT(BandNormalError(flat, groove, all, mm), 1.0);
  cv::Mat holed = truth.clone();
  holed.at<float>(5, 5) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NEAR(BandNormalError(flat, holed, all, mm), std::atan(slope) * deg, 1e-3);
  EXPECT_THROW(BandNormalError(flat, truth, cv::Mat::ones(n, n, CV_32F), mm), Error);
}

// How fast a truth decorrelates as the texture slides (CaptureEvalSummary::
// truth_shift): horizontal lines of period P match themselves moved along u, and
// moved along v by P / 4, P / 2 and P they correlate cos(2π s / P) = 0, −1 and 1, so
// the four directions pool to 0.5, 0 and 1. Only texels whose moved texel is also
// in the mask count; a bad map or a zero shift is an error.
TEST(CaptureMetrics, SlidTruthDecorrelatesAsTheLinesMoveAcrossThemselves) {
  const int n = 96, period = 16;
  cv::Mat lines(n, n, CV_32F);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) lines.at<float>(y, x) = static_cast<float>(std::cos(2 * M_PI * y / period));
  const cv::Mat all(n, n, CV_8U, cv::Scalar(1));
  auto pooled = [&](const cv::Mat& map, const cv::Mat& mask, int shift) {
    MapMoments m;
    AddSlidTruthMoments(map, mask, shift, &m);
    return m.Result().correlation;
  };
  EXPECT_NEAR(pooled(lines, all, period / 4), 0.5, 0.03);
  EXPECT_NEAR(pooled(lines, all, period / 2), 0.0, 0.03);
  EXPECT_NEAR(pooled(lines, all, period), 1.0, 1e-6);
  // Noise outside a masked band of rows: with the band alone as the mask (and the
  // moved texels inside it too) the figure is the lines' own.
  cv::Mat noisy = lines.clone();
  cv::Mat noise(n, n, CV_32F);
  cv::randu(noise, -5.0, 5.0);
  const cv::Rect band(0, 32, n, 48);
  noise(band).setTo(0.0f);
  noisy += noise;
  cv::Mat inside = cv::Mat::zeros(n, n, CV_8U);
  inside(band).setTo(1);
  EXPECT_NEAR(pooled(noisy, inside, period), 1.0, 1e-6);
  EXPECT_LT(pooled(noisy, all, period), 0.5);
  MapMoments m;
  EXPECT_THROW(AddSlidTruthMoments(lines, all, 0, &m), Error);
  EXPECT_THROW(AddSlidTruthMoments(lines, cv::Mat::ones(n, n, CV_32F), 4, &m), Error);
}

// D^HF of the skin's colour alone (Sec. 5.3's DoG on the albedo's luminance): a dark
// freckle becomes a pit, a flat albedo no relief, and it is the capture's own
// MesoscopicMap of that luminance (one copy of the numerics).
TEST(CaptureMetrics, AlbedoMesoscopicMapTurnsADarkSpotIntoAPit) {
  const int n = 32;
  MesoscopicOptions o;
  o.meso_reference_resolution = n;  // the 3×3 / 9×9 kernels at this map size
  cv::Mat albedo(n, n, CV_32FC3, cv::Scalar(0.6f, 0.45f, 0.4f));
  albedo(cv::Rect(15, 15, 2, 2)).setTo(cv::Scalar(0.2f, 0.1f, 0.1f));
  const cv::Mat seen(n, n, CV_8U, cv::Scalar(255));
  const cv::Mat d = AlbedoMesoscopicMap(albedo, seen, o);
  ASSERT_EQ(d.size(), seen.size());
  EXPECT_LT(d.at<float>(15, 15), -0.05f);           // dark reads as deep, γ = 5 mm per unit
  EXPECT_NEAR(d.at<float>(2, 2), 0.0f, 1e-6f);      // flat colour far from it: no relief
  cv::Mat lum(n, n, CV_32F, cv::Scalar(0.2126f * 0.6f + 0.7152f * 0.45f + 0.0722f * 0.4f));
  lum(cv::Rect(15, 15, 2, 2)).setTo(0.2126f * 0.2f + 0.7152f * 0.1f + 0.0722f * 0.1f);
  EXPECT_LT(cv::norm(d - MesoscopicMap(lum, seen, o), cv::NORM_INF), 1e-6);
  // A finer albedo is resampled to the seen mask's size; unseen texels stay 0.
  cv::Mat fine;
  cv::resize(albedo, fine, cv::Size(2 * n, 2 * n), 0, 0, cv::INTER_NEAREST);
  cv::Mat half_seen = seen.clone();
  half_seen(cv::Rect(0, 0, n / 2, n)).setTo(0);
  const cv::Mat df = AlbedoMesoscopicMap(fine, half_seen, o);
  ASSERT_EQ(df.size(), seen.size());
  EXPECT_EQ(df.at<float>(10, 3), 0.0f);
  EXPECT_LT(df.at<float>(15, 16), -0.05f);
  EXPECT_THROW(AlbedoMesoscopicMap(cv::Mat(n, n + 1, CV_32FC3, cv::Scalar::all(0.5)), seen, o), Error);
  EXPECT_THROW(AlbedoMesoscopicMap(cv::Mat(n, n, CV_8UC3, cv::Scalar::all(100)), seen, o), Error);
}

// `crease eval`'s files: the summary's CSV, Markdown and JSON texts as they are, and
// the Fig. 11 picture only when the summary has one.
TEST(CaptureMetrics, EvalFilesHoldTheSummaryAndThePictureOnlyWhenThereIsOne) {
  const std::filesystem::path dir = testing::TestDir() / "eval";
  CaptureEvalSummary s;
  WriteCaptureEval(dir, s);
  EXPECT_EQ(ReadFileToString(dir / "eval.json"), s.ToJson() + "\n");
  EXPECT_EQ(ReadFileToString(dir / "eval.md"), s.ToMarkdown());
  EXPECT_EQ(ReadFileToString(dir / "eval_frames.csv"), s.ToCsv());
  EXPECT_FALSE(std::filesystem::exists(dir / "error_vectors.png"));
  s.error_vectors = cv::Mat(12, 16, CV_8UC3, cv::Scalar(10, 200, 30));
  s.error_vectors_frame = 3;
  WriteCaptureEval(dir, s);
  const cv::Mat png = ReadImage(dir / "error_vectors.png", /*srgb=*/false);
  ASSERT_EQ(png.size(), cv::Size(16, 12));
  EXPECT_NEAR(png.at<cv::Vec3f>(5, 7)[1], 200.0f / 255.0f, 1e-6);
}

}  // namespace
}  // namespace crease
