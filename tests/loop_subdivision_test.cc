// Loop subdivision as sparse linear maps (core/loop_subdivision.h): affine
// invariance, smoothing of a polyhedron's creases, locality (a two-ring region
// gives the whole mesh's surface over its middle face) and the descent of a
// point's barycentrics.
#include "core/loop_subdivision.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "core/error.h"
#include "core/mesh_primitives.h"
#include "core/rng.h"

namespace crease {
namespace {

// Largest angle (degrees) between the normals of two faces sharing an edge.
double MaxDihedral(const MatX3d& V, const MatX3i& F) {
  std::vector<Eigen::Vector3d> n(F.rows());
  for (int f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    n[f] = (b - a).cross(c - a).normalized();
  }
  std::map<std::pair<int, int>, int> first;
  double worst = 0.0;
  for (int f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = first.find(key);
      if (it == first.end()) {
        first[key] = f;
      } else {
        worst = std::max(worst, std::acos(std::clamp(n[f].dot(n[it->second]), -1.0, 1.0)) * 180.0 / M_PI);
      }
    }
  }
  return worst;
}

TEST(LoopSubdivision, RowsAreAffineAndAPlaneStaysFlat) {
  const TriMesh grid = MakeGrid(6, 5, 10.0, 8.0);
  const LoopSubdivision s = BuildLoopSubdivision(grid.F, grid.num_vertices(), 3);
  ASSERT_EQ(s.levels(), 3);
  EXPECT_EQ(s.faces.rows(), 64 * grid.num_faces());
  for (const auto& S : s.steps) {
    const Eigen::VectorXd sums = S * Eigen::VectorXd::Ones(S.cols());
    EXPECT_LT((sums.array() - 1.0).abs().maxCoeff(), 1e-12);
  }
  // Tilt the grid into the plane z = 0.3 x − 0.2 y + 1: every subdivided point stays on it.
  MatX3d V = grid.V;
  V.col(2) = 0.3 * V.col(0) - 0.2 * V.col(1) + Eigen::VectorXd::Ones(V.rows());
  const MatX3d X = s.Apply(V);
  const Eigen::VectorXd off = X.col(2) - (0.3 * X.col(0) - 0.2 * X.col(1) + Eigen::VectorXd::Ones(X.rows()));
  EXPECT_LT(off.cwiseAbs().maxCoeff(), 1e-9);
}

TEST(LoopSubdivision, SmoothsTheCreasesOfAPolyhedron) {
  const TriMesh ico = MakeIcosphere(50.0, 0);  // 20 faces, creases of about 42°
  const double coarse = MaxDihedral(ico.V, ico.F);
  EXPECT_GT(coarse, 35.0);
  double previous = coarse;
  for (int levels = 1; levels <= 3; ++levels) {
    const LoopSubdivision s = BuildLoopSubdivision(ico.F, ico.num_vertices(), levels);
    const double d = MaxDihedral(s.Apply(ico.V), s.faces);
    EXPECT_LT(d, 0.65 * previous) << levels;  // each step roughly halves the crease
    previous = d;
  }
  EXPECT_LT(previous, coarse / 6.0);
}

TEST(LoopSubdivision, ATwoRingRegionGivesTheWholeMeshSurfaceOverItsMiddleFace) {
  TriMesh sphere = MakeIcosphere(40.0, 2);
  Rng rng(11);
  for (int v = 0; v < sphere.num_vertices(); ++v) sphere.V.row(v) *= 1.0 + 0.05 * rng.Normal();
  const int levels = 3, face = 17;
  // Faces within two rings of face 17's corners, face 17 first.
  std::set<int> ring = {sphere.F(face, 0), sphere.F(face, 1), sphere.F(face, 2)};
  std::vector<int> faces = {face};
  for (int step = 0; step < 2; ++step) {
    std::set<int> next = ring;
    for (int f = 0; f < sphere.num_faces(); ++f) {
      const bool touches = ring.count(sphere.F(f, 0)) || ring.count(sphere.F(f, 1)) || ring.count(sphere.F(f, 2));
      if (!touches) continue;
      if (std::find(faces.begin(), faces.end(), f) == faces.end()) faces.push_back(f);
      for (int k = 0; k < 3; ++k) next.insert(sphere.F(f, k));
    }
    ring = next;
  }
  ASSERT_LT(faces.size(), static_cast<size_t>(sphere.num_faces()));
  std::vector<int> local(sphere.num_vertices(), -1), input;
  MatX3i F(static_cast<int>(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      int& l = local[sphere.F(faces[i], k)];
      if (l < 0) {
        l = static_cast<int>(input.size());
        input.push_back(sphere.F(faces[i], k));
      }
      F(static_cast<int>(i), k) = l;
    }
  }
  MatX3d V(static_cast<int>(input.size()), 3);
  for (size_t i = 0; i < input.size(); ++i) V.row(static_cast<int>(i)) = sphere.V.row(input[i]);
  const LoopSubdivision whole = BuildLoopSubdivision(sphere.F, sphere.num_vertices(), levels);
  const LoopSubdivision part = BuildLoopSubdivision(F, static_cast<int>(input.size()), levels);
  const MatX3d Xw = whole.Apply(sphere.V), Xp = part.Apply(V);
  // Children of face 17 are faces 17·64 … in the whole mesh and 0 … 63 in the region.
  double worst = 0.0;
  for (int c = 0; c < 64; ++c) {
    for (int k = 0; k < 3; ++k) {
      worst = std::max(worst, (Xw.row(whole.faces(face * 64 + c, k)) - Xp.row(part.faces(c, k))).norm());
    }
  }
  EXPECT_LT(worst, 1e-9);
  // ... while the region's rim is not the whole mesh's (the test can fail).
  const int rim_face = static_cast<int>(faces.size()) - 1;
  EXPECT_GT((Xw.row(whole.faces(faces[rim_face] * 64, 0)) - Xp.row(part.faces(rim_face * 64, 0))).norm(), 1e-3);
}

TEST(LoopSubdivision, BarycentricsDescendToTheSamePoint) {
  // With midpoint splits (the positions the children's corners take before any
  // smoothing), the located child and barycentrics name the same point.
  Rng rng(3);
  const Eigen::Vector3d A(0, 0, 0), B(4, 1, 0), C(1, 3, 2);
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d b(rng.Uniform(), rng.Uniform(), rng.Uniform());
    b /= b.sum();
    const Eigen::Vector3d p = b[0] * A + b[1] * B + b[2] * C;
    Eigen::Vector3d c = b;
    const int child = LocateLoopChild(&c);
    const Eigen::Vector3d ab = (A + B) / 2, bc = (B + C) / 2, ca = (C + A) / 2;
    const Eigen::Vector3d corners[4][3] = {{A, ab, ca}, {ab, B, bc}, {ca, bc, C}, {ab, bc, ca}};
    const Eigen::Vector3d q = c[0] * corners[child][0] + c[1] * corners[child][1] + c[2] * corners[child][2];
    EXPECT_LT((p - q).norm(), 1e-12);
    EXPECT_GE(c.minCoeff(), -1e-12);
    EXPECT_NEAR(c.sum(), 1.0, 1e-12);
  }
}

TEST(LoopSubdivision, RejectsBadInput) {
  MatX3i F(1, 3);
  F << 0, 1, 5;
  EXPECT_THROW(BuildLoopSubdivision(F, 3, 1), Error);
  F << 0, 1, 2;
  EXPECT_THROW(BuildLoopSubdivision(F, 3, 9), Error);
  const LoopSubdivision s = BuildLoopSubdivision(F, 3, 1);
  EXPECT_THROW(s.Apply(MatX3d::Zero(4, 3)), Error);
}

}  // namespace
}  // namespace crease
