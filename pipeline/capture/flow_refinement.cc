#include "pipeline/capture/flow_refinement.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <queue>
#include <set>
#include <unordered_map>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>
#include <opencv2/video/tracking.hpp>

#include "core/error.h"
#include "core/stats.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "pipeline/capture/rig_point_residual.h"

namespace crease {

void FlowRefinementOptions::VisitFields(OptionVisitor& v) {
  v.Field("lk_window", lk_window);
  v.Field("lk_pyramid_levels", lk_pyramid_levels);
  v.Field("lk_max_iterations", lk_max_iterations);
  v.Field("lk_epsilon_px", lk_epsilon_px);
  v.Field("lk_min_eigenvalue", lk_min_eigenvalue);
  v.Field("lk_predict_from_tracker", lk_predict_from_tracker);
  v.Field("flow_pull_adaptive", flow_pull_adaptive);
  v.Field("flow_tracker_pull", flow_tracker_pull);
  v.Field("flow_step_sigma_px", flow_step_sigma_px);
  v.Field("flow_step_sigma_ratio", flow_step_sigma_ratio);
  v.Field("flow_noise_rate", flow_noise_rate);
  v.Field("flow_gate_chi2", flow_gate_chi2);
  v.Field("flow_reference_frame", flow_reference_frame);
  v.Field("flow_reference_max_px", flow_reference_max_px);
  v.Field("flow_reference_gain", flow_reference_gain);
  v.Field("outlier_intensity", outlier_intensity);
  v.Field("outlier_distance_px", outlier_distance_px);
  v.Field("flow_point_spacing_mm", flow_point_spacing_mm);
  v.Field("front_facing_min_cos", front_facing_min_cos);
  v.Field("mls_neighbours", mls_neighbours);
  v.Field("mls_radius_mm", mls_radius_mm);
  v.Field("mls_alpha", mls_alpha);
  v.Field("mls_min_neighbours", mls_min_neighbours);
  v.Field("fit_flow_weight", fit_flow_weight);
  v.Field("fit_landmark_weight", fit_landmark_weight);
  v.Field("expression_prior_weight", fit_expression_prior_weight);
  v.Field("fit_tracker_prior_weight", fit_tracker_prior_weight);
  v.Field("fit_iterations", fit_iterations);
  v.Field("fit_hessian_refresh", fit_hessian_refresh);
  v.Field("laplacian", laplacian);
  v.Field("laplacian_order", laplacian_order);
  v.Field("laplacian_smoothness", laplacian_smoothness);
  v.Field("laplacian_flow_weight", laplacian_flow_weight);
  v.Field("laplacian_landmark_weight", laplacian_landmark_weight);
}

void FlowRefinementOptions::Check() const {
  const char* o = "FlowRefinementOptions";
  CheckGe(o, "lk_window", lk_window, 5);
  if (lk_window % 2 != 1) throw Error(fmt::format("{}.lk_window = {} must be odd", o, lk_window));
  CheckGe(o, "lk_pyramid_levels", lk_pyramid_levels, 1);
  CheckLe(o, "lk_pyramid_levels", lk_pyramid_levels, 8);
  CheckGe(o, "lk_max_iterations", lk_max_iterations, 1);
  CheckGt(o, "lk_epsilon_px", lk_epsilon_px, 0.0);
  CheckGe(o, "lk_min_eigenvalue", lk_min_eigenvalue, 0.0);
  CheckGe(o, "flow_tracker_pull", flow_tracker_pull, 0.0);
  CheckLe(o, "flow_tracker_pull", flow_tracker_pull, 1.0);
  CheckGt(o, "flow_step_sigma_px", flow_step_sigma_px, 0.0);
  CheckGe(o, "flow_step_sigma_ratio", flow_step_sigma_ratio, 0.0);
  CheckGt(o, "flow_noise_rate", flow_noise_rate, 0.0);
  CheckLe(o, "flow_noise_rate", flow_noise_rate, 1.0);
  CheckGe(o, "flow_gate_chi2", flow_gate_chi2, 0.0);
  CheckGt(o, "flow_reference_max_px", flow_reference_max_px, 0.0);
  CheckGt(o, "flow_reference_gain", flow_reference_gain, 0.0);
  CheckLe(o, "flow_reference_gain", flow_reference_gain, 1.0);
  CheckGt(o, "outlier_intensity", outlier_intensity, 0.0);
  CheckGt(o, "outlier_distance_px", outlier_distance_px, 0.0);
  CheckGt(o, "flow_point_spacing_mm", flow_point_spacing_mm, 0.5);
  CheckGe(o, "front_facing_min_cos", front_facing_min_cos, -1.0);
  CheckLt(o, "front_facing_min_cos", front_facing_min_cos, 1.0);
  CheckGe(o, "mls_neighbours", mls_neighbours, 1);
  CheckGt(o, "mls_radius_mm", mls_radius_mm, 0.0);
  CheckGe(o, "mls_alpha", mls_alpha, 0.0);
  CheckGe(o, "mls_min_neighbours", mls_min_neighbours, 1);
  CheckLe(o, "mls_min_neighbours", mls_min_neighbours, mls_neighbours);
  CheckGe(o, "fit_flow_weight", fit_flow_weight, 0.0);
  CheckGe(o, "fit_landmark_weight", fit_landmark_weight, 0.0);
  CheckGe(o, "refine_expression_prior_weight", fit_expression_prior_weight, 0.0);
  CheckGe(o, "fit_tracker_prior_weight", fit_tracker_prior_weight, 0.0);
  CheckGe(o, "fit_iterations", fit_iterations, 0);
  CheckGe(o, "fit_hessian_refresh", fit_hessian_refresh, 1);
  CheckGe(o, "laplacian_order", laplacian_order, 1);
  CheckLe(o, "laplacian_order", laplacian_order, 2);
  CheckGt(o, "laplacian_smoothness", laplacian_smoothness, 0.0);
  CheckGe(o, "laplacian_flow_weight", laplacian_flow_weight, 0.0);
  CheckGe(o, "laplacian_landmark_weight", laplacian_landmark_weight, 0.0);
}

const char* ToString(FlowPointStatus status) {
  switch (status) {
    case FlowPointStatus::kInvisible:
      return "invisible";
    case FlowPointStatus::kTrusted:
      return "trusted";
    case FlowPointStatus::kRecovered:
      return "recovered";
    case FlowPointStatus::kReset:
      return "reset";
  }
  return "unknown";
}

// Affine MLS, Schaefer et al. 2006 Eq. 3–5 in row-vector form:
//   f(v) = (v − p*) (Σ_j p̂_jᵀ w_j p̂_j)⁻¹ Σ_j w_j p̂_jᵀ q̂_j + q*.
bool MlsAffine(const Eigen::Vector2d& v, const MatX2d& p, const MatX2d& q, const Eigen::VectorXd& w,
               Eigen::Vector2d* out) {
  const Eigen::Index n = p.rows();
  if (!(q.rows() == n && w.size() == n))
    throw Error(fmt::format("MlsAffine: {} points, {} images and {} weights (must be equal)", n, q.rows(), w.size()));
  double sw = 0.0;
  Eigen::Vector2d ps = Eigen::Vector2d::Zero(), qs = Eigen::Vector2d::Zero();
  for (Eigen::Index j = 0; j < n; ++j) {
    sw += w[j];
    ps += w[j] * p.row(j).transpose();
    qs += w[j] * q.row(j).transpose();
  }
  if (!(sw > 0.0) || !std::isfinite(sw)) return false;
  ps /= sw;
  qs /= sw;
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero(), B = Eigen::Matrix2d::Zero();
  for (Eigen::Index j = 0; j < n; ++j) {
    const Eigen::Vector2d ph = p.row(j).transpose() - ps, qh = q.row(j).transpose() - qs;
    A += w[j] * ph * ph.transpose();
    B += w[j] * ph * qh.transpose();
  }
  const double tr = A.trace();
  // Near-collinear (or single) control points: the affine part is undetermined.
  if (n < 3 || !(A.determinant() > 1e-3 * 0.25 * tr * tr)) {
    *out = v - ps + qs;
    return true;
  }
  *out = qs + B.transpose() * A.inverse() * (v - ps);
  return true;
}

RecoverCounts RecoverFlowOutliers(const FlowRefinementOptions& options, const FlowNeighbours& neighbours,
                                  const MatX2d& projected, MatX2d* flow, std::vector<FlowPointStatus>* status) {
  const int n = static_cast<int>(projected.rows());
  Require(flow != nullptr && status != nullptr, "RecoverFlowOutliers: null output");
  if (!(flow->rows() == n && static_cast<int>(status->size()) == n && neighbours.size() == n))
    throw Error(
        fmt::format("RecoverFlowOutliers: {} projected points, {} flow points, {} statuses and {} neighbour lists "
                    "(must be equal)",
                    n, flow->rows(), status->size(), neighbours.size()));
  if (n == 0) return {};
  if (neighbours.begin[0] != 0 || neighbours.begin[n] != static_cast<int>(neighbours.index.size()) ||
      neighbours.distance_mm.size() != neighbours.index.size() ||
      !std::is_sorted(neighbours.begin.begin(), neighbours.begin.end()))
    throw Error("RecoverFlowOutliers: malformed neighbour lists (begin must rise from 0 to the number of neighbours, "
                "one distance per neighbour)");
  const double xi_beta = options.outlier_distance_px;
  int distance_outliers = 0;
  // ξ_β on the points that passed LK and ξ_α; points without a projection take no part.
  for (int i = 0; i < n; ++i) {
    if (!projected.row(i).allFinite()) (*status)[i] = FlowPointStatus::kInvisible;
    if ((*status)[i] != FlowPointStatus::kTrusted) continue;
    if (!flow->row(i).allFinite() || (flow->row(i) - projected.row(i)).norm() > xi_beta) {
      (*status)[i] = FlowPointStatus::kReset;
      ++distance_outliers;
    }
  }
  // Recover the outliers from the trusted points only (not from each other).
  const std::vector<FlowPointStatus> in = *status;
  RecoverCounts counts;
  counts.distance_outliers = distance_outliers;
  MatX2d p, q;
  Eigen::VectorXd w;
  for (int i = 0; i < n; ++i) {
    if (in[i] == FlowPointStatus::kInvisible) {
      ++counts.invisible;
      continue;
    }
    if (in[i] == FlowPointStatus::kTrusted) {
      ++counts.trusted;
      continue;
    }
    const int b = neighbours.begin[i], e = neighbours.begin[i + 1];
    p.resize(e - b, 2);
    q.resize(e - b, 2);
    w.resize(e - b);
    int m = 0;
    for (int k = b; k < e; ++k) {
      const int j = neighbours.index[k];
      if (j < 0 || j >= n || in[j] != FlowPointStatus::kTrusted) continue;
      p.row(m) = projected.row(j);
      q.row(m) = flow->row(j);
      w[m] = 1.0 / std::pow(std::max(neighbours.distance_mm[k], 1e-6), 2.0 * options.mls_alpha);
      ++m;
    }
    Eigen::Vector2d r;
    const Eigen::Vector2d u = projected.row(i).transpose();
    if (m >= options.mls_min_neighbours && MlsAffine(u, p.topRows(m), q.topRows(m), w.head(m), &r) && r.allFinite() &&
        (r - u).norm() <= xi_beta) {
      flow->row(i) = r.transpose();
      (*status)[i] = FlowPointStatus::kRecovered;
      ++counts.recovered;
    } else {
      flow->row(i) = u.transpose();
      (*status)[i] = FlowPointStatus::kReset;
      ++counts.reset;
    }
  }
  return counts;
}

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Bilinear sample of an 8-bit single-channel image, coordinates clamped to the image.
double Bilinear8(const cv::Mat& image, double x, double y) {
  x = std::clamp(x, 0.0, image.cols - 1.0);
  y = std::clamp(y, 0.0, image.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), image.cols - 2 < 0 ? 0 : image.cols - 2);
  const int y0 = std::min(static_cast<int>(y), image.rows - 2 < 0 ? 0 : image.rows - 2);
  const int x1 = std::min(x0 + 1, image.cols - 1), y1 = std::min(y0 + 1, image.rows - 1);
  const double fx = x - x0, fy = y - y0;
  const uint8_t* r0 = image.ptr<uint8_t>(y0);
  const uint8_t* r1 = image.ptr<uint8_t>(y1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
}

// ξ_α's measure: the gray change, in [0, 1], between a point at `a` in `image_a` and
// at (bx, by) in `image_b` (8-bit images).
double IntensityChange(const cv::Mat& image_a, const cv::Point2f& a, const cv::Mat& image_b, double bx, double by) {
  return std::abs(Bilinear8(image_a, a.x, a.y) - Bilinear8(image_b, bx, by)) / 255.0;
}

// The frame's pyramid for Eq. 5's Lucas–Kanade (kept as the next frame's previous
// pyramid). Returns the time it took, ms.
double BuildFlowPyramid(const FlowRefinementOptions& o, const cv::Mat& gray8, std::vector<cv::Mat>* pyramid) {
  const auto tp = Clock::now();
  cv::buildOpticalFlowPyramid(gray8, *pyramid, cv::Size(o.lk_window, o.lk_window), o.lk_pyramid_levels - 1, true,
                              cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT, false);
  return MsSince(tp);
}

// Which of the mesh's triangles are face chart triangles. FaceChartTriangles returns a
// subset of the rig's triangles; they are matched by their sorted corners, so the
// corner order does not matter.
std::vector<uint8_t> MarkChartTriangles(const TriMesh& mesh, const MatX3i& chart_F) {
  auto key = [](int a, int b, int c) {
    std::array<int, 3> k = {a, b, c};
    std::sort(k.begin(), k.end());
    return k;
  };
  std::set<std::array<int, 3>> chart_set;
  for (int f = 0; f < chart_F.rows(); ++f) chart_set.insert(key(chart_F(f, 0), chart_F(f, 1), chart_F(f, 2)));
  std::vector<uint8_t> is_chart_tri(mesh.num_faces(), 0);
  for (int f = 0; f < mesh.num_faces(); ++f)
    is_chart_tri[f] = chart_set.count(key(mesh.F(f, 0), mesh.F(f, 1), mesh.F(f, 2))) > 0;
  return is_chart_tri;
}

// The point counts of ξ_β and the MLS recovery, into the frame's record.
void RecordCounts(const RecoverCounts& counts, RefinedFrame* out) {
  out->trusted = counts.trusted;
  out->recovered = counts.recovered;
  out->reset = counts.reset;
  out->invisible = counts.invisible;
  out->distance_outliers = counts.distance_outliers;
}

}  // namespace

std::vector<uint8_t> TrackLucasKanade(const FlowRefinementOptions& o, cv::InputArray previous, cv::InputArray next,
                                      const std::vector<cv::Point2f>& from, std::vector<cv::Point2f>* to,
                                      bool use_initial) {
  std::vector<uint8_t> status;
  std::vector<float> error;
  cv::calcOpticalFlowPyrLK(
      previous, next, from, *to, status, error, cv::Size(o.lk_window, o.lk_window), o.lk_pyramid_levels - 1,
      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, o.lk_max_iterations, o.lk_epsilon_px),
      use_initial ? cv::OPTFLOW_USE_INITIAL_FLOW : 0, o.lk_min_eigenvalue);
  return status;
}

struct FlowRefiner::Impl {
  const FaceRig& rig;
  CameraIntrinsics K;
  FlowRefinementOptions options;
  int V = 0, E = 0, I = 0;

  // Face chart and the Laplacian system.
  MatX3i chart_F;                 // chart triangles, rig vertex ids
  std::vector<int> chart_vertex;  // chart index → rig vertex
  std::vector<int> free_of;       // chart index → free variable (−1: pinned to the fit)
  int num_free = 0;
  Eigen::SimplicialLDLT<SpMat> solver;
  bool solver_ok = false;

  // Flow points.
  std::vector<int> flow_vertex;
  std::vector<int> flow_free;                  // free variable of each flow point (−1: none)
  std::vector<int> ring_begin, ring_triangle;  // per flow point, incident chart triangles
  FlowNeighbours neighbours;

  // Inner landmarks (iBUG 18–68).
  std::vector<int> landmark_ibug;    // 0-based iBUG index
  std::vector<int> landmark_vertex;  // rig vertex
  std::vector<int> landmark_free;    // free variable (−1: none)

  // Fit points: flow points, then inner landmarks. Rows of the bases (double).
  std::vector<int> fit_vertex;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> fit_B;  // (3·#fit)×E
  Eigen::MatrixXd fit_A;                                                         // (3·#fit)×I
  Eigen::VectorXd fit_n;                                                         // 3·#fit neutral
  Eigen::VectorXd fit_base;                                                      // 3·#fit n + Aα

  // Largest |entry| of each expression blendshape, mm.
  Eigen::VectorXd column_max;
  // All vertices: n + Aα, cached per identity.
  Eigen::VectorXd base_all;
  Eigen::VectorXd cached_identity;
  bool has_identity = false;

  // State across frames.
  bool has_prev = false;
  // The adaptive pull (PullToTracker): the flow chain's error variance P and the two
  // averaged estimates of the tracker's noise variance, px² per coordinate (−1: none yet).
  double chain_variance = -1.0, noise_innovation = -1.0, noise_difference = -1.0;
  std::vector<cv::Mat> prev_pyramid;
  MatX2d prev_refined;    // ũ^{t−1}: projection of L~^{t−1} at the flow points
  MatX2d prev_projected;  // u^{t−1}
  MatX2d prev2_projected, prev3_projected;  // u^{t−2}, u^{t−3} (NaN where unknown)
  // The reference frame of flow_reference_frame: the chain's first frame.
  std::vector<cv::Mat> reference_pyramid;
  MatX2d reference_positions;  // u at that frame (NaN: not visible then)
  std::vector<uint8_t> prev_visible;

  Impl(const FaceRig& r, const CameraIntrinsics& k, const FlowRefinementOptions& o) : rig(r), K(k), options(o) {}

  void Build();
  // The steps of Build, in order (see Build).
  // The face chart (chart_F, chart_vertex) and its free variables (free_of, num_free);
  // vertices on its seam with the rest of the head are pinned. Returns each rig
  // vertex's chart index (−1: not on the chart).
  std::vector<int> BuildChart();
  // The inner landmarks (iBUG 18–68): their rig vertices and free variables.
  void FindInnerLandmarks(const std::vector<int>& chart_of);
  // The flow points: a greedy Poisson-disk sample of the free chart vertices on the
  // neutral face, inner landmarks first; at least 3.
  void SampleFlowPoints(const std::vector<int>& chart_of);
  // Each flow point's free variable and incident chart triangles (for its normal).
  // Returns each rig vertex's flow point (−1: none).
  std::vector<int> IndexFlowPoints(const std::vector<int>& chart_of);
  // The chart's edges and their lengths on the neutral face, per chart vertex.
  std::vector<std::vector<std::pair<int, double>>> ChartEdges(const std::vector<int>& chart_of) const;
  // Geodesic neighbours of each flow point (ξ_β and the MLS recovery): bounded edge
  // Dijkstra on the chart of the neutral face.
  void FindNeighbours(const std::vector<int>& chart_of, const std::vector<int>& flow_of);
  // Fit points (flow points, then inner landmarks) and their basis rows; the
  // per-identity caches at α = 0.
  void BuildFitBases();
  // The chart as a mesh of its own (neutral face, chart indices).
  TriMesh ChartMesh(const std::vector<int>& chart_of) const;
  // The Laplacian system A = λ Lfᵀ M⁻¹ Lf + W (+ ε I), factorised once.
  void FactorLaplacian(const std::vector<int>& chart_of);
  void SetIdentity(const Eigen::VectorXd& identity);
  // out += Σ_b coeff_b B_b over the non-zero coefficients (all vertices, head frame).
  void AddExpressions(const Eigen::VectorXd& coeff, Eigen::VectorXd* out) const;
  MatX3d ToCamera(const Eigen::VectorXd& head, const Rigid3d& pose) const;
  // Projections of the flow points of `camera_vertices` (#V×3), px; NaN behind the camera.
  MatX2d Project(const MatX3d& camera_vertices) const;
  // Sec. 7's suggestion (flow_reference_frame): re-tracks the trusted points from the
  // chain's first frame, starting at their chained positions, and moves each chained
  // position flow_reference_gain of the way to the result where it passes ξ_α against
  // the reference and stays within flow_reference_max_px of the chain
  // (out->reference_tracked counts them). At a
  // chain's first frame it stores that frame as the reference.
  void TrackFromReference(const std::vector<cv::Mat>& pyramid, const MatX2d& u, const std::vector<uint8_t>& vis,
                          MatX2d* flow, const std::vector<FlowPointStatus>& status, RefinedFrame* out);
  // Moves the trusted flow points κ of the way to u^t (Differences 10); updates the
  // innovation statistics; records κ and σ_r in `out`.
  void PullToTracker(const MatX2d& u, MatX2d* flow, std::vector<FlowPointStatus>* status, RefinedFrame* out);
  LandmarkFrameFit SolveFit(const std::vector<int>& points, const std::vector<Eigen::Vector2d>& targets,
                            const std::vector<double>& weights, const Eigen::VectorXd& beta_tracker,
                            const Rigid3d& pose0) const;

  // The steps of Refine, in order (see Refine).
  // Input checks that need no tracked fit (the frame, the mask, α); throw Error.
  void CheckFrame(const cv::Mat& gray8, const Eigen::VectorXd& identity, const std::vector<uint8_t>& visible) const;
  // Input checks of a tracked frame (β, pose, landmarks); throw Error.
  void CheckTracked(const TrackedFrame& tracked) const;
  // Sec. 5.1 step 1: L^t (out->coarse_vertices; `head` keeps its head-frame vertices
  // for F), u^t = P(v^t) at the flow points and which of them take part (`vis`, 0/1).
  void EvaluateCoarse(const Eigen::VectorXd& identity, const LandmarkFrameFit& tf,
                      const std::vector<uint8_t>& visible, Eigen::VectorXd* head, MatX2d* u,
                      std::vector<uint8_t>* vis, RefinedFrame* out);
  // Whether flow point i of L^t (camera frame) takes part in the flow: half an LK
  // window inside the image, visible in the caller's mask, facing the camera.
  bool FlowPointUsable(int i, const MatX3d& coarse, const MatX2d& u, const std::vector<uint8_t>& visible) const;
  // Sec. 5.1 step 2: ũ^t and the status of each flow point before ξ_β: Eq. 5 and ξ_α
  // from the previous frame, then Sec. 7's reference frame (flow_reference_frame) and
  // the pull to the tracker (Differences 10). `flow` holds u^t on entry.
  std::vector<FlowPointStatus> TrackFlow(const std::vector<cv::Mat>& pyramid, const MatX2d& u,
                                         const std::vector<uint8_t>& vis, MatX2d* flow, RefinedFrame* out);
  // Eq. 5 from ũ^{t−1} and the intensity test ξ_α: a point that passes both becomes
  // kTrusted at its LK position; one failing ξ_α keeps kReset at its LK position, one
  // that LK lost keeps kReset at u^t.
  void TrackFromPrevious(const std::vector<cv::Mat>& pyramid, const MatX2d& u, const std::vector<uint8_t>& vis,
                         MatX2d* flow, std::vector<FlowPointStatus>* status, RefinedFrame* out) const;
  // Sec. 5.1 step 4 (Cao et al. 2014's post-processing): the 3D fit to the trusted and
  // recovered flow positions and the visible inner landmarks.
  LandmarkFrameFit FitToFlow(const MatX2d& flow, const std::vector<FlowPointStatus>& status,
                             const TrackedFrame& tracked, const std::vector<uint8_t>& visible,
                             bool use_landmarks) const;
  // Sec. 5.1 step 5 (Li et al. 2013): the fitted mesh F = out->vertices (evaluated
  // from `head` at out->fit) plus the Laplacian displacement d on the face chart.
  // Returns the time spent evaluating F, which overlaps the solves (ms).
  double FitAndDeform(const MatX2d& flow, const std::vector<FlowPointStatus>& status, const TrackedFrame& tracked,
                      const std::vector<uint8_t>& visible, bool use_landmarks, Eigen::VectorXd* head,
                      RefinedFrame* out) const;
  // The right-hand sides (camera x, y) of the Laplacian system: w · (the back-projection
  // of each flow point's and inner landmark's target at F's depth − F).
  void LaplacianTargets(const LandmarkFrameFit& fit, const MatX2d& flow, const std::vector<FlowPointStatus>& status,
                        const TrackedFrame& tracked, const std::vector<uint8_t>& visible, bool use_landmarks,
                        Eigen::VectorXd* bx, Eigen::VectorXd* by) const;
  // State for the next frame: ũ^t of L~^t at the flow points, u^t and its history,
  // the visibility and the frame's pyramid (moved).
  void Remember(const MatX3d& refined, const MatX2d& u, const std::vector<uint8_t>& vis,
                std::vector<cv::Mat>* pyramid);
};

// Sets up everything that does not change per frame (see the header): the face chart
// and its pinned seam, the inner landmarks, the flow points and their geodesic
// neighbours, the fit points' basis rows and the factorised Laplacian system.
void FlowRefiner::Impl::Build() {
  V = rig.num_vertices();
  E = rig.num_expressions();
  I = rig.num_identity();
  const char* what = "FlowRefiner";
  if (E <= 0) throw Error(fmt::format("{}: the rig has no expression blendshapes", what));
  if (!(rig.expression_basis.rows() == 3 * V && (I == 0 || rig.identity_basis.rows() == 3 * V)))
    throw Error(fmt::format("{}: the rig's bases do not have 3·#V = {} rows", what, 3 * V));
  const std::vector<int> chart_of = BuildChart();
  FindInnerLandmarks(chart_of);
  SampleFlowPoints(chart_of);
  const std::vector<int> flow_of = IndexFlowPoints(chart_of);
  FindNeighbours(chart_of, flow_of);
  BuildFitBases();
  if (options.laplacian) FactorLaplacian(chart_of);
}

std::vector<int> FlowRefiner::Impl::BuildChart() {
  const TriMesh& mesh = rig.neutral;
  chart_F = FaceChartTriangles(rig);
  std::vector<int> chart_of(V, -1);
  const std::vector<uint8_t> is_chart_tri = MarkChartTriangles(mesh, chart_F);
  for (int f = 0; f < chart_F.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int v = chart_F(f, c);
      if (chart_of[v] < 0) {
        chart_of[v] = static_cast<int>(chart_vertex.size());
        chart_vertex.push_back(v);
      }
    }
  }
  const int nc = static_cast<int>(chart_vertex.size());
  const std::vector<int> rep = CoincidentVertexRepresentatives(mesh);
  std::vector<uint8_t> outside(V, 0);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    if (is_chart_tri[f]) continue;
    for (int c = 0; c < 3; ++c) outside[rep[mesh.F(f, c)]] = 1;
  }
  free_of.assign(nc, -1);
  for (int c = 0; c < nc; ++c) {
    if (!outside[rep[chart_vertex[c]]]) free_of[c] = num_free++;
  }
  if (num_free <= 0) throw Error("FlowRefiner: every face chart vertex touches the rest of the head");
  return chart_of;
}

void FlowRefiner::Impl::FindInnerLandmarks(const std::vector<int>& chart_of) {
  const char* what = "FlowRefiner";
  for (int i = 17; i < LandmarkRigFitter::kNumLandmarks; ++i) {
    const std::string name = fmt::format("ibug_{}", i + 1);
    const int l = rig.LandmarkIndex(name);
    if (l < 0)
      throw Error(fmt::format("{}: the rig has no landmark '{}' (the 68 iBUG landmarks are required)", what, name));
    const int v = rig.landmarks[l].vertex;
    if (!(v >= 0 && v < V)) throw Error(fmt::format("{}: landmark '{}' has vertex {} outside the rig", what, name, v));
    landmark_ibug.push_back(i);
    landmark_vertex.push_back(v);
    landmark_free.push_back(chart_of[v] >= 0 ? free_of[chart_of[v]] : -1);
  }
}

void FlowRefiner::Impl::SampleFlowPoints(const std::vector<int>& chart_of) {
  const TriMesh& mesh = rig.neutral;
  const double s = options.flow_point_spacing_mm;
  std::unordered_map<int64_t, std::vector<int>> grid;
  auto cell = [&](const Eigen::Vector3d& p, int dx, int dy, int dz) {
    const int64_t x = static_cast<int64_t>(std::floor(p.x() / s)) + dx;
    const int64_t y = static_cast<int64_t>(std::floor(p.y() / s)) + dy;
    const int64_t z = static_cast<int64_t>(std::floor(p.z() / s)) + dz;
    return (x * 73856093) ^ (y * 19349663) ^ (z * 83492791);
  };
  std::vector<uint8_t> taken(V, 0);
  auto try_add = [&](int v) {
    if (taken[v] || chart_of[v] < 0 || free_of[chart_of[v]] < 0) return;
    const Eigen::Vector3d p = mesh.V.row(v).transpose();
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          auto it = grid.find(cell(p, dx, dy, dz));
          if (it == grid.end()) continue;
          for (int u : it->second) {
            if ((mesh.V.row(u).transpose() - p).norm() < s) return;
          }
        }
    grid[cell(p, 0, 0, 0)].push_back(v);
    taken[v] = 1;
    flow_vertex.push_back(v);
  };
  for (int v : landmark_vertex) try_add(v);
  for (int v : chart_vertex) try_add(v);
  const int nf = static_cast<int>(flow_vertex.size());
  if (nf < 3) {
    throw Error(
        fmt::format("FlowRefiner: only {} flow points at a spacing of {} mm", nf, options.flow_point_spacing_mm));
  }
}

std::vector<int> FlowRefiner::Impl::IndexFlowPoints(const std::vector<int>& chart_of) {
  const int nf = static_cast<int>(flow_vertex.size());
  std::vector<int> flow_of(V, -1);
  for (int i = 0; i < nf; ++i) flow_of[flow_vertex[i]] = i;
  flow_free.resize(nf);
  for (int i = 0; i < nf; ++i) flow_free[i] = free_of[chart_of[flow_vertex[i]]];
  // Incident chart triangles of each flow point (for its normal).
  std::vector<std::vector<int>> ring(nf);
  for (int f = 0; f < chart_F.rows(); ++f)
    for (int c = 0; c < 3; ++c)
      if (flow_of[chart_F(f, c)] >= 0) ring[flow_of[chart_F(f, c)]].push_back(f);
  ring_begin.assign(1, 0);
  for (int i = 0; i < nf; ++i) {
    ring_triangle.insert(ring_triangle.end(), ring[i].begin(), ring[i].end());
    ring_begin.push_back(static_cast<int>(ring_triangle.size()));
  }
  return flow_of;
}

std::vector<std::vector<std::pair<int, double>>> FlowRefiner::Impl::ChartEdges(const std::vector<int>& chart_of) const {
  const TriMesh& mesh = rig.neutral;
  std::vector<std::vector<std::pair<int, double>>> adj(chart_vertex.size());
  for (int f = 0; f < chart_F.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int a = chart_of[chart_F(f, c)], b = chart_of[chart_F(f, (c + 1) % 3)];
      const double len = (mesh.V.row(chart_F(f, c)) - mesh.V.row(chart_F(f, (c + 1) % 3))).norm();
      adj[a].emplace_back(b, len);
      adj[b].emplace_back(a, len);
    }
  }
  return adj;
}

void FlowRefiner::Impl::FindNeighbours(const std::vector<int>& chart_of, const std::vector<int>& flow_of) {
  const std::vector<std::vector<std::pair<int, double>>> adj = ChartEdges(chart_of);
  std::vector<double> dist(chart_vertex.size(), std::numeric_limits<double>::infinity());
  std::vector<int> touched;
  using Item = std::pair<double, int>;
  neighbours.begin.assign(1, 0);
  for (int i = 0; i < static_cast<int>(flow_vertex.size()); ++i) {
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
    const int src = chart_of[flow_vertex[i]];
    dist[src] = 0.0;
    touched.push_back(src);
    heap.emplace(0.0, src);
    std::vector<std::pair<double, int>> found;
    while (!heap.empty()) {
      const auto [d, a] = heap.top();
      heap.pop();
      if (d > dist[a]) continue;
      if (d > options.mls_radius_mm) break;
      const int fi = flow_of[chart_vertex[a]];
      if (fi >= 0 && fi != i) {
        found.emplace_back(d, fi);
        if (static_cast<int>(found.size()) >= options.mls_neighbours) break;
      }
      for (const auto& [b, len] : adj[a]) {
        if (d + len < dist[b]) {
          if (!std::isfinite(dist[b])) touched.push_back(b);
          dist[b] = d + len;
          heap.emplace(dist[b], b);
        }
      }
    }
    for (int a : touched) dist[a] = std::numeric_limits<double>::infinity();
    touched.clear();
    for (const auto& [d, j] : found) {
      neighbours.index.push_back(j);
      neighbours.distance_mm.push_back(d);
    }
    neighbours.begin.push_back(static_cast<int>(neighbours.index.size()));
  }
}

void FlowRefiner::Impl::BuildFitBases() {
  const TriMesh& mesh = rig.neutral;
  fit_vertex = flow_vertex;
  fit_vertex.insert(fit_vertex.end(), landmark_vertex.begin(), landmark_vertex.end());
  const int np = static_cast<int>(fit_vertex.size());
  fit_B.resize(3 * np, E);
  fit_A.resize(3 * np, I);
  fit_n.resize(3 * np);
  for (int k = 0; k < np; ++k) {
    const int v = fit_vertex[k];
    fit_B.middleRows(3 * k, 3) = rig.expression_basis.middleRows(3 * v, 3).cast<double>();
    if (I > 0) fit_A.middleRows(3 * k, 3) = rig.identity_basis.middleRows(3 * v, 3).cast<double>();
    fit_n.segment<3>(3 * k) = mesh.V.row(v).transpose();
  }
  fit_base = fit_n;
  column_max = rig.expression_basis.cwiseAbs().colwise().maxCoeff().transpose().cast<double>();
  base_all.resize(3 * V);
  for (int v = 0; v < V; ++v) base_all.segment<3>(3 * v) = mesh.V.row(v).transpose();
  cached_identity = Eigen::VectorXd::Zero(I);
  has_identity = true;
}

TriMesh FlowRefiner::Impl::ChartMesh(const std::vector<int>& chart_of) const {
  const int nc = static_cast<int>(chart_vertex.size());
  TriMesh cm;
  cm.V.resize(nc, 3);
  for (int c = 0; c < nc; ++c) cm.V.row(c) = rig.neutral.V.row(chart_vertex[c]);
  cm.F.resize(chart_F.rows(), 3);
  for (int f = 0; f < chart_F.rows(); ++f)
    for (int c = 0; c < 3; ++c) cm.F(f, c) = chart_of[chart_F(f, c)];
  return cm;
}

void FlowRefiner::Impl::FactorLaplacian(const std::vector<int>& chart_of) {
  const int nc = static_cast<int>(chart_vertex.size());
  const TriMesh cm = ChartMesh(chart_of);
  const SpMat L = CotangentLaplacian(cm);
  const SpMat M = MassMatrix(cm, MassMatrixType::kVoronoi);
  std::vector<Eigen::Triplet<double>> sel;
  for (int c = 0; c < nc; ++c)
    if (free_of[c] >= 0) sel.emplace_back(c, free_of[c], 1.0);
  SpMat S(nc, num_free);
  S.setFromTriplets(sel.begin(), sel.end());
  Eigen::VectorXd minv(nc);
  for (int c = 0; c < nc; ++c) {
    const double m = M.coeff(c, c);
    minv[c] = m > 0.0 ? 1.0 / m : 0.0;
  }
  const SpMat Lf = L * S;
  SpMat A = options.laplacian_order == 2 ? SpMat(Lf.transpose() * minv.asDiagonal() * Lf) : SpMat(S.transpose() * Lf);
  A *= options.laplacian_smoothness;
  Eigen::VectorXd w = Eigen::VectorXd::Zero(num_free);
  for (size_t i = 0; i < flow_free.size(); ++i)
    if (flow_free[i] >= 0) w[flow_free[i]] += options.laplacian_flow_weight;
  for (size_t j = 0; j < landmark_free.size(); ++j)
    if (landmark_free[j] >= 0) w[landmark_free[j]] += options.laplacian_landmark_weight;
  const double eps = 1e-9 * std::max(1.0, A.diagonal().mean());
  for (int f = 0; f < num_free; ++f) A.coeffRef(f, f) += w[f] + eps;
  A.makeCompressed();
  solver.compute(A);
  if (solver.info() != Eigen::Success) throw Error("FlowRefiner: the Laplacian system could not be factorised");
  solver_ok = true;
}

void FlowRefiner::Impl::SetIdentity(const Eigen::VectorXd& identity) {
  Eigen::VectorXd a = Eigen::VectorXd::Zero(I);
  a.head(identity.size()) = identity;
  if (has_identity && a == cached_identity) return;
  cached_identity = a;
  has_identity = true;
  fit_base = fit_n;
  if (I > 0) fit_base += fit_A * a;
  for (int v = 0; v < V; ++v) base_all.segment<3>(3 * v) = rig.neutral.V.row(v).transpose();
  if (I > 0) base_all += (rig.identity_basis * a.cast<float>()).cast<double>();
}

void FlowRefiner::Impl::AddExpressions(const Eigen::VectorXd& coeff, Eigen::VectorXd* out) const {
  // Only the blendshapes in use are read (the basis is 8 MB): those moving some
  // vertex by more than 10⁻⁴ mm.
  std::vector<int> used;
  for (int b = 0; b < E; ++b)
    if (std::abs(coeff[b]) * column_max[b] > 1e-4) used.push_back(b);
  if (used.empty()) return;
  const int rows = 3 * V;
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, 8192), [&](const tbb::blocked_range<int>& r) {
    const int n = static_cast<int>(r.size());
    Eigen::VectorXf acc = Eigen::VectorXf::Zero(n);
    for (int b : used) acc += static_cast<float>(coeff[b]) * rig.expression_basis.col(b).segment(r.begin(), n);
    out->segment(r.begin(), n) += acc.cast<double>();
  });
}

MatX3d FlowRefiner::Impl::ToCamera(const Eigen::VectorXd& head, const Rigid3d& pose) const {
  const Eigen::Matrix3d R = pose.rotation.toRotationMatrix();
  const Eigen::Vector3d& t = pose.translation;
  MatX3d out(V, 3);
  for (int v = 0; v < V; ++v) out.row(v) = (R * head.segment<3>(3 * v) + t).transpose();
  return out;
}

void FlowRefiner::Impl::TrackFromReference(const std::vector<cv::Mat>& pyramid, const MatX2d& u,
                                            const std::vector<uint8_t>& vis, MatX2d* flow,
                                            const std::vector<FlowPointStatus>& status, RefinedFrame* out) {
  const FlowRefinementOptions& o = options;
  if (!has_prev || reference_pyramid.empty()) {  // a chain starts here
    reference_pyramid = pyramid;
    reference_positions = u;
    for (int i = 0; i < u.rows(); ++i)
      if (!vis[i]) reference_positions.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    return;
  }
  std::vector<int> idx;
  std::vector<cv::Point2f> from, to;
  for (size_t i = 0; i < status.size(); ++i) {
    if (status[i] != FlowPointStatus::kTrusted || !reference_positions.row(i).allFinite()) continue;
    idx.push_back(static_cast<int>(i));
    from.emplace_back(static_cast<float>(reference_positions(i, 0)), static_cast<float>(reference_positions(i, 1)));
    to.emplace_back(static_cast<float>((*flow)(i, 0)), static_cast<float>((*flow)(i, 1)));
  }
  if (idx.empty()) return;
  const std::vector<uint8_t> lk_status = TrackLucasKanade(o, reference_pyramid, pyramid, from, &to, true);
  for (size_t k = 0; k < idx.size(); ++k) {
    const int i = idx[k];
    if (!lk_status[k] || !std::isfinite(to[k].x) || !std::isfinite(to[k].y)) continue;
    const Eigen::RowVector2d p(to[k].x, to[k].y);
    if ((p - flow->row(i)).norm() > o.flow_reference_max_px) continue;
    if (p.x() < 0 || p.y() < 0 || p.x() > K.width - 1 || p.y() > K.height - 1) continue;
    if (IntensityChange(reference_pyramid[0], from[k], pyramid[0], p.x(), p.y()) > o.outlier_intensity) continue;
    flow->row(i) += o.flow_reference_gain * (p - flow->row(i));
    ++out->reference_tracked;
  }
}

void FlowRefiner::Impl::PullToTracker(const MatX2d& u, MatX2d* flow, std::vector<FlowPointStatus>* status,
                                      RefinedFrame* out) {
  const FlowRefinementOptions& o = options;
  std::vector<int> trusted;
  for (size_t i = 0; i < status->size(); ++i)
    if ((*status)[i] == FlowPointStatus::kTrusted) trusted.push_back(static_cast<int>(i));
  if (trusted.empty()) return;
  double kappa = o.flow_tracker_pull;
  if (o.flow_pull_adaptive) {
    // Robust (median) statistics over the trusted points: LK's failures (a blurred
    // forehead under fast motion) are not Gaussian. For a 2D Gaussian with variance
    // σ² per coordinate, the median of |x|² is 2 ln 2 · σ².
    const double to_variance = 1.0 / (2.0 * std::log(2.0));
    std::vector<double> innovation, motion, third;
    for (int i : trusted) {
      innovation.push_back((u.row(i) - flow->row(i)).squaredNorm());
      motion.push_back((flow->row(i) - prev_refined.row(i)).squaredNorm());
      const Eigen::RowVector2d d3 =
          u.row(i) - 3.0 * prev_projected.row(i) + 3.0 * prev2_projected.row(i) - prev3_projected.row(i);
      if (d3.allFinite()) third.push_back(d3.squaredNorm());
    }
    // LK's step noise grows with the motion (its bias is a fraction of it).
    const double sigma_q = o.flow_step_sigma_px + o.flow_step_sigma_ratio * std::sqrt(Median(motion) * to_variance);
    const double q = sigma_q * sigma_q;
    const double prior = std::max(chain_variance, 0.0) + q;  // P⁻ of the flow chain
    // The tracker's noise r, bounded twice from above: the innovations (E[ν²] = P⁻ + r;
    // too high when LK failed beyond σ_q) and the tracker's third differences over
    // time (20 r for white noise; the true motion adds its third difference, ~0.2³ of
    // its amplitude for a 1 Hz motion at 30 frames/s, where second differences let in
    // 0.2²: on fast motion they read 0.9 px of noise into a tracker with 0.1 px).
    // Both averaged over frames at flow_noise_rate; r is the smaller.
    auto average = [&](double* state, double value) {
      *state = *state < 0.0 ? value : (1.0 - o.flow_noise_rate) * *state + o.flow_noise_rate * value;
      return *state;
    };
    double r = average(&noise_innovation, std::max(Median(innovation) * to_variance - prior, 0.0));
    if (third.size() >= 3) r = std::min(r, average(&noise_difference, Median(third) * to_variance / 20.0));
    else if (noise_difference >= 0.0) r = std::min(r, noise_difference);
    r = std::max(r, 1e-4);
    kappa = prior / (prior + r);  // the Kalman gain of this frame
    chain_variance = (1.0 - kappa) * prior;
    out->step_sigma_px = sigma_q;
    out->tracker_noise_px = std::sqrt(r);
    // The innovation gate: a point whose innovation is improbable under P⁻ + r is
    // an outlier (recovered by MLS or reset, like the paper's ξ_β outliers).
    if (o.flow_gate_chi2 > 0.0) {
      const double gate = o.flow_gate_chi2 * (prior + r);
      for (size_t k = 0; k < trusted.size(); ++k) {
        if (innovation[k] <= gate) continue;
        (*status)[trusted[k]] = FlowPointStatus::kReset;
        ++out->gate_outliers;
      }
    }
  }
  out->pull = kappa;
  for (int i : trusted) {
    if ((*status)[i] == FlowPointStatus::kTrusted) flow->row(i) += kappa * (u.row(i) - flow->row(i));
  }
}

MatX2d FlowRefiner::Impl::Project(const MatX3d& camera_vertices) const {
  MatX2d out(static_cast<int>(flow_vertex.size()), 2);
  for (int i = 0; i < out.rows(); ++i) {
    const Eigen::Vector3d X = camera_vertices.row(flow_vertex[i]).transpose();
    if (X.z() > 1e-6) {
      out.row(i) << K.fx * X.x() / X.z() + K.cx, K.fy * X.y() / X.z() + K.cy;
    } else {
      out.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
  }
  return out;
}

// The 3D fit: projected Levenberg–Marquardt on y = (β, ω, t), ω a left rotation
// increment re-linearised at every iteration (R ← exp([δω]×) R). Per point k with
// weight w_k and target ũ_k: r_k = √w_k (π(q) − ũ_k), q = R x_k(β) + t, x_k = base_k + B_k β;
//   ∂r/∂β = √w J_π R B_k,  ∂r/∂ω = −√w J_π [R x_k]×,  ∂r/∂t = √w J_π
// (the residual and Jacobians shared with the landmark fit: rig_point_residual.h).
LandmarkFrameFit FlowRefiner::Impl::SolveFit(const std::vector<int>& points,
                                             const std::vector<Eigen::Vector2d>& targets,
                                             const std::vector<double>& weights, const Eigen::VectorXd& beta_tracker,
                                             const Rigid3d& pose0) const {
  const int n = E + 6;
  const int m = static_cast<int>(points.size());
  const double lb = options.fit_expression_prior_weight, lt = options.fit_tracker_prior_weight;
  Eigen::VectorXd beta = beta_tracker.cwiseMax(0.0).cwiseMin(1.0);
  Eigen::Matrix3d R = pose0.rotation.toRotationMatrix();
  Eigen::Vector3d t = pose0.translation;

  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> J(2 * m, n);
  Eigen::VectorXd r(2 * m);
  // Residuals (and Jacobian) at (β, R, t); returns the energy. One point's
  // projection and Jacobians: rig_point_residual.h, weighted by M = √w_k I.
  auto evaluate = [&](const Eigen::VectorXd& b, const Eigen::Matrix3d& Rm, const Eigen::Vector3d& tv, bool jacobian) {
    double cost = 0.0;
    RigPointProjection proj;
    for (int k = 0; k < m; ++k) {
      const RigPointBasis B = fit_B.middleRows<3>(3 * points[k]);
      const double sw = std::sqrt(weights[k]);
      const Eigen::Matrix2d M = sw * Eigen::Matrix2d::Identity();
      if (!ProjectRigPoint(RigPointInHead(fit_base.segment<3>(3 * points[k]), B, b), Rm, tv, K,
                           jacobian ? &M : nullptr, &proj)) {
        r.segment<2>(2 * k).setZero();
        if (jacobian) J.middleRows(2 * k, 2).setZero();
        continue;
      }
      r.segment<2>(2 * k) = sw * (proj.pixel - targets[k]);
      cost += r.segment<2>(2 * k).squaredNorm();
      if (!jacobian) continue;
      RigPointExpressionJacobian(proj.d_head, B, J.block(2 * k, 0, 2, E));
      J.block<2, 3>(2 * k, E) = proj.d_rotation;
      J.block<2, 3>(2 * k, E + 3) = proj.d_cam;
    }
    cost += lb * b.squaredNorm() + lt * (b - beta_tracker).squaredNorm();
    return cost;
  };

  LandmarkFrameFit fit;
  double cost = evaluate(beta, R, t, true);
  double mu = 1e-3;
  int iterations = 0;
  bool converged = options.fit_iterations == 0;
  bool need_jacobian = false;
  Eigen::MatrixXd H(n, n);
  Eigen::VectorXd g(n);
  int outer = 0;
  while (iterations < options.fit_iterations && m > 0) {
    if (need_jacobian) cost = evaluate(beta, R, t, true);
    need_jacobian = false;
    // JᵀJ is the costly part (2·#points × (#E + 6)²); between refreshes the step
    // uses the last one with the current gradient (a chord Newton step; the
    // problem is close to linear near the tracker's warm start).
    if (outer++ % options.fit_hessian_refresh == 0) {
      H.setZero();
      H.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
      H.triangularView<Eigen::StrictlyUpper>() = H.transpose();
      for (int e = 0; e < E; ++e) H(e, e) += lb + lt;
    }
    g.noalias() = J.transpose() * r;
    for (int e = 0; e < E; ++e) g[e] += lb * beta[e] + lt * (beta[e] - beta_tracker[e]);
    // Active bounds: weights at a bound whose gradient pushes outwards stay there.
    std::vector<uint8_t> active(E, 0);
    for (int e = 0; e < E; ++e) active[e] = (beta[e] <= 0.0 && g[e] > 0.0) || (beta[e] >= 1.0 && g[e] < 0.0);
    bool accepted = false;
    while (!accepted && iterations < options.fit_iterations) {
      ++iterations;
      Eigen::MatrixXd A = H;
      Eigen::VectorXd rhs = -g;
      for (int j = 0; j < n; ++j) A(j, j) += mu * std::max(H(j, j), 1e-9);
      for (int e = 0; e < E; ++e) {
        if (!active[e]) continue;
        A.row(e).setZero();
        A.col(e).setZero();
        A(e, e) = 1.0;
        rhs[e] = 0.0;
      }
      const Eigen::VectorXd step = A.ldlt().solve(rhs);
      if (!step.allFinite()) break;
      const Eigen::VectorXd beta_new = (beta + step.head(E)).cwiseMax(0.0).cwiseMin(1.0);
      const Eigen::Matrix3d R_new = ExpSO3(step.segment<3>(E)) * R;
      const Eigen::Vector3d t_new = t + step.tail<3>();
      const double cost_new = evaluate(beta_new, R_new, t_new, false);
      if (cost_new < cost) {
        const double decrease = (cost - cost_new) / std::max(cost, 1e-12);
        beta = beta_new;
        R = R_new;
        t = t_new;
        cost = cost_new;
        mu = std::max(mu / 3.0, 1e-7);
        accepted = true;
        need_jacobian = true;
        if (decrease < 1e-6) converged = true;
      } else {
        mu *= 4.0;
        if (mu > 1e8) break;
      }
    }
    if (!accepted || converged) break;
  }
  fit.expression = beta;
  fit.cam_from_head = Rigid3d(Eigen::Quaterniond(R), t);
  fit.iterations = iterations;
  fit.converged = converged;
  // RMS of the unweighted 2D distances at the solution.
  double se = 0.0;
  int count = 0;
  RigPointProjection proj;
  for (int k = 0; k < m; ++k) {
    const int p = points[k];
    const Eigen::Vector3d x = RigPointInHead(fit_base.segment<3>(3 * p), fit_B.middleRows<3>(3 * p), beta);
    if (!ProjectRigPoint(x, R, t, K, nullptr, &proj)) continue;
    se += (proj.pixel - targets[k]).squaredNorm();
    ++count;
  }
  fit.rms_px = count > 0 ? std::sqrt(se / count) : 0.0;
  return fit;
}

FlowRefiner::FlowRefiner(const FaceRig& rig, const CameraIntrinsics& intrinsics, const FlowRefinementOptions& options)
    : options_(options) {
  options_.Check();
  intrinsics.Validate("FlowRefiner: camera intrinsics");
  impl_ = std::make_unique<Impl>(rig, intrinsics, options_);
  impl_->Build();
}

FlowRefiner::~FlowRefiner() = default;
FlowRefiner::FlowRefiner(FlowRefiner&&) noexcept = default;
FlowRefiner& FlowRefiner::operator=(FlowRefiner&&) noexcept = default;

const std::vector<int>& FlowRefiner::flow_vertices() const { return impl_->flow_vertex; }
const FlowNeighbours& FlowRefiner::neighbours() const { return impl_->neighbours; }
int FlowRefiner::num_chart_vertices() const { return static_cast<int>(impl_->chart_vertex.size()); }

void FlowRefiner::Reset() {
  impl_->has_prev = false;
  impl_->reference_pyramid.clear();
  impl_->chain_variance = -1.0;  // the next chain starts at u^t
  impl_->prev_pyramid.clear();
}

void FlowRefiner::Impl::CheckFrame(const cv::Mat& gray8, const Eigen::VectorXd& identity,
                                   const std::vector<uint8_t>& visible) const {
  const char* what = "FlowRefiner::Refine";
  if (gray8.empty()) throw Error(fmt::format("{}: the frame is empty", what));
  if (gray8.type() != CV_8UC1)
    throw Error(fmt::format("{}: the frame must be 8-bit gray (CV_8UC1), got type {} with {} channels", what,
                            gray8.type(), gray8.channels()));
  if (!(gray8.cols == K.width && gray8.rows == K.height))
    throw Error(fmt::format("{}: the frame is {}×{} but the camera intrinsics are {}×{}", what, gray8.cols, gray8.rows,
                            K.width, K.height));
  if (!(visible.empty() || static_cast<int>(visible.size()) == V))
    throw Error(fmt::format("{}: the visibility mask has {} entries, expected one per rig vertex ({}) or none", what,
                            visible.size(), V));
  if (identity.size() > I)
    throw Error(
        fmt::format("{}: {} identity coefficients for a rig with {} identity modes", what, identity.size(), I));
  if (!identity.allFinite()) throw Error(fmt::format("{}: the identity coefficients are not finite", what));
}

void FlowRefiner::Impl::CheckTracked(const TrackedFrame& tracked) const {
  const char* what = "FlowRefiner::Refine";
  const LandmarkFrameFit& tf = tracked.fit;
  if (tf.expression.size() != E)
    throw Error(
        fmt::format("{}: the tracked fit has {} expression weights for a rig with {}", what, tf.expression.size(), E));
  if (!tf.expression.allFinite())
    throw Error(fmt::format("{}: the tracked fit's expression weights are not finite", what));
  if (!(tf.cam_from_head.translation.allFinite() && tf.cam_from_head.rotation.coeffs().allFinite() &&
        tf.cam_from_head.rotation.norm() > 0.5))
    throw Error(fmt::format("{}: the tracked fit's pose (cam_from_head) is not finite", what));
  if (!(tracked.landmarks.rows() == 0 || tracked.landmarks.rows() == LandmarkRigFitter::kNumLandmarks))
    throw Error(fmt::format("{}: the tracked frame has {} landmarks, expected {} or none", what,
                            tracked.landmarks.rows(), LandmarkRigFitter::kNumLandmarks));
  for (int i = 0; i < tracked.landmarks.rows(); ++i) {
    if (!tracked.landmarks.row(i).allFinite())
      throw Error(fmt::format("{}: tracked landmark {} (iBUG {}) is not finite ({}, {})", what, i, i + 1,
                              tracked.landmarks(i, 0), tracked.landmarks(i, 1)));
  }
}

void FlowRefiner::Impl::EvaluateCoarse(const Eigen::VectorXd& identity, const LandmarkFrameFit& tf,
                                       const std::vector<uint8_t>& visible, Eigen::VectorXd* head, MatX2d* u,
                                       std::vector<uint8_t>* vis, RefinedFrame* out) {
  const auto te = Clock::now();
  SetIdentity(identity);
  *head = base_all;
  AddExpressions(tf.expression, head);
  out->coarse_vertices = ToCamera(*head, tf.cam_from_head);
  *u = Project(out->coarse_vertices);
  vis->assign(u->rows(), 0);
  for (int i = 0; i < u->rows(); ++i) {
    if (!u->row(i).allFinite()) continue;  // behind the camera
    (*vis)[i] = FlowPointUsable(i, out->coarse_vertices, *u, visible);
  }
  out->projected_positions = *u;
  out->evaluate_ms = MsSince(te);
}

bool FlowRefiner::Impl::FlowPointUsable(int i, const MatX3d& coarse, const MatX2d& u,
                                        const std::vector<uint8_t>& visible) const {
  const int half = options.lk_window / 2;
  const int v = flow_vertex[i];
  const Eigen::Vector3d X = coarse.row(v).transpose();
  bool ok = u(i, 0) >= half && u(i, 1) >= half && u(i, 0) <= K.width - 1 - half && u(i, 1) <= K.height - 1 - half;
  if (ok && !visible.empty()) ok = visible[v] != 0;
  if (ok) {  // grazing windows track badly, with or without a mask
    Eigen::Vector3d nrm = Eigen::Vector3d::Zero();
    for (int k = ring_begin[i]; k < ring_begin[i + 1]; ++k) {
      const int f = ring_triangle[k];
      const Eigen::Vector3d p0 = coarse.row(chart_F(f, 0)).transpose();
      nrm += (coarse.row(chart_F(f, 1)).transpose() - p0).cross(coarse.row(chart_F(f, 2)).transpose() - p0);
    }
    ok = nrm.dot(-X) >= options.front_facing_min_cos * nrm.norm() * X.norm() && nrm.norm() > 0.0;
  }
  return ok;
}

std::vector<FlowPointStatus> FlowRefiner::Impl::TrackFlow(const std::vector<cv::Mat>& pyramid, const MatX2d& u,
                                                          const std::vector<uint8_t>& vis, MatX2d* flow,
                                                          RefinedFrame* out) {
  std::vector<FlowPointStatus> status(vis.size(), FlowPointStatus::kInvisible);
  for (size_t i = 0; i < vis.size(); ++i)
    if (vis[i]) status[i] = FlowPointStatus::kReset;  // no flow yet (first frame: stays so)
  if (has_prev) TrackFromPrevious(pyramid, u, vis, flow, &status, out);
  if (options.flow_reference_frame) TrackFromReference(pyramid, u, vis, flow, status, out);
  PullToTracker(u, flow, &status, out);
  return status;
}

void FlowRefiner::Impl::TrackFromPrevious(const std::vector<cv::Mat>& pyramid, const MatX2d& u,
                                          const std::vector<uint8_t>& vis, MatX2d* flow,
                                          std::vector<FlowPointStatus>* status, RefinedFrame* out) const {
  const FlowRefinementOptions& o = options;
  std::vector<int> idx;
  std::vector<cv::Point2f> from, to;
  for (int i = 0; i < static_cast<int>(vis.size()); ++i) {
    if (!vis[i] || !prev_visible[i] || !prev_refined.row(i).allFinite()) continue;
    idx.push_back(i);
    from.emplace_back(static_cast<float>(prev_refined(i, 0)), static_cast<float>(prev_refined(i, 1)));
    Eigen::Vector2d start = prev_refined.row(i).transpose();
    if (o.lk_predict_from_tracker && prev_projected.row(i).allFinite())
      start += (u.row(i) - prev_projected.row(i)).transpose();
    to.emplace_back(static_cast<float>(start.x()), static_cast<float>(start.y()));
  }
  out->no_source = static_cast<int>(std::count(vis.begin(), vis.end(), 1)) - static_cast<int>(idx.size());
  if (idx.empty()) return;
  const std::vector<uint8_t> lk_status =
      TrackLucasKanade(o, prev_pyramid, pyramid, from, &to, o.lk_predict_from_tracker);
  for (size_t k = 0; k < idx.size(); ++k) {
    const int i = idx[k];
    const double x = to[k].x, y = to[k].y;
    if (!lk_status[k] || !std::isfinite(x) || !std::isfinite(y) || x < 0 || y < 0 || x > K.width - 1 ||
        y > K.height - 1) {
      ++out->lk_failures;
      continue;  // outlier (kReset)
    }
    (*flow)(i, 0) = x;
    (*flow)(i, 1) = y;
    if (IntensityChange(prev_pyramid[0], from[k], pyramid[0], x, y) > o.outlier_intensity) {
      ++out->intensity_outliers;
      continue;  // outlier (ξ_α)
    }
    (*status)[i] = FlowPointStatus::kTrusted;
  }
}

LandmarkFrameFit FlowRefiner::Impl::FitToFlow(const MatX2d& flow, const std::vector<FlowPointStatus>& status,
                                              const TrackedFrame& tracked, const std::vector<uint8_t>& visible,
                                              bool use_landmarks) const {
  const FlowRefinementOptions& o = options;
  const int nf = static_cast<int>(flow_vertex.size());
  std::vector<int> points;
  std::vector<Eigen::Vector2d> targets;
  std::vector<double> weights;
  if (o.fit_flow_weight > 0.0) {
    for (int i = 0; i < nf; ++i) {
      if (status[i] != FlowPointStatus::kTrusted && status[i] != FlowPointStatus::kRecovered) continue;
      points.push_back(i);
      targets.push_back(flow.row(i).transpose());
      weights.push_back(o.fit_flow_weight);
    }
  }
  if (use_landmarks && o.fit_landmark_weight > 0.0) {
    for (size_t j = 0; j < landmark_ibug.size(); ++j) {
      if (!visible.empty() && !visible[landmark_vertex[j]]) continue;
      points.push_back(nf + static_cast<int>(j));
      targets.push_back(tracked.landmarks.row(landmark_ibug[j]).transpose());
      weights.push_back(o.fit_landmark_weight);
    }
  }
  return SolveFit(points, targets, weights, tracked.fit.expression, tracked.fit.cam_from_head);
}

double FlowRefiner::Impl::FitAndDeform(const MatX2d& flow, const std::vector<FlowPointStatus>& status,
                                       const TrackedFrame& tracked, const std::vector<uint8_t>& visible,
                                       bool use_landmarks, Eigen::VectorXd* head, RefinedFrame* out) const {
  // The right-hand side needs F only at the fit points (from their basis rows), so
  // the solves run in parallel with the evaluation of all of F.
  const bool deform = options.laplacian && solver_ok;
  Eigen::VectorXd bx, by, dx, dy;
  if (deform) LaplacianTargets(out->fit, flow, status, tracked, visible, use_landmarks, &bx, &by);
  double evaluate_ms = 0.0;
  tbb::parallel_invoke(
      [&] {
        if (deform) dx = solver.solve(bx);
      },
      [&] {
        if (deform) dy = solver.solve(by);
      },
      [&] {
        const auto te = Clock::now();
        AddExpressions(out->fit.expression - tracked.fit.expression, head);
        out->vertices = ToCamera(*head, out->fit.cam_from_head);
        out->fit_positions = Project(out->vertices);
        evaluate_ms = MsSince(te);
      });
  if (deform) {  // L~ = F + d
    MatX3d& F = out->vertices;
    const int nc = static_cast<int>(chart_vertex.size());
    for (int c = 0; c < nc; ++c) {
      const int f = free_of[c];
      if (f < 0) continue;
      F(chart_vertex[c], 0) += dx[f];
      F(chart_vertex[c], 1) += dy[f];
    }
  }
  return evaluate_ms;
}

void FlowRefiner::Impl::LaplacianTargets(const LandmarkFrameFit& fit, const MatX2d& flow,
                                         const std::vector<FlowPointStatus>& status, const TrackedFrame& tracked,
                                         const std::vector<uint8_t>& visible, bool use_landmarks,
                                         Eigen::VectorXd* bx, Eigen::VectorXd* by) const {
  const int nf = static_cast<int>(flow_vertex.size());
  *bx = Eigen::VectorXd::Zero(num_free);
  *by = Eigen::VectorXd::Zero(num_free);
  const Eigen::Matrix3d R = fit.cam_from_head.rotation.toRotationMatrix();
  // w · (back-projection of the target at the fitted depth − fitted), camera x, y.
  auto add = [&](int k, int f, const Eigen::Vector2d& target, double w) {
    const Eigen::Vector3d x = RigPointInHead(fit_base.segment<3>(3 * k), fit_B.middleRows<3>(3 * k), fit.expression);
    const Eigen::Vector3d X = R * x + fit.cam_from_head.translation;
    if (!(X.z() > 1e-6) || !target.allFinite()) return;
    (*bx)[f] += w * ((target.x() - K.cx) * X.z() / K.fx - X.x());
    (*by)[f] += w * ((target.y() - K.cy) * X.z() / K.fy - X.y());
  };
  for (int i = 0; i < nf; ++i) {
    if (flow_free[i] < 0) continue;
    if (status[i] == FlowPointStatus::kTrusted || status[i] == FlowPointStatus::kRecovered)
      add(i, flow_free[i], flow.row(i).transpose(), options.laplacian_flow_weight);
  }
  if (!use_landmarks) return;
  for (size_t j = 0; j < landmark_ibug.size(); ++j) {
    if (landmark_free[j] < 0) continue;
    if (!visible.empty() && !visible[landmark_vertex[j]]) continue;
    add(nf + static_cast<int>(j), landmark_free[j], tracked.landmarks.row(landmark_ibug[j]).transpose(),
        options.laplacian_landmark_weight);
  }
}

void FlowRefiner::Impl::Remember(const MatX3d& refined, const MatX2d& u, const std::vector<uint8_t>& vis,
                                 std::vector<cv::Mat>* pyramid) {
  prev_refined = Project(refined);
  const MatX2d unknown = MatX2d::Constant(u.rows(), 2, std::numeric_limits<double>::quiet_NaN());
  const bool chained = has_prev && prev_projected.rows() == u.rows();
  prev3_projected = chained && prev2_projected.rows() == u.rows() ? prev2_projected : unknown;
  prev2_projected = chained ? prev_projected : unknown;
  prev_projected = u;
  prev_visible = vis;
  prev_pyramid = std::move(*pyramid);
  has_prev = true;
}

// Sec. 5.1 per frame: L^t and u^t (step 1), Eq. 5 and ξ_α (2), ξ_β and MLS (3),
// the 3D fit (4), the Laplacian deformation (5); see the header.
RefinedFrame FlowRefiner::Refine(const cv::Mat& gray8, const TrackedFrame& tracked, const Eigen::VectorXd& identity,
                                 const std::vector<uint8_t>& visible) {
  const auto t_start = Clock::now();
  Impl& s = *impl_;
  const FlowRefinementOptions& o = options_;
  s.CheckFrame(gray8, identity, visible);  // before any state changes
  if (!tracked.tracked) {
    Reset();
    RefinedFrame none;
    none.total_ms = MsSince(t_start);
    return none;
  }
  s.CheckTracked(tracked);
  const bool use_landmarks = tracked.landmarks.rows() == LandmarkRigFitter::kNumLandmarks;
  RefinedFrame out;
  out.refined = true;
  out.flow_vertex = s.flow_vertex;

  // --- Step 1: L^t and the flow points' projections u^t, in parallel with the frame's pyramid.
  std::vector<cv::Mat> pyramid;
  double pyramid_ms = 0.0;
  Eigen::VectorXd head;
  MatX2d u;
  std::vector<uint8_t> vis;
  tbb::parallel_invoke([&] { pyramid_ms = BuildFlowPyramid(o, gray8, &pyramid); },
                       [&] { s.EvaluateCoarse(identity, tracked.fit, visible, &head, &u, &vis, &out); });

  // --- Step 2: Lucas–Kanade from ũ^{t−1} (Eq. 5) and ξ_α.
  auto t0 = Clock::now();
  MatX2d flow = u;
  std::vector<FlowPointStatus> status = s.TrackFlow(pyramid, u, vis, &flow, &out);
  out.flow_ms = pyramid_ms + MsSince(t0);

  // --- Step 3: ξ_β and MLS recovery.
  t0 = Clock::now();
  const RecoverCounts counts = RecoverFlowOutliers(o, s.neighbours, u, &flow, &status);
  RecordCounts(counts, &out);
  out.mls_ms = MsSince(t0);
  out.flow_positions = flow;
  out.status = status;
  if (counts.trusted + counts.recovered == 0) {
    // No point measured by flow (the first frame, or after a loss): L~^t = L^t. A fit
    // to the landmarks alone would re-solve the tracker's problem under other weights
    // and priors, and every later frame's flow would start from its error.
    out.fit = tracked.fit;
    out.vertices = out.coarse_vertices;
    out.fit_positions = u;
  } else {
    // --- Step 4: 3D fit with the refined 2D positions and the tracker's landmarks.
    t0 = Clock::now();
    out.fit = s.FitToFlow(flow, status, tracked, visible, use_landmarks);
    out.fit_ms = MsSince(t0);
    // --- Step 5: fitted mesh F and the Laplacian deformation L~ = F + d (F's evaluation
    // overlaps the solves; it is counted in evaluate_ms).
    t0 = Clock::now();
    const double evaluate_f_ms = s.FitAndDeform(flow, status, tracked, visible, use_landmarks, &head, &out);
    out.evaluate_ms += evaluate_f_ms;
    out.laplacian_ms = std::max(0.0, MsSince(t0) - evaluate_f_ms);
  }
  s.Remember(out.vertices, u, vis, &pyramid);
  out.total_ms = MsSince(t_start);
  return out;
}

}  // namespace crease
