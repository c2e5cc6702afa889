#include "eval/registered_truth.h"

#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/uv_raster.h"

namespace crease {

namespace {

// Step 1 of the header: the seen truth texels of every map averaged into the pixel
// nearest their projection; `images` gets one H×W map per input, `valid` 1 where a
// texel landed, else 0.
void SplatToImage(const CameraIntrinsics& K, const cv::Mat& positions, const cv::Mat& seen,
                  const std::vector<cv::Mat>& maps, std::vector<cv::Mat>* images, cv::Mat* valid) {
  const int W = K.width, H = K.height, R = seen.rows;
  cv::Mat count = cv::Mat::zeros(H, W, CV_32F);
  images->assign(maps.size(), cv::Mat());
  for (cv::Mat& image : *images) image = cv::Mat::zeros(H, W, CV_32F);
  for (int j = 0; j < R; ++j) {
    const cv::Vec3f* p = positions.ptr<cv::Vec3f>(j);
    const uint8_t* s = seen.ptr<uint8_t>(j);
    for (int i = 0; i < R; ++i) {
      if (!s[i] || !(p[i][2] > 0.0f)) continue;
      const int x = static_cast<int>(std::lround(K.fx * p[i][0] / p[i][2] + K.cx));
      const int y = static_cast<int>(std::lround(K.fy * p[i][1] / p[i][2] + K.cy));
      if (x < 0 || y < 0 || x >= W || y >= H) continue;
      count.at<float>(y, x) += 1.0f;
      for (size_t k = 0; k < maps.size(); ++k) (*images)[k].at<float>(y, x) += maps[k].at<float>(j, i);
    }
  }
  cv::Mat has = count > 0.0f;
  for (cv::Mat& image : *images) {
    cv::divide(image, cv::max(count, 1.0f), image);
  }
  has.convertTo(*valid, CV_32F, 1.0 / 255.0);
}

}  // namespace

TruthRegistration::TruthRegistration(const FaceRig& rig, const CameraIntrinsics& intrinsics,
                                     const FrameTextureOptions& options)
    : extractor_(rig, intrinsics, options),
      zero_image_(cv::Mat::zeros(intrinsics.height, intrinsics.width, CV_32F)) {}

std::vector<cv::Mat> TruthRegistration::Register(const MatX3d& true_cam, const MatX3d& tracked_cam,
                                                 const std::vector<cv::Mat>& maps) const {
  const int R = extractor_.options().map_resolution;
  for (const cv::Mat& m : maps) {
    Require(m.rows == R && m.cols == R && m.type() == CV_32F,
            fmt::format("TruthRegistration::Register: maps must be {0}×{0} CV_32F, got {1}×{2} of type {3}", R,
                        m.cols, m.rows, m.type()));
  }
  // Step 1: the truth as an image, from the true mesh's seen texels.
  const FrameTexture truth_view = extractor_.Extract(true_cam, zero_image_);
  const cv::Mat positions = InterpolateToUv(extractor_.raster(), extractor_.chart_mesh(), true_cam);
  std::vector<cv::Mat> images;
  cv::Mat valid;
  SplatToImage(extractor_.intrinsics(), positions, truth_view.seen, maps, &images, &valid);
  // Step 2: sampled at L~^t's projections; NaN where L~^t does not see the texel or
  // a bilinear tap holds no truth.
  const FrameTexture coverage = extractor_.Extract(tracked_cam, valid);
  const cv::Mat no_data = (coverage.seen == 0) | (coverage.gray < 0.999f);
  std::vector<cv::Mat> out;
  for (const cv::Mat& image : images) {
    cv::Mat registered = extractor_.Extract(tracked_cam, image).gray.clone();
    registered.setTo(std::numeric_limits<float>::quiet_NaN(), no_data);
    out.push_back(registered);
  }
  return out;
}

}  // namespace crease
