#include "core/picture.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace crease {

cv::Mat DisplacementPicture(const cv::Mat& d, double range_mm, const cv::Mat& mask, bool bgr) {
  Require(d.type() == CV_32FC1 && range_mm > 0 && (mask.empty() || mask.size() == d.size()),
          "DisplacementPicture: expected a CV_32FC1 map, a positive range and a mask of its size");
  cv::Mat out(d.size(), CV_8UC3);
  for (int j = 0; j < d.rows; ++j) {
    const float* p = d.ptr<float>(j);
    cv::Vec3b* q = out.ptr<cv::Vec3b>(j);
    for (int i = 0; i < d.cols; ++i) {
      if (!mask.empty() && !mask.at<uint8_t>(j, i)) {
        q[i] = cv::Vec3b(60, 60, 60);
        continue;
      }
      const double x = std::clamp(p[i] / range_mm, -1.0, 1.0);
      const auto a = static_cast<uint8_t>(255 * (1 - std::abs(x)));
      const cv::Vec3b red(255, a, a), blue(a, a, 255);  // R, G, B
      const cv::Vec3b& c = x >= 0 ? red : blue;
      q[i] = bgr ? cv::Vec3b(c[2], c[1], c[0]) : c;
    }
  }
  return out;
}

}  // namespace crease
