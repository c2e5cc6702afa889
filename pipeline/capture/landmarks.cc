#include "pipeline/capture/landmarks.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include <vector>
#include <opencv2/imgproc.hpp>

#include <dlib/image_processing.h>
#include <dlib/image_processing/frontal_face_detector.h>
#include <dlib/opencv/cv_image.h>

#include "core/color.h"
#include "core/error.h"
#include "core/ibug.h"

namespace crease {

void DlibLandmarkOptions::VisitFields(OptionVisitor& v) {
  v.Field("model_path", model_path);
  v.Field("upsample", upsample);
  v.Field("detection_threshold", detection_threshold);
  v.Field("max_scale_change", max_scale_change);
  v.Field("redetect_interval", redetect_interval);
}

void DlibLandmarkOptions::Check() const {
  CheckGe("DlibLandmarkOptions", "upsample", upsample, 0);
  CheckLe("DlibLandmarkOptions", "upsample", upsample, 3);
  CheckGt("DlibLandmarkOptions", "max_scale_change", max_scale_change, 1.0);
  CheckGe("DlibLandmarkOptions", "redetect_interval", redetect_interval, 0);
}

cv::Mat ToGray8(const cv::Mat& image) {
  Require(!image.empty(), "ToGray8: empty image");
  cv::Mat gray;
  if (image.channels() == 3) {
    cv::cvtColor(image, gray, cv::COLOR_RGB2GRAY);
  } else if (image.channels() == 1) {
    gray = image;
  } else {
    throw Error(fmt::format("ToGray8: images must have 1 or 3 channels, not {}", image.channels()));
  }
  if (gray.depth() == CV_8U) return gray.clone();
  cv::Mat f;
  gray.convertTo(f, CV_32F);
  // The sRGB encoding through a table over [0, 1] (16k entries: every output code
  // is reached, and a per-pixel pow() costs ~10 ms at 640×480).
  constexpr int kSteps = 16384;
  static const std::vector<uint8_t> lut = [] {
    std::vector<uint8_t> t(kSteps + 1);
    for (int i = 0; i <= kSteps; ++i) t[i] = static_cast<uint8_t>(std::lround(LinearToSrgb(float(i) / kSteps) * 255.0f));
    return t;
  }();
  cv::Mat out(f.size(), CV_8UC1);
  for (int y = 0; y < f.rows; ++y) {
    const float* src = f.ptr<float>(y);
    uint8_t* dst = out.ptr<uint8_t>(y);
    for (int x = 0; x < f.cols; ++x) {
      const float v = std::isfinite(src[x]) ? std::clamp(src[x], 0.0f, 1.0f) : 0.0f;
      dst[x] = lut[static_cast<int>(v * kSteps + 0.5f)];
    }
  }
  return out;
}

FaceBox BoxOfPoints(const MatX2d& points, double scale) {
  FaceBox b;
  if (points.rows() == 0) return b;
  const Eigen::Vector2d lo = points.colwise().minCoeff(), hi = points.colwise().maxCoeff();
  const Eigen::Vector2d c = 0.5 * (lo + hi), half = 0.5 * scale * (hi - lo);
  b.x = c.x() - half.x();
  b.y = c.y() - half.y();
  b.width = 2 * half.x();
  b.height = 2 * half.y();
  return b;
}

struct DlibLandmarkSource::Impl {
  DlibLandmarkOptions options;
  HogFaceDetector detector;
  dlib::shape_predictor predictor;
  MatX2d previous;  // last frame's landmarks (empty after a loss)
  // The detector's box relative to stable landmarks (eye corners and nose), learnt
  // on the last detection: box side = scale · d, box centre = anchor + offset · d,
  // d the distance of the outer eye corners, anchor the mean of iBUG 28–48.
  double box_scale = 0.0;
  int frames_since_detection = 0;
  Eigen::Vector2d box_offset = Eigen::Vector2d::Zero();
};

namespace {

// Anchor (mean of the nose and eye points, iBUG 28–48) and size (outer eye corners).
void StableFrame(const MatX2d& p, Eigen::Vector2d* anchor, double* size) {
  *anchor = p.middleRows(27, 21).colwise().mean().transpose();
  *size = std::max(1e-6, InterOcularDistance(p));
}

}  // namespace

DlibLandmarkSource::DlibLandmarkSource(const DlibLandmarkOptions& options) : impl_(std::make_unique<Impl>()) {
  options.Check();
  impl_->options = options;
  impl_->detector = HogFaceDetector(options.upsample, options.detection_threshold);
  if (!std::filesystem::exists(options.model_path)) {
    throw Error(fmt::format("{}: dlib's 68-point landmark model is missing (install the Debian package "
                            "libdlib-data, or set model_path)", options.model_path));
  }
  try {
    dlib::deserialize(options.model_path) >> impl_->predictor;
  } catch (const std::exception& e) {
    throw Error(fmt::format("{}: cannot load dlib's shape predictor: {}", options.model_path, e.what()));
  }
}

DlibLandmarkSource::~DlibLandmarkSource() = default;

void DlibLandmarkSource::Reset() { impl_->previous.resize(0, 2); }

struct HogFaceDetector::Impl {
  int upsample = 0;
  double threshold = 0.0;
  mutable dlib::frontal_face_detector detector = dlib::get_frontal_face_detector();
};

HogFaceDetector::HogFaceDetector(int upsample, double threshold) : impl_(std::make_unique<Impl>()) {
  impl_->upsample = upsample;
  impl_->threshold = threshold;
}
HogFaceDetector::~HogFaceDetector() = default;
HogFaceDetector::HogFaceDetector(HogFaceDetector&&) noexcept = default;
HogFaceDetector& HogFaceDetector::operator=(HogFaceDetector&&) noexcept = default;

std::vector<FaceBox> HogFaceDetector::Detect(const cv::Mat& image) const {
  const cv::Mat gray = ToGray8(image);
  std::vector<dlib::rect_detection> dets;
  // dlib's pyramid_up is not exposed for cv_image: scale the image instead.
  double s = 1.0;
  if (impl_->upsample > 0) {
    cv::Mat up;
    s = std::pow(2.0, impl_->upsample);
    cv::resize(gray, up, cv::Size(), s, s, cv::INTER_LINEAR);
    dlib::cv_image<unsigned char> img(up);
    impl_->detector(img, dets, impl_->threshold);
  } else {
    dlib::cv_image<unsigned char> img(gray);
    impl_->detector(img, dets, impl_->threshold);
  }
  std::sort(dets.begin(), dets.end(), [](const auto& a, const auto& b) { return a.detection_confidence > b.detection_confidence; });
  std::vector<FaceBox> out;
  for (const auto& d : dets) {
    out.push_back({d.rect.left() / s, d.rect.top() / s, d.rect.width() / s, d.rect.height() / s, d.detection_confidence});
  }
  return out;
}

std::vector<FaceBox> DlibLandmarkSource::Detect(const cv::Mat& image) const { return impl_->detector.Detect(image); }

MatX2d DlibLandmarkSource::Landmarks(const cv::Mat& image, const FaceBox& box) const {
  const cv::Mat gray = ToGray8(image);
  dlib::cv_image<unsigned char> img(gray);
  const dlib::rectangle rect(std::lround(box.x), std::lround(box.y), std::lround(box.x + box.width - 1),
                             std::lround(box.y + box.height - 1));
  const dlib::full_object_detection shape = impl_->predictor(img, rect);
  Require(shape.num_parts() == 68, fmt::format("dlib's model gave {} landmarks, expected 68", shape.num_parts()));
  MatX2d p(68, 2);
  for (int i = 0; i < 68; ++i) p.row(i) << shape.part(i).x(), shape.part(i).y();
  return p;
}

LandmarkResult DlibLandmarkSource::Track(const cv::Mat& image) {
  LandmarkResult r;
  Impl& m = *impl_;
  if (m.previous.rows() == 68 && m.box_scale > 0.0) {
    // dlib's predictor expects its detector's box: placed relative to the previous
    // frame's stable landmarks as the detector's box was on the last detection
    // (the landmarks' own bounding box changes with the expression and would let
    // the box drift frame by frame).
    Eigen::Vector2d anchor;
    double d;
    StableFrame(m.previous, &anchor, &d);
    const double size = m.box_scale * d;
    const Eigen::Vector2d c = anchor + m.box_offset * d;
    FaceBox guess{c.x() - 0.5 * size, c.y() - 0.5 * size, size, size, 0.0};
    const MatX2d p = Landmarks(image, guess);
    const FaceBox nb = BoxOfPoints(p);
    const double ratio = InterOcularDistance(p) / d;
    const bool inside = nb.x >= -0.25 * nb.width && nb.y >= -0.25 * nb.height &&
                        nb.x + nb.width <= image.cols + 0.25 * nb.width && nb.y + nb.height <= image.rows + 0.25 * nb.height;
    // Periodic verification: the detector must find a face where the track is;
    // when it finds none there (the track followed an occluder or drifted), the
    // track is dropped and the detection below restarts it.
    bool verified = true;
    if (m.options.redetect_interval > 0 && ++m.frames_since_detection >= m.options.redetect_interval) {
      m.frames_since_detection = 0;
      verified = false;
      // The detector runs on the track's neighbourhood only (twice the box), which
      // costs a fraction of a full-frame detection.
      const double cx = guess.x + 0.5 * guess.width, cy = guess.y + 0.5 * guess.height;
      const int x0 = std::clamp(static_cast<int>(cx - guess.width), 0, image.cols - 1);
      const int y0 = std::clamp(static_cast<int>(cy - guess.height), 0, image.rows - 1);
      const int x1 = std::clamp(static_cast<int>(cx + guess.width), x0 + 1, image.cols);
      const int y1 = std::clamp(static_cast<int>(cy + guess.height), y0 + 1, image.rows);
      std::vector<FaceBox> found = Detect(image(cv::Rect(x0, y0, x1 - x0, y1 - y0)));
      for (FaceBox& f : found) {
        f.x += x0;
        f.y += y0;
      }
      for (const FaceBox& f : found) {
        const double ix = std::max(0.0, std::min(f.x + f.width, guess.x + guess.width) - std::max(f.x, guess.x));
        const double iy = std::max(0.0, std::min(f.y + f.height, guess.y + guess.height) - std::max(f.y, guess.y));
        const double inter = ix * iy, uni = f.width * f.height + guess.width * guess.height - inter;
        if (uni > 0 && inter / uni > 0.3) verified = true;
      }
    }
    if (verified && ratio < m.options.max_scale_change && ratio > 1.0 / m.options.max_scale_change && inside) {
      r.found = true;
      r.box = guess;
      r.points = p;
      m.previous = p;
      return r;
    }
    m.previous.resize(0, 2);  // lost: detect below
  }
  r.detected = true;
  m.frames_since_detection = 0;
  const std::vector<FaceBox> faces = Detect(image);
  if (faces.empty()) return r;
  r.found = true;
  r.box = faces.front();
  r.points = Landmarks(image, r.box);
  m.previous = r.points;
  Eigen::Vector2d anchor;
  double d;
  StableFrame(r.points, &anchor, &d);
  m.box_scale = std::max(r.box.width, r.box.height) / d;
  m.box_offset = (Eigen::Vector2d(r.box.x + 0.5 * r.box.width, r.box.y + 0.5 * r.box.height) - anchor) / d;
  return r;
}

}  // namespace crease
