// Expression wrinkles of a synthetic actor: a personal layout of wrinkle lines in
// the rig's UV chart, and their depth driven by the local compression of the skin
// under the current expression. The sum over lines is the medium-scale
// expression displacement map D of paper Sec. 4.1 — the quantity the detail
// regressor learns (Sec. 4.3) and predicts (Sec. 5.2).
//
// Model, per line ℓ and texel x within its footprint:
//   D(x) += depth_ℓ(c(x, n_ℓ(x))) · s_ℓ(x) · p_ℓ(d_ℓ(x))
//   p(d)   = −sech²(d/w) + r · sech²((|d| − 2.2w)/(0.8w))     cross-section (valley + two ridges)
//   s_ℓ(x) = strength along the line (tapered ends, breaks) × soft region weight
//   c(x,n) = 1 − λ(x,n),  λ² = nᵀ C₁ n / nᵀ C₀ n                 compression across the line
//   depth(c) = static + (max − static) · f(max(c, 0)),   f(c) = 1 − exp(−(c/c_sat)²)
// where d is the distance (mm) from x to the line's centre line, n the unit UV
// direction perpendicular to the line at the closest point, and C₀, C₁ the 2×2
// metric tensors (JᵀJ, J = ∂position/∂uv) of the actor's neutral and current
// coarse surface, averaged per vertex, interpolated over the chart and smoothed
// with a Gaussian (WrinkleStrainOptions) so that depth varies smoothly along a
// line and a wrinkle deepens exactly where and when the skin is compressed
// across it. f(0) = f'(0) = 0: no depth at neutral unless the line is static.
//
// Differences from reality (simplifications):
//  1. Wrinkles are a displacement along the normal of the coarse surface, not a
//     buckling of a skin layer; their positions are fixed in UV (as the paper
//     assumes in Sec. 4.2) and do not slide with the expression.
//  2. Widths are converted from mm to UV with one scale per rig (mm_per_uv, the
//     RMS ratio of 3D to UV lengths), so a chart with strong local distortion
//     gets locally wider or narrower wrinkles than asked.
//  3. Stretch across a line (λ > 1) only flattens static depth (by up to 50 %);
//     compression along a line is ignored.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/options.h"
#include "core/rng.h"
#include "core/types.h"
#include "core/uv_raster.h"

namespace crease {

// ---------------------------------------------------------------------------
// Face anchors in UV.

// Points of the face in the rig's UV chart that wrinkle and skin layouts hang
// on. Side 0 is the subject's right (iBUG eye 37–42, brow 18–22), side 1 the
// subject's left. From the 68 iBUG landmarks when the rig has them, otherwise
// estimated from the standard region masks (coarser).
struct FaceAnchors {
  double mm_per_uv = 0.0;     // RMS ratio of 3D (neutral, mm) to UV lengths over the face chart
  Eigen::Vector2d lateral;    // unit UV direction from side 0 to side 1
  Eigen::Vector2d up;         // unit UV direction from the mouth towards the forehead
  Eigen::Vector2d eye_outer[2], eye_inner[2], eye_center[2], lower_lid[2];
  std::vector<Eigen::Vector2d> brow[2];  // outer → inner, along the brow
  std::vector<Eigen::Vector2d> upper_lid[2];  // outer → inner corner along the upper lid margin (landmarks only)
  Eigen::Vector2d nose_bridge_top, nose_bridge_bottom, nose_tip;
  Eigen::Vector2d nose_wing[2];
  Eigen::Vector2d mouth_corner[2];
  std::vector<Eigen::Vector2d> lip_outline;  // closed polygon around both lips
  double forehead_height_mm = 0.0;  // from the mean brow point up to the top of the forehead region
  bool from_landmarks = false;
  // Outward lateral direction of side k (−lateral for side 0).
  Eigen::Vector2d Outward(int side) const { return side == 0 ? Eigen::Vector2d(-lateral) : lateral; }
};


// RMS ratio of 3D (neutral, mm) to UV lengths over the face chart: sqrt(Σ area₃D / Σ area_UV).
double MmPerUv(const FaceRig& rig);

// Throws Error when the rig has neither the iBUG landmarks nor the standard
// regions "left_eye", "right_eye", "forehead", "glabella", "nose", "mouth".
FaceAnchors ComputeFaceAnchors(const FaceRig& rig);

// A region mask of the rig (union of `names`) resampled to size × size, as a
// CV_32F weight in [0, 1] blurred by a Gaussian of `blur_mm` (0 = none). Unknown
// names are ignored; an empty union gives all ones.
cv::Mat SoftRegionWeight(const FaceRig& rig, const std::vector<std::string>& names, int size,
                         double blur_mm, double mm_per_uv);

// ---------------------------------------------------------------------------
// Layout.

enum class WrinkleFamily { kForehead, kGlabella, kCrowsFeet, kNasolabial, kUnderEye, kBunny };
std::string ToString(WrinkleFamily family);  // "forehead", "glabella", "crows_feet", …
// Throws Error naming the unknown string.
WrinkleFamily WrinkleFamilyFromString(const std::string& name);
// The rig regions a family lives in (its footprint is weighted by their soft union).
std::vector<std::string> WrinkleFamilyRegions(WrinkleFamily family);

struct WrinkleLine {
  WrinkleFamily family = WrinkleFamily::kForehead;
  std::vector<Eigen::Vector2d> points;  // centre line in UV, ≥ 2 points
  std::vector<double> strength;         // per point, [0, 1]: tapered ends, 0 in breaks
  double max_depth_mm = 0.0;     // depth at saturated compression, mm (> 0 = into the skin)
  double static_depth_mm = 0.0;  // depth at neutral, mm (0 = expression-only line)
  double width_mm = 1.0;         // w: half-width of the sech² valley, mm
  double ridge = 0.0;            // r: height of the shoulders relative to the depth
  double saturation = 0.12;      // c_sat: compression (1 − stretch) where f = 1 − 1/e
};

// How wrinkled an actor is.
struct WrinkleStyle {
  double age = 0.5;    // [0, 1]: 0 almost no lines, 1 many deep lines and static lines
  double shape = 0.0;  // [−1, 1]: −1 thin and deep, +1 wide and shallow
  bool static_lines = true;  // allow lines visible at neutral (older actors)
};

// Random layout of all six families: forehead lines, glabella frown lines,
// crow's feet, nasolabial folds, under-eye lines, bunny lines. Counts, spacing,
// depth, width, length, waviness and breaks are drawn from `rng`.
std::vector<WrinkleLine> GenerateWrinkleLayout(const FaceAnchors& anchors, const WrinkleStyle& style,
                                               Rng& rng);

// f(c) = 1 − exp(−(c/c_sat)²) for c > 0, else 0: smooth, saturating, f(0) = f'(0) = 0.
double CompressionResponse(double compression, double saturation);

// Depth of a line (mm, > 0 into the skin) at compression c = 1 − λ across it.
double WrinkleDepth(const WrinkleLine& line, double compression);

// ---------------------------------------------------------------------------
// Strain field.

struct WrinkleStrainOptions {
  int resolution = 256;        // texels of the metric-tensor maps (square)
  double smoothing_mm = 3.0;   // σ of the Gaussian smoothing the metric tensors, mm (0 = none)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Metric tensors C = JᵀJ of a surface over the rig's face chart, per texel of a
// square map: CV_32FC3 (C_uu, C_uv, C_vv), mm² per UV², smoothed by normalised
// convolution (texels outside the chart do not pull values towards 0).
class StrainField {
 public:
  StrainField(const FaceRig& rig, const WrinkleStrainOptions& options);
  // V: #V×3 positions of the rig mesh (any identity/expression).
  cv::Mat MetricMap(const MatX3d& V) const;
  int resolution() const { return options_.resolution; }

 private:
  WrinkleStrainOptions options_;
  MatX3i F_;                     // face-chart triangles of the rig
  MatX2d UV_;
  std::vector<Eigen::Matrix2d> uv_inverse_;  // per face triangle, [uv1−uv0, uv2−uv0]⁻¹ (0 if degenerate)
  Eigen::VectorXd uv_area_;      // per face triangle
  UvRaster raster_;
  cv::Mat coverage_blur_;        // blurred coverage, CV_32F
  double sigma_texels_ = 0.0;    // smoothing σ in texels
  int num_vertices_ = 0;
};

// ---------------------------------------------------------------------------
// Precomputed footprints and the per-frame displacement map.

// One line's contribution to one texel, precomputed once per actor.
struct WrinkleSample {
  int texel = 0;        // j·R + i
  int line = 0;         // index into the layout
  float value = 0.0f;   // s_ℓ(x) · p_ℓ(d): cross-section × strength × region weight (unitless)
  float nu = 0.0f;      // unit UV direction across the line at the closest point
  float nv = 0.0f;
  float neutral_metric = 0.0f;  // nᵀ C₀ n of the actor's neutral, mm² per UV²
};

class WrinkleField {
 public:
  // `region_weights[f]`: soft region weight (resolution², CV_32F) of family f
  // (WrinkleFamily order); `neutral_metric`: StrainField::MetricMap of the actor's neutral.
  WrinkleField(std::vector<WrinkleLine> lines, int resolution, double mm_per_uv,
               const std::vector<cv::Mat>& region_weights, const cv::Mat& neutral_metric);

  // Expression displacement map (CV_32F resolution², mm along the normal,
  // negative = into the skin) for the current metric map (StrainField::MetricMap).
  cv::Mat Displacement(const cv::Mat& current_metric) const;
  // Compression 1 − λ across line `line` at the sample of texel (i, j) closest to
  // its centre line, or NaN when the line does not reach it (for tests/debugging).
  double CompressionAt(const cv::Mat& current_metric, int line, int i, int j) const;

  const std::vector<WrinkleLine>& lines() const { return lines_; }
  const std::vector<WrinkleSample>& samples() const { return samples_; }
  int resolution() const { return resolution_; }

 private:
  double Compression(const cv::Mat& current_metric, const WrinkleSample& s) const;
  std::vector<WrinkleLine> lines_;
  int resolution_ = 0;
  std::vector<WrinkleSample> samples_;
};

// Bilinear lookup of a CV_32FC3 map (a metric map, a normal map) at UV (texel convention of DESIGN.md,
// clamped at the border).
Eigen::Vector3d SampleMetric(const cv::Mat& metric, double u, double v);

}  // namespace crease
