// Lights of the studio renderer (issue 3, part 3) and named light rigs.
//
// Frames. A LightRig is defined in its rig frame: when `attached_to_camera` (the
// default: the studio stands still while the head turns) the rig frame has the
// camera's axes (OpenCV: x right, y down, z forward) and its origin at the head
// origin, so positions (sphere lights) are relative to the subject and follow the
// head's translation but not its rotation; otherwise the rig frame is the head
// frame (y up, the face looking along +z). Every rig frame has three named axes:
//   up     camera: −y, head: +y
//   front  from the subject towards the viewer — camera: −z, head: +z
//   right  up × front — camera: +x, head: +x
// Azimuth turns from front towards right about up; elevation tilts towards up.
// Environment maps are latitude–longitude images in this (right, up, front)
// frame: row v (0 at the top) has polar angle θ = π·v/H from up, column u has
// azimuth φ = 2π·(u/W − 0.5) (the map's centre column faces front), i.e.
//   dir = sin θ sin φ · right + cos θ · up + sin θ cos φ · front.
//
// Intensity convention: a light's `color` is the linear value at which it renders
// a white Lambertian surface facing it (irradiance π·color), so rigs are easy to
// balance; environment maps hold radiance (a constant map of value L renders an
// unoccluded white Lambertian surface at L).
#pragma once

#include <memory>
#include <opencv2/core/mat.hpp>
#include <string>
#include <variant>
#include <vector>

#include "core/types.h"

namespace crease {

// Infinitely distant light: hard shadows (one shadow ray).
struct DirectionalLight {
  Eigen::Vector3d direction{0.0, 0.0, -1.0};  // towards the light, rig frame (normalised on use)
  Eigen::Vector3d color{1.0, 1.0, 1.0};       // linear RGB, see the intensity convention
};

// Spherical area light: soft shadows from `samples` shadow rays per shading sample,
// directions sampled uniformly in the cone the sphere subtends.
struct SphereLight {
  Eigen::Vector3d centre{0.0, 0.0, -1000.0};  // mm, rig frame
  double radius = 100.0;                      // mm
  // Linear RGB value of a white Lambertian surface at the rig origin facing the
  // light; the emitted radiance is color·(d/radius)², d = |centre|.
  Eigen::Vector3d color{1.0, 1.0, 1.0};
  int samples = 8;
};

// A latitude–longitude radiance map with a luminance-proportional sampling
// distribution (piecewise constant over pixels, weighted by sin θ).
class EnvironmentMap {
 public:
  // `latlong`: CV_32FC1/3/4 linear radiance (R, G, B; alpha ignored), ≥ 2×1 pixels,
  // finite, non-negative, not all zero. Errors name `what` (e.g. the file, read
  // with core/image_io ReadImage).
  EnvironmentMap(const cv::Mat& latlong, const std::string& what);

  int width() const { return width_; }
  int height() const { return height_; }
  const cv::Mat& image() const { return image_; }  // CV_32FC3

  // Radiance arriving from unit direction `dir` (environment frame: x right, y up,
  // z front), nearest pixel.
  Eigen::Vector3f Radiance(const Eigen::Vector3f& dir) const;
  // Direction drawn with density proportional to pixel luminance·sin θ from two
  // uniform numbers in [0, 1); *pdf is the solid-angle density (1/sr).
  Eigen::Vector3f Sample(double u1, double u2, float* pdf) const;
  // Solid-angle density of Sample at `dir`.
  float Pdf(const Eigen::Vector3f& dir) const;
  // ∫ L(ω) max(0, n·ω) dω / π over the sphere: the unoccluded value of a white
  // Lambertian surface with normal n (numerical, over the pixels).
  Eigen::Vector3d LambertValue(const Eigen::Vector3d& n) const;

 private:
  int width_ = 0, height_ = 0;
  cv::Mat image_;
  std::vector<double> row_cdf_;   // H + 1
  std::vector<double> col_cdf_;   // H × (W + 1)
  std::vector<float> pixel_pdf_;  // H × W, probability of each pixel
};

// Built-in procedural environments ("studio": soft key, fill and rim boxes over a
// dim room; "overcast": CIE overcast sky over a grey ground; "window": one bright
// window with mullions in a dim room), width × width/2 pixels, scaled so that a
// white Lambertian surface facing front renders at about 0.8.
std::shared_ptr<const EnvironmentMap> ProceduralEnvironment(const std::string& preset, int width = 256);
std::vector<std::string> ProceduralEnvironmentNames();

// Image-based light: radiance map × scale; `samples` shadow rays per shading
// sample, half drawn from the map's luminance distribution and half
// cosine-weighted, combined by multiple importance sampling.
struct EnvironmentLight {
  std::shared_ptr<const EnvironmentMap> map;
  double scale = 1.0;         // multiplies the radiance
  double rotation_deg = 0.0;  // turns the map about the rig's up axis (front towards right)
  int samples = 16;
};

// Ambient occlusion: uniform radiance `color` from every direction of the upper
// hemisphere not blocked within `max_distance_mm` (cosine-weighted shadow rays;
// diffuse only).
struct AmbientOcclusionLight {
  Eigen::Vector3d color{0.1, 0.1, 0.1};
  double max_distance_mm = 60.0;
  int samples = 4;
};

using Light = std::variant<DirectionalLight, SphereLight, EnvironmentLight, AmbientOcclusionLight>;

struct LightRig {
  std::string name;
  std::vector<Light> lights;
  bool attached_to_camera = true;  // rig frame = camera frame (else head frame), see above
};

// Throws Error naming the rig and the light for invalid parameters (non-finite or
// negative colours, zero directions, radius ≤ 0 or inside-the-light centres,
// samples < 1, missing environment maps).
void ValidateLightRig(const LightRig& rig);

// Unit direction in the rig frame for azimuth/elevation in degrees (see above):
// (0, 0) is front, (90, 0) right, (0, 90) up.
Eigen::Vector3d RigDirection(double azimuth_deg, double elevation_deg, bool attached_to_camera = true);
// A directional light from azimuth/elevation with a grey intensity (the
// `moving-light` sequence sweeps it).
DirectionalLight DirectionalFromAzimuthElevation(double azimuth_deg, double elevation_deg, double intensity = 1.0,
                                                 bool attached_to_camera = true);

// The rig of the `moving-light` sequence (the paper's Fig. 14): one directional
// light at azimuth/elevation with a grey intensity, plus weak ambient occlusion
// (0.05) so that the unlit side is not black. Camera-attached, named "moving-light".
LightRig DirectionalRig(double azimuth_deg, double elevation_deg, double intensity = 1.0);

// Named rigs (camera-attached):
//   front          directional from the camera side (5° above) + weak ambient occlusion
//   raking-above   directional grazing from above the forehead (78° elevation) + weak ambient
//   raking-side    directional grazing from the right (80° azimuth)
//   studio         key (large sphere light, upper left) + fill (sphere light, right) +
//                  rim (directional from behind) + ambient occlusion
//   ceiling        a room's ceiling light (large sphere light above the front, 55°
//                  elevation) + a screen's glow from the front + ambient occlusion
//   studio-env, overcast, window   the procedural environment maps
// Throws Error naming the unknown preset and listing the known ones.
LightRig MakeLightRig(const std::string& preset);
std::vector<std::string> LightRigNames();

}  // namespace crease
