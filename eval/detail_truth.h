// The studio's truth of the detail that paper Sec. 4.1 extracts and Secs. 4.3 and
// 5.2 regress (issue 17: one definition for extraction and evaluation).
//
// Sec. 4.1 defines a scan's detail as D^j = M^j − M_0^j, where M_0^j is the neutral
// scan carried along by the low frequencies G of the expression: it holds the
// neutral's own detail (static lines, the person's shape) and the expression's
// low frequencies, and the compatible rig (MakeRigCompatible) gives up exactly the
// same band. The studio's wrinkle layer D(β) is only part of that detail: the
// actor's coarse expression shapes hold medium frequencies of their own (ICT-
// FaceKit's were built from scans of a person: a smile's cheek bulge and
// nasolabial fold, a brow raise's forehead rolls), which G removes from M_0^j and
// from the compatible rig, so every extracted D^j carries them (0.05–0.07 mm RMS
// on the face in scans without any wrinkle layer, against a wrinkle layer of
// 0.005–0.03 mm RMS), and so must the truth D^t is scored against:
//
//   D*(β) = (1 − G)[D(β) − D(0)] + ⟨(B' − B_c) β, n_c⟩
//
// D the actor's wrinkle layer (synth/actor.h; minus its neutral, which M_0^j
// carries); (1 − G) removes its own low frequencies, because G(M^j) holds them
// and the deformation transfer G(M^0) → G(M^j) hands them to M_0^j: a groove in
// D^j comes with the shallow, broad shoulders of its blur G(D). Measured on the
// detail ladder's quick profile (one novel lined actor, R2): the wrinkle-region
// correlation of D^t with D* went from 0.215 to 0.220 (G = 3 mm) and from 0.361
// to 0.366 (G = 1 mm); on extracted brow raises D^j against D* from 0.870 to
// 0.874 (crease eval-extraction). B' the actor's personal expression basis (PersonalRig), B_c that basis
// made compatible with the model's G (MakeRigCompatible), n_c the normal of the
// compatible surface at (α, β). The coarse band is identity-free: the compatible
// rig keeps the identity modes.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/uv_raster.h"
#include "pipeline/training/detail_extraction.h"
#include "synth/actor.h"

namespace crease {

class DetailTruth {
 public:
  // `rig`: the studio's rig the actor was rendered with (a dataset's rig.crig or a
  // scan set's rig); `detail`: the G of the model being scored (its
  // DetailExtractionOptions). Maps are R×R with R the actor's map resolution.
  DetailTruth(const FaceRig& rig, const Actor& actor, const DetailExtractionOptions& detail);

  // (1 − G)[D(β) − D(0)]: the wrinkle layer beyond the neutral's, less its own
  // blur by G, mm. G is applied in the UV chart as a Gaussian of σ =
  // lowpass_bandwidth_mm, normalised by the chart's coverage (WrinkleBand), where
  // the extraction runs the heat diffusion of the same σ on the scan (core/
  // mesh_ops.h); the chart is close to isometric on the forehead and around the
  // eyes, where the lines are. Without a lowpass (σ = 0) the layer is unfiltered.
  cv::Mat Wrinkles(const Eigen::VectorXd& expression) const;
  // D(β) − D(0), unfiltered: the lines as the studio drew them.
  cv::Mat WrinkleLayer(const Eigen::VectorXd& expression) const;
  // ⟨(B' − B_c) β, n_c⟩ on the face chart (0 elsewhere), mm.
  cv::Mat CoarseBand(const Eigen::VectorXd& expression) const;
  // D*(β) = Wrinkles + CoarseBand.
  cv::Mat Detail(const Eigen::VectorXd& expression) const;
  // Per texel, the signed distance along the interpolated normal from the compatible
  // surface at (α, β) — its vertices interpolated flat, as H^t is built on L~^t
  // (pipeline/capture/hifi_mesh.h) — to `surface`, the true high-resolution surface at
  // β (a scan's mesh, head frame). NaN where a ray finds no surface within `max_mm`
  // either way. `phong_alpha` > 0: the compatible surface's triangles
  // Phong-tessellated as the studio's (synth/hires_surface.h) instead of flat.
  cv::Mat SurfaceDistance(const Eigen::VectorXd& expression, const TriMesh& surface, double phong_alpha = 0.0,
                          double max_mm = 2.0) const;
  // A check of D* without its first-order model: SurfaceDistance(β, surface) minus
  // `neutral_distance`, the same from the compatible neutral to the true neutral
  // surface (SurfaceDistance(0, neutral surface), computed once per actor): exactly
  // what L~^t at the true weights lacks beyond the neutral, the coarse facets and the
  // studio's Phong rounding included. Measured (crease 0.4.16, G = 1 mm, seed 1's four training
  // actors, wrinkle band, mean): D* agrees with it at 0.88 / 0.83 / 0.48 / 0.62 on
  // brow raise / frown / smile / sneer, Sec. 4.1's D^j at 0.83 / 0.71 / 0.62 / 0.60;
  // on smiles the exact detail is dominated by the coarse facets' rounding, which D*
  // leaves out (docs/detail-path.md, "Which of the two is right"). With `phong_alpha` > 0 (both
  // distances alike): what L~^t lacks if H^t's base were rounded as the studio's.
  cv::Mat ExactDetail(const Eigen::VectorXd& expression, const TriMesh& surface, const cv::Mat& neutral_distance,
                      double phong_alpha = 0.0, double max_mm = 2.0) const;

  int resolution() const { return raster_.width; }
  const ActorModel& model() const { return model_; }

 private:
  ActorModel model_;
  FaceRig compatible_;      // the personal rig made compatible (Sec. 4.1)
  Eigen::MatrixXd delta_;   // 3#V × #E: B' − B_c
  UvRaster raster_;         // the rig's face chart at R×R
  cv::Mat neutral_wrinkles_;
  double lowpass_texels_ = 0.0;  // σ of G in texels of the chart (0 = no lowpass)
  WrinkleBandMask chart_band_;    // the chart's coverage blurred by G
};

}  // namespace crease

namespace crease {

// Detail extraction (Sec. 4.1) of a studio scan set against the truth (the rung
// below the ladder's R0: do the regression targets hold the detail at all?). Per
// scan, the extracted D^j against the wrinkle layer alone and against D* (with the
// coarse band), on the face and in the wrinkle band (both maps minus their
// Gaussian blur of band_mm), over the face and over `regions`.
struct ExtractionTruthRow {
  std::string actor, scan;
  MapComparison wrinkles, detail;            // face
  MapComparison wrinkles_band, detail_band;  // face, wrinkle band
  MapComparison detail_regions, detail_regions_band;  // `regions` only
  // Against DetailTruth::ExactDetail, in the wrinkle band over the face: D^j, and D*.
  MapComparison exact_extracted_band, exact_detail_band;
  double coarse_band_rms_mm = 0.0;           // RMS of ⟨(B' − B_c)β, n_c⟩ on the face
};
struct ExtractionTruthReport {
  std::vector<ExtractionTruthRow> rows;
  double seconds = 0.0;
  std::string ToTable() const;
  std::string ToJson() const;
};
struct ExtractionTruthOptions {
  DetailExtractionOptions detail;
  double band_mm = 2.0;  // as TrainingOptions::validation_band_mm
  std::vector<std::string> regions = {"forehead", "glabella", "left_eye", "right_eye", "left_cheek", "right_cheek"};
  int max_actors = 0;    // 0 = all
  // Also write each scan's D* as write_truth/<actor>/<scan>.exr (mm, R×R float): the
  // targets of TrainingOptions training_targets = maps; and <scan>.png, D^j, D* and
  // D^j − D* side by side (above: as they are; below: their wrinkle band). Empty: none.
  std::filesystem::path write_truth;
  // The exact detail's base surface: 0 = flat, as H^t's (DetailTruth::ExactDetail).
  double exact_phong_alpha = 0.0;
  // Compare only texels at least this far (mm) from the chart's open edges: the lips,
  // eyelids and nostrils and the outer rim, where the extraction's diffusion meets a
  // boundary. The wrinkle band is still taken on the whole chart. 0 = everywhere.
  double rim_margin_mm = 0.0;
};
// `scans`: a folder from `crease synth scans` (each actor folder holds actor.json,
// each scan truth.json; the set names its rig). Errors name the file.
ExtractionTruthReport EvaluateExtraction(const std::filesystem::path& scans, const ExtractionTruthOptions& options);

// β of a studio truth file (a scan's truth.json or a sequence's truth/NNNNNN.json:
// an "expression" object of named weights) as the rig's expression vector. Errors
// name the file.
Eigen::VectorXd ReadTruthExpression(const FaceRig& rig, const std::filesystem::path& truth_json);

// The truth D* of frames first_frame … first_frame + frames − 1 of a studio sequence
// (`crease synth sequence`; frames < 0: all) with the G of `detail`, as R×R maps
// `out`/NNNNNN.exr (mm; R = detail.map_resolution): what `crease capture --set
// wrinkle_map_from_maps=DIR` builds its wrinkle map from (the detail ladder's rung
// R1: patches placed where the true wrinkles are) and what `crease eval` scores D^t
// against. Writes into a temporary folder renamed to `out` at the end (an existing
// `out` is replaced). Returns the number of maps written.
int WriteDetailTruthMaps(const std::filesystem::path& dataset, const DetailExtractionOptions& detail, int frames,
                         const std::filesystem::path& out);

}  // namespace crease
