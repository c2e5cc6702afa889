#include "pipeline/capture/landmark_fit.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <fmt/format.h>

#include "core/error.h"
#include "core/options.h"
#include "pipeline/capture/rig_point_residual.h"

namespace crease {

void LandmarkFitOptions::VisitFields(OptionVisitor& v) {
  v.Field("expression_prior_weight", fit_expression_prior_weight);
  v.Field("temporal_expression_weight", fit_temporal_expression_weight);
  v.Field("temporal_rotation_weight", fit_temporal_rotation_weight);
  v.Field("temporal_translation_weight", fit_temporal_translation_weight);
  v.Field("temporal_depth_weight", fit_temporal_depth_weight);
  v.Field("identity_prior_weight", fit_identity_prior_weight);
  v.Field("identity_frames", identity_frames);
  v.Field("identity_fit_interval", identity_fit_interval);
  v.Field("identity_fit_iterations", identity_fit_iterations);
  v.Field("contour_weight", contour_weight);
  v.Field("contour_tangent_weight", contour_tangent_weight);
  v.Field("landmark_robust_loss_px", landmark_robust_loss_px);
  v.Field("max_iterations", fit_max_iterations);
  v.Field("initial_max_iterations", fit_initial_max_iterations);
  v.Field("function_tolerance", fit_function_tolerance);
  v.Field("linear_solver", fit_linear_solver);
}

void LandmarkFitOptions::Check() const {
  const char* o = "LandmarkFitOptions";
  CheckGe(o, "fit_expression_prior_weight", fit_expression_prior_weight, 0.0);
  CheckGe(o, "fit_temporal_expression_weight", fit_temporal_expression_weight, 0.0);
  CheckGe(o, "fit_temporal_rotation_weight", fit_temporal_rotation_weight, 0.0);
  CheckGe(o, "fit_temporal_translation_weight", fit_temporal_translation_weight, 0.0);
  CheckGe(o, "fit_temporal_depth_weight", fit_temporal_depth_weight, 0.0);
  CheckGe(o, "fit_identity_prior_weight", fit_identity_prior_weight, 0.0);
  CheckGe(o, "identity_frames", identity_frames, 0);
  CheckGe(o, "identity_fit_interval", identity_fit_interval, 1);
  CheckGe(o, "identity_fit_iterations", identity_fit_iterations, 1);
  CheckGe(o, "contour_weight", contour_weight, 0.0);
  CheckGe(o, "contour_tangent_weight", contour_tangent_weight, 0.0);
  CheckLe(o, "contour_tangent_weight", contour_tangent_weight, 1.0);
  CheckGt(o, "landmark_robust_loss_px", landmark_robust_loss_px, 0.0);
  CheckGe(o, "fit_max_iterations", fit_max_iterations, 1);
  CheckGe(o, "fit_initial_max_iterations", fit_initial_max_iterations, 1);
  CheckGt(o, "fit_function_tolerance", fit_function_tolerance, 0.0);
  CheckLt(o, "fit_function_tolerance", fit_function_tolerance, 1.0);
}

void GroundTruthPriorOptions::VisitFields(OptionVisitor& v) {
  v.Field("gt_prior_noise_px", gt_prior_noise_px);
  v.Field("gt_prior_noise_seed", gt_prior_noise_seed);
}

void GroundTruthPriorOptions::Check() const {
  CheckGe("GroundTruthPriorOptions", "gt_prior_noise_px", gt_prior_noise_px, 0.0);
}

namespace {

constexpr int kMinPoints = 6;

// log(R) as an angle-axis vector.
Eigen::Vector3d LogSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// Left Jacobian of SO(3): exp([ω + δ]×) ≈ exp([J_l(ω) δ]×) exp([ω]×).
Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& w) {
  const double theta = w.norm();
  const Eigen::Matrix3d W = Skew(w);
  if (theta < 1e-5) return Eigen::Matrix3d::Identity() + 0.5 * W + (1.0 / 6.0) * W * W;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(theta)) / t2 * W +
         (theta - std::sin(theta)) / (t2 * theta) * W * W;
}

// One landmark's residual r = W (π(exp([ω]×) R_ref x + t) − l), x = base + B β (+ A α).
// Parameter blocks: the frame's y = [β (#E), ω (3), t (3)] in one block (so that the
// identity batch can eliminate whole frames with a Schur complement), and α (#I) when
// `identity_rows` is given.
// Analytic Jacobians from rig_point_residual.h (shared with flow refinement's 3D fit),
// weighted by W: ∂r/∂β = W J_π R B, ∂r/∂α = W J_π R A, ∂r/∂t = W J_π; our ω is not a
// left increment but R = exp([ω]×) R_ref, so ∂r/∂ω = −W J_π [R x]× J_l(ω).
class LandmarkCost final : public ceres::CostFunction {
 public:
  LandmarkCost(const Eigen::Vector3d& base, const RigPointRows& expression_rows, const Eigen::MatrixXd* identity_rows,
               const CameraIntrinsics& intrinsics, const Eigen::Matrix3d& R_ref, const Eigen::Vector2d& target,
               const Eigen::Matrix2d& W)
      : base_(base), B_(expression_rows), A_(identity_rows), K_(intrinsics), R_ref_(R_ref), target_(target), W_(W) {
    set_num_residuals(2);
    mutable_parameter_block_sizes()->push_back(static_cast<int>(B_.cols()) + 6);
    if (A_) mutable_parameter_block_sizes()->push_back(static_cast<int>(A_->cols()));
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const Eigen::Index E = B_.cols();
    const Eigen::Map<const Eigen::VectorXd> beta(p[0], E);
    const Eigen::Vector3d w(p[0][E], p[0][E + 1], p[0][E + 2]);
    const Eigen::Vector3d t(p[0][E + 3], p[0][E + 4], p[0][E + 5]);
    Eigen::Vector3d base = base_;
    // lazyProduct: coefficient-wise products; Eigen's GEMM path costs more at these sizes.
    if (A_) base += A_->lazyProduct(Eigen::Map<const Eigen::VectorXd>(p[1], A_->cols()));
    RigPointProjection proj;
    if (!ProjectRigPoint(RigPointInHead(base, B_, beta), ExpSO3(w) * R_ref_, t, K_, &W_, &proj)) return false;
    Eigen::Map<Eigen::Vector2d> r(residuals);
    r = W_ * (proj.pixel - target_);
    if (!jacobians) return true;
    if (jacobians[0]) {
      // Row-major 2 × (#E + 6): columns β, then ω, then t.
      using Strided = Eigen::Map<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>, 0, Eigen::OuterStride<>>;
      const Eigen::OuterStride<> stride(E + 6);
      RigPointExpressionJacobian(proj.d_head, B_, Strided(jacobians[0], 2, E, stride));
      Strided J_omega(jacobians[0] + E, 2, 3, stride);
      J_omega = proj.d_rotation * LeftJacobianSO3(w);
      Strided J_translation(jacobians[0] + E + 3, 2, 3, stride);
      J_translation = proj.d_cam;
    }
    if (A_ && jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> J_alpha(jacobians[1], 2, A_->cols());
      J_alpha = proj.d_head.lazyProduct(*A_);
    }
    return true;
  }

 private:
  Eigen::Vector3d base_;
  const RigPointRows& B_;
  const Eigen::MatrixXd* A_;
  CameraIntrinsics K_;
  Eigen::Matrix3d R_ref_;
  Eigen::Vector2d target_;
  Eigen::Matrix2d W_;
};

// r_k = s_k (p_k − c_k): a Gaussian prior on a parameter block about c.
class OffsetPrior final : public ceres::CostFunction {
 public:
  OffsetPrior(const Eigen::VectorXd& centre, double scale)
      : OffsetPrior(centre, Eigen::VectorXd::Constant(centre.size(), scale)) {}
  OffsetPrior(const Eigen::VectorXd& centre, const Eigen::VectorXd& scale) : centre_(centre), scale_(scale) {
    set_num_residuals(static_cast<int>(centre.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(centre.size()));
  }
  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const int n = num_residuals();
    for (int i = 0; i < n; ++i) residuals[i] = scale_[i] * (p[0][i] - centre_[i]);
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + n * n, 0.0);
      for (int i = 0; i < n; ++i) jacobians[0][i * n + i] = scale_[i];
    }
    return true;
  }

 private:
  Eigen::VectorXd centre_;
  Eigen::VectorXd scale_;
};

ceres::Problem::Options ProblemOptions() {
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  po.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  // Every block is added once per problem; skip Ceres' duplicate checks.
  po.disable_all_safety_checks = true;
  return po;
}

void BoundWeights(ceres::Problem* problem, double* beta, int E) {
  for (int b = 0; b < E; ++b) {
    problem->SetParameterLowerBound(beta, b, 0.0);
    problem->SetParameterUpperBound(beta, b, 1.0);
  }
}

}  // namespace

LandmarkRigFitter::LandmarkRigFitter(const FaceRig& rig, const CameraIntrinsics& intrinsics,
                                     const LandmarkFitOptions& options)
    : rig_(rig), intrinsics_(intrinsics), options_(options) {
  options_.Check();
  intrinsics_.Validate("LandmarkRigFitter: camera intrinsics");
  Require(rig.num_expressions() > 0, "LandmarkRigFitter: the rig has no expression blendshapes");
  const int V = rig.num_vertices(), I = rig.num_identity(), E = rig.num_expressions();
  Require(rig.expression_basis.rows() == 3 * V && (I == 0 || rig.identity_basis.rows() == 3 * V),
          "LandmarkRigFitter: the rig's bases do not have 3·#V rows");
  vertex_.resize(kNumLandmarks);
  neutral_.resize(3, kNumLandmarks);
  expr_rows_.resize(kNumLandmarks);
  identity_rows_.resize(kNumLandmarks);
  for (int i = 0; i < kNumLandmarks; ++i) {
    const std::string name = fmt::format("ibug_{}", i + 1);
    const int l = rig.LandmarkIndex(name);
    Require(l >= 0, fmt::format("LandmarkRigFitter: the rig has no landmark '{}' (the 68 iBUG landmarks "
                                "ibug_1 … ibug_68 are required; it has {} landmarks)",
                                name, rig.landmarks.size()));
    const int v = rig.landmarks[l].vertex;
    Require(v >= 0 && v < V, fmt::format("LandmarkRigFitter: landmark '{}' has vertex {} outside the rig", name, v));
    vertex_[i] = v;
    neutral_.col(i) = rig.neutral.V.row(v).transpose();
    expr_rows_[i] = rig.expression_basis.middleRows(3 * v, 3).cast<double>();
    identity_rows_[i] = I > 0 ? Eigen::MatrixXd(rig.identity_basis.middleRows(3 * v, 3).cast<double>())
                              : Eigen::MatrixXd(3, 0);
  }
  identity_ = Eigen::VectorXd::Zero(I);
  identity_fixed_ = options_.identity_frames == 0 || I == 0;
  previous_.expression = Eigen::VectorXd::Zero(E);
  UpdateBase();
}

void LandmarkRigFitter::UpdateBase() {
  base_ = neutral_;
  if (identity_.size() == 0) return;
  for (int i = 0; i < kNumLandmarks; ++i) base_.col(i) += identity_rows_[i] * identity_;
}

void LandmarkRigFitter::Reset() {
  has_previous_ = false;
  if (!identity_fixed_) {
    phase_.clear();
    identity_.setZero();
    UpdateBase();
  }
}

void LandmarkRigFitter::SetIdentity(const Eigen::VectorXd& identity) {
  const int I = rig_.num_identity();
  Require(identity.size() <= I, fmt::format("LandmarkRigFitter::SetIdentity: {} coefficients for a rig with {} "
                                            "identity modes",
                                            identity.size(), I));
  Require(identity.allFinite(), "LandmarkRigFitter::SetIdentity: non-finite coefficients");
  identity_ = Eigen::VectorXd::Zero(I);
  identity_.head(identity.size()) = identity;
  identity_fixed_ = true;
  phase_.clear();
  UpdateBase();
}

std::vector<LandmarkRigFitter::PointTerm> LandmarkRigFitter::MakeTerms(const MatX2d& landmarks,
                                                                       const std::vector<double>& weights) const {
  const char* what = "LandmarkRigFitter::Fit";
  Require(landmarks.rows() == kNumLandmarks,
          fmt::format("{}: expected {} landmarks (iBUG 68 layout), got {}", what, kNumLandmarks, landmarks.rows()));
  for (int i = 0; i < kNumLandmarks; ++i) {
    Require(landmarks.row(i).allFinite(),
            fmt::format("{}: landmark {} (iBUG {}) is not finite ({}, {})", what, i, i + 1, landmarks(i, 0),
                        landmarks(i, 1)));
  }
  Require(weights.empty() || static_cast<int>(weights.size()) == kNumLandmarks,
          fmt::format("{}: expected {} point weights or none, got {}", what, kNumLandmarks, weights.size()));
  for (size_t i = 0; i < weights.size(); ++i) {
    Require(std::isfinite(weights[i]) && weights[i] >= 0.0,
            fmt::format("{}: point weight {} is {} (must be finite and >= 0)", what, i, weights[i]));
  }
  std::vector<PointTerm> terms;
  terms.reserve(kNumLandmarks);
  for (int i = 0; i < kNumLandmarks; ++i) {
    const double confidence = weights.empty() ? 1.0 : weights[i];
    const bool contour = i < kNumContourLandmarks;
    const double w = confidence * (contour ? options_.contour_weight : 1.0);
    if (!(w > 0.0)) continue;
    PointTerm term;
    term.index = i;
    term.target = landmarks.row(i).transpose();
    term.weight = w;
    term.loss_scale = std::sqrt(w) * options_.landmark_robust_loss_px;
    term.M = Eigen::Matrix2d::Identity();
    if (contour) {
      // Tangent of the detected outline at l_i from its neighbours (one-sided at the ends).
      const int prev = std::max(i - 1, 0), next = std::min(i + 1, kNumContourLandmarks - 1);
      const Eigen::Vector2d d = landmarks.row(next) - landmarks.row(prev);
      if (d.norm() > 1e-9) {
        const Eigen::Vector2d tangent = d.normalized(), normal(-tangent.y(), tangent.x());
        term.M.row(0) = normal.transpose();
        term.M.row(1) = options_.contour_tangent_weight * tangent.transpose();
      }
    }
    term.W = std::sqrt(w) * term.M;
    if (contour) term.M.row(1).setZero();  // rms_px measures the distance across the outline
    terms.push_back(term);
  }
  Require(static_cast<int>(terms.size()) >= kMinPoints,
          fmt::format("{}: only {} landmarks have a positive weight (at least {} are needed)", what, terms.size(),
                      kMinPoints));
  return terms;
}

// Closed-form initial pose: a weighted affine camera fitted to the rig's landmark
// positions (current identity, neutral expression) and the landmarks in normalised
// image coordinates, projected to the nearest scaled rotation (weak perspective);
// depth from the scale, x/y from the centroids.
Rigid3d LandmarkRigFitter::InitialPose(const std::vector<PointTerm>& terms) const {
  double wsum = 0.0;
  Eigen::Vector3d X_mean = Eigen::Vector3d::Zero();
  Eigen::Vector2d u_mean = Eigen::Vector2d::Zero();
  std::vector<Eigen::Vector2d> u(terms.size());
  for (size_t k = 0; k < terms.size(); ++k) {
    const PointTerm& term = terms[k];
    u[k] = Eigen::Vector2d((term.target.x() - intrinsics_.cx) / intrinsics_.fx,
                           (term.target.y() - intrinsics_.cy) / intrinsics_.fy);
    wsum += term.weight;
    X_mean += term.weight * base_.col(term.index);
    u_mean += term.weight * u[k];
  }
  X_mean /= wsum;
  u_mean /= wsum;
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  Eigen::Matrix<double, 2, 3> D = Eigen::Matrix<double, 2, 3>::Zero();
  for (size_t k = 0; k < terms.size(); ++k) {
    const Eigen::Vector3d Xc = base_.col(terms[k].index) - X_mean;
    C += terms[k].weight * Xc * Xc.transpose();
    D += terms[k].weight * (u[k] - u_mean) * Xc.transpose();
  }
  const Eigen::Matrix<double, 2, 3> M = C.ldlt().solve(D.transpose()).transpose();
  const Eigen::JacobiSVD<Eigen::Matrix<double, 2, 3>> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const double s = 0.5 * (svd.singularValues()[0] + svd.singularValues()[1]);
  const Eigen::Matrix<double, 2, 3> rows = svd.matrixU() * svd.matrixV().leftCols<2>().transpose();
  Eigen::Matrix3d R;
  R.row(0) = rows.row(0);
  R.row(1) = rows.row(1);
  R.row(2) = rows.row(0).cross(rows.row(1));
  const double depth = 1.0 / s;  // of the landmarks' centroid
  const Eigen::Vector3d t(u_mean.x() * depth - R.row(0).dot(X_mean), u_mean.y() * depth - R.row(1).dot(X_mean),
                          depth - R.row(2).dot(X_mean));
  Require(s > 0.0 && std::isfinite(s) && R.allFinite() && t.allFinite(),
          "LandmarkRigFitter::Fit: the closed-form initial pose failed (degenerate landmarks?)");
  return Rigid3d(Eigen::Quaterniond(R), t);
}

namespace {

// y = [β, ω = 0, t]: a frame's parameter block, ω about R_ref = the start rotation.
Eigen::VectorXd PackFrame(const Eigen::VectorXd& expression, const Eigen::Vector3d& translation) {
  const Eigen::Index E = expression.size();
  Eigen::VectorXd y = Eigen::VectorXd::Zero(E + 6);
  y.head(E) = expression.cwiseMax(0.0).cwiseMin(1.0);
  y.tail<3>() = translation;
  return y;
}

void UnpackFrame(const Eigen::VectorXd& y, const Eigen::Matrix3d& R_ref, Eigen::VectorXd* expression,
                 Rigid3d* cam_from_head) {
  const Eigen::Index E = y.size() - 6;
  *expression = y.head(E).cwiseMax(0.0).cwiseMin(1.0);
  *cam_from_head = Rigid3d(Eigen::Quaterniond(ExpSO3(y.segment<3>(E)) * R_ref), y.tail<3>());
}

}  // namespace

LandmarkFrameFit LandmarkRigFitter::SolveFrame(const std::vector<PointTerm>& terms,
                                               const Eigen::VectorXd& expression0, const Rigid3d& pose0,
                                               bool initialise) const {
  const int E = rig_.num_expressions(), n = E + 6;
  Eigen::VectorXd y = PackFrame(expression0, pose0.translation);
  const Eigen::Matrix3d R_ref = pose0.rotation.toRotationMatrix();

  ceres::Problem problem(ProblemOptions());
  for (const PointTerm& term : terms) {
    problem.AddResidualBlock(new LandmarkCost(base_.col(term.index), expr_rows_[term.index], nullptr, intrinsics_,
                                              R_ref, term.target, term.W),
                             new ceres::HuberLoss(term.loss_scale), y.data());
  }
  if (options_.fit_expression_prior_weight > 0.0) {
    Eigen::VectorXd scale = Eigen::VectorXd::Zero(n);
    scale.head(E).setConstant(std::sqrt(options_.fit_expression_prior_weight));
    problem.AddResidualBlock(new OffsetPrior(Eigen::VectorXd::Zero(n), scale), nullptr, y.data());
  }
  // Temporal prior against the previous frame's fit (not at re-initialisation).
  if (has_previous_ && !initialise) {
    Eigen::VectorXd centre(n), scale(n);
    centre.head(E) = previous_.expression;
    // exp([ω]×) R_ref = R^{t−1}  ⇔  ω = log(R^{t−1} R_refᵀ) (0 when warm-started from t − 1).
    centre.segment<3>(E) = LogSO3(previous_.cam_from_head.rotation.toRotationMatrix() * R_ref.transpose());
    centre.tail<3>() = previous_.cam_from_head.translation;
    scale.head(E).setConstant(std::sqrt(options_.fit_temporal_expression_weight));
    scale.segment<3>(E).setConstant(std::sqrt(options_.fit_temporal_rotation_weight));
    scale.segment<2>(E + 3).setConstant(std::sqrt(options_.fit_temporal_translation_weight));
    scale[E + 5] = std::sqrt(options_.fit_temporal_depth_weight);
    if (scale.maxCoeff() > 0.0) problem.AddResidualBlock(new OffsetPrior(centre, scale), nullptr, y.data());
  }
  BoundWeights(&problem, y.data(), E);

  ceres::Solver::Options so;
  so.linear_solver_type =
      options_.fit_linear_solver == FitLinearSolver::kDenseQr ? ceres::DENSE_QR : ceres::DENSE_NORMAL_CHOLESKY;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.max_num_iterations = initialise ? options_.fit_initial_max_iterations : options_.fit_max_iterations;
  // (Re)initialisation is rare and starts far from the optimum: solve it 100× tighter.
  so.function_tolerance = options_.fit_function_tolerance * (initialise ? 0.01 : 1.0);
  // With bounds on β, Ceres follows each projected trust-region step by a line search
  // that evaluates the Jacobian several times per iteration; without it, steps are
  // simply projected onto the box: measured 3.5 → 1.8 ms per tracked frame, same fits.
  so.max_num_line_search_step_size_iterations = 0;
  ceres::Solver::Summary summary;
  if (initialise) {
    // Pose first (weak-perspective start, expression held), then everything.
    std::vector<int> held(E);
    for (int b = 0; b < E; ++b) held[b] = b;
    problem.SetManifold(y.data(), new ceres::SubsetManifold(n, held));
    ceres::Solve(so, &problem, &summary);
    problem.SetManifold(y.data(), nullptr);
  }
  ceres::Solve(so, &problem, &summary);

  LandmarkFrameFit fit;
  if (!summary.IsSolutionUsable() || !y.allFinite()) {
    fit.expression = expression0.cwiseMax(0.0).cwiseMin(1.0);
    fit.cam_from_head = pose0;
    fit.converged = false;
  } else {
    UnpackFrame(y, R_ref, &fit.expression, &fit.cam_from_head);
    fit.converged = summary.termination_type == ceres::CONVERGENCE;
  }
  fit.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  return fit;
}

// The identity phase's joint batch fit: α shared by the phase's frames, y^j = (β^j,
// ω^j, t^j) per frame (each warm-started from its stored fit), identity prior λ_α ‖α‖².
void LandmarkRigFitter::SolveIdentityBatch() {
  const int I = rig_.num_identity(), E = rig_.num_expressions(), n = E + 6;
  if (I == 0 || phase_.empty()) return;
  std::vector<Eigen::VectorXd> y(phase_.size());
  std::vector<Eigen::Matrix3d> R_ref(phase_.size());
  Eigen::VectorXd alpha = identity_;
  ceres::Problem problem(ProblemOptions());
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (size_t j = 0; j < phase_.size(); ++j) {
    y[j] = PackFrame(phase_[j].expression, phase_[j].cam_from_head.translation);
    R_ref[j] = phase_[j].cam_from_head.rotation.toRotationMatrix();
    for (const PointTerm& term : phase_[j].terms) {
      problem.AddResidualBlock(new LandmarkCost(neutral_.col(term.index), expr_rows_[term.index],
                                                &identity_rows_[term.index], intrinsics_, R_ref[j], term.target,
                                                term.W),
                               new ceres::HuberLoss(term.loss_scale), y[j].data(), alpha.data());
    }
    if (options_.fit_expression_prior_weight > 0.0) {
      Eigen::VectorXd scale = Eigen::VectorXd::Zero(n);
      scale.head(E).setConstant(std::sqrt(options_.fit_expression_prior_weight));
      problem.AddResidualBlock(new OffsetPrior(Eigen::VectorXd::Zero(n), scale), nullptr, y[j].data());
    }
    BoundWeights(&problem, y[j].data(), E);
    ordering->AddElementToGroup(y[j].data(), 0);
  }
  if (options_.fit_identity_prior_weight > 0.0) {
    problem.AddResidualBlock(new OffsetPrior(Eigen::VectorXd::Zero(I), std::sqrt(options_.fit_identity_prior_weight)),
                             nullptr, alpha.data());
  }
  ordering->AddElementToGroup(alpha.data(), 1);
  ceres::Solver::Options so;
  // Sparse normal equations were the fastest here (1.5–2× faster than DENSE_SCHUR,
  // SPARSE_SCHUR or ITERATIVE_SCHUR with the frames eliminated first; bench).
  if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ||
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE)) {
    so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  } else {
    so.linear_solver_type = ceres::DENSE_SCHUR;
    so.linear_solver_ordering = std::move(ordering);
  }
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.max_num_iterations = options_.identity_fit_iterations;
  so.function_tolerance = options_.fit_function_tolerance;
  so.max_num_line_search_step_size_iterations = 0;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable() || !alpha.allFinite()) return;  // keep the previous estimate
  identity_ = alpha;
  UpdateBase();
  for (size_t j = 0; j < phase_.size(); ++j) UnpackFrame(y[j], R_ref[j], &phase_[j].expression, &phase_[j].cam_from_head);
}

double LandmarkRigFitter::RmsPx(const std::vector<PointTerm>& terms, const LandmarkFrameFit& fit) const {
  const Camera camera(intrinsics_, fit.cam_from_head);
  double se = 0.0;
  for (const PointTerm& term : terms) {
    const Eigen::Vector3d x = base_.col(term.index) + expr_rows_[term.index] * fit.expression;
    se += (term.M * (camera.Project(x) - term.target)).squaredNorm();
  }
  return std::sqrt(se / static_cast<double>(terms.size()));
}

LandmarkFrameFit LandmarkRigFitter::Fit(const MatX2d& landmarks, const std::vector<double>& point_weights) {
  const std::vector<PointTerm> terms = MakeTerms(landmarks, point_weights);
  const bool initialise = !has_previous_;
  const Rigid3d pose0 = initialise ? InitialPose(terms) : previous_.cam_from_head;
  const Eigen::VectorXd beta0 =
      initialise ? Eigen::VectorXd(Eigen::VectorXd::Zero(rig_.num_expressions())) : previous_.expression;
  LandmarkFrameFit fit = SolveFrame(terms, beta0, pose0, initialise);
  if (!identity_fixed_) {
    // Identity phase: re-estimate α over the phase's frames, refit this frame with it.
    phase_.push_back({terms, fit.expression, fit.cam_from_head});
    const int n = static_cast<int>(phase_.size());
    if (n % options_.identity_fit_interval == 0 || n >= options_.identity_frames) {
      SolveIdentityBatch();
      const int iterations = fit.iterations;
      fit = SolveFrame(terms, phase_.back().expression, phase_.back().cam_from_head, false);
      fit.iterations += iterations;
    }
    if (n >= options_.identity_frames) {
      identity_fixed_ = true;
      phase_.clear();
      phase_.shrink_to_fit();
    }
  }
  fit.rms_px = RmsPx(terms, fit);
  previous_ = fit;
  has_previous_ = true;
  return fit;
}

MatX3d LandmarkRigFitter::HeadVertices(const LandmarkFrameFit& fit) const {
  return rig_.EvaluatePositions(identity_, fit.expression);
}

MatX2d LandmarkRigFitter::ProjectLandmarks(const LandmarkFrameFit& fit) const {
  Require(fit.expression.size() == rig_.num_expressions(),
          fmt::format("LandmarkRigFitter::ProjectLandmarks: {} expression weights for a rig with {}",
                      fit.expression.size(), rig_.num_expressions()));
  const Camera camera(intrinsics_, fit.cam_from_head);
  MatX2d out(kNumLandmarks, 2);
  for (int i = 0; i < kNumLandmarks; ++i) {
    const Eigen::Vector3d x = base_.col(i) + expr_rows_[i] * fit.expression;
    out.row(i) = camera.Project(x).transpose();
  }
  return out;
}

GroundTruthPriorFitter::GroundTruthPriorFitter(const FaceRig& rig, const CameraIntrinsics& intrinsics,
                                               const LandmarkFitOptions& fit_options,
                                               const GroundTruthPriorOptions& options)
    : fitter_(rig, intrinsics, fit_options), options_(options), rng_(options.gt_prior_noise_seed) {
  options_.Check();
}

LandmarkFrameFit GroundTruthPriorFitter::Fit(const MatX2d& projections) {
  const int n = LandmarkRigFitter::kNumLandmarks;
  const int V = fitter_.rig().num_vertices();
  Require(projections.rows() == n || projections.rows() == V,
          fmt::format("GroundTruthPriorFitter::Fit: expected the projections of all {} rig vertices or of the {} "
                      "landmarks, got {} rows",
                      V, n, projections.rows()));
  last_landmarks_.resize(n, 2);
  std::vector<double> weights(n, 1.0);
  for (int i = 0; i < n; ++i) {
    const int row = projections.rows() == n ? i : fitter_.landmark_vertex(i);
    // Draw the noise for every point, visible or not, so the noise of a frame does
    // not depend on which points are missing.
    // y, then x: one draw per statement (argument order is unspecified; GCC's kept).
    const double dy = rng_.Normal(0.0, options_.gt_prior_noise_px);
    const Eigen::Vector2d noise(rng_.Normal(0.0, options_.gt_prior_noise_px), dy);
    if (projections.row(row).allFinite()) {
      last_landmarks_.row(i) = projections.row(row) + noise.transpose();
    } else {
      last_landmarks_.row(i).setZero();
      weights[i] = 0.0;
    }
  }
  return fitter_.Fit(last_landmarks_, weights);
}

}  // namespace crease
