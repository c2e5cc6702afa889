// Tests of the Poisson fill of uncovered texels (pipeline/capture/poisson_fill.h,
// paper Sec. 5.2): properties (linear fields exact, known texels untouched, 0
// outside the domain, no NaN, thread-count independence), the coarse solver
// against the exact full-grid solve, and bad input.
#include "pipeline/capture/poisson_fill.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "core/options.h"
#include "core/rng.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

// A disc domain (a face chart stand-in) with a hole (an eye), CV_8U S×S.
cv::Mat DiscDomain(int S) {
  cv::Mat d(S, S, CV_8U, cv::Scalar(0));
  cv::circle(d, cv::Point(S / 2, S / 2), static_cast<int>(0.45 * S), cv::Scalar(255), cv::FILLED);
  cv::circle(d, cv::Point(S / 2, S * 82 / 100), S / 16, cv::Scalar(0), cv::FILLED);
  return d;
}

// Known: a thick ring enclosing the centre, and rotated squares (patches) inside
// and outside it.
cv::Mat RingKnown(int S) {
  cv::Mat k(S, S, CV_8U, cv::Scalar(0));
  cv::circle(k, cv::Point(S / 2, S / 2), S / 4, cv::Scalar(255), S / 10);
  for (const auto& [cx, cy, a] : {std::tuple{0.5, 0.5, 20.0}, std::tuple{0.55, 0.42, 60.0},
                                  std::tuple{0.8, 0.6, 10.0}, std::tuple{0.3, 0.8, 35.0}}) {
    const cv::RotatedRect r(cv::Point2f(cx * S, cy * S), cv::Size2f(S / 12.f, S / 12.f), a);
    cv::Point2f p[4];
    r.points(p);
    std::vector<cv::Point> poly(p, p + 4);
    cv::fillConvexPoly(k, poly, cv::Scalar(255));
  }
  return k;
}

cv::Mat LinearField(int S, double a, double b, double c) {
  cv::Mat m(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) m.at<float>(y, x) = static_cast<float>(a * x + b * y + c);
  return m;
}

// Texels enclosed by the ring (inside the circle of radius S/4 − ring half width).
cv::Mat Enclosed(int S, const cv::Mat& domain, const cv::Mat& known) {
  cv::Mat inner(S, S, CV_8U, cv::Scalar(0));
  cv::circle(inner, cv::Point(S / 2, S / 2), S / 4 - S / 20 - 1, cv::Scalar(255), cv::FILLED);
  cv::Mat out = inner & domain & (known == 0);
  return out;
}

PoissonFillOptions Coarse(int fill_resolution, const std::string& boundary = "zero") {
  PoissonFillOptions o;
  o.fill_resolution = fill_resolution;
  o.fill_boundary = FromString<FillBoundary>(boundary, "fill.boundary");
  return o;
}

TEST(PoissonFill, ReproducesALinearFieldWhereEnclosed) {
  const int S = 256;
  const cv::Mat domain = DiscDomain(S), known = RingKnown(S);
  const cv::Mat enclosed = Enclosed(S, domain, known);
  ASSERT_GT(cv::countNonZero(enclosed), 5000);
  const cv::Mat truth = LinearField(S, 0.013, -0.021, 0.7);  // range ≈ 8.7
  for (const std::string boundary : {"zero", "neumann"}) {
    for (int res : {256, 64, 32}) {  // exact direct solve (s = 1), and coarse s = 4, 8
      const PoissonFill fill(domain, known, Coarse(res, boundary));
      cv::Mat map = truth.clone();
      map.setTo(123.0f, known == 0);  // unknown texels must not matter
      fill.Apply(&map);
      double worst = 0.0;
      for (int y = 0; y < S; ++y)
        for (int x = 0; x < S; ++x)
          if (enclosed.at<uint8_t>(y, x))
            worst = std::max(worst, std::abs(double(map.at<float>(y, x)) - truth.at<float>(y, x)));
      std::printf("%s, fill_resolution %d (s = %d): max error in the enclosed region %.2e (field range 8.7)\n",
                  boundary.c_str(), res, fill.block_size(), worst);
      EXPECT_LT(worst / 8.7, 1e-4) << boundary << " " << res;
    }
  }
}

TEST(PoissonFill, KnownUnchangedOutsideZeroNoNan) {
  const int S = 128;
  const cv::Mat domain = DiscDomain(S), known = RingKnown(S);
  for (const std::string boundary : {"zero", "neumann"}) {
    const PoissonFill fill(domain, known, Coarse(32, boundary));
    cv::Mat map(S, S, CV_32F);
    Rng rng(3);
    for (int y = 0; y < S; ++y)
      for (int x = 0; x < S; ++x) map.at<float>(y, x) = static_cast<float>(rng.Uniform() - 0.5);
    map.setTo(std::numeric_limits<float>::quiet_NaN(), domain == 0);  // outside: anything
    const cv::Mat before = map.clone();
    fill.Apply(&map);
    for (int y = 0; y < S; ++y) {
      for (int x = 0; x < S; ++x) {
        const float v = map.at<float>(y, x);
        ASSERT_TRUE(std::isfinite(v)) << x << "," << y;
        if (!domain.at<uint8_t>(y, x)) {
          ASSERT_EQ(v, 0.0f);
        } else if (known.at<uint8_t>(y, x)) {
          const float b = before.at<float>(y, x);
          ASSERT_EQ(std::memcmp(&v, &b, sizeof(float)), 0) << x << "," << y;
        }
      }
    }
  }
}

// The coarse solver against the exact full-grid solve, on patch-like known data.
TEST(PoissonFill, CoarseSolveIsCloseToTheExactOne) {
  const int S = 256;
  const cv::Mat domain = DiscDomain(S), known = RingKnown(S);
  cv::Mat map(S, S, CV_32F);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x)
      map.at<float>(y, x) = static_cast<float>(std::sin(0.05 * x) * std::cos(0.07 * y) + 0.3 * std::sin(0.15 * x));
  cv::Mat exact = map.clone();
  PoissonFill(domain, known, Coarse(S)).Apply(&exact);
  const cv::Mat unknown = domain & (known == 0);
  // (fill_resolution, bound on the max error, bound on the RMS error); data range 2.6.
  for (const auto& [res, max_bound, rms_bound] : {std::tuple{64, 0.25, 0.04}, std::tuple{32, 0.4, 0.08}}) {
    cv::Mat coarse = map.clone(), coarse_only = map.clone();
    const PoissonFill fill(domain, known, Coarse(res));
    fill.Apply(&coarse);
    PoissonFillOptions no_smooth = Coarse(res);
    no_smooth.fill_smoothing_sweeps = 0;
    PoissonFill(domain, known, no_smooth).Apply(&coarse_only);
    double err = 0, err0 = 0, rms = 0;
    int n = 0;
    for (int y = 0; y < S; ++y)
      for (int x = 0; x < S; ++x)
        if (unknown.at<uint8_t>(y, x)) {
          err = std::max(err, std::abs(double(coarse.at<float>(y, x)) - exact.at<float>(y, x)));
          err0 = std::max(err0, std::abs(double(coarse_only.at<float>(y, x)) - exact.at<float>(y, x)));
          rms += std::pow(double(coarse.at<float>(y, x)) - exact.at<float>(y, x), 2);
          ++n;
        }
    rms = std::sqrt(rms / n);
    std::printf("s = %d vs exact: max |error| %.4f (without smoothing %.4f), RMS %.4f; data range 2.6, band %d "
                "texels\n",
                fill.block_size(), err, err0, rms, fill.num_band());
    EXPECT_LT(err, err0);
    EXPECT_LT(err, max_bound);
    EXPECT_LT(rms, rms_bound);
  }
}

TEST(PoissonFill, SameBytesForAnyThreadCount) {
  const int S = 256;
  const cv::Mat domain = DiscDomain(S), known = RingKnown(S);
  const PoissonFill fill(domain, known, Coarse(64));
  cv::Mat base(S, S, CV_32F);
  Rng rng(9);
  for (int y = 0; y < S; ++y)
    for (int x = 0; x < S; ++x) base.at<float>(y, x) = static_cast<float>(rng.Uniform());
  cv::Mat one = base.clone(), two = base.clone();
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    fill.Apply(&one);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    fill.Apply(&two);
  }
  EXPECT_EQ(std::memcmp(one.data, two.data, one.total() * sizeof(float)), 0);
}

// With Neumann at the chart border a region touching no known texel is singular: it is set to 0.
TEST(PoissonFill, NeumannIslandWithoutKnownTexelsIsZero) {
  const int S = 64;
  cv::Mat domain(S, S, CV_8U, cv::Scalar(0)), known(S, S, CV_8U, cv::Scalar(0));
  cv::rectangle(domain, cv::Rect(4, 4, 20, 20), cv::Scalar(255), cv::FILLED);   // island, nothing known
  cv::rectangle(domain, cv::Rect(36, 36, 24, 24), cv::Scalar(255), cv::FILLED);
  cv::rectangle(known, cv::Rect(40, 40, 8, 8), cv::Scalar(255), cv::FILLED);
  for (int res : {64, 16}) {
    const PoissonFill fill(domain, known, Coarse(res, "neumann"));
    cv::Mat map(S, S, CV_32F, cv::Scalar(2.5f));
    fill.Apply(&map);
    EXPECT_EQ(map.at<float>(10, 10), 0.0f);
    // The other component is constant 2.5 (Neumann: the known value spreads).
    EXPECT_NEAR(map.at<float>(58, 58), 2.5f, 1e-4);
  }
}

TEST(PoissonFill, BadInputIsAClearError) {
  const cv::Mat domain = DiscDomain(64), known = RingKnown(64);
  EXPECT_ERROR_HAS(PoissonFill(domain, RingKnown(32), Coarse(16)), "known mask is 32x32, the domain mask 64x64");
  cv::Mat f32;
  domain.convertTo(f32, CV_32F);
  EXPECT_ERROR_HAS(PoissonFill(f32, known, Coarse(16)), "domain mask must be CV_8UC1");
  EXPECT_ERROR_HAS(PoissonFill(cv::Mat(), known, Coarse(16)), "domain mask is empty");
  EXPECT_ERROR_HAS(PoissonFill(DiscDomain(66), RingKnown(66), Coarse(16)), "not a multiple of the block size");
  EXPECT_ERROR_HAS(Coarse(16, "dirichlet"), "fill.boundary = 'dirichlet' must be one of: zero, neumann");
  PoissonFillOptions bad = Coarse(16);
  bad.fill_smoothing_sweeps = -1;
  EXPECT_ERROR_HAS(PoissonFill(domain, known, bad), "fill_smoothing_sweeps");
  const PoissonFill fill(domain, known, Coarse(16));
  cv::Mat wrong_size(32, 32, CV_32F, cv::Scalar(0)), wrong_type(64, 64, CV_64F, cv::Scalar(0));
  EXPECT_ERROR_HAS(fill.Apply(&wrong_size), "map is 32x32, expected 64x64");
  EXPECT_ERROR_HAS(fill.Apply(&wrong_type), "expected a CV_32FC1 map");
}

}  // namespace
}  // namespace crease
