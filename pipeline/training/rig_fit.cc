#include "pipeline/training/rig_fit.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fmt/format.h>
#include <numeric>
#include <unordered_map>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "core/ray_caster.h"
#include "core/rng.h"
#include "core/uv_raster.h"

namespace crease {

void RigFitOptions::VisitFields(OptionVisitor& v) {
  v.Field("correspondence", correspondence);
  v.Field("identity_prior", identity_prior);
  v.Field("expression_prior", expression_prior);
  v.Field("robust_scale_mm", robust_scale_mm);
  v.Field("max_fit_vertices", max_fit_vertices);
  v.Field("closest_point_iterations", closest_point_iterations);
  v.Field("closest_point_metric", closest_point_metric);
  v.Field("max_correspondence_mm", max_correspondence_mm);
  v.Field("max_solver_iterations", max_solver_iterations);
  v.Field("seed", fit_seed);
}

void RigFitOptions::Check() const {
  const char* o = "RigFitOptions";
  CheckGe(o, "identity_prior", identity_prior, 0.0);
  CheckGe(o, "expression_prior", expression_prior, 0.0);
  CheckGt(o, "robust_scale_mm", robust_scale_mm, 0.0);
  CheckGe(o, "max_fit_vertices", max_fit_vertices, 10);
  CheckGe(o, "closest_point_iterations", closest_point_iterations, 1);
  CheckGt(o, "max_correspondence_mm", max_correspondence_mm, 0.0);
  CheckGe(o, "max_solver_iterations", max_solver_iterations, 1);
}

namespace {

// Residual of one rig vertex against a scan point (3D) or plane (1D), scaled by
// `scale`. Parameter blocks: [identity (I, if I > 0)], expression (E), ω (3), t (3).
class VertexResidual : public ceres::CostFunction {
 public:
  VertexResidual(const FaceRig& rig, int vertex, const Eigen::Vector3d& target, const Eigen::Vector3d& normal,
                 bool point_to_plane, double scale)
      : rig_(rig), v_(vertex), target_(target), normal_(normal), plane_(point_to_plane), scale_(scale) {
    set_num_residuals(plane_ ? 1 : 3);
    if (rig.num_identity() > 0) mutable_parameter_block_sizes()->push_back(rig.num_identity());
    mutable_parameter_block_sizes()->push_back(rig.num_expressions());
    mutable_parameter_block_sizes()->push_back(3);
    mutable_parameter_block_sizes()->push_back(3);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const int I = rig_.num_identity(), E = rig_.num_expressions();
    const int b0 = I > 0 ? 1 : 0;
    const double* alpha = I > 0 ? p[0] : nullptr;
    const double* beta = p[b0];
    const double* omega = p[b0 + 1];
    const double* t = p[b0 + 2];
    Eigen::Vector3d x = rig_.neutral.V.row(v_).transpose();
    for (int c = 0; c < 3; ++c) {
      const int row = 3 * v_ + c;
      for (int k = 0; k < I; ++k) x[c] += rig_.identity_basis(row, k) * alpha[k];
      for (int b = 0; b < E; ++b) x[c] += rig_.expression_basis(row, b) * beta[b];
    }
    // R(ω)x and ∂(R(ω)x)/∂ω by forward-mode differentiation.
    using Jet = ceres::Jet<double, 3>;
    Jet w[3], xj[3], y[3];
    for (int c = 0; c < 3; ++c) {
      w[c] = Jet(omega[c], c);
      xj[c] = Jet(x[c]);
    }
    ceres::AngleAxisRotatePoint(w, xj, y);
    Eigen::Vector3d r3, n = normal_;
    Eigen::Matrix3d d_omega;
    for (int c = 0; c < 3; ++c) {
      r3[c] = y[c].a + t[c] - target_[c];
      d_omega.row(c) = y[c].v.transpose();
    }
    if (plane_) {
      residuals[0] = scale_ * n.dot(r3);
    } else {
      for (int c = 0; c < 3; ++c) residuals[c] = scale_ * r3[c];
    }
    if (!jacobians) return true;
    double Rm[9];
    ceres::AngleAxisToRotationMatrix(omega, ceres::ColumnMajorAdapter3x3(Rm));
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) R(r, c) = Rm[c * 3 + r];
    // Rows of the output: the residual rows (1 or 3) = S · (R, d_omega, I) with
    // S = scale·nᵀ (plane) or scale·I.
    const int rows = plane_ ? 1 : 3;
    Eigen::MatrixXd S(rows, 3);
    if (plane_) {
      S = scale_ * n.transpose();
    } else {
      S = scale_ * Eigen::Matrix3d::Identity();
    }
    const Eigen::MatrixXd SR = S * R;
    auto fill_basis = [&](double* J, const Eigen::MatrixXf& basis, int cols) {
      for (int r = 0; r < rows; ++r) {
        for (int k = 0; k < cols; ++k) {
          double s = 0.0;
          for (int c = 0; c < 3; ++c) s += SR(r, c) * basis(3 * v_ + c, k);
          J[r * cols + k] = s;
        }
      }
    };
    if (I > 0 && jacobians[0]) fill_basis(jacobians[0], rig_.identity_basis, I);
    if (jacobians[b0]) fill_basis(jacobians[b0], rig_.expression_basis, E);
    if (jacobians[b0 + 1]) {
      const Eigen::MatrixXd Jw = S * d_omega;
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < 3; ++c) jacobians[b0 + 1][r * 3 + c] = Jw(r, c);
    }
    if (jacobians[b0 + 2]) {
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < 3; ++c) jacobians[b0 + 2][r * 3 + c] = S(r, c);
    }
    return true;
  }

 private:
  const FaceRig& rig_;
  int v_;
  Eigen::Vector3d target_, normal_;
  bool plane_;
  double scale_;
};

// r = s·x: a zero-mean Gaussian prior on a parameter block.
class ScaledPrior : public ceres::CostFunction {
 public:
  ScaledPrior(int size, double scale) : scale_(scale) {
    set_num_residuals(size);
    mutable_parameter_block_sizes()->push_back(size);
  }
  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const int n = num_residuals();
    for (int i = 0; i < n; ++i) residuals[i] = scale_ * p[0][i];
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + n * n, 0.0);
      for (int i = 0; i < n; ++i) jacobians[0][i * n + i] = scale_;
    }
    return true;
  }

 private:
  double scale_;
};

std::vector<int> FaceChartVertices(const FaceRig& rig) {
  const MatX3i F = FaceChartTriangles(rig);
  std::vector<char> used(rig.num_vertices(), 0);
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) used[F(f, k)] = 1;
  std::vector<int> out;
  for (int v = 0; v < rig.num_vertices(); ++v)
    if (used[v]) out.push_back(v);
  return out;
}

// Scan positions at UVs: a position map of the scan's chart.
struct UvLookup {
  int size = 0;
  UvRaster raster;
  cv::Mat position;  // CV_32FC3
  bool Sample(const Eigen::Vector2d& uv, Eigen::Vector3d* p) const {
    const double x = uv.x() * size - 0.5, y = uv.y() * size - 0.5;
    const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
    double wsum = 0.0;
    Eigen::Vector3d acc = Eigen::Vector3d::Zero();
    for (int dy = 0; dy <= 1; ++dy) {
      for (int dx = 0; dx <= 1; ++dx) {
        const int i = x0 + dx, j = y0 + dy;
        if (i < 0 || j < 0 || i >= size || j >= size || !raster.covered(i, j)) continue;
        const double w = (dx ? x - x0 : 1.0 - (x - x0)) * (dy ? y - y0 : 1.0 - (y - y0));
        const cv::Vec3f q = position.at<cv::Vec3f>(j, i);
        acc += w * Eigen::Vector3d(q[0], q[1], q[2]);
        wsum += w;
      }
    }
    if (!(wsum > 0.25)) return false;  // most of the stencil must be on the scan
    *p = acc / wsum;
    return true;
  }
};

UvLookup MakeUvLookup(const TriMesh& scan, int size, const std::string& what) {
  UvLookup l;
  l.size = size;
  l.raster = RasterizeUv(scan, size, size, what);
  l.position = InterpolateToUv(l.raster, scan, scan.V);
  return l;
}

// Nearest scan vertex within a radius: a uniform grid of cell size = radius.
class NearestVertex {
 public:
  NearestVertex(const MatX3d& V, double radius) : V_(V), cell_(radius) {
    for (int i = 0; i < V.rows(); ++i) grid_[Key(Cell(V.row(i)))].push_back(i);
  }
  int Find(const Eigen::Vector3d& q) const {
    const Eigen::Vector3i c = Cell(q);
    int best = -1;
    double best_d = cell_ * cell_;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = grid_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == grid_.end()) continue;
          for (int i : it->second) {
            const double d = (V_.row(i).transpose() - q).squaredNorm();
            if (d < best_d || (d == best_d && i < best)) {
              best_d = d;
              best = i;
            }
          }
        }
    return best;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / cell_)), static_cast<int>(std::floor(p.y() / cell_)),
                           static_cast<int>(std::floor(p.z() / cell_)));
  }
  static int64_t Key(const Eigen::Vector3i& c) {
    return (static_cast<int64_t>(c.x() + (1 << 20)) << 42) | (static_cast<int64_t>(c.y() + (1 << 20)) << 21) |
           static_cast<int64_t>(c.z() + (1 << 20));
  }
  const MatX3d& V_;
  double cell_;
  std::unordered_map<int64_t, std::vector<int>> grid_;
};

MatX3d PosedRig(const FaceRig& rig, const Eigen::VectorXd& alpha, const Eigen::VectorXd& beta, const double* omega,
                const double* t) {
  MatX3d X = rig.EvaluatePositions(alpha, beta);
  for (int v = 0; v < X.rows(); ++v) {
    const double x[3] = {X(v, 0), X(v, 1), X(v, 2)};
    double y[3];
    ceres::AngleAxisRotatePoint(omega, x, y);
    for (int c = 0; c < 3; ++c) X(v, c) = y[c] + t[c];
  }
  return X;
}

}  // namespace

bool ScanHasRigUvs(const FaceRig& rig, const TriMesh& scan) {
  if (!scan.has_uv() || scan.num_faces() == 0) return false;
  const int size = 256;
  const UvRaster raster = RasterizeUv(scan, size, size, "scan");
  const std::vector<int> verts = FaceChartVertices(rig);
  int hit = 0;
  for (int v : verts) {
    const int i = std::clamp(static_cast<int>(rig.neutral.UV(v, 0) * size), 0, size - 1);
    const int j = std::clamp(static_cast<int>(rig.neutral.UV(v, 1) * size), 0, size - 1);
    if (raster.covered(i, j)) ++hit;
  }
  return hit >= 0.8 * static_cast<double>(verts.size());
}

RigFitResult FitRigToScans(const FaceRig& rig, const std::vector<TriMesh>& scans,
                           const std::vector<std::string>& scan_names, const RigFitOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  Require(!scans.empty() && scans.size() == scan_names.size(), "FitRigToScans: one name per scan is needed");
  Require(rig.num_expressions() > 0, "FitRigToScans: the rig has no expression blendshapes");
  const int J = static_cast<int>(scans.size());
  const int I = rig.num_identity(), E = rig.num_expressions();
  RigFitResult result;
  result.correspondence = options.correspondence;
  if (result.correspondence == RigCorrespondence::kAuto) {
    bool all_uv = true;
    for (const auto& s : scans) all_uv = all_uv && ScanHasRigUvs(rig, s);
    result.correspondence = all_uv ? RigCorrespondence::kUv : RigCorrespondence::kClosest;
  }
  const bool uv_mode = result.correspondence == RigCorrespondence::kUv;

  // The seeded subset of face-chart vertices.
  std::vector<int> verts = FaceChartVertices(rig);
  Rng rng(options.fit_seed);
  for (int i = static_cast<int>(verts.size()) - 1; i > 0; --i) std::swap(verts[i], verts[rng.UniformInt(0, i)]);
  if (static_cast<int>(verts.size()) > options.max_fit_vertices) verts.resize(options.max_fit_vertices);
  std::sort(verts.begin(), verts.end());

  Eigen::VectorXd alpha = Eigen::VectorXd::Zero(I);
  std::vector<Eigen::VectorXd> beta(J, Eigen::VectorXd::Zero(E));
  std::vector<std::array<double, 6>> pose(J, {0, 0, 0, 0, 0, 0});  // ω, t

  // Fixed targets (uv) or per-iteration closest points.
  std::vector<std::vector<std::pair<int, Eigen::Vector3d>>> uv_targets(J);
  std::vector<MatX3d> scan_normals(J);
  std::vector<std::unique_ptr<NearestVertex>> nearest(J);
  for (int j = 0; j < J; ++j) {
    ValidateMesh(scans[j], scan_names[j], {.uv = uv_mode});
    if (uv_mode) {
      const UvLookup lookup = MakeUvLookup(scans[j], 1024, scan_names[j]);
      for (int v : verts) {
        Eigen::Vector3d p;
        if (lookup.Sample(rig.neutral.UV.row(v).transpose(), &p)) uv_targets[j].emplace_back(v, p);
      }
      Require(uv_targets[j].size() >= 10,
              fmt::format("{}: only {} of the rig's face vertices find a point with their UV on the scan", scan_names[j],
                          uv_targets[j].size()));
    } else {
      scan_normals[j] = VertexNormals(scans[j]);
      nearest[j] = std::make_unique<NearestVertex>(scans[j].V, options.max_correspondence_mm);
    }
  }

  const int outer = uv_mode ? 1 : options.closest_point_iterations;
  for (int it = 0; it < outer; ++it) {
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    for (int j = 0; j < J; ++j) {
      std::vector<std::tuple<int, Eigen::Vector3d, Eigen::Vector3d>> pairs;
      if (uv_mode) {
        for (const auto& [v, p] : uv_targets[j]) pairs.emplace_back(v, p, Eigen::Vector3d::Zero());
      } else {
        const MatX3d X = PosedRig(rig, alpha, beta[j], pose[j].data(), pose[j].data() + 3);
        const MatX3d NX = VertexNormals(TriMesh{X, rig.neutral.F, {}, {}});
        const double cos60 = 0.5;
        for (int v : verts) {
          const Eigen::Vector3d x = X.row(v);
          const int q = nearest[j]->Find(x);
          if (q < 0) continue;
          const Eigen::Vector3d nq = scan_normals[j].row(q);
          if (nq.dot(NX.row(v)) < cos60) continue;
          pairs.emplace_back(v, scans[j].V.row(q).transpose(), nq);
        }
        Require(pairs.size() >= 10,
                fmt::format("{}: only {} rig vertices have a scan point within {} mm (closest-point "
                            "correspondences need the scan roughly aligned with the rig's head frame)",
                            scan_names[j], pairs.size(), options.max_correspondence_mm));
      }
      const double scale = 1.0 / std::sqrt(static_cast<double>(pairs.size()));
      std::vector<double*> blocks;
      if (I > 0) blocks.push_back(alpha.data());
      blocks.push_back(beta[j].data());
      blocks.push_back(pose[j].data());
      blocks.push_back(pose[j].data() + 3);
      for (const auto& [v, p, n] : pairs) {
        const bool plane = !uv_mode && options.closest_point_metric == ClosestPointMetric::kPlane;
        problem.AddResidualBlock(new VertexResidual(rig, v, p, n, plane, scale),
                                 new ceres::HuberLoss(options.robust_scale_mm * scale), blocks);
      }
      if (options.expression_prior > 0.0) {
        problem.AddResidualBlock(new ScaledPrior(E, std::sqrt(options.expression_prior)), nullptr, beta[j].data());
      }
      for (int b = 0; b < E; ++b) {
        problem.SetParameterLowerBound(beta[j].data(), b, 0.0);
        problem.SetParameterUpperBound(beta[j].data(), b, 1.0);
      }
    }
    if (I > 0 && options.identity_prior > 0.0) {
      problem.AddResidualBlock(new ScaledPrior(I, std::sqrt(options.identity_prior)), nullptr, alpha.data());
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    so.max_num_iterations = options.max_solver_iterations;
    so.num_threads = 2;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    Require(summary.IsSolutionUsable(), fmt::format("rig fit of {}: {}", scan_names[0], summary.message));
    result.solver_iterations += static_cast<int>(summary.iterations.size());
  }

  result.identity = alpha;
  result.expressions = beta;
  for (int j = 0; j < J; ++j) {
    const Eigen::Vector3d w(pose[j][0], pose[j][1], pose[j][2]);
    const double angle = w.norm();
    const Eigen::Quaterniond q =
        angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle)) : Eigen::Quaterniond::Identity();
    result.scan_from_head.emplace_back(q, Eigen::Vector3d(pose[j][3], pose[j][4], pose[j][5]));
    result.fitted.push_back(PosedRig(rig, alpha, beta[j], pose[j].data(), pose[j].data() + 3));
    // RMS distance over the fit vertices: to the UV target, or point-to-plane.
    double se = 0.0;
    int n = 0;
    if (uv_mode) {
      for (const auto& [v, p] : uv_targets[j]) {
        se += (result.fitted[j].row(v).transpose() - p).squaredNorm();
        ++n;
      }
    } else {
      for (int v : verts) {
        const Eigen::Vector3d x = result.fitted[j].row(v);
        const int q = nearest[j]->Find(x);
        if (q < 0) continue;
        const Eigen::Vector3d r = x - scans[j].V.row(q).transpose();
        const double d = options.closest_point_metric == ClosestPointMetric::kPlane ? scan_normals[j].row(q).dot(r) : r.norm();
        se += d * d;
        ++n;
      }
    }
    result.rms_mm.push_back(n ? std::sqrt(se / n) : 0.0);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

TriMesh TransferUvsFromRig(const FaceRig& rig, const MatX3d& fitted_neutral, const TriMesh& scan,
                           double max_distance_mm, std::vector<int>* kept_vertices) {
  ValidateMesh(scan, "scan (UV transfer)");
  Require(fitted_neutral.rows() == rig.num_vertices(), "TransferUvsFromRig: fitted neutral has the wrong size");
  TriMesh chart;
  chart.V = fitted_neutral;
  chart.F = FaceChartTriangles(rig);
  RayCasterOptions robust;
  robust.robust = true;  // rays start on the surface, through vertices and edges
  const RayCaster caster(chart, robust, "fitted rig (UV transfer)");
  const MatX3d N = VertexNormals(scan);
  std::vector<Eigen::Vector3f> o(scan.num_vertices()), d(scan.num_vertices());
  for (int v = 0; v < scan.num_vertices(); ++v) {
    o[v] = scan.V.row(v).cast<float>();
    d[v] = N.row(v).norm() > 0 ? Eigen::Vector3f(N.row(v).normalized().cast<float>()) : Eigen::Vector3f::UnitZ();
  }
  std::vector<SignedHit> hits;
  caster.IntersectSignedBatch(o, d, static_cast<float>(max_distance_mm), &hits);
  MatX2d uv(scan.num_vertices(), 2);
  std::vector<char> has(scan.num_vertices(), 0);
  for (int v = 0; v < scan.num_vertices(); ++v) {
    if (!hits[v].valid()) continue;
    const int t = hits[v].triangle;
    const double u = hits[v].u, w = hits[v].v;
    uv.row(v) = (1 - u - w) * rig.neutral.UV.row(chart.F(t, 0)) + u * rig.neutral.UV.row(chart.F(t, 1)) +
                w * rig.neutral.UV.row(chart.F(t, 2));
    has[v] = 1;
  }
  std::vector<int> new_of(scan.num_vertices(), -1);
  std::vector<int> kept;
  std::vector<Eigen::Vector3i> faces;
  for (int f = 0; f < scan.num_faces(); ++f) {
    const Eigen::Vector3i tri = scan.F.row(f);
    if (!has[tri[0]] || !has[tri[1]] || !has[tri[2]]) continue;
    Eigen::Vector3i nt;
    for (int k = 0; k < 3; ++k) {
      if (new_of[tri[k]] < 0) {
        new_of[tri[k]] = static_cast<int>(kept.size());
        kept.push_back(tri[k]);
      }
      nt[k] = new_of[tri[k]];
    }
    faces.push_back(nt);
  }
  Require(!faces.empty(), fmt::format("UV transfer: no scan vertex lies within {} mm of the fitted rig's face",
                                      max_distance_mm));
  TriMesh out;
  out.V.resize(static_cast<int>(kept.size()), 3);
  out.UV.resize(static_cast<int>(kept.size()), 2);
  for (size_t i = 0; i < kept.size(); ++i) {
    out.V.row(static_cast<int>(i)) = scan.V.row(kept[i]);
    out.UV.row(static_cast<int>(i)) = uv.row(kept[i]);
  }
  out.F.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) out.F.row(static_cast<int>(f)) = faces[f];
  if (kept_vertices) *kept_vertices = std::move(kept);
  return out;
}

}  // namespace crease
