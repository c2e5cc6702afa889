// The high-resolution surface of a synthetic actor: a regular grid in the rig's
// face UV chart, one vertex per texel centre of an S×S grid, bound once to the
// coarse rig triangle covering it (barycentrics, as RasterizeUv). Displacement
// maps (R×R, the rig's UV layout) are sampled at the vertices bilinearly
// (texel convention of DESIGN.md); with S = R every vertex sits on a texel
// centre and the sample is the texel itself. Per frame:
//
//   P(x) = B(x) + d(x) · n̂(x),   n̂(x) = normalise(Σ_k b_k N_k)
//   B(x) = (1 − α) p + α Σ_k b_k (p − ((p − V_k)·N_k) N_k),   p = Σ_k b_k V_k
//
// V, N: coarse rig positions and area-weighted vertex normals of the frame,
// b: the texel's barycentrics, d: the total displacement (mm, sum of the layer
// maps sampled at the vertex). B is Phong tessellation (Boubekeur & Alexa 2008) of the
// coarse triangle with shape factor α: α = 0 is the flat coarse triangle, the
// default 0.75 rounds the coarse facets off (they would otherwise show under
// raking light); it departs from the flat triangle by ~ edge² · curvature / 8.
// Phong tessellation is only C0 across the coarse edges: each facet keeps a crease
// along its edges whose angle changes with the expression. Alternatively B is the
// rig's Loop subdivision surface (BuildHiResLayout's subdivision_levels), smooth
// across them. Grid cells whose four corners are covered become two
// triangles (orientation follows the coarse chart); cells spanning a UV cut (a
// 3D edge much longer than the local texel size at neutral) or a slit (corners
// on coarse triangles that share no vertex and no edge-joined vertex pair, e.g.
// across the lips or eyelids, which open) are dropped.
//
// Differences from reality: displacement is along the interpolated coarse
// normal (a smooth field), not the normal of the displaced surface, so steep
// wrinkle walls are slightly sheared rather than offset.
#pragma once

#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/loop_subdivision.h"
#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

struct HiResLayout {
  int resolution = 0;                     // S: grid = texel centres of an S×S raster
  int map_resolution = 0;                 // R: size of the displacement maps it samples
  std::vector<int> texel;                 // per vertex: grid index j·S + i
  std::vector<int> triangle;              // per vertex: coarse rig triangle (row of rig.neutral.F)
  std::vector<Eigen::Vector3f> barycentric;  // per vertex, weights of F(t,0..2), sum 1
  std::vector<int> vertex_of_texel;       // S²: vertex id, −1 where not covered
  std::vector<int> map_texel;             // per vertex: top-left texel (j·R + i) of its bilinear stencil
  std::vector<Eigen::Vector2f> map_weight;  // per vertex: bilinear fractions (fx, fy) in that stencil
  MatX3i F;                               // hi-res triangles
  int cells_across_slits = 0;             // grid cells dropped because their corners lie on
                                          //   coarse triangles not joined in the rig's topology
  MatX2d UV;                              // per vertex: texel centre ((i+0.5)/R, (j+0.5)/R)
  // The smooth base (BuildHiResLayout's subdivision_levels > 0; empty: the Phong-tessellated
  // coarse triangles): the Loop subdivision of the rig's mesh around the face chart, its input
  // vertices (rows of the coarse mesh), and per vertex its face on the subdivided mesh and
  // barycentrics there (the coarse triangle and barycentrics carried down, LocateLoopChild).
  std::shared_ptr<const LoopSubdivision> smooth;
  std::vector<int> smooth_input;
  std::vector<int> smooth_face;
  std::vector<Eigen::Vector3f> smooth_barycentric;

  int num_vertices() const { return static_cast<int>(texel.size()); }
  // Bilinear sample of an R×R CV_32F map at vertex v (exactly the texel when S = R).
  double SampleMap(const cv::Mat& map, int v) const {
    const float* m = map.ptr<float>();
    const int k = map_texel[v];
    const float fx = map_weight[v].x(), fy = map_weight[v].y();
    if (fx == 0.0f && fy == 0.0f) return m[k];
    const int dx = fx > 0.0f ? 1 : 0, dy = fy > 0.0f ? map_resolution : 0;
    return (1.0 - fy) * ((1.0 - fx) * m[k] + fx * m[k + dx]) + fy * ((1.0 - fx) * m[k + dy] + fx * m[k + dy + dx]);
  }
  int num_faces() const { return static_cast<int>(F.rows()); }
};

// Precomputes the S×S grid for the rig's face chart (FaceChartTriangles),
// sampling R×R maps (map_resolution; 0 = S). `subdivision_levels` > 0: the base B is the
// rig's Loop subdivision surface after that many steps (core/loop_subdivision.h), piecewise
// flat on triangles 2^−L of a coarse edge, instead of the Phong-tessellated coarse
// triangles: smooth across the coarse edges, as skin is. The subdivision runs on the
// faces within two rings of the chart (every chart vertex's rules see its whole
// neighbourhood; the region's artificial rim changes positions less than one coarse ring
// inwards), with the vertices of seam splits joined (FaceRig::original_vertex, else equal
// neutral positions and expression deltas); lips and eyelids stay open (boundary rules).
HiResLayout BuildHiResLayout(const FaceRig& rig, int resolution, int map_resolution = 0,
                             int subdivision_levels = 0);

// Coarse surface interpolated at the hi-res vertices: positions P (= B above, or the
// layout's smooth base, which ignores phong_alpha) and unit normals N (#hi-res × 3, the
// interpolated coarse normals either way). `coarse`: the rig mesh of the frame with
// normals (N of VertexNormals). Parallel, deterministic.
inline constexpr double kDefaultPhongAlpha = 0.75;
void InterpolateCoarse(const HiResLayout& layout, const TriMesh& coarse, MatX3d* P, MatX3d* N,
                       double phong_alpha = kDefaultPhongAlpha);

// The hi-res mesh: InterpolateCoarse displaced along the normal by
// `displacement` (CV_32F R×R, mm, positive outwards) sampled at each vertex (SampleMap); UVs
// the texel centres; normals by central differences on the grid.
TriMesh BuildHiResSurface(const HiResLayout& layout, const TriMesh& coarse, const cv::Mat& displacement,
                          double phong_alpha = kDefaultPhongAlpha);

}  // namespace crease
