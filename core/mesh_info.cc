#include "core/mesh_info.h"

namespace crease {

nlohmann::json MeshInfoJson(const TriMesh& mesh, const std::string& file) {
  const auto [lo, hi] = BoundingBox(mesh);
  const EdgeStats e = ComputeEdgeStats(mesh);
  nlohmann::json j;
  j["file"] = file;
  j["vertices"] = mesh.num_vertices();
  j["triangles"] = mesh.num_faces();
  j["has_uv"] = mesh.has_uv();
  j["has_normals"] = mesh.has_normals();
  j["bbox_min_mm"] = {lo.x(), lo.y(), lo.z()};
  j["bbox_max_mm"] = {hi.x(), hi.y(), hi.z()};
  j["extent_mm"] = {hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()};
  j["surface_area_mm2"] = TriangleAreas(mesh).sum();
  j["mean_edge_length_mm"] = MeanEdgeLength(mesh);
  j["edges"] = e.edges;
  j["boundary_edges"] = e.boundary;
  j["non_manifold_edges"] = e.non_manifold;
  if (mesh.has_uv()) {
    j["uv_min"] = {mesh.UV.col(0).minCoeff(), mesh.UV.col(1).minCoeff()};
    j["uv_max"] = {mesh.UV.col(0).maxCoeff(), mesh.UV.col(1).maxCoeff()};
  }
  return j;
}

}  // namespace crease
