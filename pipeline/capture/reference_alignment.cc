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
      sum += std::min(len, o.max_shift);
      count += 1.0;
      largest = std::max(largest, std::min(len, o.max_shift));
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

void RequireInputs(const cv::Mat& reference, const cv::Mat& texture, const cv::Mat& seen, int resolution) {
  Require(reference.type() == CV_32FC1 && texture.type() == CV_32FC1,
          fmt::format("AlignReference: expected CV_32FC1 reference and texture, got types {} and {}", reference.type(),
                      texture.type()));
  Require(!reference.empty() && reference.rows == reference.cols && texture.size() == reference.size(),
          fmt::format("AlignReference: reference {}×{} and texture {}×{} must be equal squares", reference.cols,
                      reference.rows, texture.cols, texture.rows));
  Require(seen.empty() || (seen.type() == CV_8UC1 && seen.size() == texture.size()),
          "AlignReference: the seen mask must be CV_8UC1 of the texture's size");
  Require(reference.rows % resolution == 0 && reference.rows >= resolution,
          fmt::format("AlignReference: the map's side {} is not a multiple of the flow grid's {} "
                      "(detail.reference_alignment.resolution)",
                      reference.rows, resolution));
}

// One texture on the coarse grid, high-passed (step 1), with its full-grid validity.
struct FlowInput {
  cv::Mat valid;     // CV_32F R×R, 1 where the texture holds data
  cv::Mat coarse_valid, highpass;  // coarse grid
};

FlowInput PrepareFlowInput(const cv::Mat& image, const cv::Mat& seen, const ReferenceAlignmentOptions& o) {
  cv::Mat mask = image > kNoData;
  if (!seen.empty()) cv::bitwise_and(mask, seen != 0, mask);
  FlowInput in;
  mask.convertTo(in.valid, CV_32F, 1.0 / 255.0);
  cv::Mat coarse;
  ToCoarse(image, in.valid, o.resolution, &coarse, &in.coarse_valid);
  in.highpass = HighPass(coarse, in.coarse_valid, o.highpass_sigma);
  return in;
}

// Steps 1–3 for both directions: the flow f with from(x) ≈ to(x + f(x)), or an empty
// Mat when the reference is featureless (nothing to align to). The 8-bit scale comes
// from the reference, so both images share it.
cv::Mat AlignmentFlow(const FlowInput& reference, const FlowInput& texture, bool texture_to_reference,
                      const ReferenceAlignmentOptions& o, ReferenceAlignmentReport* report) {
  cv::Scalar mean, stddev;
  cv::meanStdDev(reference.highpass, mean, stddev, reference.coarse_valid != 0.0f);
  if (!(stddev[0] > 0.0)) {
    if (report) *report = {};
    return cv::Mat();
  }
  const double gain = 32.0 / stddev[0];  // ±4 standard deviations fill the 8 bits
  const cv::Mat ref8 = ToFlowImage(reference.highpass, reference.coarse_valid, gain);
  const cv::Mat tex8 = ToFlowImage(texture.highpass, texture.coarse_valid, gain);
  const cv::Mat both = reference.coarse_valid.mul(texture.coarse_valid);
  return texture_to_reference ? CoarseFlow(tex8, ref8, both, o, report) : CoarseFlow(ref8, tex8, both, o, report);
}

}  // namespace

cv::Mat AlignReference(const cv::Mat& reference, const cv::Mat& texture, const cv::Mat& seen,
                       const ReferenceAlignmentOptions& options, ReferenceAlignmentReport* report) {
  options.Check();
  RequireInputs(reference, texture, seen, options.resolution);
  const FlowInput ref = PrepareFlowInput(reference, cv::Mat(), options);
  const FlowInput tex = PrepareFlowInput(texture, seen, options);
  const cv::Mat flow = AlignmentFlow(ref, tex, /*texture_to_reference=*/true, options, report);
  return flow.empty() ? reference.clone() : Resample(reference, ref.valid, flow);
}

void AlignTextureToReference(const cv::Mat& reference, const cv::Mat& texture, const cv::Mat& seen,
                             const ReferenceAlignmentOptions& options, cv::Mat* aligned, cv::Mat* aligned_seen,
                             ReferenceAlignmentReport* report) {
  options.Check();
  RequireInputs(reference, texture, seen, options.resolution);
  const FlowInput ref = PrepareFlowInput(reference, cv::Mat(), options);
  const FlowInput tex = PrepareFlowInput(texture, seen, options);
  const cv::Mat flow = AlignmentFlow(ref, tex, /*texture_to_reference=*/false, options, report);
  if (flow.empty()) {
    *aligned = texture.clone();
    *aligned_seen = seen.empty() ? cv::Mat(texture > kNoData) : seen.clone();
    return;
  }
  *aligned = Resample(texture, tex.valid, flow);
  *aligned_seen = *aligned > kNoData;
}

}  // namespace crease
