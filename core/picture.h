// Pictures of crease's maps for reports and previews (pure OpenCV: no file I/O;
// write them with core/image_io.h or OpenCV's writers).
#pragma once

#include <opencv2/core/mat.hpp>

namespace crease {

// A displacement map (CV_32FC1, mm) as an 8-bit picture: blue inwards, white 0,
// red outwards, saturating at ±range_mm; grey where `mask` (CV_8U, optional) is 0.
// Channels R, G, B (for WriteImage with srgb = false), or B, G, R with `bgr` (for
// OpenCV's video writer and imwrite).
cv::Mat DisplacementPicture(const cv::Mat& d, double range_mm, const cv::Mat& mask = cv::Mat(), bool bgr = false);

}  // namespace crease
