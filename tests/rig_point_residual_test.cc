// The shared 2D rig-fit residual (pipeline/capture/rig_point_residual.h): its analytic
// Jacobians against central differences, and the behind-the-camera flag.
#include "pipeline/capture/rig_point_residual.h"

#include <gtest/gtest.h>

#include <limits>

#include "core/rng.h"

namespace crease {
namespace {

struct PointScene {
  CameraIntrinsics K = CameraIntrinsics::FromFov(40.0, 640, 480);
  Eigen::Vector3d base{12.0, -20.0, 35.0};
  RigPointRows B;
  Eigen::VectorXd beta;
  Eigen::Matrix3d R = ExpSO3(Eigen::Vector3d(3.0, 0.2, -0.1));
  Eigen::Vector3d t{5.0, -8.0, 520.0};
  Eigen::Matrix2d M;
};

PointScene MakeScene() {
  PointScene s;
  Rng rng(7);
  s.B.resize(3, 9);
  for (int i = 0; i < 3; ++i) {
    for (int e = 0; e < 9; ++e) s.B(i, e) = 10.0 * rng.Normal();
  }
  s.beta.resize(9);
  for (int e = 0; e < 9; ++e) s.beta[e] = rng.Uniform(0.0, 1.0);
  s.M << 1.3, 0.4, -0.2, 0.7;  // a contour-like weight: not a multiple of I
  return s;
}

// r = M π(R x(β) + t), the weighted pixel (the target only shifts r).
Eigen::Vector2d Residual(const PointScene& s, const Eigen::VectorXd& beta, const Eigen::Matrix3d& R,
                         const Eigen::Vector3d& t) {
  RigPointProjection p;
  if (ProjectRigPoint(RigPointInHead(s.base, s.B, beta), R, t, s.K, nullptr, &p)) return s.M * p.pixel;
  ADD_FAILURE() << "the point left the camera's front";
  return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
}

TEST(RigPointResidual, JacobiansMatchCentralDifferences) {
  const PointScene s = MakeScene();
  RigPointProjection p;
  ASSERT_TRUE(ProjectRigPoint(RigPointInHead(s.base, s.B, s.beta), s.R, s.t, s.K, &s.M, &p));
  Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor> d_beta(2, 9);
  RigPointExpressionJacobian(p.d_head, s.B, d_beta);
  const double h = 1e-6;
  for (int e = 0; e < 9; ++e) {
    Eigen::VectorXd plus = s.beta, minus = s.beta;
    plus[e] += h;
    minus[e] -= h;
    const Eigen::Vector2d numeric = (Residual(s, plus, s.R, s.t) - Residual(s, minus, s.R, s.t)) / (2 * h);
    EXPECT_LT((numeric - d_beta.col(e)).norm(), 1e-6 * (1.0 + numeric.norm())) << "β_" << e;
  }
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d dw = h * Eigen::Vector3d::Unit(j);
    const Eigen::Vector2d numeric_w =
        (Residual(s, s.beta, ExpSO3(dw) * s.R, s.t) - Residual(s, s.beta, ExpSO3(-dw) * s.R, s.t)) / (2 * h);
    EXPECT_LT((numeric_w - p.d_rotation.col(j)).norm(), 1e-5 * (1.0 + numeric_w.norm())) << "δω_" << j;
    const Eigen::Vector2d numeric_t = (Residual(s, s.beta, s.R, s.t + dw) - Residual(s, s.beta, s.R, s.t - dw)) / (2 * h);
    EXPECT_LT((numeric_t - p.d_cam.col(j)).norm(), 1e-6 * (1.0 + numeric_t.norm())) << "t_" << j;
  }
  // ∂r/∂x: β enters only through x, so d_head B is the β Jacobian checked above;
  // check d_head itself along a head-frame displacement too.
  const Eigen::Vector3d dx(0.3, -0.5, 0.8);
  RigPointProjection a, b;
  ASSERT_TRUE(ProjectRigPoint(RigPointInHead(s.base + h * dx, s.B, s.beta), s.R, s.t, s.K, nullptr, &a));
  ASSERT_TRUE(ProjectRigPoint(RigPointInHead(s.base - h * dx, s.B, s.beta), s.R, s.t, s.K, nullptr, &b));
  EXPECT_LT((s.M * (a.pixel - b.pixel) / (2 * h) - p.d_head * dx).norm(), 1e-6);
}

TEST(RigPointResidual, PixelIsThePinholeProjection) {
  const PointScene s = MakeScene();
  RigPointProjection p;
  const Eigen::Vector3d x = RigPointInHead(s.base, s.B, s.beta);
  ASSERT_TRUE(ProjectRigPoint(x, s.R, s.t, s.K, nullptr, &p));
  const Camera camera(s.K, Rigid3d(Eigen::Quaterniond(s.R), s.t));
  EXPECT_LT((p.pixel - camera.Project(x)).norm(), 1e-9);
  EXPECT_LT((p.rotated - s.R * x).norm(), 1e-12);
  EXPECT_LT((x - s.base - s.B * s.beta).norm(), 1e-12);
}

TEST(RigPointResidual, PointBehindTheCameraIsFlaggedAndLeavesTheOutputUntouched) {
  const PointScene s = MakeScene();
  RigPointProjection p;
  p.pixel.setConstant(-7.0);
  const Eigen::Vector3d x = RigPointInHead(s.base, s.B, s.beta);
  const Eigen::Vector3d t_behind(s.t.x(), s.t.y(), -(s.R * x).z() - 1.0);  // q_z = −1 mm
  EXPECT_FALSE(ProjectRigPoint(x, s.R, t_behind, s.K, &s.M, &p));
  EXPECT_EQ(p.pixel, Eigen::Vector2d(-7.0, -7.0));
  const Eigen::Vector3d t_on_plane(s.t.x(), s.t.y(), -(s.R * x).z());  // q_z = 0
  EXPECT_FALSE(ProjectRigPoint(x, s.R, t_on_plane, s.K, nullptr, &p));
}

}  // namespace
}  // namespace crease
