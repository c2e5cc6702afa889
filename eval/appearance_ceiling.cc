#include "eval/appearance_ceiling.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/options.h"
#include "pipeline/training/wrinkle_map.h"

namespace crease {

void AppearanceCeilingOptions::VisitFields(OptionVisitor& v) {
  v.Field("enabled", enabled);
  v.Field("window", window);
  v.Field("window_step", window_step);
  v.Field("stride", stride);
  v.Field("ridge", ridge);
  v.Field("reference_frames", reference_frames);
  v.Field("block", block);
}

void AppearanceCeilingOptions::Check() const {
  const char* o = "AppearanceCeilingOptions";
  CheckGe(o, "appearance_window", window, 1);
  Require(window % 2 == 1, fmt::format("{}: appearance_window = {} must be odd", o, window));
  CheckLe(o, "appearance_window", window, 31);
  CheckGe(o, "appearance_window_step", window_step, 1);
  CheckGe(o, "appearance_stride", stride, 1);
  CheckGt(o, "appearance_ridge", ridge, 0.0);
  CheckGe(o, "appearance_reference_frames", reference_frames, 1);
  CheckGe(o, "appearance_block", block, 1);
}

AppearanceCeilingMeter::AppearanceCeilingMeter(const cv::Mat& reference, const cv::Mat& mask, int num_targets,
                                               const AppearanceCeilingOptions& options)
    : reference_(reference), mask_(mask), num_targets_(num_targets), options_(options) {
  options.Check();
  Require(reference.type() == CV_32FC1 && !reference.empty() && reference.rows == reference.cols,
          "appearance ceiling: the reference texture must be a square CV_32F map");
  Require(mask.type() == CV_8UC1 && mask.size() == reference.size(),
          fmt::format("appearance ceiling: the mask must be CV_8U {}×{}", reference.cols, reference.rows));
  Require(num_targets >= 1, "appearance ceiling: at least one target");
  const int h = options.window / 2;
  for (int j = -h; j <= h; ++j)
    for (int i = -h; i <= h; ++i) offsets_.emplace_back(i * options.window_step, j * options.window_step);
  const int n = static_cast<int>(offsets_.size());
  for (Half& half : half_) {
    half.xx = Eigen::MatrixXd::Zero(n, n);
    half.xy = Eigen::MatrixXd::Zero(n, num_targets);
    half.x = Eigen::VectorXd::Zero(n);
    half.y = half.yy = Eigen::VectorXd::Zero(num_targets);
  }
}

void AppearanceCeilingMeter::Add(int frame, const cv::Mat& texture, const std::vector<cv::Mat>& targets) {
  const int R = reference_.rows;
  Require(texture.type() == CV_32FC1 && texture.size() == reference_.size(),
          fmt::format("appearance ceiling, frame {}: the texture must be CV_32F {}×{}", frame, R, R));
  Require(static_cast<int>(targets.size()) == num_targets_,
          fmt::format("appearance ceiling, frame {}: {} targets, expected {}", frame, targets.size(), num_targets_));
  for (const cv::Mat& t : targets) {
    Require(t.type() == CV_32FC1 && t.size() == reference_.size(),
            fmt::format("appearance ceiling, frame {}: a target must be CV_32F {}×{}", frame, R, R));
  }
  // r = T / T_ref − 1 where both are seen, clamped, blurred to the window's spacing.
  cv::Mat r = FlattenByReference(texture, reference_, cv::Mat(), TextureReference::kRatio, 1.0);
  cv::Mat seen = r > 0;
  cv::subtract(r, 1.0, r, seen);
  r = cv::max(r, -1.0);
  r = cv::min(r, 1.0);
  const double sigma = 0.5 * options_.window_step;
  if (options_.window_step > 1) cv::GaussianBlur(r, r, cv::Size(), sigma, sigma, cv::BORDER_REPLICATE);

  const int reach = (options_.window / 2) * options_.window_step;
  const int n = static_cast<int>(offsets_.size());
  std::vector<cv::Point> centres;
  for (int y = reach; y < R - reach; y += options_.stride) {
    const uint8_t* m = mask_.ptr<uint8_t>(y);
    const uint8_t* s = seen.ptr<uint8_t>(y);
    for (int x = reach; x < R - reach; x += options_.stride) {
      if (!m[x] || !s[x]) continue;
      bool finite = true;
      for (const cv::Mat& t : targets) finite = finite && std::isfinite(t.at<float>(y, x));
      if (finite) centres.emplace_back(x, y);
    }
  }
  Half& half = half_[(frame / options_.block) % 2];
  ++half.frames;
  if (centres.empty()) return;
  Eigen::MatrixXd X(static_cast<Eigen::Index>(centres.size()), n);
  Eigen::MatrixXd Y(static_cast<Eigen::Index>(centres.size()), num_targets_);
  for (size_t k = 0; k < centres.size(); ++k) {
    const cv::Point p = centres[k];
    for (int f = 0; f < n; ++f) X(k, f) = r.at<float>(p + offsets_[f]);
    for (int t = 0; t < num_targets_; ++t) Y(k, t) = targets[t].at<float>(p);
  }
  half.xx.selfadjointView<Eigen::Lower>().rankUpdate(X.transpose());
  half.xy.noalias() += X.transpose() * Y;
  half.x += X.colwise().sum().transpose();
  half.y += Y.colwise().sum().transpose();
  half.yy += Y.colwise().squaredNorm().transpose();
  half.count += static_cast<int64_t>(centres.size());
}

std::vector<double> AppearanceCeilingMeter::FitAndScore(const Half& fit, const Half& score) const {
  const double N = static_cast<double>(fit.count), M = static_cast<double>(score.count);
  const Eigen::VectorXd mx = fit.x / N;
  const Eigen::VectorXd my = fit.y / N;
  Eigen::MatrixXd C = fit.xx.selfadjointView<Eigen::Lower>();
  C = C / N - mx * mx.transpose();
  const double lambda = options_.ridge * std::max(C.diagonal().mean(), 1e-12);
  C.diagonal().array() += lambda;
  const Eigen::MatrixXd c = fit.xy / N - mx * my.transpose();
  const Eigen::MatrixXd W = C.ldlt().solve(c);  // n × T
  const Eigen::MatrixXd Sxx = score.xx.selfadjointView<Eigen::Lower>();
  std::vector<double> corr(num_targets_, 0.0);
  for (int t = 0; t < num_targets_; ++t) {
    // p = wᵀx + d on the scored half, d = ȳ − wᵀx̄ of the fitted half.
    const Eigen::VectorXd w = W.col(t);
    const double d = my[t] - w.dot(mx);
    const double sp = w.dot(score.x) + M * d;
    const double spp = w.dot(Sxx * w) + 2.0 * d * w.dot(score.x) + M * d * d;
    const double spy = w.dot(score.xy.col(t)) + d * score.y[t];
    const double vp = spp - sp * sp / M, vy = score.yy[t] - score.y[t] * score.y[t] / M;
    corr[t] = (vp > 0 && vy > 0) ? (spy - sp * score.y[t] / M) / std::sqrt(vp * vy) : 0.0;
  }
  return corr;
}

AppearanceCeiling AppearanceCeilingMeter::Result() const {
  AppearanceCeiling a;
  for (int k = 0; k < 2; ++k) {
    a.frames[k] = half_[k].frames;
    a.samples[k] = half_[k].count;
  }
  const int n = static_cast<int>(offsets_.size());
  if (half_[0].count <= n || half_[1].count <= n) return a;  // too few texels to fit
  const std::vector<double> ab = FitAndScore(half_[0], half_[1]), ba = FitAndScore(half_[1], half_[0]);
  a.correlation.resize(num_targets_);
  for (int t = 0; t < num_targets_; ++t) a.correlation[t] = 0.5 * (ab[t] + ba[t]);
  return a;
}

}  // namespace crease
