#include "eval/rig_correspondence.h"

#include <cmath>
#include <limits>
#include <map>
#include <tuple>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/ray_caster.h"

namespace crease {

Eigen::MatrixXd RigCorrespondence::Map(const Eigen::MatrixXd& truth_values) const {
  if (same_topology) return truth_values;
  const int n = static_cast<int>(triangle.size());
  Eigen::MatrixXd out = Eigen::MatrixXd::Constant(n, truth_values.cols(), std::numeric_limits<double>::quiet_NaN());
  for (int v = 0; v < n; ++v) {
    const int t = triangle[v];
    if (t < 0) continue;
    out.row(v).setZero();
    for (int k = 0; k < 3; ++k) out.row(v) += barycentric(v, k) * truth_values.row(corners(t, k));
  }
  return out;
}

FrameTruth RigCorrespondence::MapTruth(const FrameTruth& truth) const {
  if (same_topology) return truth;
  FrameTruth out = truth;
  out.vertices = Map(truth.vertices);
  const int n = static_cast<int>(triangle.size());
  out.vertex_visible.assign(static_cast<size_t>(n), 0);
  for (int v = 0; v < n; ++v) {
    const int t = triangle[v];
    if (t < 0) continue;
    out.vertex_visible[v] = truth.vertex_visible[corners(t, 0)] && truth.vertex_visible[corners(t, 1)] &&
                            truth.vertex_visible[corners(t, 2)];
  }
  return out;
}

MatX3d RigCorrespondence::ToTrackingFrame(const MatX3d& truth_points) const {
  if (same_topology) return truth_points;
  MatX3d out(truth_points.rows(), 3);
  const Eigen::Matrix3d inv = rotation.transpose() / scale;
  for (Eigen::Index i = 0; i < truth_points.rows(); ++i) {
    out.row(i) = (inv * (truth_points.row(i).transpose() - translation)).transpose();
  }
  return out;
}

MatX3d RigCorrespondence::FromTrackingFrame(const MatX3d& tracking_points) const {
  if (same_topology) return tracking_points;
  MatX3d out(tracking_points.rows(), 3);
  const Eigen::Matrix3d sR = scale * rotation;
  for (Eigen::Index i = 0; i < tracking_points.rows(); ++i) {
    out.row(i) = (sR * tracking_points.row(i).transpose() + translation).transpose();
  }
  return out;
}

namespace {

// The 68 landmark positions of a rig's neutral, 3×68.
Eigen::Matrix3Xd LandmarkPoints(const FaceRig& rig, const std::string& role) {
  const auto names = IbugLandmarkNames();
  Eigen::Matrix3Xd P(3, static_cast<Eigen::Index>(names.size()));
  for (size_t i = 0; i < names.size(); ++i) {
    const int l = rig.LandmarkIndex(names[i]);
    Require(l >= 0, fmt::format("{} rig ({}): no landmark '{}'; rigs of different topology are put in correspondence "
                                "by their 68 iBUG landmarks", role, rig.source, names[i]));
    P.col(static_cast<Eigen::Index>(i)) = rig.neutral.V.row(rig.landmarks[l].vertex).transpose();
  }
  return P;
}

// The tracking rig as a part of the truth's: each vertex the truth vertex with its
// OBJ id and UV, as a degenerate "triangle" (v, v, v). False when one is missing.
bool CorrespondAsPart(const FaceRig& tracking, const FaceRig& truth, RigCorrespondence* c) {
  if (tracking.original_vertex.empty() || truth.original_vertex.empty()) return false;
  std::map<std::tuple<int, double, double>, int> truth_vertex;
  for (int v = 0; v < truth.num_vertices(); ++v) {
    truth_vertex.emplace(std::tuple(truth.original_vertex[v], truth.neutral.UV(v, 0), truth.neutral.UV(v, 1)), v);
  }
  const int n = tracking.num_vertices();
  c->corners.resize(n, 3);
  c->triangle.resize(static_cast<size_t>(n));
  c->barycentric = MatX3d::Zero(n, 3);
  for (int v = 0; v < n; ++v) {
    auto it = truth_vertex.find(std::tuple(tracking.original_vertex[v], tracking.neutral.UV(v, 0), tracking.neutral.UV(v, 1)));
    if (it == truth_vertex.end() || (tracking.neutral.V.row(v) - truth.neutral.V.row(it->second)).norm() > 1e-6) return false;
    c->corners.row(v) << it->second, it->second, it->second;
    c->triangle[v] = v;
    c->barycentric(v, 0) = 1.0;
  }
  c->matched = n;
  return true;
}

}  // namespace

RigCorrespondence CorrespondRigs(const FaceRig& tracking, const FaceRig& truth, const RigCorrespondenceOptions& options) {
  RigCorrespondence c;
  if (tracking.num_vertices() == truth.num_vertices()) {
    c.matched = tracking.num_vertices();
    return c;
  }
  c.same_topology = false;
  if (CorrespondAsPart(tracking, truth, &c)) return c;
  c = RigCorrespondence();
  c.same_topology = false;
  c.same_uv = false;
  // 1. The similarity of the neutral heads from their landmarks.
  const Eigen::Matrix4d S = Eigen::umeyama(LandmarkPoints(tracking, "tracking"), LandmarkPoints(truth, "truth"), true);
  const Eigen::Matrix3d sR = S.topLeftCorner<3, 3>();
  c.scale = std::cbrt(sR.determinant());
  c.rotation = sR / c.scale;
  c.translation = S.topRightCorner<3, 1>();

  // 2. Each tracking face-chart vertex, placed, along its normal onto the truth's face chart.
  TriMesh truth_face = truth.neutral;
  truth_face.F = FaceChartTriangles(truth);
  truth_face.N.resize(0, 3);
  c.corners = truth_face.F;
  const RayCaster caster(truth_face, {}, "truth rig face chart");
  TriMesh tracking_mesh = tracking.neutral;
  const MatX3d N = VertexNormals(tracking_mesh);
  const MatX3i tracking_face = FaceChartTriangles(tracking);
  std::vector<char> on_face(static_cast<size_t>(tracking.num_vertices()), 0);
  for (Eigen::Index f = 0; f < tracking_face.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_face[tracking_face(f, k)] = 1;
  std::vector<int> ids;
  std::vector<Eigen::Vector3f> origins, directions;
  for (int v = 0; v < tracking.num_vertices(); ++v) {
    if (!on_face[v]) continue;
    ids.push_back(v);
    const Eigen::Vector3d n = (c.rotation * N.row(v).transpose()).normalized();
    // 1 µm off the surface, so that a vertex lying on the truth's surface (at a
    // vertex or an edge of it) is not missed at t = 0 by both rays.
    origins.push_back((c.scale * c.rotation * tracking.neutral.V.row(v).transpose() + c.translation + 1e-3 * n)
                          .cast<float>());
    directions.push_back(n.cast<float>());
  }
  std::vector<SignedHit> hits;
  caster.IntersectSignedBatch(origins, directions, static_cast<float>(options.max_distance_mm), &hits);
  c.triangle.assign(static_cast<size_t>(tracking.num_vertices()), -1);
  c.barycentric = MatX3d::Zero(tracking.num_vertices(), 3);
  for (size_t i = 0; i < ids.size(); ++i) {
    if (!hits[i].valid()) continue;
    const int v = ids[i];
    c.triangle[v] = hits[i].triangle;
    const double u = hits[i].u, w = hits[i].v;
    c.barycentric.row(v) << 1.0 - u - w, u, w;
    ++c.matched;
  }
  Require(2 * c.matched >= static_cast<int>(ids.size()),
          fmt::format("only {} of the tracking rig's {} face vertices lie within {} mm of the truth rig's face: are "
                      "the rigs of one kind of head (landmarks, units)?",
                      c.matched, ids.size(), options.max_distance_mm));
  return c;
}

}  // namespace crease
