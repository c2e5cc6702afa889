// Loop subdivision (C. Loop, "Smooth Subdivision Surfaces Based on Triangles",
// 1987) of a triangle mesh's connectivity, as sparse linear maps: the positions
// after `levels` steps are S_L ⋯ S_1 V for any vertex positions V of the mesh, so
// a rig's frames are subdivided with one precomputation. The limit surface is C1
// (C2 away from extraordinary vertices): smooth across the coarse edges, where a
// flat or Phong-tessellated triangle mesh creases.
//
// Rules per step (Warren's β for the interior vertex rule):
//   interior edge (two faces)        3/8 (a + b) + 1/8 (c + d), c, d opposite
//   boundary edge (one face)         1/2 (a + b)
//   interior vertex of valence n     (1 − nβ) v + β Σ neighbours,
//                                    β = (5/8 − (3/8 + cos(2π/n)/4)²) / n
//   boundary vertex (two boundary    3/4 v + 1/8 (b1 + b2): the boundary is a cubic
//     edges)                           B-spline, so rims (lips, eyelids) stay smooth
//   other vertices (corners, non-manifold) and edges with more than two faces:
//     kept / midpoint.
// Face f of a step becomes faces 4f + 0..3 of the next: (a, m_ab, m_ca),
// (m_ab, b, m_bc), (m_ca, m_bc, c), (m_ab, m_bc, m_ca); LocateLoopChild maps a
// point's barycentrics in f to its child and the barycentrics there, so a point
// given on the coarse mesh (a UV raster's triangle and barycentrics) has a fixed
// place on the subdivided one.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "core/types.h"

namespace crease {

struct LoopSubdivision {
  int num_vertices = 0;  // of the input mesh (columns of steps.front())
  // Step l maps the vertices of level l to those of level l + 1 (row-major,
  // rows: the level's vertices first, then one per edge).
  std::vector<Eigen::SparseMatrix<double, Eigen::RowMajor>> steps;
  MatX3i faces;          // the faces after the last step (4^L per input face)

  int levels() const { return static_cast<int>(steps.size()); }
  // The subdivided positions of V (#num_vertices × 3).
  MatX3d Apply(const MatX3d& V) const;
};

// `F`: triangles over vertices 0..num_vertices−1 (unused vertices are carried
// along unchanged). `levels` ≥ 0.
LoopSubdivision BuildLoopSubdivision(const MatX3i& F, int num_vertices, int levels);

// The child of a face that holds the point of barycentrics `b` (in the face's
// corner order), and the point's barycentrics in that child (the children's
// corners as listed above). Repeated L times this descends L levels.
int LocateLoopChild(Eigen::Vector3d* b);

}  // namespace crease
