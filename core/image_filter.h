// Masked, normalised filtering of UV maps, shared by the wrinkle map's DoG
// (Sec. 4.2, pipeline/training/wrinkle_map.h) and the mesoscopic map's DoG
// (Sec. 5.3, pipeline/capture/frame_texture.h). A normalised convolution divides
// the blur of T·m by the blur of the mask m, so texels outside m neither count nor
// make the mask's edge look like an edge in T. The blurs themselves stay with each
// caller (the two stages use different kernels).
//
// Images are CV_32FC1, masks CV_8UC1 (nonzero = inside) of the same size.
#pragma once

#include <opencv2/core/mat.hpp>

namespace crease {

// Denominators (blurred masks) at or below this count as "no data": a texel inside
// the mask always carries at least the weight of its own kernel tap.
constexpr float kMinNormalisedWeight = 1e-6f;

// `image` with the texels outside `mask` set to 0 (whatever they held, NaN
// included). *num_nonfinite receives the number of non-finite texels inside the
// mask. With `weight`, also the mask as CV_32FC1 (1 inside, 0 outside).
cv::Mat ZeroOutsideMask(const cv::Mat& image, const cv::Mat& mask, long* num_nonfinite,
                        cv::Mat* weight = nullptr);

// The difference of two normalised blurs, scale · (num_a / den_a − num_b / den_b),
// on texels inside `mask` whose two denominators both exceed kMinNormalisedWeight;
// 0 elsewhere.
cv::Mat NormalisedDifference(const cv::Mat& num_a, const cv::Mat& den_a, const cv::Mat& num_b,
                             const cv::Mat& den_b, const cv::Mat& mask, float scale);

}  // namespace crease
