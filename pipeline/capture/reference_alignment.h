// Dense alignment of the capture's reference texture to the current texture T^t, in
// the UV domain (not in the paper; it follows the paper's own suggestion in Sec. 7 of
// registering the texture more tightly than the global tracker does).
//
// With `texture_reference: ratio|difference` (DetailRegressor, Difference 6) every
// texture is divided by (or has subtracted) a reference built from the most neutral of
// the first N frames, so that the person's brows, lids, hairline and albedo cancel and
// only the shading of wrinkles is left. With exact geometry that works (the detail
// ladder's rung R2). With a real tracker the texture slides over the face by a few
// millimetres, and by a different amount in every frame, so T^t(u) and the reference(u)
// show slightly different points of the face: every edge of the person's appearance
// then comes out of the division as a bright-dark step, which the patch features read
// as relief. ReferenceAligner removes that relative slide:
//
//   1. both textures go to a coarse grid (`resolution`², area averaging) and are
//      high-passed (minus a normalised Gaussian of σ = highpass_sigma over the chart
//      texels both see), so the flow follows the appearance's structure, not the
//      smooth change of shading with the head's pose;
//   2. dense optical flow f from T^t to the reference (OpenCV's DIS, Kroeger et al.
//      2016): T^t(x) ≈ reference(x + f(x));
//   3. f is kept only where both are seen, smoothed there with a normalised Gaussian
//      of σ = smoothing_sigma (a wrinkle that appears in T^t and not in the reference
//      must not pull the flow locally), and clamped to max_shift;
//   4. the reference is resampled at x + f(x) on the full grid (bilinear).
//
// The result is the reference as T^t's registration would have shown it; the
// flattening then divides like by like. ReferenceAligner::AlignTexture goes the other way
// and resamples T^t onto the reference's registration (ReferenceAlignmentOptions::
// warp_texture), which also moves D^t there. A slide shared by T^t and the reference (the
// tracker's constant bias) is not removed, and need not be: the flattened texture only
// compares the two. All lengths are in texels of the coarse grid.
//
// Cost (Release, R = 1024, resolution 256, 2-vCPU AMD EPYC). Alone on the machine, the
// first 90 frames of a paper-profile `detail-levers` capture (the levers' model): the
// detail regression's median per frame is 20.6 ms without the alignment and 32.2 ms
// with the reference aligned (34.6 ms before the reference was prepared once, in
// ReferenceAligner's constructor). In the experiment's runs, two captures sharing the
// 2 cores, 22.6 → 50.7 ms with warp_texture and 24.7 → 45.5 ms with the reference
// aligned. Not real time, not optimised: the full-resolution masks, products and two
// remaps with their page faults. bench/detail_regression_bench.cc BM_AlignReference
// gives 103–127 ms per call on its synthetic maps, far above the capture's figure,
// for a reason not found (its samples fall mostly in OpenCV's worker threads). An
// option for research, off by default: on the paper profile it did not raise D^t's
// correlation (docs/detail-path.md, "The reference alignment").
#pragma once

#include <opencv2/core/mat.hpp>

namespace crease {

class OptionVisitor;

struct ReferenceAlignmentOptions {
  // Off by default (the paper has no reference texture; DetailRegressor Difference 6).
  bool enabled = false;
  // Side of the grid the flow is computed on, texels. The map's side R must be a
  // multiple of it.
  int resolution = 256;
  // σ of the high-pass before the flow, coarse texels.
  double highpass_sigma = 8.0;
  // σ of the flow's smoothing, coarse texels.
  double smoothing_sigma = 4.0;
  // Largest shift kept, coarse texels (longer flow vectors are scaled down to it).
  double max_shift = 8.0;
  // false: the reference is warped onto T^t (ReferenceAligner::AlignReference); T^t,
  // and so D^t, stay in the tracker's registration. true: T^t is warped onto the
  // reference (ReferenceAligner::AlignTexture), so D^t lands where the most neutral frames put the
  // face: the tracker's expression-dependent slide is removed from D^t too.
  bool warp_texture = false;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct ReferenceAlignmentReport {
  double mean_shift = 0.0;  // mean |f| over the texels both textures see, coarse texels
  double max_shift = 0.0;   // largest |f| after smoothing and clamping, coarse texels
};

// The reference, prepared once (step 1 and its 8-bit scale), aligned against each
// texture. reference, texture: CV_32FC1 R×R linear gray (0 = no data); seen: CV_8UC1
// R×R, non-zero where `texture` holds data (empty = wherever texture > 0). Throws Error
// on wrong types or sizes, failed options, or R not a multiple of options.resolution.
// A featureless reference aligns nothing. report may be null.
class ReferenceAligner {
 public:
  ReferenceAligner(const cv::Mat& reference, const ReferenceAlignmentOptions& options);

  // The reference resampled onto `texture`'s registration (steps above). Texels whose
  // source falls where the reference has no data are 0.
  cv::Mat AlignReference(const cv::Mat& texture, const cv::Mat& seen,
                         ReferenceAlignmentReport* report = nullptr) const;
  // The other direction: `texture` resampled onto the reference's registration (the
  // flow of steps 2–3 from the reference to the texture, step 4 on the texture), and
  // its seen mask (CV_8UC1, 255 where the result holds data).
  void AlignTexture(const cv::Mat& texture, const cv::Mat& seen, cv::Mat* aligned, cv::Mat* aligned_seen,
                    ReferenceAlignmentReport* report = nullptr) const;

 private:
  cv::Mat Flow(const cv::Mat& texture, const cv::Mat& seen, bool texture_to_reference, cv::Mat* texture_valid,
               ReferenceAlignmentReport* report) const;

  ReferenceAlignmentOptions options_;
  cv::Mat reference_;
  cv::Mat valid_;         // CV_32F R×R, 1 where the reference holds data
  cv::Mat coarse_valid_;  // the same on the coarse grid
  cv::Mat reference8_;    // its high-pass as DIS reads it; empty when featureless
  double gain_ = 0.0;     // the 8-bit scale, shared by the textures
};

}  // namespace crease
