// UV rasterisation: which triangle of a mesh's UV chart covers each texel of a
// W×H map, and with which barycentrics. Computed once per topology and map size
// (UvRaster), then reused every frame to move per-vertex data into texture space
// (InterpolateToUv) — textures, displacement maps and positions of DESIGN.md.
//
// Texel convention (DESIGN.md): texel (i, j), column i in [0, W), row j in [0, H),
// samples the chart at its centre u = (i + 0.5)/W, v = (j + 0.5)/H; v grows
// downwards like image rows. Storage is row-major: index j·W + i.
//
// Coverage rule: a texel belongs to a triangle when its centre is inside it.
// Centres exactly on an edge or a vertex are decided by the top-left rule in its
// perturbation form (the centre is nudged by an infinitesimal step to the right,
// then downwards), evaluated with exact integer edge functions on UVs snapped to
// 1/kUvSubpixelSteps of a texel, as GPUs do. Hence a texel on an edge shared by
// two triangles is covered exactly once, and a chart without overlaps covers
// every texel of its interior exactly once. Where the chart overlaps itself the
// lowest triangle index wins and UvRaster::num_overlaps counts the conflicts.
// Triangles whose snapped UV area is zero cover nothing.
#pragma once

#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

// UVs are snapped to multiples of 1/kUvSubpixelSteps texel for the coverage test.
inline constexpr int kUvSubpixelSteps = 256;
// Largest |u|, |v| accepted by RasterizeUv (keeps the exact edge functions in 64 bits).
inline constexpr double kMaxAbsUv = 64.0;
// Largest width and height accepted by RasterizeUv.
inline constexpr int kMaxUvRasterSize = 32768;

struct UvRaster {
  int width = 0;           // W, texels
  int height = 0;          // H, texels
  int num_triangles = 0;   // #F of the mesh it was built for
  int num_overlaps = 0;    // texels claimed by more than one triangle (0 for a valid chart)
  std::vector<int> triangle;  // W·H, row-major; covering triangle (row of F), -1 = not covered
  // W·H, row-major; barycentrics (w0, w1, w2) of the covering triangle's vertices
  // F(t,0), F(t,1), F(t,2) at the texel centre, summing to 1, computed from the
  // unsnapped UVs, so Σ w_k·UV_k is the texel centre (a weight can be slightly
  // negative where the centre lies within 1/kUvSubpixelSteps texel of an edge).
  // Zero where not covered.
  std::vector<Eigen::Vector3f> barycentric;

  int index(int i, int j) const { return j * width + i; }
  bool covered(int i, int j) const { return triangle[static_cast<size_t>(index(i, j))] >= 0; }
  int num_covered() const;
};

// Rasterises the UV chart of `mesh` (which must have UVs: ValidateMesh with
// uv = true; errors start with `what`) into a width × height raster. Deterministic
// and parallel (TBB over bands of rows). Throws Error for sizes outside
// [1, kMaxUvRasterSize] or UVs outside [−kMaxAbsUv, kMaxAbsUv].
UvRaster RasterizeUv(const TriMesh& mesh, int width, int height,
                     const std::string& what = "UV raster mesh");

// Per-vertex data (#V×C, C in 1..4) interpolated at every texel with the raster's
// barycentrics: a CV_32FC(C) map of raster.height rows × raster.width columns,
// 0 where not covered. `raster` must come from RasterizeUv on a mesh with the same
// triangles (F) as `mesh`.
cv::Mat InterpolateToUv(const UvRaster& raster, const TriMesh& mesh, const Eigen::MatrixXd& per_vertex);

// CV_8U map: 255 where covered, 0 elsewhere.
cv::Mat CoverageMask(const UvRaster& raster);

// A square map of the UV layout at another resolution resampled to R×R (area
// averaging down, bilinear up); a map that is already R×R, empty or not square is
// returned as it is (shared data).
cv::Mat ResampleSquareMap(const cv::Mat& map, int R);

}  // namespace crease
