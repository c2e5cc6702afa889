// Dense correspondence between a tracking rig and the rig a dataset's truth was
// made with, so that a capture or a track with any rig (the procedural head on an
// ICT-FaceKit dataset, an imported rig of a user's) is measured against the truth
// by surface position, not by vertex index (issue 15).
//
// Same topology (equal vertex counts): vertex i is vertex i. A part of the truth
// rig (every vertex's OBJ id and UV found in the truth's): vertex for vertex. Otherwise:
//   1. the similarity (scale, rotation, translation; Umeyama) that maps the
//      tracking rig's 68 neutral landmarks onto the truth rig's,
//   2. each face-chart vertex of the tracking rig, so placed, finds the nearest
//      point of the truth rig's face chart along its normal (within
//      `max_distance_mm` either side; Embree), as a triangle and barycentric
//      coordinates; vertices with no hit have no correspondence.
// The truth of a tracking vertex at a frame is then the barycentric combination of
// the truth's per-vertex values (3D positions, 2D projections; visible when the
// three corners are).
#pragma once

#include <vector>

#include "core/face_rig.h"
#include "core/types.h"
#include "eval/tracking_metrics.h"

namespace crease {

struct RigCorrespondence {
  bool same_topology = true;
  // The tracking rig is a part of the truth's (ExtractParts: e.g. its face-only
  // tracking rig): every vertex is a truth vertex with the same OBJ id and UV, in
  // the same frame and UV layout, so UV maps (D^t) stay comparable.
  bool same_uv = true;
  std::vector<int> triangle;  // per tracking vertex: the truth triangle's corners' row in `corners`, -1 = none
  MatX3i corners;             // the truth triangles used (truth vertex ids)
  MatX3d barycentric;         // per tracking vertex
  // The similarity truth_from_tracking of the neutral heads: x_truth = scale · R x + t.
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;
  int matched = 0;            // tracking vertices with a correspondence

  bool Has(int v) const { return same_topology || triangle[v] >= 0; }
  // Per tracking vertex, the truth's per-vertex rows (#V_truth × k) interpolated
  // (NaN rows where there is no correspondence).
  Eigen::MatrixXd Map(const Eigen::MatrixXd& truth_values) const;
  // The truth of a frame seen from the tracking rig: vertices (2D) interpolated,
  // visible when all three corners are; landmarks and pose as they are.
  FrameTruth MapTruth(const FrameTruth& truth) const;
  // Points of the truth's head frame in the tracking rig's (the inverse similarity), and back.
  MatX3d ToTrackingFrame(const MatX3d& truth_points) const;
  MatX3d FromTrackingFrame(const MatX3d& tracking_points) const;
};

struct RigCorrespondenceOptions {
  double max_distance_mm = 15.0;  // search along the normal, either side
};

// Throws Error when the rigs differ in topology and either lacks the 68 iBUG
// landmarks, or when fewer than half the tracking rig's face-chart vertices find
// the truth's surface.
RigCorrespondence CorrespondRigs(const FaceRig& tracking, const FaceRig& truth,
                                 const RigCorrespondenceOptions& options = {});

}  // namespace crease
