#include "core/mesh_ops.h"

#include <Eigen/IterativeLinearSolvers>
#include <tbb/parallel_for.h>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <limits>
#include <numeric>
#include <queue>
#include <utility>

#include "core/error.h"
#include "core/options.h"

namespace crease {
namespace {

using Triplet = Eigen::Triplet<double>;
using Ldlt = Eigen::SimplicialLDLT<SpMat>;

Eigen::Vector3d Corner(const TriMesh& mesh, int f, int k) {
  return mesh.V.row(mesh.F(f, k)).transpose();
}

// Vertices on a boundary edge (an edge used by exactly one triangle).
std::vector<char> BoundaryMask(const TriMesh& mesh) {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(static_cast<size_t>(mesh.num_faces()) * 3);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<char> boundary(mesh.num_vertices(), 0);
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) boundary[edges[i].first] = boundary[edges[i].second] = 1;
    i = j;
  }
  return boundary;
}

// Connected components of the vertex graph given by the triangles; isolated
// vertices are components of their own. Returns a component id per vertex.
std::vector<int> ConnectedComponents(const TriMesh& mesh, int* num_components) {
  const int nv = mesh.num_vertices();
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 1; k < 3; ++k) {
      const int a = find(mesh.F(f, 0)), b = find(mesh.F(f, k));
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  std::vector<int> id(nv, -1), root_id(nv, -1);
  int n = 0;
  for (int v = 0; v < nv; ++v) {
    const int r = find(v);
    if (root_id[r] < 0) root_id[r] = n++;
    id[v] = root_id[r];
  }
  *num_components = n;
  return id;
}

// A with the rows and columns of `fixed` vertices replaced by the identity. Keeps
// A symmetric; the caller moves the coupling A(free, fixed)·x_fixed to the
// right-hand side.
SpMat WithIdentityRows(const SpMat& A, const std::vector<char>& fixed) {
  std::vector<Triplet> t;
  t.reserve(static_cast<size_t>(A.nonZeros()) + fixed.size());
  for (int c = 0; c < A.outerSize(); ++c) {
    for (SpMat::InnerIterator it(A, c); it; ++it) {
      if (!fixed[it.row()] && !fixed[it.col()]) t.emplace_back(it.row(), it.col(), it.value());
    }
  }
  for (int i = 0; i < static_cast<int>(fixed.size()); ++i) {
    if (fixed[i]) t.emplace_back(i, i, 1.0);
  }
  SpMat out(A.rows(), A.cols());
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

// A(free rows, fixed columns), zero elsewhere: rhs_free -= Coupling · x.
SpMat Coupling(const SpMat& A, const std::vector<char>& fixed) {
  std::vector<Triplet> t;
  for (int c = 0; c < A.outerSize(); ++c) {
    if (!fixed[c]) continue;
    for (SpMat::InnerIterator it(A, c); it; ++it) {
      if (!fixed[it.row()]) t.emplace_back(it.row(), it.col(), it.value());
    }
  }
  SpMat out(A.rows(), A.cols());
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

void Factorize(Ldlt& solver, const SpMat& A, const char* what) {
  solver.compute(A);
  Require(solver.info() == Eigen::Success,
          fmt::format("{}: sparse LDLT factorisation of a {}×{} system with {} non-zeros failed "
                      "(degenerate or non-manifold mesh?)",
                      what, A.rows(), A.cols(), A.nonZeros()));
}

}  // namespace

// ---------------------------------------------------------------------------

MatX3d VertexNormals(const TriMesh& mesh) {
  RequireFaceIndices(mesh, "VertexNormals");
  MatX3d N = MatX3d::Zero(mesh.num_vertices(), 3);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p0 = Corner(mesh, f, 0), p1 = Corner(mesh, f, 1), p2 = Corner(mesh, f, 2);
    const Eigen::RowVector3d n = (p1 - p0).cross(p2 - p0).transpose();
    for (int k = 0; k < 3; ++k) N.row(mesh.F(f, k)) += n;
  }
  // Vertices duplicated along UV seams share one normal (sum over all copies).
  const std::vector<int> rep = CoincidentVertexRepresentatives(mesh);
  for (int i = 0; i < N.rows(); ++i) {
    if (rep[i] != i) N.row(rep[i]) += N.row(i);
  }
  for (int i = 0; i < N.rows(); ++i) {
    if (rep[i] != i) N.row(i) = N.row(rep[i]);
  }
  for (int i = 0; i < N.rows(); ++i) {
    const double len = N.row(i).norm();
    if (len > 0.0) {
      N.row(i) /= len;
    } else {
      N.row(i).setZero();
    }
  }
  return N;
}

SpMat CotangentLaplacian(const TriMesh& mesh) {
  RequireFaceIndices(mesh, "CotangentLaplacian");
  const int nv = mesh.num_vertices();
  std::vector<Triplet> t;
  t.reserve(static_cast<size_t>(mesh.num_faces()) * 6 + nv);
  Eigen::VectorXd diagonal = Eigen::VectorXd::Zero(nv);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p[3] = {Corner(mesh, f, 0), Corner(mesh, f, 1), Corner(mesh, f, 2)};
    const double double_area = (p[1] - p[0]).cross(p[2] - p[0]).norm();
    if (!(double_area > 0.0)) continue;
    for (int k = 0; k < 3; ++k) {
      // Angle at corner k is opposite edge (i, j).
      const int i = (k + 1) % 3, j = (k + 2) % 3;
      const Eigen::Vector3d a = p[i] - p[k], b = p[j] - p[k];
      const double w = 0.5 * a.dot(b) / double_area;  // cot θ_k / 2
      const int vi = mesh.F(f, i), vj = mesh.F(f, j);
      t.emplace_back(vi, vj, -w);
      t.emplace_back(vj, vi, -w);
      diagonal[vi] += w;
      diagonal[vj] += w;
    }
  }
  for (int i = 0; i < nv; ++i) t.emplace_back(i, i, diagonal[i]);
  SpMat L(nv, nv);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

SpMat MassMatrix(const TriMesh& mesh, MassMatrixType type) {
  RequireFaceIndices(mesh, "MassMatrix");
  const int nv = mesh.num_vertices();
  Eigen::VectorXd m = Eigen::VectorXd::Zero(nv);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p[3] = {Corner(mesh, f, 0), Corner(mesh, f, 1), Corner(mesh, f, 2)};
    const double double_area = (p[1] - p[0]).cross(p[2] - p[0]).norm();
    if (!(double_area > 0.0)) continue;
    const double area = 0.5 * double_area;
    if (type == MassMatrixType::kBarycentric) {
      for (int k = 0; k < 3; ++k) m[mesh.F(f, k)] += area / 3.0;
      continue;
    }
    // Mixed Voronoi area (Meyer, Desbrun, Schröder, Barr 2003, Fig. 4).
    double dots[3];
    for (int k = 0; k < 3; ++k) {
      dots[k] = (p[(k + 1) % 3] - p[k]).dot(p[(k + 2) % 3] - p[k]);
    }
    int obtuse = -1;
    for (int k = 0; k < 3; ++k) {
      if (dots[k] < 0.0) obtuse = k;
    }
    if (obtuse >= 0) {
      for (int k = 0; k < 3; ++k) m[mesh.F(f, k)] += (k == obtuse ? 0.5 : 0.25) * area;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      // Voronoi area at corner k: (|e_ki|² cot θ_j + |e_kj|² cot θ_i) / 8.
      const int i = (k + 1) % 3, j = (k + 2) % 3;
      const double cot_i = dots[i] / double_area, cot_j = dots[j] / double_area;
      m[mesh.F(f, k)] +=
          ((p[i] - p[k]).squaredNorm() * cot_j + (p[j] - p[k]).squaredNorm() * cot_i) / 8.0;
    }
  }
  SpMat M(nv, nv);
  std::vector<Triplet> t;
  t.reserve(nv);
  for (int i = 0; i < nv; ++i) t.emplace_back(i, i, m[i]);
  M.setFromTriplets(t.begin(), t.end());
  return M;
}

// ---------------------------------------------------------------------------
// MeshLowpass

void LowpassOptions::VisitFields(OptionVisitor& v) {
  v.Field("bandwidth_mm", bandwidth_mm);
  v.Field("steps", steps);
  v.Field("mass_matrix", mass_matrix);
  v.Field("boundary", boundary);
  v.Field("solver", solver);
  v.Field("iterative_tolerance", iterative_tolerance);
}

void LowpassOptions::Check() const {
  CheckGe("LowpassOptions", "bandwidth_mm", bandwidth_mm, 0.0);
  CheckLt("LowpassOptions", "bandwidth_mm", bandwidth_mm, std::numeric_limits<double>::infinity());
  CheckGe("LowpassOptions", "steps", steps, 1);
  CheckGt("LowpassOptions", "iterative_tolerance", iterative_tolerance, 0.0);
  CheckLt("LowpassOptions", "iterative_tolerance", iterative_tolerance, 1e-2);
}

struct MeshLowpass::Impl {
  Eigen::VectorXd mass;      // diagonal of M
  std::vector<char> fixed;   // vertices that keep their input value
  SpMat coupling;            // τ L(free, fixed)
  Ldlt solver;               // M + τL with identity rows for fixed vertices ("direct")
  SpMat system;              // the same matrix, for "iterative"
  double tolerance = 0.0;
  bool iterative = false;
  // One backward-Euler step: solves (M + τL) x = rhs, warm-started from `guess`.
  Eigen::MatrixXd Solve(const Eigen::MatrixXd& rhs, const Eigen::MatrixXd& guess) const {
    if (!iterative) return solver.solve(rhs);
    Eigen::ConjugateGradient<SpMat, Eigen::Lower | Eigen::Upper, Eigen::DiagonalPreconditioner<double>> cg;
    cg.setTolerance(tolerance);
    cg.setMaxIterations(1000);
    cg.compute(system);
    Eigen::MatrixXd x(rhs.rows(), rhs.cols());
    // Columns are independent: solved in parallel (same bytes for any thread count).
    tbb::parallel_for(0, static_cast<int>(rhs.cols()),
                      [&](int c) { x.col(c) = cg.solveWithGuess(rhs.col(c), guess.col(c)); });
    return x;
  }
};

MeshLowpass::MeshLowpass(const TriMesh& input_mesh, const LowpassOptions& options)
    : options_(options), num_vertices_(input_mesh.num_vertices()) {
  options_.Check();
  // Filter on the seam-welded mesh so UV seams are not boundaries.
  auto weld = std::make_shared<const WeldedMesh>(WeldCoincidentVertices(input_mesh));
  const TriMesh& mesh = weld->mesh;
  num_inner_ = mesh.num_vertices();
  if (num_inner_ < num_vertices_) weld_ = weld;
  const double sigma = options_.bandwidth_mm;
  t_ = 0.5 * sigma * sigma;
  if (t_ == 0.0) return;
  const double tau = t_ / options_.steps;
  auto impl = std::make_shared<Impl>();
  const SpMat M = MassMatrix(mesh, options_.mass_matrix);
  const SpMat L = CotangentLaplacian(mesh);
  impl->mass = M.diagonal();
  impl->fixed.assign(num_inner_, 0);
  const std::vector<char> boundary =
      options_.boundary == LowpassBoundary::kFixed ? BoundaryMask(mesh) : std::vector<char>(num_inner_, 0);
  for (int i = 0; i < num_inner_; ++i) {
    impl->fixed[i] = boundary[i] || !(impl->mass[i] > 0.0);
  }
  const SpMat A = SpMat(M + tau * L);
  impl->coupling = Coupling(A, impl->fixed);
  impl->iterative = options_.solver == LowpassSolver::kIterative;
  impl->tolerance = options_.iterative_tolerance;
  if (impl->iterative) {
    impl->system = WithIdentityRows(A, impl->fixed);
  } else {
    Factorize(impl->solver, WithIdentityRows(A, impl->fixed), "MeshLowpass");
  }
  impl_ = std::move(impl);
}

Eigen::VectorXd MeshLowpass::ApplyInner(const Eigen::VectorXd& x) const {
  if (!impl_) return x;
  Eigen::VectorXd cur = x;
  for (int s = 0; s < options_.steps; ++s) {
    // One backward-Euler step (M + τL) x_{k+1} = M x_k of G (Sec. 4.1), fixed vertices held.
    Eigen::VectorXd rhs = impl_->mass.cwiseProduct(cur) - impl_->coupling * x;
    for (int i = 0; i < num_inner_; ++i) {
      if (impl_->fixed[i]) rhs[i] = x[i];
    }
    cur = impl_->Solve(rhs, cur);
  }
  return cur;
}

Eigen::MatrixXd MeshLowpass::ApplyInner(const Eigen::MatrixXd& X) const {
  if (!impl_) return X;
  const Eigen::MatrixXd& X0 = X;
  const Eigen::MatrixXd held = impl_->coupling * X0;
  Eigen::MatrixXd cur = X0;
  for (int s = 0; s < options_.steps; ++s) {
    Eigen::MatrixXd rhs = impl_->mass.asDiagonal() * cur - held;
    for (int i = 0; i < num_inner_; ++i) {
      if (impl_->fixed[i]) rhs.row(i) = X0.row(i);
    }
    cur = impl_->Solve(rhs, cur);
  }
  return cur;
}

Eigen::MatrixXd MeshLowpass::Gather(const Eigen::MatrixXd& X) const {
  if (!weld_) return X;
  // Seam copies are averaged into their welded vertex.
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(num_inner_, X.cols());
  Eigen::VectorXd count = Eigen::VectorXd::Zero(num_inner_);
  for (int v = 0; v < num_vertices_; ++v) {
    W.row(weld_->welded_of[v]) += X.row(v);
    count[weld_->welded_of[v]] += 1.0;
  }
  for (int w = 0; w < num_inner_; ++w) W.row(w) /= count[w];
  return W;
}

Eigen::MatrixXd MeshLowpass::Scatter(const Eigen::MatrixXd& W) const {
  if (!weld_) return W;
  Eigen::MatrixXd X(num_vertices_, W.cols());
  for (int v = 0; v < num_vertices_; ++v) X.row(v) = W.row(weld_->welded_of[v]);
  return X;
}

Eigen::VectorXd MeshLowpass::Apply(const Eigen::VectorXd& x) const {
  Require(x.size() == num_vertices_,
          fmt::format("MeshLowpass::Apply: signal has {} values, but the mesh has {} vertices",
                      x.size(), num_vertices_));
  if (!impl_) return x;
  if (!weld_) return ApplyInner(x);
  return Scatter(ApplyInner(Eigen::VectorXd(Gather(x))));
}

MatX3d MeshLowpass::Apply(const MatX3d& X) const {
  Require(X.rows() == num_vertices_,
          fmt::format("MeshLowpass::Apply: signal has {} rows, but the mesh has {} vertices",
                      X.rows(), num_vertices_));
  if (!impl_) return X;
  return Scatter(ApplyInner(Gather(Eigen::MatrixXd(X))));
}

double MeshLowpass::Response(double wavenumber) const {
  const double n = options_.steps;
  return std::pow(1.0 + wavenumber * wavenumber * t_ / n, -n);
}

double MeshLowpass::GaussianResponse(double wavenumber) const {
  return std::exp(-wavenumber * wavenumber * t_);
}

// ---------------------------------------------------------------------------
// GeodesicDistance

void GeodesicOptions::VisitFields(OptionVisitor& v) {
  v.Field("time_factor", time_factor);
  v.Field("boundary", boundary);
  v.Field("mass_matrix", mass_matrix);
  v.Field("one_ring_offset", one_ring_offset);
}

void GeodesicOptions::Check() const {
  CheckGt("GeodesicOptions", "time_factor", time_factor, 0.0);
  CheckLt("GeodesicOptions", "time_factor", time_factor, std::numeric_limits<double>::infinity());
}

struct GeodesicDistance::Impl {
  MatX3i F;
  // Per triangle: area-weighted gradient operators. grad_k = N × e_k, e_k the edge
  // opposite corner k (counter-clockwise), so ∇u = Σ_k u_k grad_k / (2A) and
  // ∫_T X·∇φ_k = X·grad_k / 2.
  std::vector<Eigen::Matrix3d> grad;  // columns grad_0..2; zero for degenerate triangles
  std::vector<int> component;         // per vertex
  int num_components = 0;
  std::vector<char> heat_fixed;       // zero-mass vertices (both heat systems)
  std::vector<char> dirichlet_fixed;  // + boundary vertices (Dirichlet heat system)
  std::vector<char> poisson_fixed;    // one pinned vertex per component + zero-mass vertices
  MatX3d V;
  bool one_ring_offset = true;
  bool use_neumann = true;
  bool use_dirichlet = false;
  SpMat dirichlet_coupling;           // (M + tL)(free, boundary)
  Ldlt heat_neumann, heat_dirichlet, poisson;
};

GeodesicDistance::GeodesicDistance(const TriMesh& input_mesh, const GeodesicOptions& options)
    : num_vertices_(input_mesh.num_vertices()) {
  options.Check();
  // Distances flow across UV seams: work on the seam-welded mesh.
  auto weld = std::make_shared<const WeldedMesh>(WeldCoincidentVertices(input_mesh));
  const TriMesh& mesh = weld->mesh;
  num_inner_ = mesh.num_vertices();
  if (num_inner_ < num_vertices_) weld_ = weld;
  RequireFaceIndices(mesh, "GeodesicDistance");
  Require(mesh.num_faces() > 0, "GeodesicDistance: mesh has no triangles");
  const double h = MeanEdgeLength(mesh);
  t_ = options.time_factor * h * h;
  auto impl = std::make_shared<Impl>();
  const int nv = num_inner_;
  impl->F = mesh.F;
  impl->V = mesh.V;
  impl->one_ring_offset = options.one_ring_offset;
  impl->grad.resize(mesh.num_faces());
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p[3] = {Corner(mesh, f, 0), Corner(mesh, f, 1), Corner(mesh, f, 2)};
    const Eigen::Vector3d n = (p[1] - p[0]).cross(p[2] - p[0]);
    const double len = n.norm();
    if (!(len > 0.0)) {
      impl->grad[f].setZero();
      continue;
    }
    const Eigen::Vector3d unit = n / len;
    for (int k = 0; k < 3; ++k) {
      impl->grad[f].col(k) = unit.cross(p[(k + 2) % 3] - p[(k + 1) % 3]);
    }
  }
  impl->component = ConnectedComponents(mesh, &impl->num_components);

  const SpMat M = MassMatrix(mesh, options.mass_matrix);
  const SpMat L = CotangentLaplacian(mesh);
  const Eigen::VectorXd mass = M.diagonal();
  impl->heat_fixed.assign(nv, 0);
  impl->poisson_fixed.assign(nv, 0);
  std::vector<char> pinned_component(impl->num_components, 0);
  for (int i = 0; i < nv; ++i) {
    const bool no_area = !(mass[i] > 0.0);
    impl->heat_fixed[i] = no_area;
    char& pinned = pinned_component[impl->component[i]];
    if (no_area || !pinned) impl->poisson_fixed[i] = 1;
    if (!no_area) pinned = 1;
  }
  // A component made only of zero-area vertices has all of them pinned above;
  // a component with area has exactly one vertex with area pinned.

  const std::vector<char> boundary = BoundaryMask(mesh);
  const bool open = std::any_of(boundary.begin(), boundary.end(), [](char b) { return b != 0; });
  impl->use_neumann = !open || options.boundary != GeodesicBoundary::kDirichlet;
  impl->use_dirichlet = open && options.boundary != GeodesicBoundary::kNeumann;

  const SpMat A = SpMat(M + t_ * L);
  if (impl->use_neumann) {
    Factorize(impl->heat_neumann, WithIdentityRows(A, impl->heat_fixed), "GeodesicDistance (heat)");
  }
  if (impl->use_dirichlet) {
    impl->dirichlet_fixed = impl->heat_fixed;
    for (int i = 0; i < nv; ++i) impl->dirichlet_fixed[i] |= boundary[i];
    impl->dirichlet_coupling = Coupling(A, impl->dirichlet_fixed);
    Factorize(impl->heat_dirichlet, WithIdentityRows(A, impl->dirichlet_fixed),
              "GeodesicDistance (Dirichlet heat)");
  }
  Factorize(impl->poisson, WithIdentityRows(L, impl->poisson_fixed), "GeodesicDistance (Poisson)");
  impl_ = std::move(impl);
}

Eigen::VectorXd GeodesicDistance::FromInner(const std::vector<int>& sources) const {
  const int nv = num_inner_;
  const Impl& m = *impl_;
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(nv);
  for (int s : sources) delta[s] = 1.0;

  // 1. Heat flow, one backward-Euler step of time t (Crane et al. 2013, Alg. 1 step I).
  Eigen::VectorXd u = Eigen::VectorXd::Zero(nv);
  if (m.use_neumann) u += m.heat_neumann.solve(delta);
  if (m.use_dirichlet) {
    // u = δ on the boundary (0 except at boundary sources); the coupling moves
    // the boundary values to the right-hand side.
    Eigen::VectorXd rhs = delta - m.dirichlet_coupling * delta;
    for (int i = 0; i < nv; ++i) {
      if (m.dirichlet_fixed[i]) rhs[i] = delta[i];
    }
    u += m.heat_dirichlet.solve(rhs);
  }

  // 2.–3. Normalised negative gradient per triangle and its weak divergence
  // b_i = ∫ X·∇φ_i (Alg. 1 steps II–III; b = −(integrated divergence)).
  Eigen::VectorXd b = Eigen::VectorXd::Zero(nv);
  for (int f = 0; f < static_cast<int>(m.grad.size()); ++f) {
    const Eigen::Vector3d uf(u[m.F(f, 0)], u[m.F(f, 1)], u[m.F(f, 2)]);
    const Eigen::Vector3d g = m.grad[f] * uf;  // 2A·∇u
    const double len = g.norm();
    if (!(len > 0.0) || !std::isfinite(len)) continue;
    const Eigen::Vector3d X = -g / len;
    const Eigen::Vector3d contrib = 0.5 * (m.grad[f].transpose() * X);
    for (int k = 0; k < 3; ++k) b[m.F(f, k)] += contrib[k];
  }
  for (int i = 0; i < nv; ++i) {
    if (m.poisson_fixed[i]) b[i] = 0.0;
  }

  // 3. Poisson: L φ = b (Alg. 1 step III, in the PSD sign convention).
  Eigen::VectorXd phi = m.poisson.solve(b);

  // 4. Additive constant per component. φ is a least-squares fit and rounds off
  // the cone tip at the sources, so φ(source) sits above the cone: with
  // one_ring_offset, the constant is fitted instead on the sources' one-ring,
  // where the distance is known (the edge length to the nearest adjacent source);
  // otherwise it is the mean of φ over the sources (Crane et al.).
  const double inf = std::numeric_limits<double>::infinity();
  const int nc = m.num_components;
  std::vector<double> source_sum(nc, 0.0), ring_sum(nc, 0.0);
  std::vector<int> source_count(nc, 0), ring_count(nc, 0);
  std::vector<char> is_source(nv, 0);
  for (int s : sources) {
    if (is_source[s]) continue;  // repeated index
    is_source[s] = 1;
    source_sum[m.component[s]] += phi[s];
    ++source_count[m.component[s]];
  }
  if (m.one_ring_offset) {
    Eigen::VectorXd ring = Eigen::VectorXd::Constant(nv, inf);
    for (int f = 0; f < m.F.rows(); ++f) {
      for (int k = 0; k < 3; ++k) {
        const int p = m.F(f, k), q = m.F(f, (k + 1) % 3);
        if (is_source[p] == is_source[q]) continue;
        const int s = is_source[p] ? p : q, j = is_source[p] ? q : p;
        ring[j] = std::min(ring[j], (m.V.row(s) - m.V.row(j)).norm());
      }
    }
    for (int j = 0; j < nv; ++j) {
      if (ring[j] == inf) continue;
      ring_sum[m.component[j]] += phi[j] - ring[j];
      ++ring_count[m.component[j]];
    }
  }
  for (int i = 0; i < nv; ++i) {
    const int c = m.component[i];
    if (source_count[c] == 0) {
      phi[i] = inf;
      continue;
    }
    const double offset = ring_count[c] > 0 ? ring_sum[c] / ring_count[c]
                                            : source_sum[c] / source_count[c];
    phi[i] = std::max(0.0, phi[i] - offset);
  }
  for (int s : sources) phi[s] = 0.0;
  return phi;
}

Eigen::VectorXd GeodesicDistance::From(const std::vector<int>& sources) const {
  Require(!sources.empty(), "GeodesicDistance::From: no source vertices given");
  for (int s : sources) {
    Require(s >= 0 && s < num_vertices_, fmt::format("GeodesicDistance::From: source vertex {} is out of "
                                                     "range (the mesh has {} vertices)", s, num_vertices_));
  }
  if (!weld_) return FromInner(sources);
  std::vector<int> inner;
  for (int s : sources) inner.push_back(weld_->welded_of[s]);
  std::sort(inner.begin(), inner.end());
  inner.erase(std::unique(inner.begin(), inner.end()), inner.end());
  const Eigen::VectorXd d = FromInner(inner);
  Eigen::VectorXd out(num_vertices_);
  for (int v = 0; v < num_vertices_; ++v) out[v] = d[weld_->welded_of[v]];
  return out;
}

// ---------------------------------------------------------------------------

Eigen::VectorXd DijkstraDistance(const TriMesh& mesh, const std::vector<int>& sources) {
  RequireFaceIndices(mesh, "DijkstraDistance");
  const int nv = mesh.num_vertices();
  Require(!sources.empty(), "DijkstraDistance: no source vertices given");
  for (int s : sources) {
    Require(s >= 0 && s < nv, fmt::format("DijkstraDistance: source vertex {} is out of range "
                                          "(the mesh has {} vertices)", s, nv));
  }
  // Compressed adjacency (each undirected edge stored in both directions; an
  // interior edge appears twice per direction, which Dijkstra tolerates).
  std::vector<int> start(nv + 1, 0);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) start[mesh.F(f, k) + 1] += 2;
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<int> adj(start[nv]);
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k);
      adj[fill[a]++] = mesh.F(f, (k + 1) % 3);
      adj[fill[a]++] = mesh.F(f, (k + 2) % 3);
    }
  }
  const double inf = std::numeric_limits<double>::infinity();
  Eigen::VectorXd d = Eigen::VectorXd::Constant(nv, inf);
  using Entry = std::pair<double, int>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue;
  for (int s : sources) {
    d[s] = 0.0;
    queue.emplace(0.0, s);
  }
  while (!queue.empty()) {
    const auto [dist, v] = queue.top();
    queue.pop();
    if (dist > d[v]) continue;
    for (int e = start[v]; e < start[v + 1]; ++e) {
      const int w = adj[e];
      const double nd = dist + (mesh.V.row(v) - mesh.V.row(w)).norm();
      if (nd < d[w]) {
        d[w] = nd;
        queue.emplace(nd, w);
      }
    }
  }
  return d;
}

}  // namespace crease
