// Coarse mesh refinement L^t → L~^t with optical flow (paper Sec. 5.1).
//
// Per frame t, given the global tracker's coarse mesh L^t (the rig at the tracked
// fit: β^t, cam_from_head^t, identity α fixed) and the frame I^t:
//   1. Project: u_i^t = P(v_i^t) for the flow points i of L^t (a fixed subset of
//      the face chart's vertices, see flow_point_spacing_mm). A point takes part
//      when it is visible (the caller's per-vertex mask, if given), faces the camera
//      (front_facing_min_cos, on L^t) and lies half an LK window inside the image.
//   2. Flow (Eq. 5): pyramidal Lucas–Kanade (cv::calcOpticalFlowPyrLK, 21×21
//      window) from the refined positions ũ_i^{t−1} of the previous frame (the
//      projections of L~^{t−1}) to ũ_i^t. The frame's pyramid is built once (in
//      parallel with step 1) and kept as the next frame's previous pyramid.
//   3. Outliers: a point is an outlier when LK fails (status 0, or leaves the
//      image), when |I^{t−1}(ũ^{t−1}) − I^t(ũ^t)| > ξ_α (gray in [0, 1], bilinear),
//      or when ‖ũ^t − u^t‖ > ξ_β. Outliers are recovered by 2D affine moving least
//      squares (Schaefer et al. 2006) from their trusted neighbours, neighbours and
//      weights from geodesic distances precomputed once; a recovered point that
//      again violates ξ_β is reset to u^t (RecoverFlowOutliers).
//   4. 3D fit (Cao et al. 2014's post-processing "to include the 2D mesh positions
//      as constraints in the 3D fit"): β ∈ [0, 1]^#E and the pose re-solved,
//      warm-started from the tracker's fit, minimising
//        E(β, R, t) = w_f Σ_{i trusted/recovered} ‖π(R x_i(β) + t) − ũ_i^t‖²
//                   + w_l Σ_{j inner landmarks} ‖π(R x_j(β) + t) − l_j‖²
//                   + λ_β ‖β‖² + λ_τ ‖β − β^t_tracker‖²
//      with x(β) = n + Aα + Bβ (head frame, mm), π the pinhole projection, l_j the
//      tracker's landmarks (iBUG 18–68). Projected Levenberg–Marquardt (weights at
//      an active bound are held) with analytic Jacobians: ∂r/∂β = J_π R B,
//      ∂r/∂ω = −J_π [R x]× (left rotation increment), ∂r/∂t = J_π; dense normal
//      equations, JᵀJ rebuilt every fit_hessian_refresh steps.
//   5. Laplacian deformation (after Li et al. 2013) of the fitted mesh F on the
//      face chart, to allow shapes outside the prior: displacements d (camera x, y;
//      depth unchanged) minimise
//        λ dᵀ L d  (laplacian_order 1)  or  λ Σ_k M_k ((M⁻¹ L d)_k)²  (order 2)
//          + w_d Σ_{flow points i} ‖d_i − δ_i‖² + w_m Σ_{inner landmarks j} ‖d_j − δ_j‖²
//      over the face chart's vertices (L: cotangent Laplacian, M: Voronoi masses of
//      the neutral face chart), with d = 0 on the chart's seam with the rest of the
//      head (so the head stays closed); δ_i is the back-projection of ũ_i^t at F's
//      depth minus F (δ = 0 for invisible and reset points: pulled to F), δ_j the
//      same for the tracker's landmark. The weights do not change from frame to
//      frame, so the system is factorised once (constructor) and a frame costs two
//      triangular solves (x and y), which run in parallel with the evaluation of F
//      on all vertices. Vertices between flow points follow by the smoothness
//      term. L~^t = F + d.
//
// Lost frames: when the tracker lost the face (!tracked.tracked), Refine returns
// an unrefined result (refined = false) and Reset()s, so the next tracked frame
// starts from the projections u^t (no flow), like the first frame.
//
// Speed: see FlowRefiner below (bench/flow_refinement_bench.cc).
//
// Differences from the paper:
//   1. Flow runs on a subset of the face chart's vertices ("flow points", a greedy
//      Poisson-disk sample of the neutral face with spacing flow_point_spacing_mm,
//      407 of the procedural rig's 6,854 face-chart vertices at 9 mm; ~260 visible
//      in a frontal view), not on every vertex: OpenCV's CPU LK costs ~15 µs per
//      point with a 21×21 window and 3 levels here (the paper used OpenCV's GPU
//      LK). Vertices between flow points follow by the Laplacian deformation.
//   2. Geodesic distance: edge-graph Dijkstra (an upper bound, within ~8 % on
//      regular meshes, core/mesh_ops.h) on the face chart of the rig's neutral
//      mesh (mean identity), bounded by mls_radius_mm, precomputed in the
//      constructor (the paper: "precomputed in the first frame"; the identity
//      changes the distances by a few %). The lid and lip slits are holes of the
//      chart, so neighbours do not reach across a closed mouth or eye.
//   3. MLS: the paper does not give the domain; we map the projected coarse
//      positions u^t of the trusted neighbours onto their flow positions ũ^t and
//      evaluate at the outlier's u^t, weights 1/d_geo^{2α} over the mls_neighbours
//      nearest flow points within mls_radius_mm; fewer than mls_min_neighbours
//      trusted neighbours → reset (near-collinear neighbours: translation only).
//   4. Points without a flow source — visible now but not in the previous frame —
//      are treated as outliers (recovered by MLS when they have trusted neighbours,
//      else reset); in the first frame and after Reset() all are reset (ũ^t = u^t).
//      Invisible points take ũ^t = u^t (kInvisible) and are pulled to F.
//   5. The intensity test reads one bilinear sample of the 8-bit gray frame / 255
//      (sRGB-encoded, what LK runs on); the paper does not say which image.
//   6. 3D fit: Cao et al. 2014's post-processing is not described in detail; ours
//      uses the trusted and recovered flow points plus the tracker's 51 inner
//      landmarks (the jaw contour slides along the outline and is not used),
//      squared (non-robust) residuals, the tracker's expression prior and a pull
//      towards the tracker's β; no temporal prior (the tracker's fit carries it).
//      The identity is fixed.
//   7. Laplacian deformation: Li et al. 2013 deform in 3D towards 3D targets; ours
//      has 2D targets and moves vertices parallel to the image plane at the fitted
//      depth (the depth stays the prior's), with soft constraints of fixed weight
//      so that the factorisation is reused (invisible and reset points are pulled
//      to F rather than dropped). The default is the membrane energy (order 1): on
//      the test sequence it was as accurate as the bi-Laplacian and its solves are
//      ~2.5× cheaper (factor 160k vs 509k non-zeros).
//   8. Visibility comes from the caller (depth buffer) or, when not given, from the
//      front-facing test alone (no self-occlusion: pass a mask for large head turns).
//   9. Not in the paper, for speed on a CPU: LK on ~260 points, the pyramid built in
//      parallel with L^t, JᵀJ of the 3D fit reused between refreshes, only the
//      blendshapes in use evaluated on all vertices.
//  10. Pull to the tracker: each trusted LK position moves κ of the way to u^t,
//      with κ the gain of a Kalman filter (flow_pull_adaptive; the paper chains
//      pure flow, bounded only by ξ_β). Flow measures the motion between frames,
//      not where a point is: a chained point keeps the error it started with plus
//      LK's per-step error, while the tracker's error changes over a sequence (its
//      identity settles over the first frames), so the chain holds on to errors the
//      tracker has since corrected. LK's error on the studio's renders, measured
//      from the true positions (`crease eval` reports it: "LK from the true
//      positions"; the quickstart's 211 frames: 78 % of 0.28 px per frame): at 0.6 px of motion per frame (talking) it recovers
//      81 % of the motion, 0.27 px of error per step (the forehead's smooth shading
//      does not move with the surface: 78 % there; the irises move with the gaze;
//      sensor noise, motion blur and the light change this by < 2 %; a pure image
//      shift is recovered to 97.5 %); at 10 px per frame (fast-motion, blurred)
//      2.3 px per step, 6.5 px on the forehead. Hence σ_q grows with the motion.
//      The tracker's noise r is the smaller of two upper bounds, both from medians
//      (robust to LK's failures): the innovations minus the chain's P⁻ (too high
//      when LK fails beyond σ_q) and the tracker's third differences over time (the
//      true motion leaks in less than into second differences, which read 0.9 px of
//      noise into a fast-motion ground-truth fit). A version with one steady-state
//      gain from the mean innovation served talking but read a fast-motion chain's LK
//      failures as tracker noise, pulled less and less, and lost it (ground-truth
//      prior, fast-motion: 2.0 → 5.5 px). Innovations beyond flow_gate_chi2 ×
//      (P⁻ + r) are outliers. Measured (2D vertex error coarse → refined, jitter
//      coarse → refined), before the third differences unless said:
//        quickstart sequence (ICT actor 101, workout-talking, 640×480, first 120
//        frames), ground-truth prior: κ = 0 with ξ_β = 5 px 2.07 → 2.20 px (the
//        trusted points' error jumps 1.1 px above u^t's at frame 4, when the
//        tracker's error drops, and decays only through ξ_β resets); fixed κ = 0.05
//        / 0.1 / 0.2 (ξ_β = 20 px): 2.11 / 2.09 / 2.07 px, jitter 0.135 → 0.141 /
//        0.140 / 0.138 px; adaptive 2.04 px, jitter 0.113 px. Regressor: κ = 0 with
//        ξ_β = 5 5.93 → 5.65 px; fixed κ 5.21 / 5.26 / 5.38 px; adaptive 5.39 px
//        (without the gate 5.21, with χ² = 9.21 5.55), jitter 3.36 → 0.77 px;
//        a fast-motion clip (91 frames), ground-truth prior 2.01 → 1.99 px,
//        jitter 0.33 → 0.38 px (no gate 2.04, 0.43; χ² 9.21 1.97, 0.37);
//        regressor 8.87 → 8.21 px;
//        with third differences (the default): quickstart ground-truth prior 2.07 →
//        2.04 px (jitter 0.135 → 0.113), regressor 5.93 → 5.39 px (3.36 → 0.81),
//        ground-truth fit 0.68 → 0.38 px (aligned 3D 0.68 → 0.43 mm); fast-motion
//        clip ground-truth prior 2.01 → 1.94 px (jitter 0.325 → 0.302), regressor
//        8.87 → 8.23 px, ground-truth fit 0.47 → 0.40 px (jitter 0.026 → 0.041);
//        tracking-refinement, paper profile, 3 seeds: see reports/REPRODUCTION.md.
//      In tests/flow_refinement_test.cc (8 frames, a jittery but unbiased tracker)
//      κ settles at 0.28 (1.0 for the same frames with the true fit) and the
//      refined error is 0.90 px against the coarse 1.65 px (jitter 2.15 → 0.73 px).
//  11. A frame without any trusted or recovered flow point (the first frame, after
//      a loss) is not refitted: L~^t = L^t. The paper does not say; a fit to the
//      51 landmarks alone under the refinement's weights moved the flow points of
//      the quickstart's first frame from 4.39 px (u^0) to 5.59 px, and the later
//      frames' flow started from there.
//  12. The Laplacian step hardly moves the flow points at the default weights
//      (w_d = λ = 1: a vertex's cotangent weights sum to ~5, so a lone constraint
//      moves it ~1/6 of the way to ũ^t; L~^t's error at the flow points equals
//      F's within 0.05 px in the runs above). Raising w_d to 10 or 100 made L~^t
//      follow ũ^t and increased the error with both trackers (e.g. ground-truth
//      prior 2.52 and 2.72 px instead of 2.20 at κ = 0), because ũ^t is not yet
//      better than F; it stays at 1 until flow is.
//  13. ξ_β = 20 px instead of 5: with a jittery tracker (the landmark regressor
//      jumps ~3 px from frame to frame) 5 px rejected a quarter of the flow points
//      every frame and reset them to u^t, where the tracker is worst (9.6 px);
//      the pull of Differences 10 bounds the drift that ξ_β was for. Regressor,
//      κ = 0.2: 5.58 px at ξ_β = 5, 5.45 at 10, 5.38 at 20; the ground-truth-prior
//      run is unchanged (2.06–2.07 px).
//  14. Sec. 7 suggests relating each frame back to a reference frame against drift;
//      flow_reference_frame does (the chain's first frame, LK started at the chained
//      position, kept when within 3 px and passing ξ_α), off by default: with the
//      pull of Differences 10 it changes little (quickstart, 120 frames: ground-
//      truth prior 2.04 px either way, jitter 0.113 → 0.121 px; regressor 5.39 →
//      5.31 px, jitter 0.81 → 0.96 px; ground-truth fit 0.38 → 0.36 px; fast-motion
//      clip: ground-truth prior 1.94 px either way, regressor 8.23 → 8.26 px,
//      ground-truth fit 0.40 px either way) and costs a second LK pass.
//      flow_reference_gain < 1 blends the reference's position into the chain's
//      instead of taking it (crease 0.4.14, not in the paper). What the texture's
//      drift on the skin says (`crease eval`'s registered.drift_mm; the held
//      expressions, the real tracker, 3 seeds; detail-levers --profile holds-refine):
//      the default drifts 2.07 mm; the pure chain 1.64, the reference frame with the
//      pull 1.29, the pure chain with the reference 0.85, and with gain 0.3 and the
//      Laplacian following the flow points (laplacian_flow_weight 10; the variant
//      gated-level-anchored) 0.76 ± 0.13 mm (at most 1.30 against 3.27), jitter
//      0.40 px instead of 0.59, 2D error 5.83 px either way; D^t against the truth
//      registered through the image 0.188 instead of 0.137, but D^t on a still face
//      0.845 instead of 0.898. The pull keeps the chain on the tracker's error, which
//      changes with the expression; without it the chain keeps its first frame's
//      error instead. With the true landmarks the anchored chain drifts 0.70 mm
//      (0.76 with the default) but sits 4.1 px off instead of 2.5: the drift's floor
//      of ~0.7 mm is LK's on the smooth forehead, not the tracker's. Off by default.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/types.h"
#include "pipeline/capture/landmark_fit.h"
#include "pipeline/capture/tracker.h"

namespace crease {

class OptionVisitor;

struct FlowRefinementOptions {
  // --- Flow (Sec. 5.1) ---
  // LK window side, px (Sec. 5.1: 21×21 neighbourhood). Odd, ≥ 5.
  int lk_window = 21;
  // Pyramid levels of LK including the full resolution (not in the paper; 3 levels
  // follow motions up to ~±40 px between frames).
  int lk_pyramid_levels = 3;
  // LK stops after this many iterations per level or when the update is below
  // lk_epsilon_px (not in the paper; OpenCV's defaults are 30 and 0.01).
  int lk_max_iterations = 20;
  double lk_epsilon_px = 0.03;
  // LK's minimum eigenvalue of the window's structure tensor (OpenCV's
  // minEigThreshold, normalised by the window's pixel count); weaker windows fail.
  double lk_min_eigenvalue = 1e-4;
  // Start LK at ũ^{t−1} + (u^t − u^{t−1}) (the tracker's predicted motion) instead
  // of ũ^{t−1}. Not in the paper; helps with fast motion.
  bool lk_predict_from_tracker = false;
  // κ: each frame, a trusted flow position moves this fraction of the way to the
  // tracker's u^t: ũ^t ← ũ^t + κ (u^t − ũ^t) (not in the paper; see Differences 10).
  // With flow_pull_adaptive, κ is the gain of a Kalman filter shared by the flow
  // points: LK predicts with step noise σ_q = flow_step_sigma_px +
  // flow_step_sigma_ratio × the frame's median LK motion (per coordinate; LK's error
  // grows with the motion), the tracker observes with noise r estimated from the
  // innovations u^t − ũ^t and from the tracker's third differences over time
  // (medians, averaged over frames at rate flow_noise_rate; the smaller of the two):
  // a steady tracker pulls hard, a jittery one little. Else κ = flow_tracker_pull
  // (0 = the paper's pure flow chain).
  bool flow_pull_adaptive = true;
  double flow_tracker_pull = 0.2;
  double flow_step_sigma_px = 0.1;
  double flow_step_sigma_ratio = 0.25;
  double flow_noise_rate = 0.1;
  // With flow_pull_adaptive: a trusted point whose squared innovation |u^t − ũ^t|²
  // exceeds this multiple of its variance (P⁻ + r per coordinate) is an outlier,
  // like the paper's ξ_β (0 disables). ξ_β stays as an absolute bound.
  double flow_gate_chi2 = 25.0;
  // Sec. 7's suggestion, off by default (Differences 14): also track each trusted
  // point from the chain's first frame (the reference), starting at its chained
  // position, and move the chained position towards it (flow_reference_gain) when it
  // passes ξ_α against the reference and lies within flow_reference_max_px of the
  // chained one.
  bool flow_reference_frame = false;
  double flow_reference_max_px = 3.0;
  // With flow_reference_frame: the chained position moves this fraction of the way to
  // the position tracked from the reference (1 = takes it). Below 1 the pair is a
  // complementary filter: the chain carries the frame-to-frame motion, smooth, and the
  // reference bounds the drift, its per-frame noise averaged over ~1/gain frames.
  double flow_reference_gain = 1.0;
  // ξ_α: intensity outlier threshold on gray in [0, 1] (8-bit / 255), Sec. 5.1.
  double outlier_intensity = 0.02;
  // ξ_β: distance outlier threshold between ũ^t and u^t, px (Sec. 5.1: 5 px; see
  // Differences 13).
  double outlier_distance_px = 20.0;
  // Spacing of the flow points on the neutral face, mm (not in the paper, which
  // tracks every vertex on the GPU; see Differences 1). 9 mm: 407 points on the
  // procedural rig's face, ~260 of them visible in a frontal view.
  double flow_point_spacing_mm = 9.0;
  // A point is visible only when its normal (on L^t) faces the camera with
  // cos(angle to the viewing ray) ≥ this, with or without a visibility mask
  // (grazing windows track badly).
  double front_facing_min_cos = 0.25;

  // --- MLS outlier recovery (Schaefer et al. 2006, affine, Sec. 5.1) ---
  // Neighbours of each flow point (nearest by geodesic distance on the neutral face).
  int mls_neighbours = 12;
  // Neighbours farther than this (geodesic, mm) are not used.
  double mls_radius_mm = 35.0;
  // α: weights 1 / d^{2α} (Schaefer et al.'s α; 1 in their examples).
  double mls_alpha = 1.0;
  // An outlier needs at least this many trusted neighbours to be recovered (3 for an
  // affine map); otherwise it is reset to u^t.
  int mls_min_neighbours = 3;

  // --- 3D fit (Sec. 5.1, "post-processing step in Cao et al. [2014]") ---
  // w_f: weight of each trusted or recovered flow point, px⁻² (relative to a landmark's w_l).
  double fit_flow_weight = 1.0;
  // w_l: weight of each of the tracker's 51 inner landmarks (iBUG 18–68).
  double fit_landmark_weight = 0.5;
  // λ_β: expression prior (pulls β to 0), px² per unit weight² (the tracker's default).
  // Key `refine_expression_prior_weight`: `fit_expression_prior_weight` is the
  // landmark fit's (LandmarkFitOptions), and until crease 0.4.1 one key set both.
  double fit_expression_prior_weight = 5.0;
  // λ_τ: pulls β towards the tracker's β, px² per unit weight² (0 disables).
  double fit_tracker_prior_weight = 1.0;
  // Levenberg–Marquardt iterations from the tracker's fit.
  int fit_iterations = 5;
  // JᵀJ is rebuilt every this many accepted steps (1 = every step, plain LM); in
  // between, steps reuse it with the current gradient. Not in the paper: speed.
  int fit_hessian_refresh = 3;

  // --- Laplacian deformation (after Li et al. 2013) ---
  // false: L~^t is the 3D fit (ablation).
  bool laplacian = true;
  // Smoothness energy: 2 = bi-Laplacian λ Σ M (M⁻¹L d)² (smooth interpolation between
  // constraints), 1 = membrane λ dᵀL d (sparser factor, ~2.5× faster solves, but
  // cusps at the constraints).
  int laplacian_order = 1;
  // λ: weight of the smoothness energy.
  double laplacian_smoothness = 1.0;
  // w_d: soft constraint weight of every flow point (to ũ^t, or to the fit when
  // invisible / reset).
  double laplacian_flow_weight = 1.0;
  // w_m: soft constraint weight of the tracker's inner landmarks (noisier than flow).
  double laplacian_landmark_weight = 1.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

enum class FlowPointStatus : uint8_t {
  kInvisible = 0,  // not visible (or too close to the image border): ũ = u, not used
  kTrusted,        // LK succeeded and passed both outlier tests
  kRecovered,      // outlier recovered by MLS from trusted neighbours
  kReset,          // outlier not recoverable, or no flow source (first frame): ũ = u
};
const char* ToString(FlowPointStatus status);

// Per flow point, its nearest flow points by geodesic distance (compressed rows):
// neighbours of point i are index[begin[i] … begin[i+1]), sorted by distance.
struct FlowNeighbours {
  std::vector<int> begin;  // n + 1 offsets
  std::vector<int> index;  // neighbour flow point
  std::vector<double> distance_mm;
  int size() const { return begin.empty() ? 0 : static_cast<int>(begin.size()) - 1; }
};

// Affine moving least squares (Schaefer et al. 2006, Sec. 2.1): the affine map
// f(x) = (x − p*) M + q* minimising Σ_j w_j ‖f(p_j) − q_j‖², evaluated at v.
// p, q: n×2 control points and their images; w: n weights > 0. Returns false (out
// untouched) when Σ w = 0; a degenerate (near-collinear) configuration falls back
// to the translation q* − p*.
bool MlsAffine(const Eigen::Vector2d& v, const MatX2d& p, const MatX2d& q, const Eigen::VectorXd& w,
               Eigen::Vector2d* out);

struct RecoverCounts {
  int trusted = 0, recovered = 0, reset = 0, invisible = 0;
  int distance_outliers = 0;  // trusted on input but farther than ξ_β from u
};

// Outlier test ξ_β and MLS recovery (Sec. 5.1) on one frame's flow points.
//   projected: n×2 u^t, px.   flow: n×2 ũ^t from LK, px (in/out).
//   status (in/out, n): in — kInvisible (skipped), kTrusted (LK succeeded and passed
//   ξ_α), kReset (already an outlier: LK failed or ξ_α); out — every kTrusted point
//   farther than ξ_β from u becomes an outlier too; each outlier becomes kRecovered
//   (ũ = the MLS map of its trusted neighbours, within ξ_β of u) or kReset (ũ = u).
// MLS weights: 1 / d_geo^{2α} from `neighbours` (geodesic distances, mm).
RecoverCounts RecoverFlowOutliers(const FlowRefinementOptions& options, const FlowNeighbours& neighbours,
                                  const MatX2d& projected, MatX2d* flow, std::vector<FlowPointStatus>* status);

struct RefinedFrame {
  bool refined = false;                 // false when the frame was not tracked (all else empty)
  MatX3d vertices;                      // L~^t: all #V rig vertices, camera frame, mm
  MatX3d coarse_vertices;               // L^t: all #V, camera frame (the tracker's fit evaluated)
  LandmarkFrameFit fit;                 // the 3D fit with the 2D positions as constraints (β in [0,1], cam_from_head)
  std::vector<int> flow_vertex;         // rig vertex of each flow point
  MatX2d flow_positions;                // ũ^t per flow point, px
  MatX2d projected_positions;           // u^t per flow point, px (projection of L^t)
  MatX2d fit_positions;                 // per flow point, px: projection of the 3D fit F (before the Laplacian)
  std::vector<FlowPointStatus> status;  // per flow point
  int trusted = 0, recovered = 0, reset = 0, invisible = 0;
  // κ applied this frame, and the tracker noise σ_r and LK step noise σ_q (px per
  // coordinate) it was derived from (0 with a fixed κ).
  double pull = 0, tracker_noise_px = 0, step_sigma_px = 0;
  // Outliers by cause (a point counts once, for the first test it failed): LK failed
  // (status 0, or left the image), ξ_α, ξ_β; and visible points without a flow source.
  int lk_failures = 0, intensity_outliers = 0, distance_outliers = 0, no_source = 0;
  int reference_tracked = 0;  // trusted points re-tracked from the reference frame (flow_reference_frame)
  int gate_outliers = 0;  // trusted by LK and ξ_α, rejected by the innovation gate (flow_gate_chi2)
  // Wall-clock times, ms. flow: pyramid (built in parallel with L^t's evaluation) +
  // LK + ξ_α; mls: ξ_β + MLS; fit: the 3D fit; evaluate: the rig on all vertices
  // (L^t and F), projections and visibility; laplacian: right-hand side, solves and
  // update beyond what overlaps F's evaluation. total: the whole Refine.
  double flow_ms = 0, mls_ms = 0, fit_ms = 0, laplacian_ms = 0;
  double evaluate_ms = 0;
  double total_ms = 0;
};

// The coarse mesh refinement of Sec. 5.1. Holds the state that persists across
// frames (previous pyramid and refined positions) and what is precomputed once
// (flow points, geodesic neighbours, the factorised Laplacian system). Not
// thread-safe; one per sequence. `rig` must outlive the refiner.
//
// Speed (bench/flow_refinement_bench.cc: 640×480 studio frames of the procedural
// rig, 14,071 vertices, 407 flow points of which 256 visible, 5 fit iterations;
// TBB and OpenCV use both cores of this 2-vCPU machine, which was shared with other
// engineers' builds, so the figures vary 2–3× with the load):
//   quietest (load ~1): 6.6 ms per frame, median of 3 runs of 3 s (fastest frame
//            4.5 ms): flow (pyramid + LK + ξ_α) 3.7, 3D fit 1.35, evaluation of
//            L^t and F (all vertices) 1.25, Laplacian solves beyond their overlap
//            with F 0.46, MLS 0.035 ms; front-facing test instead of a mask: 6.6 ms;
//   load ~2: 7.6–8.9 ms mean; load ~5: ~20 ms median (main thread's CPU ~9 ms).
//   Construction (flow points, Dijkstra neighbours, factorisation): 42 ms.
// LK dominates (~15 µs per point and 3 levels in OpenCV's CPU code). Cheaper
// settings (same run): flow_point_spacing_mm = 10 (204 visible points) 4.8 ms;
// 2 pyramid levels with lk_predict_from_tracker 5.1 ms.
// Eq. 5's pyramidal Lucas–Kanade with the options' window, pyramid levels, stopping
// rule and minimum eigenvalue, from `from` in `previous` to `next` (8-bit gray
// images, or their pyramids from cv::buildOpticalFlowPyramid). `to`: the starting
// positions when `use_initial` (else overwritten), the tracked ones after. Returns
// LK's status per point (0 = not found). The refinement and the eval's "LK from the
// true positions" both run it.
std::vector<uint8_t> TrackLucasKanade(const FlowRefinementOptions& options, cv::InputArray previous,
                                      cv::InputArray next, const std::vector<cv::Point2f>& from,
                                      std::vector<cv::Point2f>* to, bool use_initial);

class FlowRefiner {
 public:
  // Throws Error when the rig lacks the 68 iBUG landmarks or expressions, has no face
  // chart, the intrinsics are invalid, or options fail Check().
  FlowRefiner(const FaceRig& rig, const CameraIntrinsics& intrinsics, const FlowRefinementOptions& options);
  ~FlowRefiner();
  FlowRefiner(FlowRefiner&&) noexcept;
  FlowRefiner& operator=(FlowRefiner&&) noexcept;

  // gray8: CV_8UC1 frame of the intrinsics' size (sRGB-encoded gray, what LK runs
  // on). tracked: the global tracker's frame (tracked.fit valid when
  // tracked.tracked; tracked.landmarks 68×2 px, or empty to use no landmarks).
  // identity: α (#I or fewer, zero-padded), fixed. visible: per rig vertex (#V),
  // non-zero = visible in this frame (from a depth buffer); empty = front-facing
  // test of L^t. When !tracked.tracked: returns {refined = false} and Reset()s.
  // Throws Error naming the problem for an empty or wrongly sized/typed image, a
  // wrongly sized visibility mask, identity or expression vector, non-finite
  // landmarks, weights or pose.
  RefinedFrame Refine(const cv::Mat& gray8, const TrackedFrame& tracked, const Eigen::VectorXd& identity,
                      const std::vector<uint8_t>& visible = {});

  // After a loss: the next frame starts from the projections u^t of L^t (no flow).
  void Reset();

  const FlowRefinementOptions& options() const { return options_; }
  // Rig vertices of the flow points (fixed at construction).
  const std::vector<int>& flow_vertices() const;
  const FlowNeighbours& neighbours() const;
  // Vertices of the face chart (those the Laplacian deformation moves).
  int num_chart_vertices() const;

 private:
  struct Impl;
  FlowRefinementOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
