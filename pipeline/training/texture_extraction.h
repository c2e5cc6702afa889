// Texture T in the rig's UV layout from calibrated images of a mesh (paper Sec. 4.1
// "extract the texture T^j from the scan images", and the same operation per frame
// at capture time, Sec. 5.1).
//
// For every texel covered by the mesh's UV chart, the surface point and normal are
// interpolated from the mesh; each camera that sees the point (in front, inside
// the image, not occluded — a shadow ray towards the camera centre through an
// Embree BVH of the mesh — and viewed at less than `max_view_angle_deg` from the
// normal) contributes its bilinearly sampled colour with weight cos(θ)^p, θ the
// angle between normal and view direction. T is the weighted mean.
//
// Differences from the paper:
//   1. The paper does not say how the scan images are combined; a cosine-weighted
//      blend of all visible cameras is the common choice.
//   2. The view angle θ (the max_view_angle_deg test and the weight) can be judged
//      by normals other than the mesh's own (`view_normals`): the trainer passes the
//      normals of M_0^j, the scan without its expression detail (Sec. 4.1). With the
//      scan's own normals, the walls of a wrinkle tilt θ by up to ±30°, so on an
//      oblique forehead the upper walls of the lines exceed the limit and vanish
//      from T^j (black streaks exactly on the wrinkles, which the capture's
//      texture, taken through the smooth L~^t, never has). Measured on a studio scan
//      (brow raise, one camera, 1024² map): 3,127 of 53,725 forehead texels were
//      dropped as back-facing with the scan's normals, 0 with M_0^j's (the
//      report's texture picture: 3,714 black texels on the forehead → 275, the
//      rest truly occluded). Effect on the detail-ladder's quick profile (one seed,
//      studio light, 640×480): R0 held out 0.333 → 0.316, R2 D^t in the wrinkle
//      regions 0.247 → 0.258 (band 0.313 → 0.308), R3 0.086 → 0.077, still face
//      0.89 → 0.87: within one seed's noise. The holes were real, but they are
//      not what limits the detail regression (issue 17).
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/tri_mesh.h"

namespace crease {

class OptionVisitor;
class RayCaster;
struct UvRaster;

struct TextureOptions {
  // Views more oblique than this are ignored, degrees.
  double max_view_angle_deg = 75.0;
  // p in the camera weight cos(θ)^p.
  double view_weight_power = 2.0;
  // Start of the visibility ray above the surface, mm (avoids self-hits).
  double visibility_offset_mm = 0.05;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct ExtractedTexture {
  cv::Mat color;   // CV_32FC3, linear RGB; 0 where unseen
  cv::Mat gray;    // CV_32F, linear luminance (Rec. 709 weights); 0 where unseen
  cv::Mat weight;  // CV_32F, sum of camera weights; 0 where unseen
  cv::Mat seen;    // CV_8U, 255 where at least one camera saw the texel
};

// `raster` from RasterizeUv on `mesh` (same triangles), `caster` a RayCaster of
// `mesh` for visibility (null: no occlusion test). images[i] is the linear-light
// CV_32FC3 (or CV_32F) photograph of cameras[i], sized like its intrinsics.
// `view_normals` (#V×3, optional): the normals that judge the view angle θ
// (Difference 2); null = the mesh's own vertex normals. Throws Error naming the
// camera on a size mismatch.
ExtractedTexture ExtractTexture(const TriMesh& mesh, const UvRaster& raster, const RayCaster* caster,
                                const std::vector<Camera>& cameras, const std::vector<cv::Mat>& images,
                                const TextureOptions& options, const MatX3d* view_normals = nullptr);

// Rec. 709 luminance of a linear CV_32FC3 image (CV_32F passes through).
cv::Mat Luminance(const cv::Mat& linear_rgb);

}  // namespace crease
