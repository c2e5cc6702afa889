// Skin of a synthetic actor, as maps in the rig's UV layout (square, texel
// convention of DESIGN.md):
//   * mesoscopic displacement (pores and fine lines, ~10–50 µm; the layer that
//     paper Sec. 5.3 adds from image detail), CV_32F, mm along the normal;
//   * diffuse albedo (linear RGB, CV_32FC3): per-actor tone, low-frequency
//     colour variation, blotches, freckles, redder lips, darker brows, a tint
//     around the eyes;
//   * specular intensity (CV_32F, weight of the specular lobe, 1 = nominal skin)
//     and roughness (CV_32F, GGX α) with an oily T-zone.
// Each map is drawn from its own seeded stream, independent of the wrinkle
// layout. Everything hangs on FaceAnchors and the rig's region masks, so it
// works on any rig with a face UV chart.
//
// Differences from reality: pores are isotropic pits on band-passed noise (no
// pore orientation field); fine lines are short straight scratches in two
// dominant directions; albedo is a multiplicative layer stack, not a spectral
// melanin/haemoglobin model; brows are a colour only (no hair geometry).
#pragma once

#include <cstdint>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "synth/wrinkles.h"

namespace crease {

struct MesoscopicParams {
  uint64_t seed = 0;
  double pore_depth_mm = 0.03;       // depth of a typical pore pit, mm
  double pore_density_per_mm2 = 1.0; // pits per mm² on the cheeks and nose (forehead 0.7×, elsewhere 0.4×)
  double roughness_mm = 0.012;       // RMS of the band-passed micro relief, mm
  double fine_line_depth_mm = 0.015; // depth of fine lines, mm
  double fine_line_density = 0.5;    // fine lines per mm² (short scratches)
};

struct SkinParams {
  uint64_t seed = 0;
  double tone = 0.3;         // [0, 1]: 0 very light, 1 very dark
  double redness = 0.3;      // [0, 1]: overall rosiness (haemoglobin)
  double variation = 0.5;    // [0, 1]: low-frequency colour variation
  double blotches = 0.3;     // [0, 1]: red blotches
  double freckles = 0.2;     // [0, 1]: freckle density and contrast
  double lip_redness = 0.6;  // [0, 1]
  double brow_darkness = 0.7;  // [0, 1]
  double eye_tint = 0.4;     // [0, 1]: darker, bluish-purple tint around the eyes
  double oiliness = 0.5;     // [0, 1]: specular boost and lower roughness in the T-zone
  double specular = 1.0;     // overall specular weight (1 = nominal skin)
  double roughness = 0.4;    // base GGX α
};

// Random parameters for one actor (own stream: `rng` is consumed, nothing else).
MesoscopicParams GenerateMesoscopicParams(Rng& rng);
SkinParams GenerateSkinParams(Rng& rng);

// Mesoscopic displacement map, CV_32F size², mm (negative = pits/valleys).
cv::Mat BuildMesoscopicMap(const FaceRig& rig, const FaceAnchors& anchors, const MesoscopicParams& params,
                           int size);

struct SkinMaps {
  cv::Mat albedo;     // CV_32FC3, linear RGB in [0, 1]
  cv::Mat specular;   // CV_32F, specular lobe weight (≈ 0.5–1.8)
  cv::Mat roughness;  // CV_32F, GGX α (≈ 0.2–0.55)
  cv::Mat hair;       // CV_32F, weight of scalp hair painted on the chart (ScalpHairline), 0 = skin
  Eigen::Vector3f hair_color = Eigen::Vector3f::Zero();  // its linear RGB (the brows' colour)
};

// Scalp hair for a head without a hair part (the ICT-FaceKit head is bald):
// short-cropped hair on the scalp above a hairline, in the head frame (mm; x =
// the subject's left, y up, z forward). The hairline's height above the eye line
// (mean height of iBUG 37–48) depends on the azimuth θ about the vertical axis
// through the ears (x = 0, z = mean z of iBUG 1 and 17): 62 mm at the front,
// receding to 45 mm at the temples (60°) and over the ears (to 110°), down to the
// nape (−45 mm) behind them (≥ 130°); linear in between, soft over ±1.5 mm.
struct ScalpHairline {
  static constexpr double kFrontHeightMm = 62.0;  // the hairline above the eye line at the front
  double eye_y = 0.0;  // the eye line's height, mm
  double ear_z = 0.0;  // the ears' depth, mm
  // Hair weight in [0, 1] of a neutral head-frame point.
  double Weight(const Eigen::Vector3d& p) const;
};
// From the rig's 68 iBUG landmarks (throws Error naming the rig without them).
ScalpHairline ScalpHairlineOf(const FaceRig& rig);
// True when the studio paints scalp hair on the rig's chart: the rig has the 68
// iBUG landmarks and no hair part of its own.
bool PaintsScalpHair(const FaceRig& rig);
// The skin maps in the rig's UV layout. A rig with the 68 iBUG landmarks and
// without a part named "hair" (a hair cap of its own, as the procedural head's)
// gets scalp hair painted above its ScalpHairline (SkinMaps::hair).
SkinMaps BuildSkinMaps(const FaceRig& rig, const FaceAnchors& anchors, const SkinParams& params, int size);

// Random field helpers shared by the actor layers: white noise of `rng` on a
// grid of `cells`² (cells ≥ 2), blurred by `sigma_cells`, normalised to zero
// mean and unit RMS, then resized (bicubic) to size². Deterministic.
cv::Mat SmoothNoise(Rng& rng, int cells, double sigma_cells, int size);

}  // namespace crease
