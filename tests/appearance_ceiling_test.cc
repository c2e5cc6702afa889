// Rung A of the detail ladder (eval/appearance_ceiling.h): a texture whose shading
// is a local linear function of the detail gives a ceiling near 1, a texture
// unrelated to it a ceiling near 0, and the halves alternate in blocks.
#include "eval/appearance_ceiling.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/rng.h"

namespace crease {
namespace {

constexpr int kR = 96;

// A smooth random field (mm-like amplitude ~0.1).
cv::Mat Field(Rng& rng, double sigma) {
  cv::Mat f(kR, kR, CV_32F);
  for (int y = 0; y < kR; ++y)
    for (int x = 0; x < kR; ++x) f.at<float>(y, x) = static_cast<float>(rng.Uniform(-1.0, 1.0));
  cv::GaussianBlur(f, f, cv::Size(), sigma, sigma, cv::BORDER_REFLECT);
  double lo, hi;
  cv::minMaxLoc(f, &lo, &hi);
  return f * (0.1 / std::max(std::abs(lo), std::abs(hi)));
}

AppearanceCeilingOptions SmallOptions() {
  AppearanceCeilingOptions o;
  o.window = 5;
  o.window_step = 2;
  o.stride = 2;
  o.block = 2;
  return o;
}

// The reference albedo × shading: a ramp, 0 (unseen) in a corner.
cv::Mat Reference() {
  cv::Mat ref(kR, kR, CV_32F);
  for (int y = 0; y < kR; ++y)
    for (int x = 0; x < kR; ++x) ref.at<float>(y, x) = (x < 10 && y < 10) ? 0.f : 0.2f + 0.3f * x / kR;
  return ref;
}

// Runs 12 frames. `shaded`: the texture darkens in the grooves (cavity) and with
// the vertical slope of the detail (a light from above), else it varies at random.
AppearanceCeiling RunFrames(bool shaded) {
  Rng rng(7);
  const cv::Mat ref = Reference();
  const cv::Mat mask(kR, kR, CV_8U, cv::Scalar(255));
  AppearanceCeilingMeter meter(ref, mask, 2, SmallOptions());
  for (int frame = 0; frame < 12; ++frame) {
    const cv::Mat detail = Field(rng, 3.0);
    cv::Mat slope;
    cv::Sobel(detail, slope, CV_32F, 0, 1, 3, 1.0 / 8.0);
    const cv::Mat contrast = shaded ? cv::Mat(detail * 3.0 + slope * 4.0) : Field(rng, 3.0);
    cv::Mat texture = ref.mul(1.0 + contrast);
    const cv::Mat unrelated = Field(rng, 3.0);
    meter.Add(frame, texture, {detail, unrelated});
  }
  return meter.Result();
}

TEST(AppearanceCeiling, ShadingOfTheDetailIsExplainedAndNoiseIsNot) {
  const AppearanceCeiling shaded = RunFrames(true);
  ASSERT_TRUE(shaded.measured());
  EXPECT_GT(shaded.correlation[0], 0.9);           // the detail, from its shading
  EXPECT_LT(std::abs(shaded.correlation[1]), 0.2);  // a field the texture knows nothing of
  const AppearanceCeiling random = RunFrames(false);
  ASSERT_TRUE(random.measured());
  EXPECT_LT(std::abs(random.correlation[0]), 0.2);
}

TEST(AppearanceCeiling, FramesAlternateBetweenHalvesInBlocks) {
  const AppearanceCeiling a = RunFrames(true);
  EXPECT_EQ(a.frames[0], 6);  // frames 0–1, 4–5, 8–9 and 2–3, 6–7, 10–11 with block 2
  EXPECT_EQ(a.frames[1], 6);
  EXPECT_GT(a.samples[0], 0);
  EXPECT_EQ(a.samples[0], a.samples[1]);  // the same mask and seen texels every frame
}

TEST(AppearanceCeiling, OneHalfAloneIsNotMeasured) {
  const cv::Mat ref = Reference();
  AppearanceCeilingMeter meter(ref, cv::Mat(kR, kR, CV_8U, cv::Scalar(255)), 1, SmallOptions());
  Rng rng(3);
  meter.Add(0, ref, {Field(rng, 3.0)});
  meter.Add(1, ref, {Field(rng, 3.0)});
  EXPECT_FALSE(meter.Result().measured());
}

TEST(AppearanceCeiling, WrongSizesAndOptionsAreErrors) {
  const cv::Mat ref = Reference();
  const cv::Mat mask(kR, kR, CV_8U, cv::Scalar(255));
  EXPECT_THROW(AppearanceCeilingMeter(ref, cv::Mat(kR / 2, kR / 2, CV_8U), 1, SmallOptions()), Error);
  AppearanceCeilingOptions even = SmallOptions();
  even.window = 4;
  EXPECT_THROW(AppearanceCeilingMeter(ref, mask, 1, even), Error);
  AppearanceCeilingMeter meter(ref, mask, 1, SmallOptions());
  EXPECT_THROW(meter.Add(0, cv::Mat(kR, kR, CV_64F, cv::Scalar(0.5)), {ref}), Error);
  EXPECT_THROW(meter.Add(0, ref, {ref, ref}), Error);
}

}  // namespace
}  // namespace crease
