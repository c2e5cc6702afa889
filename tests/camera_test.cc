#include "core/camera.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/error.h"

namespace crease {
namespace {

Camera TestCamera() {
  const CameraIntrinsics k{800.0, 820.0, 319.5, 239.5, 640, 480};
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.3, 1.0, -0.2).normalized()));
  return Camera(k, Rigid3d(q, Eigen::Vector3d(10.0, -5.0, 600.0)));
}

TEST(Camera, ProjectsLikeThePinholeFormula) {
  Camera cam(CameraIntrinsics{500, 500, 320, 240, 640, 480}, Rigid3d());
  const Eigen::Vector2d p = cam.Project(Eigen::Vector3d(10, -20, 100));
  EXPECT_DOUBLE_EQ(p.x(), 320 + 500 * 0.1);
  EXPECT_DOUBLE_EQ(p.y(), 240 - 500 * 0.2);
  EXPECT_TRUE(std::isnan(cam.Project(Eigen::Vector3d(0, 0, -5)).x()));
}

TEST(Camera, RigidTransformsCompose) {
  const Rigid3d a = TestCamera().cam_from_head;
  const Rigid3d id = a * a.Inverse();
  EXPECT_LT((id * Eigen::Vector3d(1, 2, 3) - Eigen::Vector3d(1, 2, 3)).norm(), 1e-12);
}

TEST(Camera, PixelRayHitsTheProjectedPoint) {
  const Camera cam = TestCamera();
  const Eigen::Vector3d X(5.0, 7.0, 20.0);
  const Eigen::Vector2d p = cam.Project(X);
  const Eigen::Vector3d dir = cam.PixelRayInHead(p.x(), p.y());
  const Eigen::Vector3d c = cam.CentreInHead();
  EXPECT_LT(((X - c).normalized() - dir).norm(), 1e-12);
}

TEST(Camera, LookAtCentresTheTarget) {
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(40, 640, 480), Eigen::Vector3d(0, 0, 500),
                                  Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  const Eigen::Vector2d c = cam.Project(Eigen::Vector3d::Zero());
  EXPECT_NEAR(c.x(), 319.5, 1e-9);
  EXPECT_NEAR(c.y(), 239.5, 1e-9);
  // Head +y (up) appears upwards in the image (smaller row).
  EXPECT_LT(cam.Project(Eigen::Vector3d(0, 10, 0)).y(), c.y());
  // Head +x appears to the right.
  EXPECT_GT(cam.Project(Eigen::Vector3d(10, 0, 0)).x(), c.x());
}

TEST(Camera, JsonRoundTripAndErrors) {
  const Camera cam = TestCamera();
  const Camera back = CameraFromJson(CameraToJson(cam), "cam.json");
  EXPECT_EQ(back.intrinsics.fx, cam.intrinsics.fx);
  EXPECT_EQ(back.intrinsics.height, cam.intrinsics.height);
  EXPECT_LT((back.cam_from_head.translation - cam.cam_from_head.translation).norm(), 1e-12);
  EXPECT_LT(back.cam_from_head.rotation.angularDistance(cam.cam_from_head.rotation), 1e-12);

  nlohmann::json j = CameraToJson(cam);
  j.erase("fy");
  try {
    CameraFromJson(j, "cam.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cam.json: camera field 'fy' is missing"), std::string::npos);
  }
  j = CameraToJson(cam);
  j["fx"] = -3;
  EXPECT_THROW(CameraFromJson(j, "cam.json"), Error);
  // Issue 19: an image size beyond int was undefined behaviour (UBSan in the sanitizer
  // build, fuzz/regressions/camera_json_fuzzer); a fraction of a pixel is refused too.
  for (const double width : {1e10, -1e10, 640.5}) {
    j = CameraToJson(cam);
    j["width"] = width;
    try {
      CameraFromJson(j, "cam.json");
      FAIL() << width;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("cam.json: camera field 'width' must be a whole number of pixels"),
                std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace crease
