// Fitting the rig to an actor's scans (paper Sec. 4.1: "we solve for the identity
// parameter given all expressions {M^j}"), and the UV layout transferred from the
// fitted neutral L^0 to the high-resolution neutral M^0 when the scans have none.
//
// One Ceres problem per actor: identity coefficients α shared by all its scans,
// expression weights β^j ∈ [0, 1] and a rigid pose (ω^j, t^j) per scan (rig head
// frame → scan frame). The energy is
//   Σ_j (1/|V_j|) Σ_{v ∈ V_j} ρ(‖r_v^j‖²) + λ_α ‖α‖² + λ_β Σ_j ‖β^j‖²,
// ρ a Huber loss, V_j a seeded subset of the rig's face-chart vertices, and r_v^j:
//   * "uv" correspondences (the scans carry the rig's UV chart, e.g. synthetic
//     scans or scans registered to the rig's template): the vertex against the scan
//     point with the same UV, r = R(ω)x_v + t − p(uv_v) (3 residuals);
//   * "closest" (scans without the chart): iterated closest points, q the nearest
//     scan vertex, pairs farther than max_correspondence_mm or with normals more
//     than 60° apart dropped; point-to-plane r = n_q · (R(ω)x_v + t − q) by default,
//     or point-to-point r = R(ω)x_v + t − q (closest_point_metric). Point-to-plane
//     converges from further away and is unbiased on coarse scans, but lets the rig
//     slide along flat regions (the forehead) by a millimetre or two, which shifts
//     the UVs transferred to the scan by as much: training is unaffected (textures
//     and D^j share the transferred layout), but a comparison with ground truth in
//     the rig's own layout is then limited by that shift. The scans must start roughly aligned with the rig's head frame
//     (within ~1 cm and ~10°): there is no global registration.
// x_v = n_v + Σ_k α_k I_vk + Σ_b β_b B_vb, the rig's vertex (identity modes are in
// units of their standard deviation, so λ_α is a Gaussian prior).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

class OptionVisitor;

// RigFitOptions::closest_point_metric: point-to-point or point-to-plane distances.
enum class ClosestPointMetric { kPoint, kPlane };
constexpr std::array<const char*, 2> OptionEnumNames(ClosestPointMetric) { return {"point", "plane"}; }

// RigFitOptions::correspondence and the path RigFitResult took.
enum class RigCorrespondence { kAuto, kUv, kClosest };
constexpr std::array<const char*, 3> OptionEnumNames(RigCorrespondence) { return {"auto", "uv", "closest"}; }

struct RigFitOptions {
  // "uv", "closest", or "auto" (uv when the scans have UVs covering the rig's
  // face chart, else closest).
  RigCorrespondence correspondence = RigCorrespondence::kAuto;
  // λ_α: prior weight of the identity coefficients, in mm² of mean squared residual
  // per unit coefficient².
  double identity_prior = 0.01;
  // λ_β: weight of the expression weights, mm² per unit weight².
  double expression_prior = 0.001;
  // Scale of the Huber loss on a vertex residual, mm.
  double robust_scale_mm = 2.0;
  // Face-chart vertices used per scan (a seeded subset; all when larger).
  int max_fit_vertices = 1000;
  // Closest-point path: outer iterations and the largest pair distance, mm.
  int closest_point_iterations = 6;
  ClosestPointMetric closest_point_metric = ClosestPointMetric::kPlane;
  double max_correspondence_mm = 10.0;
  int max_solver_iterations = 50;
  uint64_t fit_seed = 7;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct RigFitResult {
  RigCorrespondence correspondence{};        // the path taken: kUv or kClosest
  Eigen::VectorXd identity;                  // α
  std::vector<Eigen::VectorXd> expressions;  // β^j
  std::vector<Rigid3d> scan_from_head;       // (ω^j, t^j)
  std::vector<MatX3d> fitted;                // L^j: the rig's vertices in the scan's frame
  std::vector<double> rms_mm;                // per scan, over the fit vertices
  int solver_iterations = 0;
  double seconds = 0.0;
};

// `scans[0]` is the neutral. Throws Error naming the scan on bad input (no face
// chart overlap in "uv" mode, no correspondences, non-finite values).
RigFitResult FitRigToScans(const FaceRig& rig, const std::vector<TriMesh>& scans,
                           const std::vector<std::string>& scan_names, const RigFitOptions& options);

// True when `scan` has UVs and its UV chart covers most (≥ 80 %) of the rig's
// face-chart vertices' UVs — the condition for "uv" correspondences.
bool ScanHasRigUvs(const FaceRig& rig, const TriMesh& scan);

// UVs for a high-resolution neutral scan M^0 without the rig's chart, transferred
// from the fitted neutral L^0 (Sec. 4.1): each scan vertex takes the UV of the
// point of L^0's face chart it projects onto along its normal (within
// max_distance_mm). Triangles with a vertex that finds no face-chart point are
// dropped, together with unused vertices; `kept_vertices` maps new → old vertex
// ids so the actor's other scans can be cut the same way.
TriMesh TransferUvsFromRig(const FaceRig& rig, const MatX3d& fitted_neutral, const TriMesh& scan,
                           double max_distance_mm, std::vector<int>* kept_vertices);

}  // namespace crease
