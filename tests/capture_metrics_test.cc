// The wrinkle offset of eval/capture_metrics.h (the slide of the paper's Fig. 14).
#include "eval/capture_metrics.h"

#include <gtest/gtest.h>

#include <cmath>

#include <opencv2/core.hpp>

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

}  // namespace
}  // namespace crease
