#include "synth/sensor.h"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "core/error.h"

namespace crease {
namespace {

double SrgbDecode(double s) { return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4); }

// Linear values at which the 8-bit code changes: code k for v in [t[k-1], t[k]).
const std::array<float, 255>& SrgbThresholds() {
  static const std::array<float, 255> t = [] {
    std::array<float, 255> a{};
    for (int k = 0; k < 255; ++k) a[static_cast<size_t>(k)] = static_cast<float>(SrgbDecode((k + 0.5) / 255.0));
    return a;
  }();
  return t;
}

const std::array<float, 256>& SrgbDecodeTable() {
  static const std::array<float, 256> t = [] {
    std::array<float, 256> a{};
    for (int k = 0; k < 256; ++k) a[static_cast<size_t>(k)] = static_cast<float>(SrgbDecode(k / 255.0));
    return a;
  }();
  return t;
}

void RequireLinear(const cv::Mat& image, const char* what) {
  Require(!image.empty() && (image.type() == CV_32FC1 || image.type() == CV_32FC3),
          fmt::format("{}: expected a non-empty CV_32FC1 or CV_32FC3 image, got type {}", what, image.type()));
}

}  // namespace

void SensorOptions::VisitFields(OptionVisitor& v) {
  v.Field("exposure", exposure);
  v.Field("noise", noise);
  v.Field("full_well_electrons", full_well_electrons);
  v.Field("read_noise_electrons", read_noise_electrons);
  v.Field("jpeg_quality", jpeg_quality);
}

void SensorOptions::Check() const {
  const char* o = "SensorOptions";
  CheckGt(o, "exposure", exposure, 0.0);
  CheckGe(o, "full_well_electrons", full_well_electrons, 1.0);
  CheckLe(o, "full_well_electrons", full_well_electrons, 1e9);
  CheckGe(o, "read_noise_electrons", read_noise_electrons, 0.0);
  CheckGe(o, "jpeg_quality", jpeg_quality, 0);
  CheckLe(o, "jpeg_quality", jpeg_quality, 100);
}

int64_t SamplePoisson(double lambda, Rng& rng) {
  Require(std::isfinite(lambda) && lambda >= 0.0, fmt::format("SamplePoisson: lambda = {} must be >= 0", lambda));
  if (lambda == 0.0) return 0;
  if (lambda < 12.0) {  // Knuth
    const double limit = std::exp(-lambda);
    int64_t k = 0;
    double p = rng.Uniform();
    while (p > limit) {
      ++k;
      p *= rng.Uniform();
    }
    return k;
  }
  // PTRS (Hörmann 1993, "The transformed rejection method for generating Poisson random variables").
  const double slam = std::sqrt(lambda), loglam = std::log(lambda);
  const double b = 0.931 + 2.53 * slam;
  const double a = -0.059 + 0.02483 * b;
  const double inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
  const double vr = 0.9277 - 3.6224 / (b - 2.0);
  while (true) {
    const double u = rng.Uniform() - 0.5;
    const double v = rng.Uniform();
    const double us = 0.5 - std::abs(u);
    const double k = std::floor((2.0 * a / us + b) * u + lambda + 0.43);
    if (us >= 0.07 && v <= vr) return static_cast<int64_t>(k);
    if (k < 0.0 || (us < 0.013 && v > us)) continue;
    if (std::log(v) + std::log(inv_alpha) - std::log(a / (us * us) + b) <= -lambda + k * loglam - std::lgamma(k + 1.0)) {
      return static_cast<int64_t>(k);
    }
  }
}

cv::Mat EncodeSrgb8(const cv::Mat& linear) {
  RequireLinear(linear, "EncodeSrgb8");
  const auto& t = SrgbThresholds();
  cv::Mat out(linear.rows, linear.cols, CV_8UC(linear.channels()));
  const int n = linear.cols * linear.channels();
  tbb::parallel_for(tbb::blocked_range<int>(0, linear.rows, 16), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      const float* src = linear.ptr<float>(y);
      uint8_t* dst = out.ptr<uint8_t>(y);
      for (int i = 0; i < n; ++i) {
        const float v = src[i];
        dst[i] = std::isnan(v) ? 0 : static_cast<uint8_t>(std::upper_bound(t.begin(), t.end(), v) - t.begin());
      }
    }
  });
  return out;
}

cv::Mat DecodeSrgb8(const cv::Mat& srgb8) {
  Require(!srgb8.empty() && srgb8.depth() == CV_8U, "DecodeSrgb8: expected a non-empty 8-bit image");
  const auto& t = SrgbDecodeTable();
  cv::Mat out(srgb8.rows, srgb8.cols, CV_32FC(srgb8.channels()));
  const int n = srgb8.cols * srgb8.channels();
  for (int y = 0; y < srgb8.rows; ++y) {
    const uint8_t* src = srgb8.ptr<uint8_t>(y);
    float* dst = out.ptr<float>(y);
    for (int i = 0; i < n; ++i) dst[i] = t[src[i]];
  }
  return out;
}

cv::Mat JpegRoundTrip(const cv::Mat& srgb8, int quality) {
  Require(!srgb8.empty() && (srgb8.type() == CV_8UC1 || srgb8.type() == CV_8UC3),
          "JpegRoundTrip: expected a CV_8UC1 or CV_8UC3 image");
  Require(quality >= 1 && quality <= 100, fmt::format("JpegRoundTrip: quality = {} must lie in [1, 100]", quality));
  cv::Mat bgr;
  if (srgb8.channels() == 3) {
    cv::cvtColor(srgb8, bgr, cv::COLOR_RGB2BGR);
  } else {
    bgr = srgb8;
  }
  std::vector<uint8_t> buffer;
  Require(cv::imencode(".jpg", bgr, buffer, {cv::IMWRITE_JPEG_QUALITY, quality}), "JpegRoundTrip: JPEG encoding failed");
  cv::Mat decoded = cv::imdecode(buffer, srgb8.channels() == 3 ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE);
  Require(!decoded.empty(), "JpegRoundTrip: JPEG decoding failed");
  if (srgb8.channels() == 3) cv::cvtColor(decoded, decoded, cv::COLOR_BGR2RGB);
  return decoded;
}

SensorImage ApplySensor(const cv::Mat& linear, const SensorOptions& options, Rng& rng) {
  options.Check();
  RequireLinear(linear, "ApplySensor");
  const uint64_t seed = rng.NextU64();
  SensorImage out;
  out.linear.create(linear.rows, linear.cols, linear.type());
  const int n = linear.cols * linear.channels();
  const double fw = options.full_well_electrons;
  std::atomic<bool> bad{false};
  tbb::parallel_for(tbb::blocked_range<int>(0, linear.rows, 8), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      Rng row_rng(seed ^ (0x9E3779B97F4A7C15ULL * (static_cast<uint64_t>(y) + 1)));
      const float* src = linear.ptr<float>(y);
      float* dst = out.linear.ptr<float>(y);
      for (int i = 0; i < n; ++i) {
        const double x = static_cast<double>(src[i]) * options.exposure;
        if (!std::isfinite(x) || x < 0.0) {
          bad = true;
          dst[i] = 0.0f;
          continue;
        }
        double value = x;
        if (options.noise) {
          // Above the full well the pixel saturates anyway; cap λ to keep sampling cheap.
          const double lambda = std::min(x, 2.0) * fw;
          const double electrons = static_cast<double>(SamplePoisson(lambda, row_rng)) +
                                   options.read_noise_electrons * row_rng.Normal();
          value = x > 2.0 ? 1.0 : electrons / fw;
        }
        dst[i] = static_cast<float>(std::clamp(value, 0.0, 1.0));
      }
    }
  });
  Require(!bad.load(), "ApplySensor: the linear image must be finite and >= 0");
  out.srgb8 = EncodeSrgb8(out.linear);
  if (options.jpeg_quality > 0) out.srgb8 = JpegRoundTrip(out.srgb8, options.jpeg_quality);
  out.decoded = DecodeSrgb8(out.srgb8);
  return out;
}

}  // namespace crease
