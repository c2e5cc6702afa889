#include "pipeline/capture/tracking_record.h"

#include <algorithm>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "core/color.h"

namespace crease {

nlohmann::json PoseJson(const Rigid3d& p) {
  const Eigen::Quaterniond& q = p.rotation;
  return {{"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
          {"translation_mm", {p.translation.x(), p.translation.y(), p.translation.z()}}};
}

nlohmann::json TrackedFrameJson(const TrackedFrame& t, const FaceRig& rig) {
  nlohmann::json j;
  j["frame"] = t.frame;
  j["tracked"] = t.tracked;
  j["detected"] = t.detected;
  j["confidence"] = t.confidence;
  nlohmann::json lm = nlohmann::json::array();
  for (int i = 0; i < t.landmarks.rows(); ++i) lm.push_back({t.landmarks(i, 0), t.landmarks(i, 1)});
  j["landmarks"] = lm;
  if (t.tracked) {
    j["cam_from_head"] = PoseJson(t.fit.cam_from_head);
    nlohmann::json w = nlohmann::json::object();
    for (int e = 0; e < rig.num_expressions(); ++e) w[rig.expression_names[e]] = t.fit.expression[e];
    j["expression"] = w;
    j["rms_px"] = t.fit.rms_px;
  }
  return j;
}

TriMesh RigMeshWithVertices(const FaceRig& rig, const MatX3d& V) {
  TriMesh m = rig.neutral;
  m.V = V;
  m.N.resize(0, 3);
  return m;
}

cv::Mat PreviewBgr(const cv::Mat& linear_rgb) {
  cv::Mat bgr(linear_rgb.size(), CV_8UC3);
  for (int j = 0; j < linear_rgb.rows; ++j) {
    const cv::Vec3f* p = linear_rgb.ptr<cv::Vec3f>(j);
    cv::Vec3b* q = bgr.ptr<cv::Vec3b>(j);
    for (int i = 0; i < linear_rgb.cols; ++i) {
      for (int c = 0; c < 3; ++c) {
        q[i][2 - c] =
            static_cast<uint8_t>(std::clamp(255.0 * LinearToSrgb(std::clamp(p[i][c], 0.0f, 1.0f)) + 0.5, 0.0, 255.0));
      }
    }
  }
  return bgr;
}

void DrawTracking(const TrackedFrame& t, const MatX2d& projected, const MatX3i& face_F, cv::Mat* bgr) {
  if (t.tracked && projected.rows() > 0) {
    // The mesh over the face chart as a faint wireframe (every 4th triangle, 35 % opacity).
    cv::Mat wire = bgr->clone();
    for (int f = 0; f < face_F.rows(); f += 4) {
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2d a = projected.row(face_F(f, k)), b = projected.row(face_F(f, (k + 1) % 3));
        if (!a.allFinite() || !b.allFinite()) continue;
        cv::line(wire, cv::Point2d(a.x(), a.y()), cv::Point2d(b.x(), b.y()), cv::Scalar(230, 140, 40), 1, cv::LINE_AA);
      }
    }
    cv::addWeighted(wire, 0.35, *bgr, 0.65, 0.0, *bgr);
  }
  for (int i = 0; i < t.landmarks.rows(); ++i) {
    cv::circle(*bgr, cv::Point2d(t.landmarks(i, 0), t.landmarks(i, 1)), 2, cv::Scalar(60, 220, 60), -1, cv::LINE_AA);
  }
  cv::putText(*bgr, fmt::format("{} {:.2f}", t.tracked ? "tracked" : "lost", t.confidence), cv::Point(8, 18),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, t.tracked ? cv::Scalar(60, 220, 60) : cv::Scalar(40, 40, 230), 1,
              cv::LINE_AA);
}

}  // namespace crease
