#include "core/image_filter.h"

#include <cmath>
#include <cstdint>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace crease {
namespace {

template <class F>
void ForRows(int rows, const F& f) {
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) f(y);
  });
}

}  // namespace

cv::Mat ZeroOutsideMask(const cv::Mat& image, const cv::Mat& mask, long* num_nonfinite, cv::Mat* weight) {
  cv::Mat out(image.size(), CV_32F);
  if (weight != nullptr) weight->create(image.size(), CV_32F);
  std::vector<long> bad_rows(static_cast<size_t>(image.rows), 0);
  ForRows(image.rows, [&](int y) {
    const float* t = image.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    float* o = out.ptr<float>(y);
    float* w = weight != nullptr ? weight->ptr<float>(y) : nullptr;
    long bad = 0;
    for (int x = 0; x < image.cols; ++x) {
      if (m[x]) {
        if (!std::isfinite(t[x])) ++bad;
        o[x] = t[x];
      } else {
        o[x] = 0.0f;
      }
      if (w != nullptr) w[x] = m[x] ? 1.0f : 0.0f;
    }
    bad_rows[static_cast<size_t>(y)] = bad;
  });
  long bad = 0;
  for (const long b : bad_rows) bad += b;
  *num_nonfinite = bad;
  return out;
}

cv::Mat NormalisedDifference(const cv::Mat& num_a, const cv::Mat& den_a, const cv::Mat& num_b,
                             const cv::Mat& den_b, const cv::Mat& mask, float scale) {
  cv::Mat out(num_a.size(), CV_32F);
  ForRows(num_a.rows, [&](int y) {
    const uint8_t* m = mask.ptr<uint8_t>(y);
    const float* na = num_a.ptr<float>(y);
    const float* da = den_a.ptr<float>(y);
    const float* nb = num_b.ptr<float>(y);
    const float* db = den_b.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < num_a.cols; ++x) {
      o[x] = (m[x] && da[x] > kMinNormalisedWeight && db[x] > kMinNormalisedWeight)
                 ? scale * (na[x] / da[x] - nb[x] / db[x])
                 : 0.0f;
    }
  });
  return out;
}

}  // namespace crease
