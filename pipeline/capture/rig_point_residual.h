// One rig point seen through the pinhole camera, with the Jacobians of the 2D rig
// fits: the numerics shared by the global tracker's landmark fit
// (landmark_fit.cc, LandmarkCost; paper Sec. 5) and flow refinement's 3D fit to
// the refined 2D points (flow_refinement.cc, FlowRefiner SolveFit; Sec. 5.1).
//
//   x(β)  = x_0 + B β        the point in the head frame, mm; x_0 its base position
//                            (neutral + identity), B its 3 rows of the expression
//                            basis (3×#E, row-major: each row contiguous)
//   q     = R x + t          the point in the camera frame, mm (R, t = cam_from_head)
//   π(q)  = (f_x q_x/q_z + c_x, f_y q_y/q_z + c_y)   pixel, OpenCV pinhole
//
// Each fit forms its residual r = M (π(q) − l) with its own 2×2 weight M (√w I for a
// flow point, W_i for a landmark or a jaw-contour point) and its own solver; the
// Jacobians below carry M on the left:
//   ∂r/∂q = M J_π                   (= ∂r/∂t)        J_π = ∂π/∂q (2×3)
//   ∂r/∂x = M J_π R                 (∂r/∂β = M J_π R B, ∂r/∂α = M J_π R A)
//   ∂r/∂δω = −M J_π [R x]×          for the left increment R ← exp([δω]×) R
#pragma once

#include <Eigen/Core>

#include "core/camera.h"

namespace crease {

// Points with q_z at or below this depth (mm) count as behind the camera.
inline constexpr double kMinRigPointDepthMm = 1e-6;

// B of one point stored on its own (3×#E, row-major).
using RigPointRows = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>;
// B of one point as an argument: 3×#E rows of a row-major basis (contiguous rows, any
// row stride), e.g. a RigPointRows or three rows of a row-major (3·#V)×#E basis.
using RigPointBasis = Eigen::Ref<const Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>, 0,
                                 Eigen::OuterStride<>>;
// A 2×#E destination inside a row-major Jacobian (contiguous rows, any row stride).
using RigPointJacobianRows =
    Eigen::Ref<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>, 0, Eigen::OuterStride<>>;

struct RigPointProjection {
  Eigen::Vector2d pixel;                   // π(q), px
  Eigen::Vector3d rotated;                 // R x, mm
  Eigen::Matrix<double, 2, 3> d_cam;       // M J_π = ∂r/∂q = ∂r/∂t, px/mm (weighted)
  Eigen::Matrix<double, 2, 3> d_head;      // M J_π R = ∂r/∂x, px/mm
  Eigen::Matrix<double, 2, 3> d_rotation;  // −M J_π [R x]× = ∂r/∂δω, px/rad
};

// x(β) = x_0 + B β, one dot product per row.
inline Eigen::Vector3d RigPointInHead(const Eigen::Vector3d& base, const RigPointBasis& B,
                                      const Eigen::VectorXd& beta) {
  return base + Eigen::Vector3d(B.row(0).dot(beta), B.row(1).dot(beta), B.row(2).dot(beta));
}

// Projects x under (R, t). Returns false (out untouched) when q_z ≤ kMinRigPointDepthMm.
// With `weight` null only `pixel` and `rotated` are set; otherwise the three Jacobians
// too, weighted on the left by *weight (M).
inline bool ProjectRigPoint(const Eigen::Vector3d& x, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                            const CameraIntrinsics& K, const Eigen::Matrix2d* weight, RigPointProjection* out) {
  const Eigen::Vector3d Rx = R * x;
  const Eigen::Vector3d q = Rx + t;
  if (!(q.z() > kMinRigPointDepthMm)) return false;
  const double iz = 1.0 / q.z();
  out->pixel = Eigen::Vector2d(K.fx * q.x() * iz + K.cx, K.fy * q.y() * iz + K.cy);
  out->rotated = Rx;
  if (!weight) return true;
  Eigen::Matrix<double, 2, 3> J;
  J << K.fx * iz, 0.0, -K.fx * q.x() * iz * iz, 0.0, K.fy * iz, -K.fy * q.y() * iz * iz;
  out->d_cam = *weight * J;
  out->d_head = out->d_cam * R;
  out->d_rotation = -out->d_cam * Skew(Rx);
  return true;
}

// ∂r/∂β = (M J_π R) B into `out` (2×#E), each row an axpy over the contiguous rows of B
// (vectorised; no temporary).
inline void RigPointExpressionJacobian(const Eigen::Matrix<double, 2, 3>& d_head, const RigPointBasis& B,
                                       RigPointJacobianRows out) {
  for (int a = 0; a < 2; ++a) out.row(a) = d_head(a, 0) * B.row(0) + d_head(a, 1) * B.row(1) + d_head(a, 2) * B.row(2);
}

}  // namespace crease
