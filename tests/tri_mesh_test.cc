#include "core/tri_mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/mesh_primitives.h"

namespace crease {
namespace {

TEST(TriMesh, GridIsValidAndHasExpectedTopology) {
  const TriMesh m = MakeGrid(4, 3, 40.0, 30.0);
  EXPECT_EQ(m.num_vertices(), 20);
  EXPECT_EQ(m.num_faces(), 24);
  EXPECT_NO_THROW(ValidateMesh(m, "grid", {.uv = true, .normals = true}));
  const EdgeStats e = ComputeEdgeStats(m);
  EXPECT_EQ(e.boundary, 2 * (4 + 3));
  EXPECT_EQ(e.non_manifold, 0);
  EXPECT_NEAR(TriangleAreas(m).sum(), 1200.0, 1e-9);
}

TEST(TriMesh, IcosphereIsClosed) {
  const TriMesh m = MakeIcosphere(10.0, 2);
  EXPECT_EQ(m.num_faces(), 320);
  EXPECT_EQ(m.num_vertices(), 162);
  EXPECT_EQ(ComputeEdgeStats(m).boundary, 0);
}

std::string ErrorOf(const TriMesh& m, const MeshRequirements& req = {}) {
  try {
    ValidateMesh(m, "bad.ply", req);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(TriMesh, ValidationNamesTheProblem) {
  TriMesh m = MakeGrid(2, 2, 1.0, 1.0);
  m.F(3, 1) = 99;
  EXPECT_NE(ErrorOf(m).find("bad.ply: triangle 3 references vertex 99"), std::string::npos) << ErrorOf(m);

  m = MakeGrid(2, 2, 1.0, 1.0);
  m.V(5, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(ErrorOf(m).find("vertex 5 has a non-finite coordinate"), std::string::npos) << ErrorOf(m);

  m = MakeGrid(2, 2, 1.0, 1.0);
  m.UV.resize(0, 2);
  EXPECT_EQ(ErrorOf(m), "");
  EXPECT_NE(ErrorOf(m, {.uv = true}).find("no UV coordinates"), std::string::npos);

  m = MakeGrid(2, 2, 1.0, 1.0);
  m.UV.conservativeResize(3, 2);
  EXPECT_NE(ErrorOf(m).find("3 UVs for 9 vertices"), std::string::npos) << ErrorOf(m);

  m = MakeGrid(2, 2, 1.0, 1.0);
  m.F(0, 2) = m.F(0, 0);
  EXPECT_NE(ErrorOf(m).find("uses one vertex twice"), std::string::npos);

  EXPECT_NE(ErrorOf(TriMesh{}).find("no triangles"), std::string::npos);
}

}  // namespace
}  // namespace crease

namespace crease {
namespace {

TEST(TriMesh, WeldingSeesThroughUvSeams) {
  // A UV sphere duplicates the seam column (u = 0 and u = 1) and the poles.
  const TriMesh m = MakeUVSphere(10.0, 8, 12);
  const WeldedMesh w = WeldCoincidentVertices(m);
  // Closed after welding: (rings−1)·segments + 2 poles.
  EXPECT_EQ(w.mesh.num_vertices(), 7 * 12 + 2);
  EXPECT_EQ(ComputeEdgeStats(w.mesh).boundary, 0);
  EXPECT_EQ(w.mesh.num_faces(), m.num_faces());
  for (int v = 0; v < m.num_vertices(); ++v) {
    EXPECT_EQ(m.V.row(v), w.mesh.V.row(w.welded_of[v]));
  }
  const auto rep = CoincidentVertexRepresentatives(m);
  EXPECT_EQ(rep[12], 0);  // first-ring seam copy: vertex (i = 12) duplicates (i = 0) on ring 0
}

}  // namespace
}  // namespace crease
