// Synthetic actors: seeded random people on a FaceRig, with every layer of
// facial detail kept separately as ground truth (issue 3, part 2):
//
//   hi-res surface = coarse rig surface (identity α, expression β)
//                  + (static shape S + expression wrinkles D(β) + mesoscopic M) · n̂
//
//   * α: Gaussian identity coefficients in the rig's modes;
//   * S: person-specific medium-scale shape the rig cannot express (smooth,
//     band-limited random field, a few tenths of a mm);
//   * D(β): expression wrinkles (synth/wrinkles.h) — the medium-scale
//     expression displacement that paper Sec. 4.1 extracts from scans and
//     Sec. 4.3 / 5.2 regress;
//   * M: mesoscopic detail (pores, fine lines; synth/skin.h), static;
//   * skin albedo, specular and roughness maps (synth/skin.h), independent of
//     the wrinkle layout;
//   * personal expression deviations: the actor's own version of the rig's
//     expression shapes (ExpressionDeviationParams), so the coarse surface is
//     V0 + Iα + B'β with B' ≠ B (PersonalRig).
// Maps are CV_32F R×R (R = ActorOptions::resolution, 1024 as in Sec. 4.2) in the
// rig's UV layout, mm along the normal, positive outwards.
//
// An Actor is the definition (parameters and layouts, written as JSON); with
// the rig it rebuilds every map and surface bit-identically on the same build.
// ActorModel precomputes everything per actor once; ActorModel::Frame builds
// the ground truth of one expression (≤ 0.2 s with R = 1024, bench/actor_bench.cc).
//
// Differences from the paper/reality:
//  1. The paper's training data are scans; here the medium band D is generated
//     directly (wrinkle lines driven by coarse strain), so the coarse mesh needs
//     no deformation-transfer cleaning (Sec. 4.1) and D is exact by construction.
//  2. The static shape S and the wrinkles are displacements along the
//     interpolated coarse normal (see synth/hires_surface.h), not free-form
//     geometry; no self-intersections are prevented.
//  3. Pores and wrinkles are fixed in UV; they do not slide with the skin.
//  4. Wrinkles fade out under the scalp hair the studio paints on a chart without a
//     hair part (ICT-FaceKit), and forehead lines are laid out below its hairline:
//     lines under the hair would be in the truth but in no image.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/image_io.h"
#include "core/options.h"
#include "core/tri_mesh.h"
#include "synth/hires_surface.h"
#include "synth/skin.h"
#include "synth/wrinkles.h"

namespace crease {

struct ActorOptions {
  int resolution = 1024;           // R: maps, texels per side (1024², Sec. 4.2); also the hi-res grid S
                                   //   unless the chart then has fewer than surface_min_vertices
  int surface_min_vertices = 300000;  // the hi-res grid S ≥ R is refined until it has this many vertices
  double identity_stddev = 1.0;    // σ of each identity coefficient (units of the rig's modes)
  double identity_clamp = 2.5;     // |α_k| ≤ identity_clamp · σ
  double age_min = 0.0;            // actor age drawn uniformly in [age_min, age_max] ⊂ [0, 1]
  double age_max = 1.0;            //   (0: almost no lines, 1: many deep and static lines)
  double style_min = -1.0;         // wrinkle shape drawn in [style_min, style_max] ⊂ [−1, 1]
  double style_max = 1.0;          //   (−1 thin and deep, +1 wide and shallow)
  bool static_lines = true;        // allow lines visible at neutral (older actors)
  double static_shape_rms_mm = 0.3;        // RMS of S, mm (each actor draws 0.5–1.5× this)
  double static_shape_wavelength_mm = 14.0;  // typical feature size of S, mm
  double mesoscopic_scale = 1.0;   // multiplier of the mesoscopic amplitudes
  int strain_resolution = 256;     // metric-tensor map size for wrinkle compression, texels
  double strain_smoothing_mm = 3.0;  // σ smoothing the compression field, mm
  double phong_alpha = kDefaultPhongAlpha;  // α: rounding of the coarse facets under the hi-res surface
  int subdivision_levels = 0;      // > 0: the hi-res surface's base is the rig's Loop subdivision surface
                                   //   after this many steps (smooth across the coarse edges; phong_alpha
                                   //   unused), BuildHiResLayout; 0: the Phong-tessellated coarse facets
  double expression_deviation = 0.3;        // σ of the personal expression deviations (0 = none)
  double expression_deviation_wavelength_mm = 40.0;  // their feature size, mm

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Personal expression deviations: this actor's version of each of the rig's
// expression shapes differs from the rig's by a gain, a left–right asymmetry and
// a smooth spatial modulation of the delta, all drawn per shape:
//   B'_b(v) = B_b(v) · g_b · (1 + a_b · x_v / 60 mm) · (1 + n_b(p_v)),
//   g_b = 1 + σ·N(0,1), a_b = σ_a·N(0,1), n_b a smooth random field of standard
//   deviation σ_n and feature size `wavelength_mm` over the neutral positions p_v,
// with σ = `amount` (factors clamped to [0, 2]); σ_a and σ_n are σ, lowered for a
// shape that moves far so that the stretch they add (σ_n · 2π/λ · max|B_b|, and
// σ_a · max|B_b| / 60 mm) stays under kDeviationMaxStrain: jawOpen's 35 mm folded
// the chin over itself at σ 0.3 without it. No rig shared by all actors
// represents these expressions exactly: the model error that the tracker's
// blendshape prior cannot fit and Sec. 5.1's refinement is there to correct.
inline constexpr double kDeviationMaxStrain = 0.08;  // the spatial deviations' stretch of the skin, at most about

struct ExpressionDeviationParams {
  uint64_t seed = 0;
  double amount = 0.0;          // σ; 0 = the rig's own shapes
  double wavelength_mm = 40.0;  // feature size of the spatial modulation, mm
};

struct StaticShapeParams {
  uint64_t seed = 0;
  double rms_mm = 0.3;          // RMS of the field, mm
  double wavelength_mm = 14.0;  // typical feature size, mm
};

// The definition of one actor.
struct Actor {
  static constexpr int kFormatVersion = 1;
  uint64_t seed = 0;           // the seed it was generated from (informative)
  ActorOptions options;
  Eigen::VectorXd identity;    // α, #I of the rig (or fewer: the rest are 0)
  WrinkleStyle style;
  std::vector<WrinkleLine> wrinkles;
  StaticShapeParams static_shape;
  MesoscopicParams mesoscopic;
  SkinParams skin;
  ExpressionDeviationParams expression_deviation;  // absent in older actor files: none
  std::string source;          // the file it was read from (ActorFromJson's `what`), named by errors; not written
};

// The rig as this actor's face moves: `rig` with the actor's expression
// deviations applied to its expression basis (the rig itself when they are 0).
// ActorModel renders with it, and evaluation takes the truth from it.
FaceRig PersonalRig(const FaceRig& rig, const Actor& actor);

// A random actor for `rig`. Independent streams (forked from `seed`) draw the
// identity, the style, the wrinkle layout, the static shape, the mesoscopic
// detail and the skin, so e.g. the skin does not change when wrinkle code does.
Actor GenerateActor(const FaceRig& rig, uint64_t seed, const ActorOptions& options = {});

// JSON (text) of the definition; doubles are written with round-trip precision.
std::string ActorToJson(const Actor& actor);
// Parses an actor definition; errors start with `what` (the file name) and name
// the field ("actor.json: field 'wrinkles[3].width_mm' must be a number").
Actor ActorFromJson(const std::string& text, const std::string& what);
void WriteActor(const std::filesystem::path& path, const Actor& actor);  // atomic
Actor ReadActor(const std::filesystem::path& path);

// Person-specific static shape S, CV_32F size², mm. ActorModel multiplies it by
// ChartRimFade(…, kStaticShapeRimFadeMm), so the face meets the rest of the head
// (which carries no displacement) without a step at the seam.
cv::Mat BuildStaticShapeMap(const FaceAnchors& anchors, const StaticShapeParams& params, int size);

// CV_32F size² weight in the rig's UV layout: 0 on and outside the face chart's
// rim, rising smoothly (smoothstep) to 1 at `width_mm` inside it (UV distance ×
// mm_per_uv). With `outer_rim_only`, holes in the chart (eyes and mouth of a chart
// that leaves them open, as ICT-FaceKit's does) are not rim.
cv::Mat ChartRimFade(const FaceRig& rig, int size, double mm_per_uv, double width_mm, bool outer_rim_only = false);
inline constexpr double kStaticShapeRimFadeMm = 10.0;

// Ground truth of one frame, per layer.
struct ActorFrame {
  Eigen::VectorXd identity;     // rig parameters α
  Eigen::VectorXd expression;   // rig parameters β
  TriMesh coarse;               // rig surface (identity + expression) with vertex normals
  cv::Mat expression_displacement;  // D, CV_32F R×R, mm (Sec. 4.1's medium-scale expression detail)
  cv::Mat static_displacement;      // S, CV_32F R×R, mm (shared with the model; do not modify)
  cv::Mat mesoscopic_displacement;  // M, CV_32F R×R, mm (shared with the model; do not modify)
  TriMesh hires;                // full high-resolution surface (empty when not built)
  double seconds = 0.0;         // time to build this frame
};

class ActorModel {
 public:
  // Precomputes the layers of `actor` on `rig` (copied). Throws Error when the
  // actor does not fit the rig (too many identity coefficients) or the rig lacks
  // UVs or the landmarks/regions that anchor the layout.
  ActorModel(const FaceRig& rig, const Actor& actor);

  // β: #E expression weights (or fewer; empty = neutral).
  ActorFrame Frame(const Eigen::VectorXd& expression, bool build_hires = true) const;
  // D for coarse rig positions V (#V×3) of this actor.
  cv::Mat ExpressionDisplacement(const MatX3d& V) const;

  // The actor's personal rig (PersonalRig: the input rig with its expression deviations).
  const FaceRig& rig() const { return rig_; }
  const Actor& actor() const { return actor_; }
  const FaceAnchors& anchors() const { return anchors_; }
  const HiResLayout& layout() const { return layout_; }
  const StrainField& strain() const { return *strain_; }
  const WrinkleField& wrinkles() const { return *wrinkles_; }
  const cv::Mat& neutral_metric() const { return neutral_metric_; }
  const cv::Mat& static_displacement() const { return static_; }
  const cv::Mat& mesoscopic_displacement() const { return meso_; }
  const SkinMaps& skin() const { return skin_; }

 private:
  FaceRig rig_;
  Actor actor_;
  FaceAnchors anchors_;
  HiResLayout layout_;
  std::unique_ptr<StrainField> strain_;
  std::unique_ptr<WrinkleField> wrinkles_;
  cv::Mat neutral_metric_;
  cv::Mat static_;
  cv::Mat meso_;
  SkinMaps skin_;
};

// Writes the frame's layer maps as float EXR into `dir` (expression_displacement.exr,
// static_displacement.exr, mesoscopic_displacement.exr). Inline so that only
// callers of it link crease_core_image (core/image_io.h).
inline void WriteActorFrameMaps(const std::filesystem::path& dir, const ActorFrame& frame) {
  std::filesystem::create_directories(dir);
  WriteImage(dir / "expression_displacement.exr", frame.expression_displacement);
  WriteImage(dir / "static_displacement.exr", frame.static_displacement);
  WriteImage(dir / "mesoscopic_displacement.exr", frame.mesoscopic_displacement);
}

// Writes the actor's skin maps (albedo.exr, specular.exr, roughness.exr) into `dir`.
inline void WriteActorSkinMaps(const std::filesystem::path& dir, const SkinMaps& skin) {
  std::filesystem::create_directories(dir);
  WriteImage(dir / "albedo.exr", skin.albedo);
  WriteImage(dir / "specular.exr", skin.specular);
  WriteImage(dir / "roughness.exr", skin.roughness);
}

}  // namespace crease
