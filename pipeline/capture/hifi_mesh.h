// The high-fidelity mesh H^t (paper Sec. 5.3, last paragraph): the refined coarse
// mesh L~^t augmented with the combined displacement map D^t + D^HF. The paper
// uses GPU displacement mapping (tessellation); here the same is done on the CPU:
// a dense mesh on a regular UV grid over the face chart whose topology and
// barycentric stencils are built once, displaced per frame.
//
// Grid. Vertex (a, b), a, b in [0, N), N = hifi_mesh_resolution, sits at the UV
// u = (a + 0.5)/N, v = (b + 0.5)/N — the texel centres of an N×N map — and exists
// when the face chart covers that point (core/uv_raster.h rule); it stores the
// covering coarse triangle and its barycentrics w. Each grid cell becomes two
// triangles along the (a, b)–(a+1, b+1) diagonal when all four corners exist, or
// one triangle when exactly three do. A triangle is only made when none of its
// edges crosses a boundary edge of the chart in UV (an edge of one chart triangle
// only), so the dense mesh follows concave parts of the chart's outline and does
// not bridge the slits of the eyelids and lips (opened slightly in UV; their rims
// are distinct vertices). Triangles are oriented like the coarse chart
// (counter-clockwise seen from outside).
//
// Per frame, for grid vertex g with coarse triangle (i, j, k) and barycentrics w:
//   p_g = Σ w·V,   n_g = normalise(Σ w·N)   (N: area-weighted vertex normals of
//   the whole coarse mesh, UV seams welded, as core/mesh_ops.h VertexNormals)
//   H_g = p_g + D(u_g, v_g) · n_g
// with D sampled bilinearly (texel convention of DESIGN.md, clamped at the map
// border). The output normals are area-weighted vertex normals of the displaced
// dense mesh (each vertex gathers its ≤ 6 grid triangles). With D = 0 the dense
// vertices lie exactly on L~^t.
//
// Speed (bench/frame_texture_bench.cc and a min-of-N thread-CPU-time loop,
// 2-vCPU Sapphire Rapids under a load average of 4–6 from other builds, see
// frame_texture.h; procedural rig): N = 512 gives 175,874 vertices and 349,681
// triangles. BuildInto (topology kept from the previous frame) 9.7 / 4.3–6.0 ms
// with 1 / 2 threads (target ≤ 5 ms: met only in the better runs); Build (a new
// TriMesh, 15 MB of fresh memory per call, page faults) 14–16 ms with 2 threads —
// use BuildInto in a capture loop.
//
// Differences from the paper:
//   1. CPU displacement of a fixed UV grid instead of GPU tessellation; the
//      displacement direction is the interpolated (Phong) normal of L~^t.
//   2. Grid vertices exist only where the chart covers the texel centre, so the
//      dense mesh's boundary lies up to one grid cell inside the chart's boundary.
//   3. Optionally (phong_alpha > 0) the base under the displacement is a Phong
//      tessellation of L~^t instead of its flat triangles. On the studio's surface
//      (rounded with α = 0.75) the detail a flat base leaves to D^t includes the
//      change of the facets' rounding with the expression, which neither D* nor the
//      regression holds (eval/detail_truth.h, ExactDetail: D* agrees with the exact
//      detail of a Phong base at 0.92 / 0.87 / 0.64 on brow raise / frown / smile,
//      with that of a flat base at 0.76 / 0.75 / 0.39). Its cost (bench/
//      frame_texture_bench.cc, N = 512, 2-vCPU AMD EPYC, idle, median of 7): BuildInto
//      9.8 / 5.8 ms with 1 / 2 threads against 7.5 / 4.0 ms flat.
#pragma once

#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

class OptionVisitor;

struct HifiMeshOptions {
  // N: UV grid of the dense mesh, vertices per side (the paper's GPU tessellation
  // level is not given; 512 puts a vertex every ~0.5 mm on a typical face).
  int hifi_mesh_resolution = 512;
  // Shape factor α of a Phong tessellation of L~^t's triangles under the grid
  // (Boubekeur and Alexa 2008, as the studio rounds its surface, synth/hires_surface.h):
  //   p_g = (1 − α) Σ w·V + α Σ_k w_k (p − ((p − V_k)·N̂_k) N̂_k)
  // 0 (the default) = the flat triangles. Not in the paper (its GPU tessellation is
  // not specified); see Difference 3.
  double phong_alpha = 0.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

class HifiMeshBuilder {
 public:
  // Face chart of `rig` (FaceChartTriangles, neutral UVs); grid, stencils and the
  // dense topology are built here. Throws Error on invalid options or rig.
  HifiMeshBuilder(const FaceRig& rig, const HifiMeshOptions& options);
  ~HifiMeshBuilder();
  HifiMeshBuilder(HifiMeshBuilder&&) noexcept;
  HifiMeshBuilder& operator=(HifiMeshBuilder&&) noexcept;

  // H^t (Sec. 5.3). cam_vertices: #V×3 (L~^t, any frame of reference, mm, finite);
  // displacement: CV_32F R×R, mm along the outward normal (D^t + D^HF; any square
  // R, sampled bilinearly at each grid vertex's UV). Returns a TriMesh with V, F,
  // UV (the grid UVs) and N (unit normals of the displaced mesh). Throws Error
  // naming the wrong shape or type, the first non-finite vertex, or non-finite
  // sampled displacements.
  TriMesh Build(const MatX3d& cam_vertices, const cv::Mat& displacement) const;
  // Same into `mesh`: V and N are overwritten; F and UV are written only when
  // their row counts differ from this builder's (pass a mesh that came from this
  // builder, or an empty one), which saves copying the topology every frame.
  void BuildInto(const MatX3d& cam_vertices, const cv::Mat& displacement, TriMesh* mesh) const;

  int num_vertices() const;
  int num_triangles() const;
  int grid_resolution() const;
  // Per dense vertex, its grid node b·N + a.
  const std::vector<int>& grid_node() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
