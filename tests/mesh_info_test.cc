#include "core/mesh_info.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/mesh_primitives.h"

namespace crease {
namespace {

// A 4×3-cell grid of 40×30 mm: its counts, size and topology, and UV bounds only
// when it has UVs.
TEST(MeshInfo, GridSummaryHasItsCountsSizeAndTopology) {
  TriMesh m = MakeGrid(4, 3, 40.0, 30.0);
  const nlohmann::json j = MeshInfoJson(m, "grid.ply");
  EXPECT_EQ(j["file"], "grid.ply");
  EXPECT_EQ(j["vertices"], 20);
  EXPECT_EQ(j["triangles"], 24);
  EXPECT_EQ(j["has_uv"], true);
  EXPECT_EQ(j["extent_mm"], nlohmann::json({40.0, 30.0, 0.0}));
  EXPECT_EQ(j["bbox_min_mm"], nlohmann::json({0.0, 0.0, 0.0}));
  EXPECT_NEAR(j["surface_area_mm2"].get<double>(), 1200.0, 1e-9);
  EXPECT_EQ(j["edges"], 4 * 4 + 5 * 3 + 12);   // rows, columns, one diagonal per cell
  EXPECT_EQ(j["boundary_edges"], 2 * (4 + 3));
  EXPECT_EQ(j["non_manifold_edges"], 0);
  EXPECT_GT(j["mean_edge_length_mm"].get<double>(), 10.0);  // between the 10 mm sides and the diagonals
  EXPECT_LT(j["mean_edge_length_mm"].get<double>(), std::hypot(10.0, 10.0));
  EXPECT_EQ(j["uv_max"], nlohmann::json({1.0, 1.0}));
  m.UV.resize(0, 2);
  const nlohmann::json no_uv = MeshInfoJson(m, "grid.ply");
  EXPECT_EQ(no_uv["has_uv"], false);
  EXPECT_FALSE(no_uv.contains("uv_min"));
}

}  // namespace
}  // namespace crease
