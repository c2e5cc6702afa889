// TriMesh — crease's triangle mesh: positions in millimetres, triangles, one
// per-vertex UV chart and optional normals.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/types.h"

namespace crease {

struct TriMesh {
  MatX3d V;   // #V×3 vertex positions, mm.
  MatX3i F;   // #F×3 vertex indices per triangle, counter-clockwise seen from outside.
  MatX2d UV;  // #V×2 texture coordinates (u right, v down, texel convention of DESIGN.md),
              // one single chart; empty (0 rows) when the mesh has none.
  MatX3d N;   // #V×3 unit vertex normals; empty when not computed/loaded.

  int num_vertices() const { return static_cast<int>(V.rows()); }
  int num_faces() const { return static_cast<int>(F.rows()); }
  bool has_uv() const { return UV.rows() > 0; }
  bool has_normals() const { return N.rows() > 0; }
};

struct MeshRequirements {
  bool uv = false;       // per-vertex UVs must be present
  bool normals = false;  // per-vertex normals must be present
  bool non_empty = true; // at least one triangle
};

// Throws Error when a triangle references a vertex outside [0, #V); the message
// starts with `what` and names the first such triangle and its vertex.
void RequireFaceIndices(const TriMesh& mesh, std::string_view what);

// Checks that the mesh is well formed: F indices in [0, #V), no degenerate index
// triples (a triangle using one vertex twice), finite V/UV/N, UV and N sized #V
// when present, UV/N present when required. Throws Error whose message starts
// with `what` (typically the file name) and names the offending element.
void ValidateMesh(const TriMesh& mesh, const std::string& what,
                  const MeshRequirements& req = {});

// Axis-aligned bounding box of the vertices, as (min, max).
std::pair<Eigen::Vector3d, Eigen::Vector3d> BoundingBox(const TriMesh& mesh);

// Number of undirected edges, boundary edges (used by one triangle) and
// non-manifold edges (used by more than two).
struct EdgeStats {
  int edges = 0;
  int boundary = 0;
  int non_manifold = 0;
};
EdgeStats ComputeEdgeStats(const TriMesh& mesh);

// Triangles: area of each triangle, mm².
Eigen::VectorXd TriangleAreas(const TriMesh& mesh);

// Mean edge length, mm.
double MeanEdgeLength(const TriMesh& mesh);

// UV seams: a mesh with one UV per vertex duplicates the vertices along seams
// (same position, different UV). Geometry operators must see through them.
// Per vertex, the lowest-index vertex with bit-identical position (itself when unique).
std::vector<int> CoincidentVertexRepresentatives(const TriMesh& mesh);

// The mesh with coincident vertices merged (UVs dropped, since they differ along
// seams): `welded_of[v]` is vertex v's index in `mesh`, `vertex_of[w]` one
// original vertex of welded vertex w. Triangles that collapse are dropped.
struct WeldedMesh {
  TriMesh mesh;
  std::vector<int> welded_of;
  std::vector<int> vertex_of;
};
WeldedMesh WeldCoincidentVertices(const TriMesh& mesh);

}  // namespace crease
