// Dense alignment of the reference texture to T^t; see reference_alignment.h.
#include "pipeline/capture/reference_alignment.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/error.h"
#include "core/options.h"

namespace crease {

void ReferenceAlignmentOptions::VisitFields(OptionVisitor& v) {
  v.Field("enabled", enabled);
  v.Field("resolution", resolution);
  v.Field("highpass_sigma", highpass_sigma);
  v.Field("smoothing_sigma", smoothing_sigma);
  v.Field("max_shift", max_shift);
  v.Field("warp_texture", warp_texture);
}

void ReferenceAlignmentOptions::Check() const {
  const char* o = "ReferenceAlignmentOptions";
  CheckGe(o, "resolution", resolution, 16);
  CheckLe(o, "resolution", resolution, 4096);
  CheckGt(o, "highpass_sigma", highpass_sigma, 0.0);
  CheckGe(o, "smoothing_sigma", smoothing_sigma, 0.0);
  CheckGt(o, "max_shift", max_shift, 0.0);
}

namespace {

constexpr float kNoData = 1e-4f;

// Normalised Gaussian blur of `value` over the texels where weight > 0: Σ G·w·v / Σ G·w
// (0 where Σ G·w is negligible). sigma ≤ 0 returns value.
cv::Mat NormalisedBlur(const cv::Mat& value, const cv::Mat& weight, double sigma) {
  if (sigma <= 0.0) return value.clone();
  cv::Mat weighted, num, den;
  if (value.channels() == 1) {
    cv::multiply(value, weight, weighted);
  } else {
    cv::Mat w2;
    cv::merge(std::vector<cv::Mat>{weight, weight}, w2);
    cv::multiply(value, w2, weighted);
  }
  cv::GaussianBlur(weighted, num, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
  cv::GaussianBlur(weight, den, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
  cv::Mat out(value.size(), value.type(), cv::Scalar::all(0));
  const int c = value.channels();
  for (int y = 0; y < out.rows; ++y) {
    const float* n = num.ptr<float>(y);
    const float* d = den.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < out.cols; ++x)
      if (d[x] > 1e-3f)
        for (int k = 0; k < c; ++k) o[c * x + k] = n[c * x + k] / d[x];
  }
  return out;
}

// Step 1: the mean of `image` over its `valid` (CV_32F 0/1) texels on the coarse grid,
// and the coarse validity (1 where at least half the texels were valid, else 0).
void ToCoarse(const cv::Mat& image, const cv::Mat& valid, int res, cv::Mat* value, cv::Mat* coarse_valid) {
  cv::Mat weighted, num, den;
  cv::multiply(image, valid, weighted);
  cv::resize(weighted, num, cv::Size(res, res), 0, 0, cv::INTER_AREA);
  cv::resize(valid, den, cv::Size(res, res), 0, 0, cv::INTER_AREA);
  *value = cv::Mat(res, res, CV_32F, cv::Scalar(0));
  *coarse_valid = cv::Mat(res, res, CV_32F, cv::Scalar(0));
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x) {
      const float d = den.at<float>(y, x);
      if (d < 0.5f) continue;
      value->at<float>(y, x) = num.at<float>(y, x) / d;
      coarse_valid->at<float>(y, x) = 1.0f;
    }
}

// Step 1's high-pass: value minus its normalised blur over the valid texels (0 outside).
cv::Mat HighPass(const cv::Mat& value, const cv::Mat& valid, double sigma) {
  cv::Mat hp = value - NormalisedBlur(value, valid, sigma);
  hp.setTo(0.0f, valid == 0.0f);
  return hp;
}

// The 8-bit image DIS reads: 128 + gain · high-pass, 128 where invalid.
cv::Mat ToFlowImage(const cv::Mat& hp, const cv::Mat& valid, double gain) {
  cv::Mat out;
  hp.convertTo(out, CV_8U, gain, 128.0);
  out.setTo(128, valid == 0.0f);
  return out;
}

// Steps 2–3: the smoothed, clamped flow f on the coarse grid, from8(x) ≈ to8(x + f(x)).
cv::Mat CoarseFlow(const cv::Mat& from8, const cv::Mat& to8, const cv::Mat& both, const ReferenceAlignmentOptions& o,
                   ReferenceAlignmentReport* report) {
  cv::Ptr<cv::DISOpticalFlow> dis = cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_MEDIUM);
  cv::Mat flow;
  dis->calc(from8, to8, flow);
  flow = NormalisedBlur(flow, both, o.smoothing_sigma);
  double sum = 0.0, count = 0.0, largest = 0.0;
  for (int y = 0; y < flow.rows; ++y)
    for (int x = 0; x < flow.cols; ++x) {
      cv::Vec2f& f = flow.at<cv::Vec2f>(y, x);
      if (!std::isfinite(f[0]) || !std::isfinite(f[1])) f = cv::Vec2f(0, 0);
      const double len = std::hypot(f[0], f[1]);
      if (len > o.max_shift) f *= static_cast<float>(o.max_shift / len);
      if (both.at<float>(y, x) == 0.0f) continue;
      const double kept = std::min(len, o.max_shift);
      sum += kept;
      count += 1.0;
      largest = std::max(largest, kept);
    }
  if (report) *report = {count > 0 ? sum / count : 0.0, largest};
  return flow;
}

// Step 4: `image` sampled at x + f(x) on the full grid, normalised by its own sampled
// validity so that texels next to the chart's edge keep their value.
cv::Mat Resample(const cv::Mat& image, const cv::Mat& valid, const cv::Mat& coarse_flow) {
  const int R = image.rows;
  const float scale = static_cast<float>(R) / static_cast<float>(coarse_flow.rows);
  cv::Mat flow;
  cv::resize(coarse_flow, flow, image.size(), 0, 0, cv::INTER_LINEAR);
  cv::Mat map_x(image.size(), CV_32F), map_y(image.size(), CV_32F);
  for (int y = 0; y < R; ++y) {
    const cv::Vec2f* f = flow.ptr<cv::Vec2f>(y);
    float* mx = map_x.ptr<float>(y);
    float* my = map_y.ptr<float>(y);
    for (int x = 0; x < R; ++x) {
      mx[x] = static_cast<float>(x) + scale * f[x][0];
      my[x] = static_cast<float>(y) + scale * f[x][1];
    }
  }
  cv::Mat weighted, num, den;
  cv::multiply(image, valid, weighted);
  cv::remap(weighted, num, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::remap(valid, den, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::Mat out(image.size(), CV_32F, cv::Scalar(0));
  for (int y = 0; y < R; ++y) {
    const float* n = num.ptr<float>(y);
    const float* d = den.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < R; ++x)
      if (d[x] > 0.5f) o[x] = n[x] / d[x];
  }
  return out;
}

void RequireReference(const cv::Mat& reference, int resolution) {
  Require(reference.type() == CV_32FC1,
          fmt::format("ReferenceAligner: expected a CV_32FC1 reference, got type {}", reference.type()));
  Require(!reference.empty() && reference.rows == reference.cols,
          fmt::format("ReferenceAligner: the reference is {}×{}, expected a square map", reference.cols, reference.rows));
  Require(reference.rows % resolution == 0 && reference.rows >= resolution,
          fmt::format("ReferenceAligner: the map's side {} is not a multiple of the flow grid's {} "
                      "(detail.reference_alignment.resolution)",
                      reference.rows, resolution));
}

void RequireTexture(const cv::Mat& reference, const cv::Mat& texture, const cv::Mat& seen) {
  Require(texture.type() == CV_32FC1,
          fmt::format("ReferenceAligner: expected a CV_32FC1 texture, got type {}", texture.type()));
  Require(texture.size() == reference.size(),
          fmt::format("ReferenceAligner: the texture is {}×{}, the reference {}×{}", texture.cols, texture.rows,
                      reference.cols, reference.rows));
  Require(seen.empty() || (seen.type() == CV_8UC1 && seen.size() == texture.size()),
          "ReferenceAligner: the seen mask must be CV_8UC1 of the texture's size");
}

// Step 1 on one texture: its full-grid validity (CV_32F 0/1), and on the coarse grid
// its validity and high-pass.
void PrepareFlowInput(const cv::Mat& image, const cv::Mat& seen, const ReferenceAlignmentOptions& o, cv::Mat* valid,
                      cv::Mat* coarse_valid, cv::Mat* highpass) {
  cv::Mat mask = image > kNoData;
  if (!seen.empty()) cv::bitwise_and(mask, seen != 0, mask);
  mask.convertTo(*valid, CV_32F, 1.0 / 255.0);
  cv::Mat coarse;
  ToCoarse(image, *valid, o.resolution, &coarse, coarse_valid);
  *highpass = HighPass(coarse, *coarse_valid, o.highpass_sigma);
}

}  // namespace

ReferenceAligner::ReferenceAligner(const cv::Mat& reference, const ReferenceAlignmentOptions& options)
    : options_(options), reference_(reference) {
  options_.Check();
  RequireReference(reference_, options_.resolution);
  cv::Mat highpass;
  PrepareFlowInput(reference_, cv::Mat(), options_, &valid_, &coarse_valid_, &highpass);
  cv::Scalar mean, stddev;
  cv::meanStdDev(highpass, mean, stddev, coarse_valid_ != 0.0f);
  if (!(stddev[0] > 0.0)) return;  // featureless: nothing to align to (reference8_ stays empty)
  gain_ = 32.0 / stddev[0];        // ±4 standard deviations fill the 8 bits
  reference8_ = ToFlowImage(highpass, coarse_valid_, gain_);
}

// Steps 1–3 for the texture: the flow f with from(x) ≈ to(x + f(x)) (texture to
// reference, or the other way), or an empty Mat when the reference is featureless;
// `texture_valid`: the texture's full-grid validity.
cv::Mat ReferenceAligner::Flow(const cv::Mat& texture, const cv::Mat& seen, bool texture_to_reference,
                               cv::Mat* texture_valid, ReferenceAlignmentReport* report) const {
  RequireTexture(reference_, texture, seen);
  if (reference8_.empty()) {
    if (report) *report = {};
    return cv::Mat();
  }
  cv::Mat coarse_valid, highpass;
  PrepareFlowInput(texture, seen, options_, texture_valid, &coarse_valid, &highpass);
  const cv::Mat texture8 = ToFlowImage(highpass, coarse_valid, gain_);  // the reference's scale
  const cv::Mat both = coarse_valid_.mul(coarse_valid);
  return texture_to_reference ? CoarseFlow(texture8, reference8_, both, options_, report)
                              : CoarseFlow(reference8_, texture8, both, options_, report);
}

cv::Mat ReferenceAligner::AlignReference(const cv::Mat& texture, const cv::Mat& seen,
                                         ReferenceAlignmentReport* report) const {
  cv::Mat texture_valid;
  const cv::Mat flow = Flow(texture, seen, /*texture_to_reference=*/true, &texture_valid, report);
  return flow.empty() ? reference_.clone() : Resample(reference_, valid_, flow);
}

void ReferenceAligner::AlignTexture(const cv::Mat& texture, const cv::Mat& seen, cv::Mat* aligned,
                                    cv::Mat* aligned_seen, ReferenceAlignmentReport* report) const {
  cv::Mat texture_valid;
  const cv::Mat flow = Flow(texture, seen, /*texture_to_reference=*/false, &texture_valid, report);
  if (flow.empty()) {
    *aligned = texture.clone();
    *aligned_seen = seen.empty() ? cv::Mat(texture > kNoData) : seen.clone();
    return;
  }
  *aligned = Resample(texture, texture_valid, flow);
  *aligned_seen = *aligned > kNoData;
}

}  // namespace crease
