// Mesh operators: vertex normals, the cotangent Laplacian and mass matrices, the
// mesh Gaussian lowpass G / G^HF of Sec. 4.1 (implicit heat diffusion), and
// geodesic distance (the heat method, used by Sec. 5.1, and edge Dijkstra).
//
// Conventions shared by everything here:
//   * V is #V×3, mm; F is #F×3, counter-clockwise seen from outside (TriMesh).
//   * L is the cotangent Laplacian in the *positive* semi-definite convention,
//       (L x)_i = Σ_j w_ij (x_i − x_j),   w_ij = (cot α_ij + cot β_ij) / 2,
//     i.e. the finite-element stiffness matrix K_ij = ∫ ∇φ_i·∇φ_j, so that
//     xᵀ L x = ∫ |∇x|² (Dirichlet energy, mm⁰ for x in mm: L is unitless).
//     libigl's igl::cotmatrix returns −L (negative semi-definite).
//   * M is the lumped (diagonal) mass matrix, mm²; M⁻¹L approximates −Δ.
//   * Triangles of zero area contribute nothing (no cotangent, no area).
// The heavy sparse-solver headers stay in mesh_ops.cc: the classes below keep
// their factorisations behind a pointer.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

class OptionVisitor;

// ---------------------------------------------------------------------------
// Normals, Laplacian, mass.

// Area-weighted vertex normals: n_i = normalise(Σ_{f ∋ i} (p1 − p0) × (p2 − p0)),
// i.e. the sum of the unnormalised face normals (each of length 2·area_f).
// Returns #V×3 unit vectors pointing outwards for counter-clockwise triangles.
// Vertices duplicated along UV seams (bit-identical positions) get one shared
// normal, the sum over all their copies, so shading and displacement along
// normals stay continuous across seams.
// Vertices in no triangle, or whose incident face normals sum to zero (only
// degenerate triangles, or a pinched fold), get (0, 0, 0): callers that divide
// by the normal must check.
MatX3d VertexNormals(const TriMesh& mesh);

// Phong tessellation (Boubekeur and Alexa 2008) of a triangle with vertices v[k]
// and unit vertex normals n[k], at barycentrics b with shape factor α (0 = the flat
// triangle): p, given as the flat point Σ_k b_k v_k, becomes
//   (1 − α) p + α Σ_k b_k (p − ((p − v_k)·n_k) n_k).
// One copy for the studio's surface (synth/hires_surface.h), H^t's optional base
// (pipeline/capture/hifi_mesh.h) and the exact detail (eval/detail_truth.h).
inline void PhongTessellate(double alpha, const double b[3], const double* const v[3], const double* const n[3],
                            double p[3]) {
  double q[3] = {0.0, 0.0, 0.0};
  for (int k = 0; k < 3; ++k) {
    const double d = (p[0] - v[k][0]) * n[k][0] + (p[1] - v[k][1]) * n[k][1] + (p[2] - v[k][2]) * n[k][2];
    for (int c = 0; c < 3; ++c) q[c] += b[k] * (p[c] - d * n[k][c]);
  }
  for (int c = 0; c < 3; ++c) p[c] = (1.0 - alpha) * p[c] + alpha * q[c];
}

// Cotangent Laplacian, #V×#V, symmetric, positive semi-definite, rows sum to 0:
//   (L x)_i = Σ_j w_ij (x_i − x_j),  w_ij = (cot α_ij + cot β_ij) / 2,
// α_ij, β_ij the angles opposite edge ij (one angle on a boundary edge). This is
// −igl::cotmatrix. Off-diagonals are −w_ij and can be positive for obtuse
// triangles; L stays PSD regardless (it is the P1 stiffness matrix). With the
// natural (Neumann) boundary built in, L applied to a function linear in the
// plane of a flat mesh is zero at interior vertices but not at boundary ones.
SpMat CotangentLaplacian(const TriMesh& mesh);

enum class MassMatrixType {
  kBarycentric,  // 1/3 of the incident triangle areas
  kVoronoi,      // mixed Voronoi areas (Meyer et al. 2003): Voronoi cells for
                 // non-obtuse triangles, area/2 to the obtuse corner and area/4 to
                 // the others otherwise
};
// Names for options and files (ToString / FromString in core/options.h).
constexpr std::array<const char*, 2> OptionEnumNames(MassMatrixType) { return {"barycentric", "voronoi"}; }

// Lumped mass matrix, #V×#V diagonal, mm². Both types sum to the surface area.
// Barycentric is the classic choice but is pointwise inconsistent where vertex
// valences alternate (on the alternating-diagonal grid of MakeGrid the masses are
// 4/3·h² and 2/3·h²); Voronoi gives h² for every interior vertex there.
SpMat MassMatrix(const TriMesh& mesh, MassMatrixType type = MassMatrixType::kBarycentric);

// ---------------------------------------------------------------------------
// Mesh Gaussian G and G^HF (Sec. 4.1).

// Default bandwidths. The paper names the filters (G^HF: "a narrow Gaussian" that
// removes pores; G: the lowpass that separates low from medium expression
// frequencies) but gives no widths. Interpretation (difference from the paper 1):
// σ is the standard deviation, in mm along the surface, of the Gaussian that the
// filter approximates; its amplitude response is exp(−k²σ²/2), which is 1/2 at the
// wavelength λ½ = 2πσ / √(2 ln 2) ≈ 5.34 σ.
//  * G: σ = 3 mm, λ½ ≈ 16 mm. The coarse tracking mesh resolves only shapes
//    longer than ~10–15 mm; forehead furrows (spacing ~10 mm) pass G's complement
//    (the medium band) at ~80 %, crow's feet (3–5 mm) essentially fully.
//  * G^HF: σ = 0.3 mm, λ½ ≈ 1.6 mm. Pores (0.1–0.5 mm) are removed (a 0.5 mm
//    wavelength keeps < 1 % with 8 steps), 3 mm wrinkles keep ~82 %.
inline constexpr double kGaussianBandwidthMm = 3.0;               // G, Sec. 4.1
inline constexpr double kHighFrequencyGaussianBandwidthMm = 0.3;  // G^HF, Sec. 4.1

// LowpassOptions::boundary and ::solver (see there).
enum class LowpassBoundary { kNatural, kFixed };
constexpr std::array<const char*, 2> OptionEnumNames(LowpassBoundary) { return {"natural", "fixed"}; }
enum class LowpassSolver { kDirect, kIterative };
constexpr std::array<const char*, 2> OptionEnumNames(LowpassSolver) { return {"direct", "iterative"}; }

struct LowpassOptions {
  // σ, mm: standard deviation of the Gaussian approximated (geodesic). Default:
  // kGaussianBandwidthMm (G); use kHighFrequencyGaussianBandwidthMm for G^HF.
  // 0 disables the filter (Apply returns its input), for ablations.
  double bandwidth_mm = kGaussianBandwidthMm;  // G / G^HF, Sec. 4.1 (not given)
  // n: number of backward-Euler steps splitting the diffusion time t = σ²/2.
  // The response (1 + k²t/n)^(−n) approaches exp(−k²σ²/2) as n grows; at kσ = 2
  // it is 0.198 / 0.168 / 0.152 for n = 4 / 8 / 16 against 0.135. Cost: n solves.
  int steps = 8;
  // Lumped mass in the diffusion: "voronoi" (default, pointwise consistent on
  // regular grids of any valence) or "barycentric".
  MassMatrixType mass_matrix = MassMatrixType::kVoronoi;
  // Boundary condition: "natural" (Neumann, zero normal flux: no heat leaves
  // the surface, constants are kept, a linear function bends near the boundary so
  // boundary vertices of a smoothed open mesh slide inwards along the surface, by
  // ~1.1 σ on a flat grid, decaying to < 1e-5 mm at 6 σ from the boundary) or
  // "fixed" (Dirichlet: boundary vertices keep their input values; a planar mesh
  // is then reproduced exactly, but detail at the boundary is not filtered).
  LowpassBoundary boundary = LowpassBoundary::kNatural;
  // How each step's system (M + τL) x = M x_k is solved: "direct" (one sparse
  // LDLᵀ factorisation in the constructor; best for wide filters and repeated use)
  // or "iterative" (conjugate gradients with a Jacobi preconditioner, warm-started
  // from the previous step; no factorisation, best for narrow filters such as G^HF
  // on dense scans, where M + τL is close to diagonal and CG needs a few iterations).
  LowpassSolver solver = LowpassSolver::kDirect;
  // "iterative": relative residual at which CG stops (per step and coordinate; 1e-8
  // of positions ~100 mm is ~1e-6 mm).
  double iterative_tolerance = 1e-8;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// The mesh Gaussian as implicit heat diffusion (Sec. 4.1, G and G^HF;
// interpretation, differences from the paper 1–3):
//   1. Bandwidth: see kGaussianBandwidthMm.
//   2. A Gaussian of standard deviation σ is the heat kernel at time t = σ²/2
//      (∂x/∂τ = Δx). The diffusion runs as n backward-Euler steps of τ = t/n:
//        (M + τ L) x_{k+1} = M x_k,   x_0 = input,   output = x_n,
//      with M, L built once from the constructor's mesh (a linear filter, not
//      curvature flow: the operator is not rebuilt as the surface smooths).
//      One sparse LDLᵀ factorisation of M + τL is made in the constructor and
//      reused by every step and every Apply.
//   3. Transfer function: an eigenfunction of M⁻¹L with eigenvalue λ is scaled by
//      (1 + λ t/n)^(−n). On a flat region λ ≈ k² for a sine of wavenumber k
//      (wavelength 2π/k), so the response is (1 + k²σ²/(2n))^(−n) → exp(−k²σ²/2)
//      (n → ∞); for finite n it passes slightly more than the Gaussian at high
//      frequencies (see LowpassOptions::steps). On a regular grid of spacing h,
//      λ = (4/h²) sin²(kh/2) exactly (Voronoi mass).
// Constant functions are kept exactly (L·1 = 0); with "natural" boundaries a
// smoothed planar mesh stays in its plane to rounding, with "fixed" it is kept
// vertex by vertex. Apply is const and may be called from several threads.
class MeshLowpass {
 public:
  // Builds M, L of `mesh` and factorises. Vertices duplicated along UV seams are
  // welded first (core/tri_mesh.h), so seams are not boundaries; their copies
  // are averaged on input and get the same filtered value. Vertices without area (in no
  // non-degenerate triangle) keep their input values. Throws Error on invalid
  // options or if the factorisation fails.
  explicit MeshLowpass(const TriMesh& mesh, const LowpassOptions& options = {});

  // X: #V×3 (e.g. mesh.V), returns #V×3 filtered. Throws Error on a size mismatch.
  MatX3d Apply(const MatX3d& X) const;
  // x: #V scalar field, returns #V filtered.
  Eigen::VectorXd Apply(const Eigen::VectorXd& x) const;

  // Diffusion time t = σ²/2, mm².
  double diffusion_time() const { return t_; }
  // Amplitude response (1 + k² t/n)^(−n) of the filter to a sine of wavenumber
  // k (rad/mm) on a flat, finely sampled region; GaussianResponse gives the ideal
  // exp(−k²σ²/2).
  double Response(double wavenumber) const;
  double GaussianResponse(double wavenumber) const;
  const LowpassOptions& options() const { return options_; }
  int num_vertices() const { return num_vertices_; }

 private:
  struct Impl;
  Eigen::VectorXd ApplyInner(const Eigen::VectorXd& x) const;
  Eigen::MatrixXd ApplyInner(const Eigen::MatrixXd& X) const;
  Eigen::MatrixXd Gather(const Eigen::MatrixXd& X) const;   // #V → welded (seam copies averaged)
  Eigen::MatrixXd Scatter(const Eigen::MatrixXd& W) const;  // welded → #V
  LowpassOptions options_;
  double t_ = 0.0;
  int num_vertices_ = 0;  // of the input mesh
  int num_inner_ = 0;     // after welding UV seams
  std::shared_ptr<const WeldedMesh> weld_;  // null when the mesh has no seam copies
  std::shared_ptr<const Impl> impl_;  // null when bandwidth_mm == 0
};

// ---------------------------------------------------------------------------
// Geodesic distance.

// GeodesicOptions::boundary (see there).
enum class GeodesicBoundary { kNeumann, kDirichlet, kAveraged };
constexpr std::array<const char*, 3> OptionEnumNames(GeodesicBoundary) { return {"neumann", "dirichlet", "averaged"}; }

struct GeodesicOptions {
  // m: heat time t = m·h², h = mean edge length (Crane et al. 2013, Sec. 3.2.4,
  // who recommend m = 1). Larger m gives smoother but less accurate distances.
  double time_factor = 1.0;
  // Boundary condition of the heat step on open meshes (Crane et al. 2013,
  // Sec. 3.2.5): "neumann", "dirichlet" (u = 0 on the boundary except at
  // sources), or "averaged" (mean of the two solutions, their recommendation;
  // one more factorisation). Ignored on closed meshes.
  GeodesicBoundary boundary = GeodesicBoundary::kAveraged;
  // Lumped mass in the heat step: "voronoi" or "barycentric".
  MassMatrixType mass_matrix = MassMatrixType::kVoronoi;
  // Additive constant (step 4 below): true fits it on the sources' one-ring,
  // where the distance is known (edge length); false takes φ at the sources
  // (Crane et al.), which underestimates all distances by ~0.1–0.15 h.
  bool one_ring_offset = true;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Geodesic distance by the heat method (Crane, Weischedel, Wardetzky 2013, "Geodesics
// in Heat"), as used for the geodesic search of Sec. 5.1 ("precomputed in the first
// frame"). Per query:
//   1. heat flow: (M + tL) u = δ_sources            (one backward-Euler step)
//   2. X = −∇u / |∇u| per triangle                   (unit field pointing away)
//   3. Poisson: L φ = b, b_i = ∫ X·∇φ_i              (least squares ∇φ ≈ X)
//   4. subtract a constant per connected component so that distances start at 0.
// M + tL (and, on open meshes with "averaged"/"dirichlet", its Dirichlet variant)
// and L are factorised once in the constructor. L is singular (constants); it is
// made definite by pinning one vertex per connected component (φ = 0 there,
// rows/columns replaced by the identity) — pinning, not regularisation, so the
// solution is the exact least-squares φ up to the per-component constant of
// step 4 (the weak divergence b sums to 0, so the pinned system is consistent).
// Difference from Crane et al.: step 4 fits the constant on the sources' one-ring
// (GeodesicOptions::one_ring_offset).
// Accuracy measured in tests/mesh_ops_test.cc (defaults: t = h², "averaged",
// one-ring offset), relative error over vertices more than 5 edges from the source:
//   * flat 81×81-vertex alternating-diagonal grid, centre source: max 3.6 %, mean
//     1.1 % (beyond 10 edges: max 2.8 %); distances are underestimated by ~1 %
//     because the t = h² heat kernel is anisotropic on a lattice (larger m lowers
//     the far-field error, m = 4 gives ~0.5 %, at the cost of accuracy near sources);
//     corner source: max 4.0 %, mean 1.1 %;
//   * 10242-vertex icosphere (h = 1.9 mm, R = 50 mm) vs the great circle: max 1.1 %,
//     mean 0.15 % (with one_ring_offset = false: max 3.1 %, mean 0.65 %).
// Edge Dijkstra (DijkstraDistance) is worse on both: max 8.2 % / mean 5.3 % on the
// grid, max 23 % / mean 8.5 % on the icosphere. The heat method's error is largest
// within a few edges of the sources (the cone tip is resolved by few triangles) and
// on ridges between several sources, whose kink the least-squares φ rounds off
// (by up to ~0.65 h measured). From is const and may be called from several threads.
class GeodesicDistance {
 public:
  // Vertices duplicated along UV seams are welded first, so distances flow
  // across seams. Throws Error on invalid options or if a factorisation fails.
  explicit GeodesicDistance(const TriMesh& mesh, const GeodesicOptions& options = {});

  // Distances (mm, along the surface) from the nearest of `sources` (vertex
  // indices), #V; 0 at the sources, ≥ 0 elsewhere (small negative values near the
  // sources are clamped to 0); +infinity on connected components that contain no
  // source. Throws Error if `sources` is empty or holds an index out of range.
  Eigen::VectorXd From(const std::vector<int>& sources) const;

  // The heat time t = m·h², mm².
  double heat_time() const { return t_; }
  int num_vertices() const { return num_vertices_; }

 private:
  struct Impl;
  Eigen::VectorXd FromInner(const std::vector<int>& sources) const;  // welded ids
  double t_ = 0.0;
  int num_vertices_ = 0;  // of the input mesh
  int num_inner_ = 0;     // after welding UV seams
  std::shared_ptr<const WeldedMesh> weld_;  // null when the mesh has no seam copies
  std::shared_ptr<const Impl> impl_;
};

// Shortest paths along mesh edges (Dijkstra), mm, #V; +infinity where no edge
// path exists. Exact for the edge graph, and so an upper bound on the geodesic
// distance: it overestimates paths that cut across triangles (on the
// alternating-diagonal grid by up to ~8 %, see the tests). For comparison and for
// meshes where the heat method's smoothing near the source matters.
Eigen::VectorXd DijkstraDistance(const TriMesh& mesh, const std::vector<int>& sources);

}  // namespace crease
