// The actor's wrinkle map (paper Sec. 4.2): where in UV expression wrinkles
// form, and how they are oriented. Built from J gray textures — the training
// expressions' textures T^j (Sec. 4.2) or, at capture time, the first N video
// frames' textures (Sec. 5.2) — so nothing here knows about scans.
//
// Per texture T^j (a gray, linear [0, 1] texture in the rig's UV layout):
//   r_j = G_large * T^j − G_small * T^j                      (DoG, DogResponse)
// positive on dark lines: wrinkles appear as shadow lines in the texture.
// Over the J textures, per texel p of the valid region (the union of the named
// rig regions — forehead, glabella, around the eyes, cheeks — intersected with
// the texture coverage):
//   W(p) = (1/J) Σ_j [r_j(p) > α] · r_j(p)                   (WrinkleProbability)
// and outside the valid region W = 0. The orientation at p is the average of the
// doubled-angle gradient vectors of the contributing texels,
//   O(p) = G_o * Σ_j [r_j > α] v_j  /  G_o * Σ_j [r_j > α],
//   v_j  = (g_x² − g_y², 2 g_x g_y),  g = ∇(G_d * T^j),
// and the patch angle θ(p) = ½ atan2(O_y, O_x) + kπ ∈ [φ_0 − π/2, φ_0 + π/2) is the direction across
// the wrinkle (the gradient direction, in texel coordinates: x = i to the right,
// y = j downwards, so θ grows clockwise on screen).
//
// Texels follow DESIGN.md: texel (i, j) of an S×S map covers u = (i + 0.5)/S,
// v = (j + 0.5)/S, v downwards. Maps are CV_32F, masks CV_8U (non-zero = set).
//
// Differences from the paper:
//   1. "A small kernel of size 6 and a large kernel of size 8" is read as Gaussian
//      standard deviations in texels of a 1024² map. A wrinkle 1–3 mm wide spans
//      ~5–15 texels there, so σ = 6 / 8 make the DoG a band-pass at wrinkle scale;
//      reading 6 and 8 as window widths (σ ≈ 1–1.5) would respond to pores. For
//      other map sizes the σ scale with size / dog_reference_resolution.
//   2. The DoG is a normalised convolution, blur(T·m)/blur(m) with m the texture's
//      coverage mask, so the face boundary and holes (eyes, mouth) and the image
//      border do not produce false wrinkles. The paper does not say.
//   3. W divides by J (all textures), i.e. W = mean_j of the thresholded response,
//      so W mixes how often and how strongly a wrinkle appears. The paper's "average
//      filter response across textures for each filtered pixel value above α"
//      could also divide by the number of contributing textures.
//   4. The paper's 2-channel gradient image averages raw texture gradients. Those
//      cancel across a dark line (opposite signs on its two sides) and vanish at its
//      centre, where patches are centred. We average the sign-free doubled-angle
//      vectors (the structure tensor's orientation part) of the contributing texels
//      instead, lightly smoothed (σ_o) so that the line's flanks inform its centre;
//      gradients are taken on the texture smoothed by σ_d (pixel noise, pores).
//   5. Optional, off by default as in the paper: regions can be taken out of the
//      valid region (patch_exclude_regions, grown by a margin), e.g. the brows. Our
//      forehead and eye regions, built from the landmarks, include the brows, and
//      dark brow hair gives the strongest DoG response of the face; on the studio's
//      scans the training pairs with the largest displacement are brow patches (the
//      brow moving with a raise, not a wrinkle). Excluding the brows halved the
//      pairs but did not raise D^t's correlation with a novel actor's wrinkles
//      (quick detail-accuracy, seed 1: 0.062 with them, −0.006 without), so the
//      default keeps the paper's regions. Regions the rig does not define are
//      skipped (a rig imported from blendshape OBJs has no brow masks).
//   6. Optional (texture_reference = ratio or difference; the paper reads T
//      itself): the map and the patch features read T flattened by a reference
//      texture of the same person under the same light, T · mean(T_ref) / T_ref or
//      T − T_ref + mean(T_ref). Texture = albedo ×
//      shading, so the static appearance — brows, lashes, the hairline, lids,
//      moles, skin tone — cancels and the expression's shading is left. On the
//      studio's scans the raw map puts most patches on the hair edge, the brows
//      and the lids (their texture patches are dark hair edges, their displacement
//      patches unrelated to them); flattened, the patches sit on the lines.
//      With texture_reference_level > 0 a fixed gray level replaces mean(T_ref),
//      so the flattened texture no longer carries the person's skin tone and the
//      absolute threshold α means the same shading contrast on every skin.
//      Measured (crease 0.4.10, detail-levers' workout-level against workout: the
//      ratio, α 0.002, G 1 mm, N = 120; level 0.2; paper profile, 3 seeds): the
//      training pairs per actor even out (seed 3: 105–440 → 460–651), the
//      dark-skinned novel actor of seed 2 gets 884 patches instead of 107, D^t vs D*
//      at R2 0.165 → 0.204 (every seed gains), still face 0.90 → 0.85; at R3
//      0.064 → 0.068, still face 0.911 → 0.894.
//      Reference: the actor's neutral scan in training; in capture the per-texel
//      median of the quarter of the N wrinkle frames whose tracked expression is
//      closest to the neutral (the user's resting appearance).
//      Measured (crease 0.4.1; stratified studio scans, 4 actors, studio light;
//      novel actor's 241-frame wrinkle-workout at 640×480, ground-truth fit):
//        pairs:  3045 (none), 249 (ratio), 308 (difference);
//        leave one actor out, cascade, held out: 0.17–0.38 (mean patch
//        0.08–0.19) / 0.47–0.74 (0.32–0.64) / 0.43–0.63 (0.30–0.55): the patches sit
//        on lines, whose displacement is more alike across actors;
//        capture, D^t against D* in the wrinkle regions: 0.149 / 0.078 / 0.144; its
//        wrinkle band 0.167 / 0.117 / 0.136; against the wrinkle layer alone 0.095 /
//        0.014 / 0.027. The gain of the patch regression does not reach the
//        capture, so the default stays the paper's "none".
//   7. The paper orients a patch along the gradient, which fixes e1 up to its sign.
//      Under a directional light a groove's dark wall lies on the side away from
//      the light, so the texture's dark line sits beside the groove, on a side
//      that only the sign of e1 relative to the light decides. With θ ∈ [0, π)
//      (φ_0 = 90°) the sign flips between nearly vertical lines leaning either way.
//      orientation_reference_deg moves that flip to the lines across which a
//      light along φ_0 casts no asymmetry. Measured (crease 0.4.15, rung R0: seed 1
//      of detail-levers' gated-level pairs, studio light, key 40° to the side and
//      30° up; cascade, leave one actor out): φ_0 = 0° 0.295, 45° 0.458, 70° 0.480,
//      90° 0.488, 110° 0.443, 135° 0.382. The sign matters as much as any lever
//      measured, and the default is the best of them, so it stays.
//   8. Optional (orient_patches = false; the paper orients every patch): every
//      patch in one frame, e1 along φ_0. The light then lies in the same place in
//      every patch's frame. Measured (crease 0.4.15, detail-levers' gated-level →
//      gated-level-fixed, held expressions, 3 seeds): R0 (cascade, leave one actor
//      out) 0.488 / 0.436 / 0.438 → 0.557 / 0.494 / 0.517; R2 D^t vs D* 0.288 →
//      0.313, band 0.305 → 0.321; R3 0.038 → 0.052, registered band 0.137 → 0.153,
//      still face 0.898 → 0.901; band normal errors unchanged. The R0 gain mostly
//      does not reach the capture, so the default stays the paper's.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"

namespace crease {

class OptionVisitor;

// WrinkleMapOptions::texture_reference (see there).
enum class TextureReference { kNone, kRatio, kDifference };
constexpr std::array<const char*, 3> OptionEnumNames(TextureReference) { return {"none", "ratio", "difference"}; }
namespace internal {
class DogFilter;  // wrinkle_map.cc: the DoG's normalised-convolution denominators
}  // namespace internal

struct WrinkleMapOptions {
  // σ of the DoG's small Gaussian, texels at dog_reference_resolution (Sec. 4.2:
  // "small kernel of size 6"; see Difference 1).
  double dog_small_sigma = 6.0;
  // σ of the DoG's large Gaussian, texels at dog_reference_resolution (Sec. 4.2:
  // "large kernel of size 8").
  double dog_large_sigma = 8.0;
  // Map resolution at which the σ of this struct are given, texels (Sec. 4.2 uses
  // 1024² maps). A map of size S uses σ · S / dog_reference_resolution; 0 = the σ
  // are texels of whatever map is filtered.
  int dog_reference_resolution = 1024;
  // α: a texel contributes to the wrinkle map where its DoG response exceeds this,
  // intensity units of linear [0, 1] textures (Sec. 4.2: 0.005).
  double wrinkle_threshold = 0.005;
  // The rig regions (RegionMask names) wrinkles are searched in (Sec. 4.2: the
  // forehead, around the eyes, along the crease of the cheek). Empty = the whole
  // covered texture.
  std::vector<std::string> patch_regions = {"forehead",  "glabella",   "left_eye",
                                            "right_eye", "left_cheek", "right_cheek"};
  // Regions taken out of patch_regions, each grown by patch_exclude_margin texels
  // at dog_reference_resolution (Difference 5; e.g. ["brow_left", "brow_right"]).
  // Names the rig does not define are skipped.
  std::vector<std::string> patch_exclude_regions = {};
  double patch_exclude_margin = 8.0;
  // σ_d: Gaussian pre-smoothing of the texture before its gradient is taken for
  // the orientation, texels at dog_reference_resolution (not in the paper;
  // Difference 4). 0 = raw central differences.
  double orientation_gradient_sigma = 1.5;
  // σ_o: Gaussian smoothing of the averaged doubled-angle gradient vectors, texels
  // at dog_reference_resolution (not in the paper; Difference 4). 0 = none.
  double orientation_smoothing_sigma = 3.0;
  // φ_0, degrees in texel coordinates (x right, y down): the patch angle θ is taken
  // in [φ_0 − 90°, φ_0 + 90°), so that every patch's x axis e1 has a non-negative
  // component along (cos φ_0, sin φ_0) (not in the paper; Difference 7). 90 = e1
  // points down the chart, θ ∈ [0°, 180°) (the default, crease's convention).
  double orientation_reference_deg = 90.0;
  // Sec. 4.2 orients every patch across its line (true, the paper). false: every
  // patch keeps one frame, e1 along φ_0 (not in the paper; Difference 8).
  bool orient_patches = true;
  // What the wrinkle map and the patch features read (issue 17; not in the paper,
  // Difference 6): "none" — the texture T itself (the paper); "ratio" — T
  // flattened by a reference texture of the same person under the same light,
  // T · mean(T_ref) / T_ref; "difference" — T − T_ref + mean(T_ref)
  // (FlattenByReference). Either way the person's static appearance (brows, lashes,
  // hairline, lids, moles) cancels and what is left is the shading the expression
  // changes; the ratio also cancels the albedo's scaling of that shading but
  // amplifies noise where T_ref is dark. The reference is the actor's neutral scan
  // in training and, in capture, the per-texel median of the wrinkle frames closest
  // to the neutral (MedianTexture).
  TextureReference texture_reference = TextureReference::kNone;
  // m of the flattening (Difference 6): 0 = the reference's own mean gray level
  // mean(T_ref), so the flattened texture keeps the person's brightness and the
  // absolute α selects fewer wrinkles on a darker skin; > 0 = this gray level for
  // every person, T · m / T_ref, so α applies to the shading alone, whatever the skin
  // tone (issue 17: on the paper profile a dark-skinned novel actor got 53 patches
  // against 281–349, and training actors contribute pairs in proportion to their
  // brightness). Only with texture_reference ratio or difference.
  double texture_reference_level = 0.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Difference 6 (WrinkleMapOptions::texture_reference, `mode` kRatio or kDifference;
// kNone throws Error): T · m / T_ref or T − T_ref + m on the texels where both are
// seen (T, T_ref > 1e-4 and `coverage` non-zero; empty = all), 0 elsewhere; m = the
// mean of T_ref over those texels of the reference (pass reference_mean < 0 to
// compute it). All CV_32FC1 of one size.
cv::Mat FlattenByReference(const cv::Mat& texture, const cv::Mat& reference, const cv::Mat& coverage,
                           TextureReference mode, double reference_mean = -1.0);
// m of FlattenByReference: the mean of `reference` over its texels above 1e-4 within
// `coverage` (empty = all); 0 when there are none.
double ReferenceMean(const cv::Mat& reference, const cv::Mat& coverage);
// m of FlattenByReference under `options`: texture_reference_level when it is > 0,
// else ReferenceMean(reference, coverage) (the person's own brightness).
double FlatteningLevel(const WrinkleMapOptions& options, const cv::Mat& reference, const cv::Mat& coverage);
// The per-texel median of `textures` over the frames that saw the texel (`seen`:
// CV_8U masks, one per texture, or empty = all seen); 0 where none did.
cv::Mat MedianTexture(const std::vector<cv::Mat>& textures, const std::vector<cv::Mat>& seen);

// Scale of the σ of `options` for a map of `map_size` texels (Difference 1).
double SigmaScale(const WrinkleMapOptions& options, int map_size);

// DoG response r = G_large * T − G_small * T of a gray texture (CV_32FC1),
// positive on dark lines (Sec. 4.2). `coverage` (CV_8U, same size, non-zero =
// covered; empty = all covered) turns both blurs into normalised convolutions
// blur(T·m)/blur(m): texels outside coverage never leak in (they may hold
// anything, NaN included) and the result is 0 there. Non-finite texels inside
// coverage, a wrong type or a size mismatch throw Error starting with `what`.
cv::Mat DogResponse(const cv::Mat& gray_texture, const WrinkleMapOptions& options,
                    const cv::Mat& coverage = cv::Mat(), const std::string& what = "texture");

// The valid region of Sec. 4.2 as a CV_8U map_size² mask (255 = valid): the union
// of the regions named in `names`, each resampled to map_size by nearest texel
// centre (masks may have any square resolution), intersected with `coverage`
// (CV_8U map_size², empty = all covered). Empty `names` = the coverage alone.
// An unknown name throws Error naming it and the available regions.
cv::Mat ValidRegionMask(const std::vector<RegionMask>& regions, const std::vector<std::string>& names,
                        int map_size, const cv::Mat& coverage = cv::Mat());

// 255 where `coverage` (CV_8U, 255 = covered) lies at least `texels` from an uncovered
// texel or the raster's border: the chart without a margin along its open edges (lips,
// eyelids, nostrils, outer rim). All of the coverage when texels ≤ 0.
cv::Mat AwayFromRims(const cv::Mat& coverage, double texels);

// Where patches may be placed: ValidRegionMask of options.patch_regions minus the
// options.patch_exclude_regions the rig defines, each dilated by
// patch_exclude_margin (scaled like the σ, SigmaScale).
cv::Mat PatchRegionMask(const std::vector<RegionMask>& regions, const WrinkleMapOptions& options, int map_size,
                        const cv::Mat& coverage = cv::Mat());

// W(p) = (1/J) Σ_j [r_j(p) > α] · r_j(p) on texels where `valid` is set, 0
// elsewhere (Sec. 4.2; Difference 3). `responses`: J ≥ 1 CV_32FC1 maps of one
// size; `valid`: CV_8U of that size or empty (= all valid).
cv::Mat WrinkleProbability(const std::vector<cv::Mat>& responses, const cv::Mat& valid, double alpha);

struct WrinkleMap {
  cv::Mat probability;  // W: CV_32F S×S, ≥ 0; 0 outside `valid`
  cv::Mat orientation;  // CV_32FC2 S×S: averaged doubled-angle gradient (g_x²−g_y², 2 g_x g_y) of
                        // the contributing texels (the paper's 2-channel gradient image, Difference 4)
  cv::Mat angle;        // CV_32F S×S: θ ∈ [0, π), radians, the direction across the wrinkle (x right, y down)
  cv::Mat valid;        // CV_8U S×S: named regions ∩ coverage
  cv::Mat coverage;     // CV_8U S×S: texels the textures define (all 255 when none was given)
  cv::Mat contributions;  // CV_32S S×S: number of textures with r_j > α (anywhere in coverage)
  int num_textures = 0;   // J

  int size() const { return probability.cols; }
};

// Accumulates textures one at a time (capture: the first N frames, Sec. 5.2;
// training: the actor's expressions, Sec. 4.2) without keeping them.
class WrinkleMapBuilder {
 public:
  // `map_size`: S of the textures to come. `coverage`: CV_8U S×S (non-zero where
  // the textures are defined) or empty (all). `regions`: the rig's region masks;
  // options.patch_regions picks from them. Throws Error on invalid options, a
  // coverage of another size or unknown region names.
  WrinkleMapBuilder(int map_size, const cv::Mat& coverage, const std::vector<RegionMask>& regions,
                    const WrinkleMapOptions& options);

  // Adds T^j (CV_32FC1 S×S, linear [0, 1]) and returns its DoG response r_j
  // (for ExtractTrainingPatches). `what` names the texture in errors. `counts`
  // (CV_8U S×S, optional): only its non-zero texels add to the map.
  cv::Mat Add(const cv::Mat& gray_texture, const std::string& what = "texture", const cv::Mat& counts = {});

  int num_textures() const { return num_textures_; }
  // The map of the textures added so far; throws Error when none was added.
  WrinkleMap Finish() const;

 private:
  WrinkleMapOptions options_;
  int size_ = 0;
  cv::Mat coverage_;        // CV_8U, 255 / 0
  cv::Mat valid_;           // CV_8U
  cv::Mat response_sum_;    // CV_32F: Σ_j [r_j > α] r_j
  cv::Mat count_;           // CV_32S: Σ_j [r_j > α]
  cv::Mat orientation_sum_;  // CV_32FC2: Σ_j [r_j > α] v_j
  int num_textures_ = 0;
  std::shared_ptr<const internal::DogFilter> filter_;  // built once from the coverage
};

// All at once: the wrinkle map of `textures` (≥ 1, CV_32FC1, one square size).
// When `responses` is given it receives r_j of every texture (same order).
WrinkleMap ComputeWrinkleMap(const std::vector<cv::Mat>& textures, const cv::Mat& coverage,
                             const std::vector<RegionMask>& regions, const WrinkleMapOptions& options,
                             std::vector<cv::Mat>* responses = nullptr);

}  // namespace crease
