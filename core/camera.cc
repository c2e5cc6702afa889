#include "core/camera.h"

#include <cmath>
#include <limits>
#include <numbers>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_io.h"

namespace crease {

Eigen::Matrix<double, 3, 4> Rigid3d::ToMatrix() const {
  Eigen::Matrix<double, 3, 4> m;
  m.leftCols<3>() = rotation.toRotationMatrix();
  m.col(3) = translation;
  return m;
}

CameraIntrinsics CameraIntrinsics::FromFov(double horizontal_fov_deg, int width, int height) {
  CameraIntrinsics k;
  k.fx = k.fy = 0.5 * width / std::tan(0.5 * horizontal_fov_deg * std::numbers::pi / 180.0);
  k.cx = 0.5 * (width - 1);
  k.cy = 0.5 * (height - 1);
  k.width = width;
  k.height = height;
  return k;
}

void CameraIntrinsics::Validate(const std::string& what) const {
  Require(std::isfinite(fx) && std::isfinite(fy) && fx > 0 && fy > 0,
          fmt::format("{}: focal lengths must be positive and finite (fx = {}, fy = {})", what, fx, fy));
  Require(std::isfinite(cx) && std::isfinite(cy),
          fmt::format("{}: principal point must be finite", what));
  Require(width > 0 && height > 0,
          fmt::format("{}: image size must be positive ({} x {})", what, width, height));
}

Eigen::Vector2d Camera::ProjectCamPoint(const Eigen::Vector3d& p) const {
  if (!(p.z() > 1e-9)) {
    return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
  }
  return {intrinsics.fx * p.x() / p.z() + intrinsics.cx, intrinsics.fy * p.y() / p.z() + intrinsics.cy};
}

MatX2d Camera::ProjectAll(const MatX3d& points_in_head) const {
  MatX2d out(points_in_head.rows(), 2);
  const Eigen::Matrix3d R = cam_from_head.rotation.toRotationMatrix();
  for (Eigen::Index i = 0; i < points_in_head.rows(); ++i) {
    const Eigen::Vector3d p = R * points_in_head.row(i).transpose() + cam_from_head.translation;
    out.row(i) = ProjectCamPoint(p).transpose();
  }
  return out;
}

Eigen::Vector3d Camera::PixelRayInHead(double x, double y) const {
  const Eigen::Vector3d d_cam((x - intrinsics.cx) / intrinsics.fx, (y - intrinsics.cy) / intrinsics.fy, 1.0);
  return (cam_from_head.rotation.conjugate() * d_cam).normalized();
}

Eigen::Vector3d Camera::CentreInHead() const { return cam_from_head.Inverse().translation; }

nlohmann::json CameraToJson(const Camera& c) {
  const auto& q = c.cam_from_head.rotation;
  const auto& t = c.cam_from_head.translation;
  return {{"fx", c.intrinsics.fx},         {"fy", c.intrinsics.fy},
          {"cx", c.intrinsics.cx},         {"cy", c.intrinsics.cy},
          {"width", c.intrinsics.width},   {"height", c.intrinsics.height},
          {"cam_from_head",
           {{"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}}, {"translation_mm", {t.x(), t.y(), t.z()}}}}};
}

namespace {
double NumberField(const nlohmann::json& j, const char* key, const std::string& what) {
  auto it = j.find(key);
  Require(it != j.end(), fmt::format("{}: camera field '{}' is missing", what, key));
  Require(it->is_number(), fmt::format("{}: camera field '{}' must be a number", what, key));
  return it->get<double>();
}
// An image size: a whole number that fits an int (a width of 1e10 was undefined
// behaviour in the conversion, issue 19); Validate() then requires it positive.
int IntField(const nlohmann::json& j, const char* key, const std::string& what) {
  const double v = NumberField(j, key, what);
  Require(v == std::floor(v) && std::abs(v) <= std::numeric_limits<int>::max(),
          fmt::format("{}: camera field '{}' must be a whole number of pixels, got {}", what, key, v));
  return static_cast<int>(v);
}
std::vector<double> ArrayField(const nlohmann::json& j, const char* key, size_t n, const std::string& what) {
  auto it = j.find(key);
  Require(it != j.end() && it->is_array() && it->size() == n,
          fmt::format("{}: camera field '{}' must be an array of {} numbers", what, key, n));
  std::vector<double> v;
  for (const auto& e : *it) {
    Require(e.is_number(), fmt::format("{}: camera field '{}' must hold numbers", what, key));
    v.push_back(e.get<double>());
  }
  return v;
}
}  // namespace

Camera CameraFromJson(const nlohmann::json& j, const std::string& what) {
  Require(j.is_object(), fmt::format("{}: a camera must be a JSON object", what));
  Camera c;
  c.intrinsics.fx = NumberField(j, "fx", what);
  c.intrinsics.fy = NumberField(j, "fy", what);
  c.intrinsics.cx = NumberField(j, "cx", what);
  c.intrinsics.cy = NumberField(j, "cy", what);
  c.intrinsics.width = IntField(j, "width", what);
  c.intrinsics.height = IntField(j, "height", what);
  c.intrinsics.Validate(what);
  auto pose = j.find("cam_from_head");
  Require(pose != j.end() && pose->is_object(),
          fmt::format("{}: camera field 'cam_from_head' is missing", what));
  const auto q = ArrayField(*pose, "rotation_wxyz", 4, what);
  const auto t = ArrayField(*pose, "translation_mm", 3, what);
  const Eigen::Quaterniond rq(q[0], q[1], q[2], q[3]);
  Require(std::isfinite(rq.norm()) && rq.norm() > 1e-12,
          fmt::format("{}: cam_from_head.rotation_wxyz is not a valid quaternion", what));
  c.cam_from_head = Rigid3d(rq, Eigen::Vector3d(t[0], t[1], t[2]));
  Require(c.cam_from_head.translation.allFinite(),
          fmt::format("{}: cam_from_head.translation_mm must be finite", what));
  return c;
}

Camera ReadCamera(const std::filesystem::path& path) {
  return CameraFromJson(ReadJsonFile(path), path.string());
}

void WriteCamera(const std::filesystem::path& path, const Camera& camera) {
  WriteJsonFile(path, CameraToJson(camera));
}

Camera LookAtCamera(const CameraIntrinsics& k, const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                    const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();      // forward
  const Eigen::Vector3d x = z.cross(up).normalized();         // right
  const Eigen::Vector3d y = z.cross(x);                       // down
  Eigen::Matrix3d cam_from_head_R;
  cam_from_head_R.row(0) = x.transpose();
  cam_from_head_R.row(1) = y.transpose();
  cam_from_head_R.row(2) = z.transpose();
  const Eigen::Quaterniond q(cam_from_head_R);
  return Camera(k, Rigid3d(q, -(cam_from_head_R * eye)));
}

}  // namespace crease
