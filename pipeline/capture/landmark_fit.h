// Per-frame fit of the blendshape rig to 2D landmarks — the rig fit of the global
// face tracker (issue 5, part 2 "Rig fit"; paper Sec. 5: "We start by tracking the
// low-resolution face mesh using the global face tracker", DDE, Cao et al. 2014),
// and the experimental control "ground-truth-prior" (issue 5, part 4).
//
// Per frame t, with the identity α fixed, the fitter minimises over the expression
// weights β ∈ [0, 1]^#E and the pose cam_from_head = (R, t):
//
//   E(β, R, t) = Σ_i ρ_i(‖W_i (π(R x_i(α, β) + t) − l_i)‖²)      landmark term, px²
//              + λ_β ‖β‖²                                        expression prior
//              + λ_Δβ ‖β − β^{t−1}‖² + λ_ω ‖log(R^{t−1} Rᵀ)‖²    temporal prior
//              + λ_τ ‖(t − t^{t−1})_xy‖² + λ_z (t − t^{t−1})_z²   (not after a Reset)
//
//   x_i(α, β) = n_i + A_i α + B_i β   the rig's landmark vertex i in the head frame (mm);
//             A_i, B_i its three rows of the identity and expression bases
//   π         the camera's pinhole projection (core/camera.h), l_i the landmark (px)
//   W_i       √c_i · I for inner points (iBUG 18–68), with c_i the per-point
//             confidence; for the jaw contour (iBUG 1–17) √(c_i·w_c) · [n_iᵀ; s·τ_iᵀ],
//             n_i / τ_i the normal / tangent of the detected outline at l_i,
//             w_c = contour_weight, s = contour_tangent_weight (see below)
//   ρ_i       Huber loss with scale landmark_robust_loss_px (in px, before W_i)
//
// Solve (fast path, one Ceres problem per frame): R is parametrised as
// exp([ω]×) · R_ref with ω ∈ R³ (an angle-axis increment, radians) about the warm
// start R_ref (the previous frame's rotation), t ∈ R³ (mm); β has Ceres box bounds
// [0, 1]. Jacobians are analytic: one rig point's projection and Jacobians from
// rig_point_residual.h (shared with flow refinement's 3D fit), with the 68 landmark
// vertices' precomputed basis rows (3×#E, 3×#I each) and the left Jacobian of SO(3)
// for ω; Levenberg–
// Marquardt with dense normal equations, a few iterations from the previous frame
// (~0.9 ms per frame on one core at 68 points and 49 expressions,
// bench/landmark_fit_bench.cc). The first frame, and the first after Reset(), starts
// from a closed-form pose: a weak-perspective (affine) fit of the rig's neutral
// landmarks to the landmarks, projected to a scaled rotation; then a pose-only solve,
// then the full solve.
//
// Jaw contour (iBUG 1–17, 0-based 0–16): a detector places these points on the
// visible face outline, where they slide along the outline as the head turns or the
// jaw moves, while the rig's contour landmarks are fixed vertices. We use sliding
// (point-to-outline) correspondences with a lower weight: the residual's component
// along the detected outline (tangent τ_i, from the neighbouring contour points) is
// scaled by contour_tangent_weight (0 = free sliding, 1 = an ordinary point), the
// component across it (normal n_i) is kept; both carry contour_weight.
//
// Identity: during the first identity_frames frames (after construction, or after a
// Reset() while the identity is not yet fixed) every frame is fitted as above with
// the current α; every identity_fit_interval frames of the phase and at its last
// frame, α is re-estimated by a joint batch fit over all frames of the phase so far
// (α shared; β^j, R^j, t^j per frame, warm-started; the landmark terms and expression
// prior above plus λ_α ‖α‖², identity coefficients in units of their standard
// deviation; no temporal terms), and the frame is refitted with the new α. After
// identity_frames frames α is fixed. The batch costs ~0.6 ms per frame and iteration:
// the default phase (20 frames, batches at 5, 10, 15, 20 with 5 iterations) takes
// ~0.2 s in all on one core, its last frame ~60 ms. Identity modes that barely move
// the 68 landmarks (e.g. the back of the head) stay near 0 under the prior.
//
// Weights are in px² (the landmark term is a sum of squared pixel residuals): the
// defaults suit faces ~150–250 px wide (a 640×480 camera at ~0.5 m); scale them with
// the square of the face's size in pixels.
//
// Differences from the paper:
//   1. The paper's global tracker is DDE (Cao et al. 2014), which regresses the rig's
//      parameters (and 2D displacements) directly from the image with a trained
//      regressor. We instead fit the rig to 2D landmarks from a landmark source
//      (pipeline/capture/landmarks.h); DDE's parameter regression is not reproduced.
//   2. DDE estimates the identity (and the focal length) progressively over the whole
//      sequence from a set of representative frames; we estimate α over the first
//      identity_frames frames only, with a known camera, then fix it.
//   3. The jaw contour is handled by sliding correspondences along the detected
//      outline, not by re-selecting the rig's silhouette vertices per frame (Cao et
//      al. 2014 / FaceWarehouse): the normal offset of the true silhouette from the
//      rig's fixed contour vertices under large head turns is not modelled.
//   4. No 2D displacement vectors or Laplacian deformation here: shapes outside the
//      blendshape prior are the job of the flow refinement (Sec. 5.1).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/rng.h"
#include "core/types.h"
#include "pipeline/capture/rig_point_residual.h"

namespace crease {

class OptionVisitor;

// LandmarkFitOptions::fit_linear_solver: Ceres' DENSE_NORMAL_CHOLESKY or DENSE_QR.
enum class FitLinearSolver { kDenseNormalCholesky, kDenseQr };
constexpr std::array<const char*, 2> OptionEnumNames(FitLinearSolver) { return {"dense_normal_cholesky", "dense_qr"}; }

struct LandmarkFitOptions {
  // λ_β: expression prior (pulls weights to 0), px² per unit weight².
  double fit_expression_prior_weight = 5.0;
  // Temporal prior against jitter: weights on the change from the previous frame's
  // fit (0 disables each). They trade jitter against lag: with the defaults a
  // still face under 1 px landmark noise jitters ~2.5× less in its expression weights
  // and ~1.5× less in rotation than without, and a sudden jump (17°, 22 mm) is caught
  // up within a few frames (tests/landmark_fit_test.cc).
  // λ_Δβ: change of the expression weights, px² per unit weight².
  double fit_temporal_expression_weight = 50.0;
  // λ_ω: change of the head rotation, px² per rad² (1° ≈ 0.0175 rad).
  double fit_temporal_rotation_weight = 2000.0;
  // λ_τ: change of the translation across the image (camera x, y), px² per mm².
  double fit_temporal_translation_weight = 0.5;
  // λ_z: change of the depth (camera z), px² per mm². Depth is ~z/r ≈ 8× less
  // observed than x, y (r the face's radius), so its prior is weaker to avoid lag.
  double fit_temporal_depth_weight = 0.02;
  // λ_α: identity prior (coefficients in units of their standard deviation), px² per std².
  double fit_identity_prior_weight = 20.0;
  // Frames over which the identity is estimated, after which it is fixed. 0 = keep
  // the mean identity (α = 0) from the start.
  int identity_frames = 20;
  // The joint batch fit over the phase's frames so far runs every this many frames of
  // the phase, and at its last frame (1 = at every frame of the phase).
  int identity_fit_interval = 5;
  // Solver iterations of each identity batch fit (warm-started from the previous one).
  int identity_fit_iterations = 5;
  // w_c: weight of the jaw-contour points (iBUG 1–17) relative to the inner points.
  double contour_weight = 0.5;
  // s: weight of the contour residual's component along the detected outline,
  // relative to the component across it; 0 lets the points slide freely along the
  // outline, 1 treats them as ordinary points (weighted by contour_weight).
  double contour_tangent_weight = 0.1;
  // Scale of the Huber loss on a landmark's residual, px.
  double landmark_robust_loss_px = 5.0;
  // Solver iterations of a tracked frame (warm-started from the previous frame).
  int fit_max_iterations = 10;
  // Solver iterations at (re)initialisation (first frame, after Reset()).
  int fit_initial_max_iterations = 50;
  // A solve stops when an iteration lowers the energy by less than this fraction
  // (Ceres' function_tolerance; 10⁻⁴ of ~50 px² is far below the landmark noise).
  // (Re)initialisation frames use 1/100 of it.
  double fit_function_tolerance = 1e-4;
  // Linear solver of the per-frame problem: "dense_normal_cholesky" or "dense_qr".
  FitLinearSolver fit_linear_solver = FitLinearSolver::kDenseNormalCholesky;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// The fit of one frame.
struct LandmarkFrameFit {
  Eigen::VectorXd expression;  // β, #E weights in [0, 1]
  Rigid3d cam_from_head;       // head pose, mm
  // RMS over the points with positive confidence of the 2D distance between the
  // projected rig landmark and the landmark, px (jaw-contour points: the distance
  // across the detected outline).
  double rms_px = 0.0;
  int iterations = 0;      // solver iterations of the frame's solve(s) (identity batch fits excluded)
  bool converged = false;  // the frame's last solve met a convergence tolerance
};

// The global tracker's per-frame rig fit. Holds the state that persists across frames
// (previous fit, identity, the identity phase's frames). Not thread-safe; one per
// sequence. `rig` must outlive the fitter.
class LandmarkRigFitter {
 public:
  static constexpr int kNumLandmarks = 68;
  static constexpr int kNumContourLandmarks = 17;  // iBUG 1–17 (0-based 0–16)

  // Throws Error when the rig lacks the 68 iBUG landmarks ("ibug_1" … "ibug_68") or
  // expressions, the intrinsics are invalid, or options fail Check().
  LandmarkRigFitter(const FaceRig& rig, const CameraIntrinsics& intrinsics, const LandmarkFitOptions& options);

  // Fits the next frame. `landmarks`: 68×2 pixels, iBUG order (row i = iBUG point
  // i + 1). `point_weights`: optional per-point confidence ≥ 0 (68 values; empty =
  // all 1; 0 ignores a point). Throws Error for a wrong landmark count, non-finite
  // landmarks or weights, or fewer than 6 points with positive weight.
  LandmarkFrameFit Fit(const MatX2d& landmarks, const std::vector<double>& point_weights = {});

  // After a tracking loss: the next frame re-initialises the pose (closed form) and
  // has no temporal prior. A fixed identity is kept; an identity phase in progress
  // restarts (its frames are dropped, α returns to 0).
  void Reset();

  // Fixes the identity to known coefficients (#I; shorter = zero-padded) and ends the
  // identity phase.
  void SetIdentity(const Eigen::VectorXd& identity);

  const Eigen::VectorXd& identity() const { return identity_; }
  bool identity_fixed() const { return identity_fixed_; }
  // Frames collected by the identity phase in progress.
  int identity_phase_frames() const { return static_cast<int>(phase_.size()); }
  const LandmarkFitOptions& options() const { return options_; }
  const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  const FaceRig& rig() const { return rig_; }
  // Rig vertex of iBUG point i (0-based).
  int landmark_vertex(int i) const { return vertex_[i]; }

  // L^t: all rig vertices (#V×3, mm) in the head frame for the current identity and
  // the fit's expression weights.
  MatX3d HeadVertices(const LandmarkFrameFit& fit) const;
  // The rig's 68 landmarks projected with the fit's pose (68×2 px, iBUG order).
  MatX2d ProjectLandmarks(const LandmarkFrameFit& fit) const;

 private:
  // One landmark's residual weighting in one frame.
  struct PointTerm {
    int index = 0;            // iBUG point, 0-based
    Eigen::Vector2d target;   // l_i, px
    Eigen::Matrix2d W;        // W_i (√confidence, contour weighting)
    Eigen::Matrix2d M;        // the residual rms_px measures: I, or [n_iᵀ; 0] on the contour
    double loss_scale = 0.0;  // Huber scale on W_i·(π − l_i), px
    double weight = 0.0;      // confidence × contour weight (the closed-form initial pose's weight)
  };
  struct PhaseFrame {
    std::vector<PointTerm> terms;
    Eigen::VectorXd expression;
    Rigid3d cam_from_head;
  };

  std::vector<PointTerm> MakeTerms(const MatX2d& landmarks, const std::vector<double>& point_weights) const;
  void UpdateBase();
  Rigid3d InitialPose(const std::vector<PointTerm>& terms) const;
  LandmarkFrameFit SolveFrame(const std::vector<PointTerm>& terms, const Eigen::VectorXd& expression0,
                              const Rigid3d& pose0, bool initialise) const;
  void SolveIdentityBatch();
  double RmsPx(const std::vector<PointTerm>& terms, const LandmarkFrameFit& fit) const;

  const FaceRig& rig_;
  CameraIntrinsics intrinsics_;
  LandmarkFitOptions options_;
  std::vector<int> vertex_;            // 68 rig vertex ids
  Eigen::Matrix3Xd neutral_;           // 3×68 n_i
  Eigen::Matrix3Xd base_;              // 3×68 n_i + A_i α
  std::vector<RigPointRows> expr_rows_;         // per landmark, B_i (3×#E)
  std::vector<Eigen::MatrixXd> identity_rows_;  // per landmark, A_i (3×#I)
  Eigen::VectorXd identity_;
  bool identity_fixed_ = false;
  bool has_previous_ = false;
  LandmarkFrameFit previous_;
  std::vector<PhaseFrame> phase_;
};

// Experimental control "ground-truth-prior" (issue 5, part 4): "the rig fitted to a
// synthetic sequence's ground-truth projections plus optional noise — for experiments
// that isolate later stages only, never a default". It feeds a LandmarkRigFitter
// (same model, same options, same identity phase) with the ground-truth 2D
// projections of the rig's 68 landmark vertices instead of a landmark detector's
// output, so its result is the rig's best explanation of the truth, not the truth
// itself. Only meaningful on synthetic data whose meshes share the rig's vertex ids
// (the studio's actors are built on the procedural rig).
struct GroundTruthPriorOptions {
  // σ of the zero-mean Gaussian noise added to each landmark coordinate, px.
  double gt_prior_noise_px = 0.0;
  // Seed of the noise (the same seed gives the same noise sequence).
  uint64_t gt_prior_noise_seed = 1;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

class GroundTruthPriorFitter {
 public:
  GroundTruthPriorFitter(const FaceRig& rig, const CameraIntrinsics& intrinsics, const LandmarkFitOptions& fit_options,
                         const GroundTruthPriorOptions& options);

  // `projections`: the frame's ground-truth pixels of all rig vertices (#V×2) or of
  // the 68 landmarks (68×2, iBUG order). Rows that are NaN (behind the camera) get
  // confidence 0. Adds the noise, then LandmarkRigFitter::Fit.
  LandmarkFrameFit Fit(const MatX2d& projections);
  // The noisy landmarks the last Fit used (68×2 px).
  const MatX2d& last_landmarks() const { return last_landmarks_; }
  void Reset() { fitter_.Reset(); }
  LandmarkRigFitter& fitter() { return fitter_; }
  const LandmarkRigFitter& fitter() const { return fitter_; }

 private:
  LandmarkRigFitter fitter_;
  GroundTruthPriorOptions options_;
  Rng rng_;
  MatX2d last_landmarks_;
};

}  // namespace crease
