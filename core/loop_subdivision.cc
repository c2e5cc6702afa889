#include "core/loop_subdivision.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"

namespace crease {

namespace {

// The edges of a triangle list: per face corner k the edge from corner k to k + 1,
// per edge its endpoints and the vertices opposite it (up to two) and its face count.
struct EdgeTable {
  std::vector<std::array<int, 2>> ends;
  std::vector<std::array<int, 2>> opposite;
  std::vector<int> faces;
  MatX3i face_edge;  // #F × 3
};

EdgeTable BuildEdges(const MatX3i& F) {
  struct HalfEdge {
    int lo, hi, face, corner;
  };
  std::vector<HalfEdge> h;
  h.reserve(3 * static_cast<size_t>(F.rows()));
  for (int f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      h.push_back({std::min(a, b), std::max(a, b), f, k});
    }
  }
  std::sort(h.begin(), h.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.lo != y.lo ? x.lo < y.lo : x.hi != y.hi ? x.hi < y.hi : x.face != y.face ? x.face < y.face
                                                                                    : x.corner < y.corner;
  });
  EdgeTable t;
  t.face_edge.resize(F.rows(), 3);
  for (size_t i = 0; i < h.size(); ++i) {
    if (i == 0 || h[i].lo != h[i - 1].lo || h[i].hi != h[i - 1].hi) {
      t.ends.push_back({h[i].lo, h[i].hi});
      t.opposite.push_back({-1, -1});
      t.faces.push_back(0);
    }
    const int e = static_cast<int>(t.ends.size()) - 1;
    t.face_edge(h[i].face, h[i].corner) = e;
    if (t.faces[e] < 2) t.opposite[e][t.faces[e]] = F(h[i].face, (h[i].corner + 2) % 3);
    ++t.faces[e];
  }
  return t;
}

double LoopBeta(int valence) {
  const double c = 3.0 / 8.0 + 0.25 * std::cos(2.0 * std::numbers::pi / valence);
  return (5.0 / 8.0 - c * c) / valence;
}

// One step: the matrix (n + #E) × n and the child faces.
Eigen::SparseMatrix<double, Eigen::RowMajor> LoopStep(const MatX3i& F, int n, MatX3i* children) {
  const EdgeTable t = BuildEdges(F);
  const int num_edges = static_cast<int>(t.ends.size());
  std::vector<std::vector<int>> neighbours(n), boundary(n);
  for (int e = 0; e < num_edges; ++e) {
    const auto [a, b] = t.ends[e];
    neighbours[a].push_back(b);
    neighbours[b].push_back(a);
    if (t.faces[e] == 1) {
      boundary[a].push_back(b);
      boundary[b].push_back(a);
    }
  }
  std::vector<Eigen::Triplet<double>> w;
  w.reserve(8 * static_cast<size_t>(n) + 4 * static_cast<size_t>(num_edges));
  for (int v = 0; v < n; ++v) {
    const bool interior = boundary[v].empty() && neighbours[v].size() >= 3;
    if (interior) {
      const int valence = static_cast<int>(neighbours[v].size());
      const double beta = LoopBeta(valence);
      w.emplace_back(v, v, 1.0 - valence * beta);
      for (int u : neighbours[v]) w.emplace_back(v, u, beta);
    } else if (boundary[v].size() == 2) {
      w.emplace_back(v, v, 0.75);
      for (int u : boundary[v]) w.emplace_back(v, u, 0.125);
    } else {
      w.emplace_back(v, v, 1.0);  // isolated, a corner or non-manifold: kept
    }
  }
  for (int e = 0; e < num_edges; ++e) {
    const auto [a, b] = t.ends[e];
    const int row = n + e;
    if (t.faces[e] == 2) {
      w.emplace_back(row, a, 0.375);
      w.emplace_back(row, b, 0.375);
      w.emplace_back(row, t.opposite[e][0], 0.125);
      w.emplace_back(row, t.opposite[e][1], 0.125);
    } else {
      w.emplace_back(row, a, 0.5);
      w.emplace_back(row, b, 0.5);
    }
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> S(n + num_edges, n);
  S.setFromTriplets(w.begin(), w.end());
  children->resize(4 * F.rows(), 3);
  for (int f = 0; f < F.rows(); ++f) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    const int ab = n + t.face_edge(f, 0), bc = n + t.face_edge(f, 1), ca = n + t.face_edge(f, 2);
    children->row(4 * f + 0) << a, ab, ca;
    children->row(4 * f + 1) << ab, b, bc;
    children->row(4 * f + 2) << ca, bc, c;
    children->row(4 * f + 3) << ab, bc, ca;
  }
  return S;
}

}  // namespace

LoopSubdivision BuildLoopSubdivision(const MatX3i& F, int num_vertices, int levels) {
  Require(levels >= 0 && levels <= 6, fmt::format("Loop subdivision: levels = {} must be in [0, 6]", levels));
  Require(num_vertices >= 0, "Loop subdivision: negative vertex count");
  Require(F.size() == 0 || (F.minCoeff() >= 0 && F.maxCoeff() < num_vertices),
          fmt::format("Loop subdivision: a face refers to a vertex outside [0, {})", num_vertices));
  LoopSubdivision s;
  s.num_vertices = num_vertices;
  s.faces = F;
  int n = num_vertices;
  for (int l = 0; l < levels; ++l) {
    MatX3i children;
    s.steps.push_back(LoopStep(s.faces, n, &children));
    n = static_cast<int>(s.steps.back().rows());
    s.faces = std::move(children);
  }
  return s;
}

MatX3d LoopSubdivision::Apply(const MatX3d& V) const {
  Require(V.rows() == num_vertices,
          fmt::format("Loop subdivision: {} positions for a mesh of {} vertices", V.rows(), num_vertices));
  MatX3d x = V;
  for (const auto& S : steps) {
    MatX3d y(S.rows(), 3);
    tbb::parallel_for(tbb::blocked_range<int>(0, static_cast<int>(S.rows()), 4096),
                      [&](const tbb::blocked_range<int>& r) {
                        for (int i = r.begin(); i < r.end(); ++i) {
                          Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
                          for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(S, i); it; ++it) {
                            p += it.value() * x.row(it.col());
                          }
                          y.row(i) = p;
                        }
                      });
    x = std::move(y);
  }
  return x;
}

int LocateLoopChild(Eigen::Vector3d* b) {
  Eigen::Vector3d& w = *b;
  if (w[0] >= 0.5) {
    w = Eigen::Vector3d(2 * w[0] - 1, 2 * w[1], 2 * w[2]);
    return 0;
  }
  if (w[1] >= 0.5) {
    w = Eigen::Vector3d(2 * w[0], 2 * w[1] - 1, 2 * w[2]);
    return 1;
  }
  if (w[2] >= 0.5) {
    w = Eigen::Vector3d(2 * w[0], 2 * w[1], 2 * w[2] - 1);
    return 2;
  }
  // The middle child (m_ab, m_bc, m_ca).
  w = Eigen::Vector3d(1 - 2 * w[2], 1 - 2 * w[0], 1 - 2 * w[1]);
  return 3;
}

}  // namespace crease
