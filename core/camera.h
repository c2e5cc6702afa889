// Pinhole camera (OpenCV convention: x right, y down, z forward; pixel (x, y)
// has its centre at (x, y); DESIGN.md) and rigid transforms.
//
// Transform names carry their frames: `a_from_b` maps a point expressed in
// frame b to frame a, so `point_in_cam = cam_from_head * point_in_head`.
#pragma once

#include <filesystem>
#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>

#include "core/types.h"

namespace crease {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();  // mm

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& r, const Eigen::Vector3d& t) : rotation(r.normalized()), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return rotation * p + translation; }
  Rigid3d operator*(const Rigid3d& b) const {  // (a_from_b * b_from_c) = a_from_c
    return Rigid3d(rotation * b.rotation, rotation * b.translation + translation);
  }
  Rigid3d Inverse() const {
    const Eigen::Quaterniond inv = rotation.conjugate();
    return Rigid3d(inv, -(inv * translation));
  }
  Eigen::Matrix<double, 3, 4> ToMatrix() const;
};

// [v]×: the cross-product matrix, [v]× x = v × x.
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// exp([ω]×): the rotation by the angle-axis vector ω (radians).
inline Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& w) {
  const double theta = w.norm();
  if (theta < 1e-12) return Eigen::Matrix3d::Identity() + Skew(w);
  return Eigen::AngleAxisd(theta, w / theta).toRotationMatrix();
}

struct CameraIntrinsics {
  double fx = 0.0, fy = 0.0;  // focal lengths, pixels
  double cx = 0.0, cy = 0.0;  // principal point, pixels
  int width = 0, height = 0;  // image size, pixels

  // Intrinsics from a horizontal field of view (degrees), principal point at the centre.
  static CameraIntrinsics FromFov(double horizontal_fov_deg, int width, int height);
  // Throws Error("<what>: ...") for non-positive focal lengths or sizes, non-finite values.
  void Validate(const std::string& what) const;
};

class Camera {
 public:
  CameraIntrinsics intrinsics;
  Rigid3d cam_from_head;

  Camera() = default;
  Camera(const CameraIntrinsics& k, const Rigid3d& pose) : intrinsics(k), cam_from_head(pose) {}

  // Pixel of a point in camera coordinates. Points with z <= 0 project to NaN.
  Eigen::Vector2d ProjectCamPoint(const Eigen::Vector3d& point_in_cam) const;
  // Pixel of a point in head coordinates.
  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_head) const {
    return ProjectCamPoint(cam_from_head * point_in_head);
  }
  // Projects every row of `points_in_head` (#N×3); rows behind the camera are NaN.
  MatX2d ProjectAll(const MatX3d& points_in_head) const;

  // Unit ray direction in head coordinates through pixel (x, y), and the camera
  // centre in head coordinates.
  Eigen::Vector3d PixelRayInHead(double x, double y) const;
  Eigen::Vector3d CentreInHead() const;

  bool InImage(const Eigen::Vector2d& pixel) const {
    return pixel.x() >= -0.5 && pixel.y() >= -0.5 && pixel.x() < intrinsics.width - 0.5 &&
           pixel.y() < intrinsics.height - 0.5;
  }
};

// JSON form: {"fx":…, "fy":…, "cx":…, "cy":…, "width":…, "height":…,
//             "cam_from_head": {"rotation_wxyz": [w,x,y,z], "translation_mm": [x,y,z]}}
nlohmann::json CameraToJson(const Camera& camera);
// Errors name `what` and the missing or invalid field.
Camera CameraFromJson(const nlohmann::json& j, const std::string& what);
Camera ReadCamera(const std::filesystem::path& path);
void WriteCamera(const std::filesystem::path& path, const Camera& camera);

// A camera at `eye_in_head` looking at `target_in_head`, with `up_in_head`
// appearing upwards in the image (the image's y axis points down).
Camera LookAtCamera(const CameraIntrinsics& k, const Eigen::Vector3d& eye_in_head,
                    const Eigen::Vector3d& target_in_head, const Eigen::Vector3d& up_in_head);

}  // namespace crease
