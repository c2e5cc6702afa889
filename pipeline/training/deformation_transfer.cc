#include "pipeline/training/deformation_transfer.h"

#include <Eigen/SparseCholesky>
#include <cmath>
#include <fmt/format.h>
#include <vector>

#include "core/error.h"

namespace crease {
namespace {

using Ldlt = Eigen::SimplicialLDLT<SpMat>;

// Edge matrix with Sumner and Popović's fourth vertex: [v1 − v0, v2 − v0, n],
// n = (v1 − v0) × (v2 − v0) / √|(v1 − v0) × (v2 − v0)|.
bool FrameOf(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, Eigen::Matrix3d* V) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a;
  const Eigen::Vector3d cr = e1.cross(e2);
  const double len = cr.norm();
  if (!(len > 0.0)) return false;
  V->col(0) = e1;
  V->col(1) = e2;
  V->col(2) = cr / std::sqrt(len);
  return true;
}

void RequireFinite(const MatX3d& V, const std::string& what, const char* which) {
  for (int i = 0; i < V.rows(); ++i) {
    Require(V.row(i).allFinite(), fmt::format("{}: {} vertex {} is not finite", what, which, i));
  }
}

}  // namespace

struct DeformationTransfer::Impl {
  std::string what;
  int num_vertices = 0;
  WeldedMesh weld;              // of the target rest mesh
  MatX3d source_rest;           // welded
  Eigen::MatrixXd target_rest;  // welded, #W×3
  std::vector<Eigen::Matrix3d> source_rest_inverse;  // per welded triangle, V_t⁻¹ (zero when degenerate)
  SpMat GtA;                    // Gᵀ A, #W × 3#F
  Eigen::VectorXd anchor;       // diagonal w·M
  Ldlt solver;
};

DeformationTransfer::DeformationTransfer(const TriMesh& source_rest, const TriMesh& target_rest,
                                         const DeformationTransferOptions& options, const std::string& what)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.what = what;
  Require(source_rest.num_vertices() == target_rest.num_vertices() &&
              source_rest.num_faces() == target_rest.num_faces() && source_rest.F == target_rest.F,
          fmt::format("{}: source ({} vertices, {} triangles) and target ({} vertices, {} triangles) must "
                      "share their topology",
                      what, source_rest.num_vertices(), source_rest.num_faces(), target_rest.num_vertices(),
                      target_rest.num_faces()));
  Require(target_rest.num_faces() > 0, fmt::format("{}: the mesh has no triangles", what));
  Require(options.anchor_weight > 0.0 && std::isfinite(options.anchor_weight),
          fmt::format("{}: anchor_weight = {} must be > 0", what, options.anchor_weight));
  RequireFinite(source_rest.V, what, "source rest");
  RequireFinite(target_rest.V, what, "target rest");
  m.num_vertices = target_rest.num_vertices();

  // Weld UV-seam copies (of the target; the source has the same topology).
  m.weld = WeldCoincidentVertices(target_rest);
  const TriMesh& tw = m.weld.mesh;
  const int nw = tw.num_vertices(), nf = tw.num_faces();
  m.source_rest.resize(nw, 3);
  for (int w = 0; w < nw; ++w) m.source_rest.row(w) = source_rest.V.row(m.weld.vertex_of[w]);
  m.target_rest = tw.V;

  m.source_rest_inverse.assign(nf, Eigen::Matrix3d::Zero());
  std::vector<Eigen::Triplet<double>> g;
  g.reserve(static_cast<size_t>(nf) * 9);
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(nw);
  for (int f = 0; f < nf; ++f) {
    const int i0 = tw.F(f, 0), i1 = tw.F(f, 1), i2 = tw.F(f, 2);
    Eigen::Matrix3d Vs;
    if (FrameOf(m.source_rest.row(i0), m.source_rest.row(i1), m.source_rest.row(i2), &Vs)) {
      m.source_rest_inverse[f] = Vs.inverse();
    }
    // Gradient of the hat functions on the target's rest triangle:
    // ∇φ_i = n × e_i / (2A), e_i the edge opposite vertex i (counter-clockwise).
    const Eigen::Vector3d p0 = tw.V.row(i0), p1 = tw.V.row(i1), p2 = tw.V.row(i2);
    const Eigen::Vector3d cr = (p1 - p0).cross(p2 - p0);
    const double twice_area = cr.norm();
    if (!(twice_area > 0.0)) continue;  // degenerate: no energy
    const Eigen::Vector3d n = cr / twice_area;
    const double area = 0.5 * twice_area;
    const Eigen::Vector3d grad[3] = {n.cross(p2 - p1) / twice_area, n.cross(p0 - p2) / twice_area,
                                     n.cross(p1 - p0) / twice_area};
    const int ids[3] = {i0, i1, i2};
    for (int k = 0; k < 3; ++k) {
      for (int d = 0; d < 3; ++d) g.emplace_back(3 * f + d, ids[k], grad[k][d]);
      mass[ids[k]] += area / 3.0;
    }
  }
  SpMat G(3 * nf, nw);
  G.setFromTriplets(g.begin(), g.end());
  Eigen::VectorXd areas(3 * nf);
  for (int f = 0; f < nf; ++f) {
    const Eigen::Vector3d p0 = tw.V.row(tw.F(f, 0)), p1 = tw.V.row(tw.F(f, 1)), p2 = tw.V.row(tw.F(f, 2));
    areas.segment<3>(3 * f).setConstant(0.5 * (p1 - p0).cross(p2 - p0).norm());
  }
  m.GtA = SpMat(G.transpose()) * areas.asDiagonal();
  SpMat L = m.GtA * G;
  // Weak anchor: ε relative to the mean diagonal of L, spread by the mass so it is
  // resolution-independent. Vertices without area get a unit anchor (they follow x̂).
  const double mean_l = L.diagonal().mean(), mean_m = mass.mean();
  Require(mean_l > 0.0 && mean_m > 0.0, fmt::format("{}: the mesh has no area", what));
  const double w = options.anchor_weight * mean_l / mean_m;
  m.anchor.resize(nw);
  for (int i = 0; i < nw; ++i) m.anchor[i] = mass[i] > 0.0 ? w * mass[i] : 1.0;
  SpMat A = L;
  for (int i = 0; i < nw; ++i) A.coeffRef(i, i) += m.anchor[i];
  A.makeCompressed();
  m.solver.compute(A);
  Require(m.solver.info() == Eigen::Success,
          fmt::format("{}: sparse LDLT factorisation of the {}×{} Poisson system failed (degenerate mesh?)",
                      what, nw, nw));
}

DeformationTransfer::~DeformationTransfer() = default;
DeformationTransfer::DeformationTransfer(DeformationTransfer&&) noexcept = default;
DeformationTransfer& DeformationTransfer::operator=(DeformationTransfer&&) noexcept = default;

int DeformationTransfer::num_vertices() const { return impl_->num_vertices; }

MatX3d DeformationTransfer::Transfer(const MatX3d& source_deformed) const {
  const Impl& m = *impl_;
  Require(source_deformed.rows() == m.num_vertices,
          fmt::format("{}: deformed source has {} vertices, expected {}", m.what, source_deformed.rows(),
                      m.num_vertices));
  RequireFinite(source_deformed, m.what, "deformed source");
  const TriMesh& tw = m.weld.mesh;
  const int nw = tw.num_vertices(), nf = tw.num_faces();
  MatX3d S1(nw, 3);
  for (int w = 0; w < nw; ++w) S1.row(w) = source_deformed.row(m.weld.vertex_of[w]);
  // Per triangle, the source's deformation gradient Q_t = Ṽ_t V_t⁻¹; its rows
  // are the target gradients of the x, y and z coordinate functions.
  Eigen::MatrixXd q(3 * nf, 3);
  for (int f = 0; f < nf; ++f) {
    Eigen::Matrix3d Vd;
    Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
    if (FrameOf(S1.row(tw.F(f, 0)), S1.row(tw.F(f, 1)), S1.row(tw.F(f, 2)), &Vd) &&
        !m.source_rest_inverse[f].isZero()) {
      Q = Vd * m.source_rest_inverse[f];
    }
    // Column c of q holds, at rows 3f..3f+2, the gradient of coordinate c: row c of Q.
    q.block<3, 3>(3 * f, 0) = Q.transpose();
  }
  const Eigen::MatrixXd x_hat = m.target_rest + (S1 - m.source_rest);
  const Eigen::MatrixXd rhs = m.GtA * q + m.anchor.asDiagonal() * x_hat;
  const Eigen::MatrixXd x = m.solver.solve(rhs);
  MatX3d out(m.num_vertices, 3);
  for (int v = 0; v < m.num_vertices; ++v) out.row(v) = x.row(m.weld.welded_of[v]);
  return out;
}

}  // namespace crease
