// Studio renderer (issue 3, part 3): a ray tracer on Embree (core RayCaster, BVH
// built once, refitted per frame) that renders a TriMesh with per-part materials
// and face-chart material maps under a LightRig, with hard and soft shadows,
// environment lighting, ambient occlusion, a skin BRDF (synth/brdf.h), an optional
// screen-space subsurface approximation and N×N supersampling. Relighting: the
// same Renderer renders any frame (UpdateGeometry) under any rig, camera and
// options without rebuilding the BVH.
//
// Frames: the mesh is in head coordinates (mm); Camera::cam_from_head places it;
// lights are in the rig frame (synth/lights.h). Output images are linear-light
// RGB (R, G, B channel order, DESIGN.md); pixel (x, y) has its centre at (x, y).
//
// Determinism: Render draws one 64-bit frame seed from the Rng passed in and
// derives an independent generator per pixel from it, so the image depends only
// on the seed — not on TBB's scheduling or the number of threads.
//
// Differences from a full path tracer (documented approximations):
//   1. Direct lighting only (no interreflections); ambient occlusion stands in for
//      indirect light.
//   2. Environment lights combine luminance importance sampling with cosine-weighted
//      sampling (MIS, balance heuristic), but do not sample the specular lobe:
//      glossy reflections of very smooth parts (eyes) are noisier.
//   3. Subsurface scattering is approximated by blurring the diffuse irradiance in
//      screen space with a depth-aware Gaussian whose width is given in mm per
//      colour channel (red scatters furthest), in the spirit of Jimenez et al.'s
//      screen-space SSS; not a diffusion profile.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/options.h"
#include "core/ray_caster.h"
#include "core/rng.h"
#include "core/tri_mesh.h"
#include "synth/brdf.h"
#include "synth/lights.h"

namespace crease {

// What the surface is made of. Face-chart maps cover UV ∈ [0, 1]² (v down, texel
// convention of DESIGN.md, bilinear lookup, clamped at the border); any map may be
// empty. A triangle's part is the part of its first vertex.
struct SceneMaterials {
  cv::Mat albedo;     // CV_32FC3 linear RGB diffuse albedo ρ_d
  cv::Mat specular;   // CV_32FC1 specular intensity ρ_s
  cv::Mat roughness;  // CV_32FC1 perceptual roughness
  std::vector<int> vertex_part;          // #V part ids in [0, #part_materials), or empty (no parts)
  std::vector<Material> part_materials;  // material of each part (Material::textured selects the maps)
  // Without parts: `face` where the hit's UV lies in [0, 1]² (then the maps
  // apply), `other` elsewhere (UVs outside the chart belong to non-face parts).
  Material face = MaterialPreset("skin");
  Material other = MaterialPreset("grey");
};

struct RenderOptions {
  // N: N×N stratified, jittered samples per pixel; 1 = one ray through the pixel
  // centre (fast mode).
  int samples_per_axis = 1;
  bool shadows = true;   // cast shadow rays (false: every light is unoccluded)
  bool passes = false;   // also output depth, normal, UV, triangle id and part id (pixel centres)
  std::vector<double> background = {0.0, 0.0, 0.0};  // linear RGB of rays that miss the mesh
  // Rays that miss see the rig's first environment light instead of `background`.
  bool environment_background = false;
  // Screen-space subsurface approximation: blur width (Gaussian σ) of the diffuse
  // irradiance for the red channel, mm (green ×0.5, blue ×0.25); 0 = off.
  double subsurface_mm = 0.0;
  // Shadow-ray origins are offset along the geometric normal by this much, mm.
  double ray_epsilon_mm = 0.005;
  int tile_size = 16;  // pixels per tile side (a multiple of 4: 4×4-pixel ray packets)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct RenderStats {
  int64_t primary_rays = 0;
  int64_t shadow_rays = 0;
  double seconds = 0.0;
};

struct RenderResult {
  cv::Mat image;  // CV_32FC3 linear RGB
  cv::Mat alpha;  // CV_32FC1 fraction of the pixel's samples that hit the mesh
  // Passes (only with RenderOptions::passes; from the ray through each pixel centre):
  cv::Mat depth;        // CV_32FC1 z in the camera frame, mm; 0 where no hit
  cv::Mat normal;       // CV_32FC3 unit shading normal in the camera frame, facing the camera; 0 where no hit
  cv::Mat uv;           // CV_32FC2 interpolated UV; 0 where no hit
  cv::Mat triangle_id;  // CV_32SC1 row of F; -1 where no hit
  cv::Mat part_id;      // CV_32SC1 part (−1 where no hit or no parts)
  RenderStats stats;
};

// How the BVH is built (core RayCaster; not paper parameters).
struct RendererOptions {
  // Refittable BVH (RayCasterOptions::dynamic): UpdateGeometry refits instead of
  // rebuilding — fast per-frame updates, slightly slower rays.
  bool dynamic = true;
  BvhBuildQuality build_quality = BvhBuildQuality::kMedium;  // when !dynamic: "low", "medium" or "high"
  bool robust = false;                   // Embree robust traversal (no misses on shared edges)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

class Renderer {
 public:
  // Builds the BVH of `mesh` (ValidateMesh with UVs required; errors start with
  // `what`) and takes its normals (computed when absent) and materials (checked).
  Renderer(const TriMesh& mesh, SceneMaterials materials, const RendererOptions& options = {},
           const std::string& what = "Renderer mesh");
  ~Renderer();
  Renderer(Renderer&&) noexcept;
  Renderer& operator=(Renderer&&) noexcept;

  int num_vertices() const;
  int num_triangles() const;

  // A new frame of the same topology: V is #V×3 mm; N (#V×3 unit normals) is
  // computed from V when empty. Refits the BVH. Throws Error on a wrong shape.
  void UpdateGeometry(const MatX3d& V, const MatX3d& N = MatX3d());
  // New materials (same checks as the constructor); geometry untouched.
  void SetMaterials(SceneMaterials materials);

  // Renders the current geometry. Thread-parallel (TBB), deterministic given rng's state.
  RenderResult Render(const Camera& camera, const LightRig& rig, const RenderOptions& options, Rng& rng) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Motion blur over the shutter interval: `subframes` renders at shutter times
// s_k = (k + 0.5)/subframes in [0, 1], each with the geometry and camera that
// `frame_at(s_k)` returns, averaged (image and alpha; passes come from the
// subframe nearest s = 0.5). Leaves `renderer` at the last subframe's geometry.
struct MotionBlurFrame {
  MatX3d V;       // #V×3 mm
  Camera camera;
};
RenderResult RenderMotionBlurred(Renderer& renderer, const std::function<MotionBlurFrame(double)>& frame_at,
                                 int subframes, const LightRig& rig, const RenderOptions& options, Rng& rng);
// Same, interpolating linearly between the frames at shutter open and close
// (vertices and camera translation linearly, rotation by slerp; intrinsics of `open`).
RenderResult RenderMotionBlurred(Renderer& renderer, const MotionBlurFrame& open, const MotionBlurFrame& close,
                                 int subframes, const LightRig& rig, const RenderOptions& options, Rng& rng);

}  // namespace crease
