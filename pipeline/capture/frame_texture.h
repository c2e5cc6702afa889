// Per-frame texture T^t (paper Sec. 5.1, last paragraph: "the image textures {T^t}
// computed from the refined meshes") and the mesoscopic displacement map D^HF
// (Sec. 5.3).
//
// T^t is the input image resampled into the rig's face UV chart (the layout of
// every texture and displacement map, DESIGN.md texel convention) from the refined
// coarse mesh L~^t, in the units of the training textures
// (pipeline/training/texture_extraction.h): linear gray, Rec. 709 luminance, 0
// where unseen. Everything per texel that does not change per frame (the UV
// raster of the chart: covering triangle and barycentrics) is built once in
// FrameTextureExtractor's constructor; a frame costs a depth buffer of the rig
// mesh at image resolution plus one projection and one bilinear sample per
// covered texel.
//
// Visibility of a texel (all must hold):
//   * its surface point p (barycentric interpolation of the mesh, camera frame) is
//     in front of the camera and its bilinear footprint (the 2×2 pixels around the
//     projection) lies inside the image;
//   * the view angle θ (between the normal and the direction to the camera) is
//     below max_view_angle_deg; cos θ is interpolated from per-vertex values
//     (area-weighted vertex normals of the whole rig mesh, seams welded as in
//     core/mesh_ops.h VertexNormals);
//   * depth test on the whole footprint: each of the 2×2 pixels of the depth
//     buffer (the whole rig mesh — eyes, teeth, mouth cavity, cranium — rasterised
//     at pixel centres, nearest z, front and back faces) holds a depth within ±τ
//     of p_z, with
//       τ = depth_tolerance_mm + √2 · (p_z / f) · tan θ,   f = min(fx, fy)
//     (the depth change of the surface itself across one pixel diagonal at its
//     obliquity; tan θ interpolated from per-vertex values, capped at 10). A
//     footprint pixel nearer than p_z − τ means an occluder (the nose before the far
//     cheek); farther than p_z + τ, or empty, means the sample would mix in what
//     lies behind a silhouette. Either way the texel is unseen, so seen texels never
//     blend colours across occlusion borders. What a depth test cannot separate —
//     two layers of skin at equal depth, such as closed lips or the fold of an upper
//     lid — may still be sampled from the other layer.
//
// Speeds (bench/frame_texture_bench.cc and a min-of-N thread-CPU-time loop;
// 2-vCPU Sapphire Rapids, Release, procedural rig 14,071 vertices / 27,104
// triangles, face chart ~700k covered texels at R = 1024, 640×480 frame, face
// ~250 px wide). Measured while other builds kept the load average at 4–6 on the
// 2 vCPUs, so wall times were 2–3× the CPU times; cv::remap of a 1024² map (the
// PLATFORM.md reference, 7.1 / 4.1 ms for 1 / 2 threads) took 9.5–10 / 3.8–4.3 ms
// in the same runs. Minimum over repetitions, 1 / 2 TBB threads:
//   DepthBuffer          2.2–3.8 / 1.8–3.3 ms
//   VisibleVertices      3.0–4.5 / 2.4–3.6 ms   (target ≤ 2 ms: not met)
//   Extract (R = 1024)   15–17 / 7.4–9 ms       (target ≤ 5 ms: not met; about
//                        a third is the depth buffer, the rest the texel loop)
//   MesoscopicMap (1024) 20–27 ms (computed once, on the first frame)
// Extract with `visible_vertices` shares one depth buffer between both.
//
// Differences from the paper:
//   1. The paper renders the texture on the GPU and does not describe its
//      visibility handling; here a CPU z-buffer of the coarse mesh and a view-angle
//      limit decide which texels are seen (unseen texels are 0 and flagged).
//   2. The view angle and the slope of the depth tolerance are interpolated from
//      per-vertex values rather than computed from an interpolated normal per
//      texel (cheaper; differs by < 1° on the coarse mesh's triangles).
//   3. Triangles with a vertex less than 1 mm in front of the camera are not
//      rasterised into the depth buffer (no near-plane clipping).
//   4. T^t is blended with the previous frames' blend where both saw the texel,
//      T_s^t = (1 − a) T^t + a T_s^{t−1} (BlendTextureHistory; temporal_weight
//      a = 0.7 by default since crease 0.4.6, 0.5 before; 0 = the paper). Sec. 5.1
//      asks for a temporally stable texture and gets it from the flow refinement
//      alone, which leaves the camera's noise in it, and the fern features (pixel
//      differences, Sec. 4.3) flip on it.
//      The blend lowers the noise's variance to (1 − a)/(1 + a) of a frame's (1/3)
//      and lags a change of the face by a/(1 − a) frames (1). Measured (issue 17's
//      ladder, quick profile, rung R2, 3 seeds, lined novel actors: age ≥ 0.7,
//      640×480): D^t's frame-to-frame correlation on a still face 0.884 ± 0.030 →
//      0.950 ± 0.027 at a = 0.5, and its wrinkle-region correlation with D* 0.148 →
//      0.174; with the flattened-texture training levers (ratio, α = 0.002, G 1 mm)
//      0.729 ± 0.157 → 0.867 ± 0.089 (a = 0.5) and 0.929 ± 0.060 (a = 0.7), the
//      correlation 0.371 → 0.389 / 0.394. On the quickstart's novel actor (seed 101,
//      211 frames, tracker's own landmarks, rung R3) a = 0.5 / 0.7 / 0.8 give a still
//      face of 0.881 / 0.926 / 0.941 and a wrinkle-region correlation of 0.082 / 0.085 /
//      0.089, hence the default 0.7 (lag 2.3 frames, noise variance 0.18 of a frame's);
//      the 3-seed ladder above at a = 0.7 with the paper's settings: still face R2
//      0.971 ± 0.018, R3 0.936 ± 0.027 (0.950 / 0.920 at a = 0.5), correlation R2 0.16,
//      R3 0.06 (0.17 / 0.07). About 1 ms per frame at R = 1024
//      (bench/frame_texture_bench BM_BlendTextureHistory, 2 cores).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "core/types.h"
#include "core/uv_raster.h"

namespace crease {

class OptionVisitor;

struct FrameTextureOptions {
  int map_resolution = 1024;  // R: texels per side of T^t (1024², Sec. 4.2 / 5.1)
  // Texels seen more obliquely than this (angle between normal and view
  // direction) are unseen, degrees (as TextureOptions of training).
  double max_view_angle_deg = 75.0;
  // τ0: base tolerance of the depth test, mm; the slope term of the header
  // comment is added per texel. Not in the paper.
  double depth_tolerance_mm = 1.0;
  // Optional: texels of the seen mask within this many texels of a covered but
  // unseen texel are dropped too (a square erosion towards occlusion and
  // view-angle borders; the chart's own boundary is not eroded). 0 = off: the
  // footprint depth test already keeps blended samples out. Costs a few extra
  // passes over the R×R masks.
  int erode_seen_texels = 0;
  // a of Difference 4: the previous frames' share of T^t, in [0, 0.95]. 0 = off (the paper).
  double temporal_weight = 0.7;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct FrameTexture {
  cv::Mat gray;  // CV_32F R×R: linear luminance (Rec. 709) of the image, 0 where unseen
  cv::Mat seen;  // CV_8U R×R: 255 where seen, 0 elsewhere
  int num_seen = 0;  // texels set in `seen`
  double ms = 0;     // wall time of Extract, milliseconds
};

// Area-weighted vertex normals of meshes with the rig's topology, equal to
// VertexNormals (core/mesh_ops.h) — UV-seam copies share one normal — with the
// seam groups taken once from the rig's neutral instead of a sort per call. A
// group is merged in a frame only where its copies still coincide exactly.
class RigVertexNormals {
 public:
  explicit RigVertexNormals(const TriMesh& neutral);
  // V: #V×3 (any frame); N resized to #V×3 unit normals, (0,0,0) where undefined.
  void Compute(const MatX3d& V, MatX3d* N) const;
  int num_vertices() const { return num_vertices_; }

 private:
  int num_vertices_ = 0;
  MatX3i F_;
  std::vector<std::pair<int, int>> seam_pairs_;  // (copy, representative), copy > representative
};

// Difference 4: `texture` becomes (1 − weight) T + weight H on the texels that both
// `texture` and `history` saw (elsewhere it stays as extracted), and `history`
// becomes that result. An empty `history` (the first frame, or after a lost face)
// is only filled. Throws Error when the maps differ in size or type.
void BlendTextureHistory(double weight, FrameTexture* texture, FrameTexture* history);

class FrameTextureExtractor {
 public:
  // Topology and UVs from rig.neutral restricted to FaceChartTriangles(rig); the
  // UV raster (and anything per texel that does not change per frame) is built
  // once here. Throws Error on invalid options, intrinsics or rig.
  FrameTextureExtractor(const FaceRig& rig, const CameraIntrinsics& intrinsics, const FrameTextureOptions& options);
  ~FrameTextureExtractor();
  FrameTextureExtractor(FrameTextureExtractor&&) noexcept;
  FrameTextureExtractor& operator=(FrameTextureExtractor&&) noexcept;

  // Depth buffer of the whole rig mesh with vertices `cam_vertices` (#V×3, camera
  // frame, mm): CV_32F height×width, z (mm) of the nearest surface through each
  // pixel centre, +inf where no triangle covers the pixel.
  cv::Mat DepthBuffer(const MatX3d& cam_vertices) const;

  // Per-vertex visibility (#V, 255/0) of the mesh with vertices `cam_vertices`
  // (#V×3, camera frame, mm): in front of the camera, inside the image,
  // front-facing (vertex normal towards the camera), not occluded (the depth buffer
  // at the vertex's nearest pixel is not nearer than z − τ, τ as in the header
  // comment with tan θ capped at 10).
  std::vector<uint8_t> VisibleVertices(const MatX3d& cam_vertices) const;

  // T^t: texture of `image` (CV_32FC3 linear RGB or CV_32FC1, sized like the
  // intrinsics) in the rig's UV layout from `cam_vertices` (the refined mesh L~^t,
  // #V×3, camera frame, mm), visibility-aware (depth buffer + view angle, header
  // comment), bilinear sampling. Throws Error naming the wrong image size or type,
  // or the vertex array's shape or first non-finite vertex. Thread-safe (const).
  FrameTexture Extract(const MatX3d& cam_vertices, const cv::Mat& image) const;
  // Same into `out`, reusing its buffers when they have the right size and type
  // (a capture loop avoids reallocating 5 MB per frame). When `visible_vertices` is
  // given it receives VisibleVertices(cam_vertices) from the same depth buffer (one
  // rasterisation per frame for both).
  void Extract(const MatX3d& cam_vertices, const cv::Mat& image, FrameTexture* out,
               std::vector<uint8_t>* visible_vertices = nullptr) const;

  const cv::Mat& coverage() const;  // CV_8U R×R: 255 where the face chart covers the texel
  const UvRaster& raster() const;   // the face chart's raster (triangles index chart_mesh().F)
  // The face chart mesh: rig.neutral's V and UV with F = FaceChartTriangles(rig).
  const TriMesh& chart_mesh() const;
  const FrameTextureOptions& options() const;
  const CameraIntrinsics& intrinsics() const;
  int num_vertices() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The mesoscopic map of Sec. 5.3:
//   D^HF = γ · (G_small * T − G_large * T)
// on the first frame's texture T: a narrow-band DoG ("3×3 for the high and 9×9
// for the low kernel", γ = 5), as normalised convolutions over `seen`
// (G * (T·m) / G * m), 0 outside `seen`.
//
// Sign and units: T is linear intensity in [0, 1] and D^HF is a displacement in
// mm along the outward normal, so γ is in mm per unit of intensity. A dark pore
// has T below its surroundings, so G_small * T < G_large * T there and D^HF < 0:
// dark pores become inward displacement (the sign convention of the actor's maps,
// synth/actor.h: negative = pits). With γ = 5, a pore 0.01 darker than the local
// mean gives ~−0.05 mm at its centre (reduced by the small kernel's blur).
//
// Kernels (DESIGN.md: ambiguous sizes are interpreted and documented): "3×3" and
// "9×9" are read as the window widths of Gaussian kernels at R = 1024 with
// OpenCV's default σ for a window k, σ(k) = 0.3·((k − 1)/2 − 1) + 0.8 (σ = 0.8 and
// 1.7 texels). For a map of size R, σ scales by R / meso_reference_resolution and
// the window to the odd width nearest k·R/1024 (1 = no blur).
struct MesoscopicOptions {
  int meso_small_kernel = 3;    // high-frequency Gaussian window, texels at the reference resolution (Sec. 5.3: 3×3)
  int meso_large_kernel = 9;    // low-frequency Gaussian window, texels at the reference resolution (Sec. 5.3: 9×9)
  double meso_scale = 5.0;      // γ, mm per unit of linear intensity (Sec. 5.3: γ = 5)
  int meso_reference_resolution = 1024;  // map size at which the kernels are given (Sec. 4.2 maps are 1024²)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// D^HF (CV_32F R×R, mm) of a gray texture (CV_32FC1, square) and its seen mask
// (CV_8U, same size, non-zero = seen). Texels outside `seen` may hold anything.
// Throws Error on a wrong type or size, or non-finite seen texels.
cv::Mat MesoscopicMap(const cv::Mat& gray_texture, const cv::Mat& seen, const MesoscopicOptions& options);

}  // namespace crease
