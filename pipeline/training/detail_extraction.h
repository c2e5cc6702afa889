// Detail extraction (paper Sec. 4.1): the medium-scale expression detail of each
// training scan as a displacement map D^j in the rig's UV layout, and the rig made
// compatible so that it carries no medium expression frequencies itself.
//
// For one actor with neutral scan M^0 and expression scans M^j (one topology, UVs
// in the rig's layout — transferred from the fitted rig when the scans have none,
// see rig_fit.h):
//   1. M^j ← G^HF(M^j) for all j (narrow mesh Gaussian: pores go);
//   2. G(M^0), G(M^j): the lowpass that separates low from medium frequencies;
//   3. M_0^j: the deformation G(M^0) → G(M^j) transferred to M^0 (Sumner and
//      Popović 2004; deformation_transfer.h): the expression of M^j without its
//      medium-frequency expression detail;
//   4. D^j: signed distance from M_0^j to M^j along M_0^j's normal, traced in both
//      directions with Embree, stored as an R×R map (R = 1024) in the UV layout.
// The rig: the deformation G(L^0) → G(L^b) of every blendshape b transferred to
// L^0 (MakeRigCompatible).
//
// Differences from the paper:
//   1. G and G^HF are implicit heat diffusion (core/mesh_ops.h MeshLowpass) with
//      bandwidths in mm (the paper gives none): σ_G = 3 mm, σ_HF = 0.3 mm.
//   2. The filters of an actor are built once on its (G^HF-smoothed) neutral scan
//      and applied to all its scans as linear operators (same topology), instead of
//      one operator per scan's own geometry; the expression strain (~10–30 %)
//      changes the effective bandwidth by about as much locally. This makes one
//      factorisation per actor and filter instead of one per scan.
//   3. The rays are traced per texel of the map (position and normal of M_0^j
//      interpolated at the texel centre) rather than per vertex and then
//      rasterised, so the map is exact at any scan resolution.
//   4. G and the deformation transfer run on an "operator grid": the scans
//      resampled at the texel centres of an S×S raster of their UV chart (S =
//      operator_resolution, 256 by default: ~0.8 mm spacing on a face, against
//      σ_G = 3 mm), not on the full scans (~1M vertices, where one sparse
//      factorisation takes tens of seconds). The transfer's result is carried to
//      the full-resolution neutral as M_0^j(v) = Σ_k w_k (O_0^j(k) + R_k o_v):
//      w_k the bilinear weights of v's UV on the grid, O_0^j the transferred grid,
//      R_k the rotation of grid vertex k's normal, o_v = M^0(v) − Σ_k w_k O^0(k) the
//      vertex's detail above the grid surface. Only the detail's twist about the
//      normal is lost (it does not change the distance along the normal).
//      Grid cells that a scan stretches more than 2.5× (lips and eyelids that open)
//      are cut, so the filter does not couple surfaces across a slit.
//   5. G^HF runs on the full scans with conjugate gradients (core/mesh_ops.h
//      LowpassOptions::solver = "iterative"): it is narrow, so a handful of
//      iterations per step replace a factorisation.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

class OptionVisitor;

struct DetailExtractionOptions {
  // σ of the lowpass G separating low from medium frequencies, mm (Sec. 4.1; not
  // given in the paper, see core/mesh_ops.h kGaussianBandwidthMm). 0 = no lowpass
  // (then D^j is the whole expression change beyond the neutral: an ablation).
  double lowpass_bandwidth_mm = 3.0;  // G, Sec. 4.1
  // σ of the narrow Gaussian G^HF that removes pores, mm (Sec. 4.1; not given).
  // 0 disables it.
  double high_frequency_bandwidth_mm = 0.3;  // G^HF, Sec. 4.1
  // Backward-Euler steps of the heat diffusion of G (core/mesh_ops.h
  // LowpassOptions::steps): 8 follow the Gaussian's response closely.
  int lowpass_steps = 8;
  // Steps of G^HF. 2 suffice: G^HF only has to remove pores (response 0.11 at
  // kσ = 2 and < 0.01 at kσ = 6 against the Gaussian's 0.135 and 0), and it runs
  // on the full scans.
  int high_frequency_steps = 2;
  // Resolution R of the displacement and texture maps (R×R), Sec. 4.2: 1024.
  int map_resolution = 1024;
  // Rays from M_0^j search M^j up to this distance each way, mm; texels without a
  // hit get D = 0 and are marked invalid.
  double max_displacement_mm = 5.0;
  // S of the operator grid on which G and the deformation transfer run
  // (Difference 4); 0 = on the full scans (also used when the scans have fewer
  // vertices than the grid would).
  int operator_resolution = 256;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// One scan's extracted detail.
struct ExtractedDetail {
  cv::Mat displacement;  // D^j: CV_32F R×R, mm, positive outwards (along M_0^j's normal); 0 where invalid
  cv::Mat valid;         // CV_8U R×R: 255 where the ray from M_0^j hit M^j
  MatX3d aligned;        // M_0^j vertex positions (#V×3, mm)
  MatX3d aligned_normals;  // M_0^j unit vertex normals (#V×3)
  int rays_missed = 0;   // covered texels whose ray found no surface within max_displacement_mm
  // Seconds per sub-step: G^HF, G + deformation transfer, M_0^j and its normals, rays.
  double seconds_hf = 0, seconds_transfer = 0, seconds_aligned = 0, seconds_rays = 0;
};

// The per-actor precomputation: filters on the neutral, the UV raster, the
// deformation-transfer factorisation. Build once per actor, Extract per scan.
class DetailExtractor {
 public:
  // `neutral`: M^0 with UVs in the rig's layout ([0,1]², texel convention of
  // DESIGN.md) and one topology shared by the actor's scans. `other_scans`: the
  // vertex positions of the actor's other scans, optional, used only to find
  // operator-grid cells that open up (lips, eyelids; Difference 4). Throws Error
  // (starting with `what`) on a mesh without UVs, invalid options or failed
  // factorisations.
  DetailExtractor(const TriMesh& neutral, const DetailExtractionOptions& options,
                  const std::string& what = "neutral scan", const std::vector<MatX3d>& other_scans = {});
  ~DetailExtractor();
  DetailExtractor(DetailExtractor&&) noexcept;
  DetailExtractor& operator=(DetailExtractor&&) noexcept;

  // D^j of the scan with vertex positions `expression` (#V×3, same topology as the
  // neutral; pass the neutral's positions for D^0 ≈ 0). `what` names the scan in errors.
  ExtractedDetail Extract(const MatX3d& expression, const std::string& what) const;

  // The neutral after G^HF (the M^0 every D^j is relative to).
  const TriMesh& smoothed_neutral() const;
  // CV_8U R×R: texels covered by the neutral's UV chart.
  const cv::Mat& coverage() const;
  // G^HF applied to positions of the actor's topology (identity when disabled).
  MatX3d HighFrequencyFilter(const MatX3d& V) const;
  // Vertices of the operator grid (0 when G runs on the full mesh).
  int operator_grid_vertices() const;
  const DetailExtractionOptions& options() const;

 public:
  struct Impl;  // implementation detail (detail_extraction.cc)

 private:
  std::unique_ptr<Impl> impl_;
};

// The rig made compatible for detail regression (Sec. 4.1): every expression
// blendshape replaced by the deformation G(L^0) → G(L^0 + B_b) transferred to L^0,
// L^0 the rig's neutral (mean identity). Identity modes are kept. Only the
// `lowpass_bandwidth_mm` and `lowpass_steps` of the options matter; with a
// bandwidth of 0 the rig is returned unchanged.
FaceRig MakeRigCompatible(const FaceRig& rig, const DetailExtractionOptions& options);

// Accuracy of an extracted map against a reference map (e.g. the studio's ground
// truth), over the texels where `mask` is set and both maps are finite.
struct MapComparison {
  int texels = 0;
  double rmse_mm = 0.0;
  double correlation = 0.0;     // Pearson
  double reference_rms_mm = 0.0;  // RMS of the reference (scale for rmse)
  double extracted_rms_mm = 0.0;
};
MapComparison CompareMaps(const cv::Mat& extracted, const cv::Mat& reference, const cv::Mat& mask);
// As JSON: texels, rmse_mm, correlation, reference_rms_mm, extracted_rms_mm (the
// reports of training, capture evaluation and the detail ladder).
nlohmann::json MapComparisonJson(const MapComparison& c);

// The sums behind CompareMaps, to pool texels over several maps (e.g. all frames
// of a sequence): Add() each (extracted, reference, mask), then Result().
struct MapMoments {
  int64_t n = 0;
  double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, se = 0;
  void Add(const cv::Mat& extracted, const cv::Mat& reference, const cv::Mat& mask);
  void AddValue(double extracted, double reference);  // one sample (skipped unless both finite)
  MapComparison Result() const;
};

// Millimetres per texel of an R×R map of the mesh's UV chart (mean scale: the
// square root of 3D area over UV area, divided by R).
double MmPerTexel(const TriMesh& mesh, int R);

// The wrinkle band of a displacement map: the map minus its Gaussian blur of σ
// texels, the blur a normalised convolution inside `mask` (CV_8U) so the chart
// boundary does not leak in; 0 where the blurred mask vanishes. Removes the broad
// medium-frequency expression shape a regressed or extracted D legitimately holds
// (the part of the coarse expression the compatible rig gives up, Sec. 4.1) but a
// wrinkle-layer ground truth does not.
cv::Mat WrinkleBand(const cv::Mat& d, const cv::Mat& mask, double sigma_texels);

// WrinkleBand's normaliser (the mask as float and its blur), for banding many maps
// with one mask: the blur of the mask is then paid once.
struct WrinkleBandMask {
  cv::Mat mask;     // CV_32F in [0, 1]
  cv::Mat blurred;  // its Gaussian blur of σ texels
  double sigma_texels = 0.0;
};
WrinkleBandMask MakeWrinkleBandMask(const cv::Mat& mask, double sigma_texels);
cv::Mat WrinkleBand(const cv::Mat& d, const WrinkleBandMask& mask);

}  // namespace crease
