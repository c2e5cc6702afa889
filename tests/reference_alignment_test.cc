// ReferenceAligner (pipeline/capture/reference_alignment.h): a reference texture shifted
// against T^t comes back registered to it; an aligned pair stays as it is; bad input
// is refused.
#include "pipeline/capture/reference_alignment.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/rng.h"

namespace crease {
namespace {

constexpr int kR = 512;

// A skin-like texture: smooth random blobs (σ 6 texels) around 0.5 on a disc-shaped
// chart of radius 200 texels, 0 outside.
cv::Mat BlobTexture(uint64_t seed) {
  Rng rng(seed);
  cv::Mat noise(kR, kR, CV_32F);
  for (int y = 0; y < kR; ++y)
    for (int x = 0; x < kR; ++x) noise.at<float>(y, x) = static_cast<float>(rng.Uniform(-1.0, 1.0));
  cv::GaussianBlur(noise, noise, cv::Size(0, 0), 6.0);
  cv::Mat texture = 0.5f + noise * (0.15f / static_cast<float>(cv::norm(noise, cv::NORM_INF)));
  return texture;
}

cv::Mat Chart(double cx, double cy) {
  cv::Mat chart(kR, kR, CV_8U, cv::Scalar(0));
  cv::circle(chart, cv::Point(static_cast<int>(cx), static_cast<int>(cy)), 200, cv::Scalar(255), cv::FILLED);
  return chart;
}

// `texture` sampled at x + (dx, dy), 0 outside the chart.
cv::Mat Shifted(const cv::Mat& texture, const cv::Mat& chart, float dx, float dy) {
  const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, -dx, 0, 1, -dy);
  cv::Mat out;
  cv::warpAffine(texture, out, m, texture.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
  out.setTo(0.0f, chart == 0);
  return out;
}

// RMS difference of a and b over the texels of the inner disc (radius 150).
double InnerRms(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat inner(kR, kR, CV_8U, cv::Scalar(0));
  cv::circle(inner, cv::Point(kR / 2, kR / 2), 150, cv::Scalar(255), cv::FILLED);
  cv::Mat d = a - b;
  return std::sqrt(cv::mean(d.mul(d), inner)[0]);
}

ReferenceAlignmentOptions Enabled() {
  ReferenceAlignmentOptions o;
  o.enabled = true;
  o.resolution = 128;
  return o;
}

TEST(ReferenceAlignment, RegistersAShiftedReference) {
  const cv::Mat base = BlobTexture(3);
  const cv::Mat chart = Chart(kR / 2, kR / 2);
  cv::Mat texture = base.clone();
  texture.setTo(0.0f, chart == 0);
  // The reference shows the face 6.5 texels right and 4.25 down of where T^t shows it.
  const cv::Mat reference = Shifted(base, chart, -6.5f, 4.25f);
  ReferenceAlignmentReport report;
  const cv::Mat aligned = ReferenceAligner(reference, Enabled()).AlignReference(texture, cv::Mat(), &report);
  const double before = InnerRms(reference, texture), after = InnerRms(aligned, texture);
  EXPECT_LT(after, 0.15 * before) << "before " << before << ", after " << after;
  // The shift in coarse texels (512 / 128 = 4 fine texels each): |(6.5, 4.25)| / 4.
  EXPECT_NEAR(report.mean_shift, std::hypot(6.5, 4.25) / 4.0, 0.3);
}

TEST(ReferenceAlignment, RegistersAShiftedTextureToTheReference) {
  const cv::Mat base = BlobTexture(4);
  const cv::Mat chart = Chart(kR / 2, kR / 2);
  cv::Mat reference = base.clone();
  reference.setTo(0.0f, chart == 0);
  const cv::Mat texture = Shifted(base, chart, 5.0f, -3.5f);
  cv::Mat aligned, aligned_seen;
  ReferenceAlignmentReport report;
  ReferenceAligner(reference, Enabled()).AlignTexture(texture, chart, &aligned, &aligned_seen, &report);
  const double before = InnerRms(texture, reference), after = InnerRms(aligned, reference);
  EXPECT_LT(after, 0.15 * before) << "before " << before << ", after " << after;
  EXPECT_NEAR(report.mean_shift, std::hypot(5.0, 3.5) / 4.0, 0.3);
  // The seen mask follows the data: set where the result holds the texture's values.
  EXPECT_EQ(cv::countNonZero(aligned_seen != (aligned > 1e-4f)), 0);
  EXPECT_GT(cv::countNonZero(aligned_seen), cv::countNonZero(chart) * 9 / 10);
}

TEST(ReferenceAlignment, LeavesAnAlignedPairAlone) {
  const cv::Mat chart = Chart(kR / 2, kR / 2);
  cv::Mat texture = BlobTexture(5);
  texture.setTo(0.0f, chart == 0);
  // The same face under another light: a smooth ramp of brightness.
  cv::Mat ramp(kR, kR, CV_32F);
  for (int y = 0; y < kR; ++y)
    for (int x = 0; x < kR; ++x) ramp.at<float>(y, x) = 0.8f + 0.4f * static_cast<float>(x) / kR;
  const cv::Mat reference = texture.mul(ramp);
  ReferenceAlignmentReport report;
  const cv::Mat aligned = ReferenceAligner(reference, Enabled()).AlignReference(texture, cv::Mat(), &report);
  EXPECT_LT(report.mean_shift, 0.1);
  EXPECT_LT(InnerRms(aligned, reference), 0.004);
}

TEST(ReferenceAlignment, KeepsTheChartsEdgeAndNoData) {
  const cv::Mat base = BlobTexture(7);
  const cv::Mat chart = Chart(kR / 2, kR / 2);
  cv::Mat texture = base.clone();
  texture.setTo(0.0f, chart == 0);
  const cv::Mat reference = Shifted(base, chart, 3.0f, 0.0f);
  const cv::Mat aligned = ReferenceAligner(reference, Enabled()).AlignReference(texture, cv::Mat());
  // No texel of the result darker than the chart's darkest (no 0 mixed in at the edge),
  // and nothing outside the chart that the flow could not have brought in.
  double lo = 0.0;
  cv::minMaxLoc(reference, &lo, nullptr, nullptr, nullptr, chart);
  cv::Mat inside = aligned > 1e-4f;
  double alo = 0.0;
  cv::minMaxLoc(aligned, &alo, nullptr, nullptr, nullptr, inside);
  EXPECT_GE(alo, lo - 1e-4);
  cv::Mat far_out(kR, kR, CV_8U, cv::Scalar(255));
  cv::circle(far_out, cv::Point(kR / 2, kR / 2), 240, cv::Scalar(0), cv::FILLED);
  EXPECT_EQ(cv::countNonZero((aligned > 1e-4f) & far_out), 0);
}

TEST(ReferenceAlignment, RefusesBadInput) {
  const cv::Mat a(kR, kR, CV_32F, cv::Scalar(0.5));
  ReferenceAlignmentOptions o = Enabled();
  const ReferenceAligner aligner(a, o);
  EXPECT_THROW(aligner.AlignReference(cv::Mat(kR / 2, kR / 2, CV_32F, cv::Scalar(0.5)), cv::Mat()), Error);
  EXPECT_THROW(aligner.AlignReference(cv::Mat(kR, kR, CV_8U, cv::Scalar(1)), cv::Mat()), Error);
  EXPECT_THROW(aligner.AlignReference(a, cv::Mat(kR, kR, CV_32F)), Error);
  o.resolution = 100;  // 512 is not a multiple
  EXPECT_THROW(ReferenceAligner(a, o), Error);
  o = Enabled();
  o.max_shift = 0.0;
  EXPECT_THROW(ReferenceAligner(a, o), Error);
  // A featureless reference: returned unchanged, no shift.
  ReferenceAlignmentReport report;
  const cv::Mat out = ReferenceAligner(a, Enabled()).AlignReference(a, cv::Mat(), &report);
  EXPECT_EQ(cv::norm(out, a, cv::NORM_INF), 0.0);
  EXPECT_EQ(report.mean_shift, 0.0);
}

}  // namespace
}  // namespace crease
