// Eigen shorthands used across crease. Per-vertex and per-face arrays are
// row-major so that one row (one vertex, one triangle) is contiguous in memory.
#pragma once

#include <algorithm>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>

namespace crease {

using MatX3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using MatX2d = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using MatX3f = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
using MatX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using SpMat = Eigen::SparseMatrix<double>;

// `v` cut or zero-padded to n entries (rig parameters given for fewer modes than a
// rig has: the rest are 0).
inline Eigen::VectorXd ZeroPadded(const Eigen::VectorXd& v, Eigen::Index n) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(n);
  const Eigen::Index k = std::min(n, v.size());
  out.head(k) = v.head(k);
  return out;
}

}  // namespace crease
