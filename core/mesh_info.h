// A mesh described for people and tools (`crease mesh info`).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "core/tri_mesh.h"

namespace crease {

// The mesh's summary: file, vertices, triangles, has_uv, has_normals, bbox_min_mm,
// bbox_max_mm, extent_mm, surface_area_mm2, mean_edge_length_mm, edges,
// boundary_edges, non_manifold_edges and, with UVs, uv_min and uv_max.
nlohmann::json MeshInfoJson(const TriMesh& mesh, const std::string& file);

}  // namespace crease
