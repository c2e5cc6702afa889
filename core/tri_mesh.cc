#include "core/tri_mesh.h"

#include <algorithm>
#include <cmath>
#include <tuple>
#include <fmt/format.h>

#include "core/error.h"

namespace crease {
namespace {

void RequireFaceIndicesOf(const TriMesh& mesh, int f, std::string_view what) {
  const int nv = mesh.num_vertices();
  for (int k = 0; k < 3; ++k) {
    const int v = mesh.F(f, k);
    if (v < 0 || v >= nv) {
      throw Error(fmt::format("{}: triangle {} references vertex {}, but the mesh has {} vertices",
                              what, f, v, nv));
    }
  }
}

}  // namespace

void RequireFaceIndices(const TriMesh& mesh, std::string_view what) {
  for (int f = 0; f < mesh.num_faces(); ++f) RequireFaceIndicesOf(mesh, f, what);
}

void ValidateMesh(const TriMesh& mesh, const std::string& what, const MeshRequirements& req) {
  const int nv = mesh.num_vertices();
  if (req.non_empty) {
    Require(mesh.num_faces() > 0, fmt::format("{}: mesh has no triangles", what));
    Require(nv > 0, fmt::format("{}: mesh has no vertices", what));
  }
  for (int i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(mesh.V(i, k))) {
        throw Error(fmt::format("{}: vertex {} has a non-finite coordinate ({}, {}, {})", what, i,
                                mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2)));
      }
    }
  }
  for (int f = 0; f < mesh.num_faces(); ++f) {
    RequireFaceIndicesOf(mesh, f, what);
    if (mesh.F(f, 0) == mesh.F(f, 1) || mesh.F(f, 1) == mesh.F(f, 2) || mesh.F(f, 0) == mesh.F(f, 2)) {
      throw Error(fmt::format("{}: triangle {} uses one vertex twice ({}, {}, {})", what, f,
                              mesh.F(f, 0), mesh.F(f, 1), mesh.F(f, 2)));
    }
  }
  if (mesh.has_uv()) {
    Require(mesh.UV.rows() == nv, fmt::format("{}: mesh has {} UVs for {} vertices (expected one per vertex)",
                                              what, mesh.UV.rows(), nv));
    for (int i = 0; i < nv; ++i) {
      if (!std::isfinite(mesh.UV(i, 0)) || !std::isfinite(mesh.UV(i, 1))) {
        throw Error(fmt::format("{}: vertex {} has a non-finite UV", what, i));
      }
    }
  } else if (req.uv) {
    throw Error(fmt::format("{}: mesh has no UV coordinates, but this step needs a UV chart "
                            "(export the mesh with texture coordinates)", what));
  }
  if (mesh.has_normals()) {
    Require(mesh.N.rows() == nv, fmt::format("{}: mesh has {} normals for {} vertices", what,
                                             mesh.N.rows(), nv));
    Require(mesh.N.allFinite(), fmt::format("{}: mesh has non-finite normals", what));
  } else if (req.normals) {
    throw Error(fmt::format("{}: mesh has no normals, but this step needs them", what));
  }
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> BoundingBox(const TriMesh& mesh) {
  if (mesh.num_vertices() == 0) return {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  return {mesh.V.colwise().minCoeff().transpose(), mesh.V.colwise().maxCoeff().transpose()};
}

EdgeStats ComputeEdgeStats(const TriMesh& mesh) {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(static_cast<size_t>(mesh.num_faces()) * 3);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  EdgeStats s;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    ++s.edges;
    if (j - i == 1) ++s.boundary;
    if (j - i > 2) ++s.non_manifold;
    i = j;
  }
  return s;
}

Eigen::VectorXd TriangleAreas(const TriMesh& mesh) {
  Eigen::VectorXd a(mesh.num_faces());
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p0 = mesh.V.row(mesh.F(f, 0)), p1 = mesh.V.row(mesh.F(f, 1)),
                          p2 = mesh.V.row(mesh.F(f, 2));
    a[f] = 0.5 * (p1 - p0).cross(p2 - p0).norm();
  }
  return a;
}

double MeanEdgeLength(const TriMesh& mesh) {
  if (mesh.num_faces() == 0) return 0.0;
  double sum = 0.0;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      sum += (mesh.V.row(mesh.F(f, k)) - mesh.V.row(mesh.F(f, (k + 1) % 3))).norm();
    }
  }
  return sum / (3.0 * mesh.num_faces());
}

std::vector<int> CoincidentVertexRepresentatives(const TriMesh& mesh) {
  const int nv = mesh.num_vertices();
  std::vector<int> order(nv);
  for (int i = 0; i < nv; ++i) order[i] = i;
  auto key = [&](int i) { return std::make_tuple(mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2)); };
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const auto ka = key(a), kb = key(b);
    return ka != kb ? ka < kb : a < b;
  });
  std::vector<int> rep(nv);
  for (int i = 0; i < nv;) {
    int j = i;
    while (j < nv && key(order[j]) == key(order[i])) rep[order[j++]] = order[i];
    i = j;
  }
  return rep;
}

WeldedMesh WeldCoincidentVertices(const TriMesh& mesh) {
  const std::vector<int> rep = CoincidentVertexRepresentatives(mesh);
  WeldedMesh w;
  w.welded_of.assign(mesh.num_vertices(), -1);
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    if (rep[v] == v) {
      w.welded_of[v] = static_cast<int>(w.vertex_of.size());
      w.vertex_of.push_back(v);
    }
  }
  for (int v = 0; v < mesh.num_vertices(); ++v) w.welded_of[v] = w.welded_of[rep[v]];
  w.mesh.V.resize(static_cast<int>(w.vertex_of.size()), 3);
  for (size_t i = 0; i < w.vertex_of.size(); ++i) w.mesh.V.row(static_cast<int>(i)) = mesh.V.row(w.vertex_of[i]);
  std::vector<Eigen::Vector3i> faces;
  faces.reserve(mesh.num_faces());
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3i t(w.welded_of[mesh.F(f, 0)], w.welded_of[mesh.F(f, 1)], w.welded_of[mesh.F(f, 2)]);
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) faces.push_back(t);
  }
  w.mesh.F.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) w.mesh.F.row(static_cast<int>(f)) = faces[f].transpose();
  return w;
}

}  // namespace crease
