// Online detail regression (paper Sec. 5.2): from the per-frame texture T^t to the
// displacement map D^t of medium-scale wrinkles, with the trained detail model
// (pipeline/training/detail_model.h).
//
//   first N frames:  AddWrinkleFrame(T^t, seen^t)   — the user's wrinkle map W
//                    (Sec. 4.2 on the first N frames, WrinkleMapBuilder)
//   once:            FixLayout()                    — the patch layout (PlacePatches,
//                    Sec. 4.2), the per-frame sampler (PatchSampler) and the
//                    Poisson fill's precomputation (PoissonFill), all fixed from now on
//   every frame:     D^t = Regress(T^t, seen^t)
//     1. sample   t_i = the w×w patches of T^t on the fixed layout (PatchSampler::Sample:
//                 the raw gray samples, exactly as ExtractTrainingPatches feeds training);
//     2. regress  c_i = c̄ + Σ_k R^k(t_i)                                        (Eq. 6)
//                 (FernCascade::PredictBatch);
//     3. reconstruct d_i = mean + basis · c_i                 (PCA, Sec. 4.3 / 5.2);
//     4. merge    texels covered by several patches average them (PatchSampler::Splat,
//                 bilinear weights);
//     5. fill     texels of the face chart no patch covers: Laplace solve with the
//                 pre-computed PoissonFill (poisson_fill.h), zero Dirichlet at the chart
//                 border by default; 0 outside the chart.
//
// Unseen texels (occlusion, grazing view: FrameTexture::seen = 0, T^t = 0 there):
//   * Wrinkle map. The DoG would read the step to 0 at an occlusion border as a dark
//     line. Before a frame is added, its unseen chart texels are replaced by a smooth
//     extension of its seen texels (normalised Gaussian of σ = wrinkle_extension_sigma
//     on a 4× coarser grid), so occlusion borders give no response; and W is averaged
//     over the frames in which a texel was seen — W(p) = Σ_j [r_j > α] r_j / J_p with
//     J_p the number of frames that saw p — and set to 0 where
//     J_p < wrinkle_min_seen_fraction · J (too little evidence). A texel counts as
//     seen (J_p, and its response) only when it lies wrinkle_seen_margin_sigmas large
//     DoG σ inside the frame's seen texels: the DoG reads the seam between the seen
//     texture and its smooth extension (the face's silhouette, the nostrils) as a line.
//   * Regression. A patch whose footprint (a 9×9 grid of its samples) touches more
//     than patch_max_unseen_fraction unseen texels in this frame is dropped: it is not
//     regressed into D^t. Dropped patches are left out of the average of step 4 (the
//     other patches covering a texel keep their full weight: the splat of the kept
//     patches is divided by their share of the bilinear weight, 1 − Σ_dropped w_k/Σ w,
//     from per-patch share lists precomputed in FixLayout); texels that only dropped
//     patches cover are 0 (no evidence of a wrinkle) — they stay "known" for the fill,
//     whose precomputation needs a coverage fixed once (the paper's pre-factorisation).
//   * Optional gate (gate_by_response, default off = the paper): a patch also drops
//     out when this frame's DoG response at its centre is ≤ α — the rule by which
//     training pairs were selected (ExtractTrainingPatches), so the regressor is only
//     asked about patches like the ones it was trained on. Without the gate a frame
//     with no wrinkle still gets whatever the cascade predicts for a flat patch. The
//     gate is soft by default (gate_softness s): the patch's weight w ramps from 0 at
//     a response of (1 − s)α to 1 at (1 + s)α, scales its d_i and counts 1 − w
//     dropped in the merge (whose kept share is then floored at 1/4, so a texel fades
//     to 0 with its patches' weights). A hard gate switched patches whose response
//     sensor noise moved across α on and off from frame to frame.
//
// Speed (bench/detail_regression_bench.cc BM_Regress, 2-vCPU Sapphire Rapids shared with
// three other builds — load average 3.5–4.3 — Release, R = 1024, /work/main/out/model.cdm:
// K = 1280, F = 5, w = 32, D = 16; chart and regions of out/scans/rig.crig (~62 % of the
// texels); wrinkle map from the five training textures of actor_002 (200 patches, 21
// of them dropped for unseen texels in the regressed frame); fill_resolution 128).
// Minimum over 100–140 frames per step, milliseconds, two runs (means are 1.5–3× higher
// under this load; the minima of the steps do not all fall in one frame; with a load
// average of ~4 on 2 cores the second thread rarely gets a core, so 2 threads gain little):
//
//   step                          1 thread     2 threads    notes
//   1 sample (+ transpose, seen)  1.32 / 1.14  1.03 / 1.07  PatchSampler::Sample, 200 × 1024 samples
//   2 regress (Eq. 6)             1.39 / 1.20  1.04 / 0.96  FernCascade::PredictBatch, AVX2
//   3 reconstruct (PCA)           0.56 / 0.48  0.42 / 0.32  200×16 · 16×1024 in column blocks
//   4 merge                       3.51 / 3.27  2.74 / 2.73  PatchSampler::Splat (+ renormalisation)
//   5 fill                        4.44 / 2.92  2.69 / 3.36  PoissonFill, 624k unknowns, 9.8k coarse
//   sum of the step minima        11.2 / 9.0   7.9 / 8.4
//   whole-frame minimum           12.8 / 10.6  13.8 / 12.5
//
// The fill alone (BM_RegressorFill, same chart): minimum 2.7–4.2 ms at fill_resolution
// 128, 5.0–7.2 ms at 256 (39k coarse unknowns). With gate_by_response the gate adds
// ~1.1 ms to step 1 (minimum, 2 threads: 200 windowed DoG evaluations). Once per capture: AddWrinkleFrame
// ~55 ms CPU per frame (the DoG and gradients of WrinkleMapBuilder at 1024²; 125 ms
// wall under load), FixLayout ~170 ms CPU (placement, sampler, merge shares,
// factorisation).
//
// Differences from the paper:
//   1. The paper's texture T^t has no unseen texels it speaks of; the treatment above
//      (extension before the DoG, per-texel frame counts, dropped patches) is ours.
//   2. Sec. 5.2 says the wrinkle map is built "as described in Section 4.3" (it is
//      Sec. 4.2) from the first N frames; the layout is placed with the model's
//      PatchLayoutOptions (w, ρ) exactly as in training (Sec. 4.2).
//   3. The Poisson fill solves on a coarse grid and smooths near the patches
//      (poisson_fill.h, Difference 1) instead of pre-factorising the full-resolution
//      matrix; its boundary condition at the chart border is a choice (zero Dirichlet).
//   4. The optional response gate (off by default) is not in the paper. Without it a
//      frame shows the cascade's answer for patches unlike its training pairs: on the
//      test model a line-free frame gets |D| up to 0.023 mm against 0.09 mm grooves
//      (tests/detail_regression_test.cc); with out/model.cdm on actor_002's training
//      textures, the neutral one gets D^t in [−0.056, 0.136] mm with the forehead
//      groove of the brow raise (whose D^t is in [−0.38, 0.18] mm) still visible; the
//      gate keeps 91 of 200 patches and removes that groove ([−0.058, 0.058] mm).
//      Its ramp (gate_softness, header "Optional gate") is ours too: the hard
//      threshold of training's pair selection made patches flicker at capture.
//   5. Step 4 "average" is the bilinear-weighted average of PatchSampler::Splat
//      (patches.h, Difference 3).
//   6. With the model's texture_reference ratio or difference (wrinkle_map.h,
//      Difference 6; not in the paper) T^t is flattened by a reference: the per-texel
//      median of the most neutral quarter of the first N frames. Optionally
//      (reference_alignment.enabled) the reference is first aligned to each T^t by
//      dense flow in UV (reference_alignment.h), against the tracker's slide; with
//      reference_alignment.warp_texture T^t is aligned to that reference instead
//      (also without flattening), so that D^t follows the neutral frames'
//      registration. The wrinkle map's per-texel frame counts J_p stay those of the
//      unaligned frames.
//   7. Optionally (recentre_radius > 0) the patches move with their lines in every frame
//      (options above): the DoG response at 2·⌊radius/step⌋ + 1 candidate centres per
//      patch (the gate's windowed DoG), then the patches are sampled and merged on the
//      moved frames without the precomputed sampler (SamplePatches / SplatPatches,
//      patches.h): Σ g_k w_k d_k / Σ g_k w_k over this frame's patches, the soft gate's
//      floor on the share as in step 4. The unseen check keeps the layout's footprints,
//      and texels the moved patches reach beyond the layout's coverage are left to the
//      fill, whose known texels stay the layout's. Measured effect (docs/detail-path.md,
//      "Patches that move with their lines"; radius 8, step 2; R3, 3 seeds, D^t against
//      the registered truth's band): with the default refinement +0.02 (holds 0.134 →
//      0.155, talking workout 0.133 → 0.147), with the anchored dense one nothing (0.266
//      → 0.266, 0.212 → 0.206); the still face −0.01 to −0.02, the band normal error up
//      0.07–0.15 × L~^t's; 3.4 × the regression's time (BM_Regress/2/2/8 16.6 ms against
//      4.9 ms, 345 patches).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "pipeline/capture/poisson_fill.h"
#include "pipeline/capture/reference_alignment.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/wrinkle_map.h"

namespace crease {

class OptionVisitor;

struct DetailRegressionOptions {
  // N, Sec. 5.2: the first N frames' textures build the wrinkle map (a user option;
  // "a small set of extremal expressions ... only a few seconds"). NeedsWrinkleFrames()
  // is true until this many were added; FixLayout may be called earlier.
  int wrinkle_frames = 30;
  // Texels seen in fewer than this fraction of the wrinkle frames get W = 0 (not in the
  // paper; header "Unseen texels"). 0 = any texel seen once counts.
  double wrinkle_min_seen_fraction = 0.5;
  // σ of the smooth extension of the seen texels into unseen ones before the DoG,
  // texels at the model's dog_reference_resolution (not in the paper).
  double wrinkle_extension_sigma = 16.0;
  // Seen texels closer than this to an unseen chart texel of the frame neither add to
  // the wrinkle map nor count as seen (J_p), in units of the wrinkle DoG's large σ
  // (the model's dog_large_sigma; 1.5 = 12 texels of a 1024² map at the paper's
  // kernel 8). Not in the paper; header "Unseen texels". 0 = off (before crease
  // 0.4.17). Measured on the holds' novel actors (seeds 1–3, `gated-level`, 2×2
  // studio): the rows of patches along the face's silhouette and around the
  // nostrils go, R2 keeps 588 / 530 / 407 of 752 / 686 / 601 patches and R3 1358 /
  // 1300 / 1367 of 1526 / 1460 / 1533, and every figure stays within 0.007 (R2
  // wrinkle band 0.332 → 0.335, still face 0.846 → 0.844; R3 registered band
  // 0.152 / 0.105 / 0.183 → 0.153 / 0.105 / 0.182). 2σ: R2 band 0.337, still face 0.833.
  double wrinkle_seen_margin_sigmas = 1.5;
  // A patch is dropped in a frame when more than this fraction of its footprint
  // (9×9 grid of samples) is unseen (not in the paper). 0 = any unseen sample drops it.
  double patch_max_unseen_fraction = 0.0;
  // Drop patches whose DoG response at the centre is ≤ α in this frame (training's
  // pair-selection rule, Sec. 4.2; not in the paper's capture). Default off (the paper).
  bool gate_by_response = false;
  // With the gate: its ramp s. A patch's weight rises from 0 at a response of
  // (1 − s)α to 1 at (1 + s)α and scales its d_i (header, "Optional gate"); 0 = the
  // hard gate (before crease 0.4.18). Not in the paper. Measured on the holds' novel
  // actors (seeds 1–3, `gated-level`, 2×2 studio), s = 0 → 0.75: at R3 (the tracker)
  // the still face 0.927 / 0.860 / 0.892 → 0.957 / 0.923 / 0.941, D^t against the
  // registered truth's band 0.153 / 0.105 / 0.182 → 0.161 / 0.111 / 0.202, the band
  // normal error 1.69 → 1.60 × L~^t's, band jitter 4.0 → 2.9 µm (means); at R2 the
  // band 0.335 → 0.354, still face 0.844 → 0.843, jitter 2.3 → 1.8 µm. s = 1: R2
  // still face 0.870, but a higher normal error (R2 1.10 ×, R3 1.64 ×).
  double gate_softness = 0.75;
  // Re-centring (Difference 7, not in the paper; 0 = off, the paper): in every frame each
  // patch moves along its x axis e1 (across its line) to the candidate centre, within
  // ±recentre_radius of its place in the layout at steps of recentre_step, where the
  // frame's DoG response is largest (refined between steps by a parabola), and is
  // sampled and merged there. Texels at the model's dog_reference_resolution, like the
  // DoG's σ. The tracker's texture drifts 1–3 mm on the skin during a capture, so a line
  // leaves the patch the wrinkle frames laid on it.
  double recentre_radius = 0.0;
  double recentre_step = 1.0;
  PoissonFillOptions fill;  // Sec. 5.2 Poisson fill (poisson_fill.h)
  // Difference 6 (reference_alignment.h; off by default): align the reference to every
  // T^t before flattening (with the model's texture_reference ratio or difference), or
  // with warp_texture, T^t to the reference (with or without flattening).
  ReferenceAlignmentOptions reference_alignment;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Wall time of the steps of one Regress call, milliseconds.
struct DetailTiming {
  double align_ms = 0;        // 0: the reference aligned to T^t (reference_alignment.h; 0 when off)
  double sample_ms = 0;       // 1: patches sampled (and transposed), seen / gate checks
  double regress_ms = 0;      // 2: Eq. 6, the fern cascade
  double reconstruct_ms = 0;  // 3: PCA reconstruction
  double merge_ms = 0;        // 4: Splat, and the renormalisation where patches were dropped
  double fill_ms = 0;         // 5: Poisson fill
  int patches = 0;            // patches of the layout
  int dropped = 0;            // patches dropped this frame (unseen or gated)
  // Not a time: the reference alignment's mean shift this frame, texels of its grid
  // (ReferenceAlignmentReport::mean_shift); −1 when the alignment is off.
  double reference_shift = -1.0;
  double total_ms() const { return align_ms + sample_ms + regress_ms + reconstruct_ms + merge_ms + fill_ms; }
};

class DetailRegressor {
 public:
  // model: the trained model (validated here). regions: the rig's region masks
  // (FaceRig::regions; model.wrinkle.patch_regions picks from them). coverage: CV_8U
  // R×R, non-zero on the texels of the face chart (R = model.map_resolution). Throws
  // Error on a bad model, options, coverage or unknown region names.
  DetailRegressor(const DetailModel& model, const std::vector<RegionMask>& regions, const cv::Mat& coverage,
                  const DetailRegressionOptions& options);
  ~DetailRegressor();
  DetailRegressor(DetailRegressor&&) noexcept;
  DetailRegressor& operator=(DetailRegressor&&) noexcept;

  // Adds T^t (CV_32F R×R, linear [0, 1], 0 where unseen) and its seen mask (CV_8U R×R,
  // non-zero = seen; empty = all seen) to the wrinkle map (Sec. 5.2). Throws Error
  // after FixLayout, on a wrong type or size, or non-finite seen texels.
  // `expression`: how far the frame's expression is from the neutral (capture: the
  // norm of the tracker's β). With the model's texture_reference = neutral the
  // reference is the per-texel median of the quarter of the wrinkle frames closest
  // to the neutral (at least one; all frames when every value is equal).
  // `map_texture` (optional, CV_32F R×R): build the wrinkle map from it instead of
  // `gray`, unflattened (the ladder's rung R1, true patch sites); `gray` still feeds
  // the reference.
  void AddWrinkleFrame(const cv::Mat& gray, const cv::Mat& seen, double expression = 0.0,
                       const cv::Mat& map_texture = cv::Mat());
  // True while fewer than options.wrinkle_frames frames were added and the layout is
  // not fixed.
  bool NeedsWrinkleFrames() const;
  // Fixes the wrinkle map and the patch layout (Sec. 4.2 placement with the model's
  // w, ρ), builds the sampler and the Poisson fill. Throws Error when no frame was
  // added or the layout is already fixed. A map without wrinkles gives an empty
  // layout (D^t = 0).
  void FixLayout();
  bool layout_fixed() const;

  // D^t: CV_32F R×R, mm along the normal; see the header comment for the steps. 0
  // outside the face chart. Requires layout_fixed(); gray / seen as for
  // AddWrinkleFrame. Const and deterministic (the same bytes for any thread count).
  cv::Mat Regress(const cv::Mat& gray, const cv::Mat& seen, DetailTiming* timing = nullptr) const;

  // Issue 17's rung R2-oracle (not in the paper): D^t as a perfect regressor would
  // give it. The patches of `truth` (CV_32F R×R, mm: the frame's true D*) on the
  // fixed layout, projected onto the model's PCA basis (the best the model can
  // output), then dropped (unseen, gated: decided on gray / seen as in Regress),
  // merged and Poisson-filled exactly as Regress does with the regressed ones. So
  // the oracle's D^t against D* is the ceiling of the layout, the gate, the PCA, the
  // merge and the fill; the regression costs the rest. Throws Error as Regress, and
  // on a truth map of the wrong type or size or with non-finite values.
  cv::Mat AssembleFromTruth(const cv::Mat& gray, const cv::Mat& seen, const cv::Mat& truth,
                            DetailTiming* timing = nullptr) const;

  // Issue 17's rung R2-pairs (not in the paper): this frame's regression pairs on the
  // fixed layout, to score a model on the video's own patches (`crease model
  // eval-pairs`) beside the scans' pairs. Row i of `texture` is patch i's t_i exactly
  // as Regress feeds the regressor (T^t flattened as Regress flattens it, the raw
  // samples of PatchSampler, as training cuts them); row i of `displacement` is the
  // same patch of `truth` (CV_32F R×R, mm: the frame's true D*). Only the patches
  // Regress keeps (not dropped: unseen, gated), in layout order; `patches` (optional)
  // receives their layout indices. Throws Error as AssembleFromTruth.
  void CutPairs(const cv::Mat& gray, const cv::Mat& seen, const cv::Mat& truth, Eigen::MatrixXf* texture,
                Eigen::MatrixXf* displacement, std::vector<int>* patches = nullptr) const;

  // Which patches of layout() drop out of the frame (1 = dropped: unseen, or gated;
  // header "Unseen texels"), as Regress decides. Requires layout_fixed().
  std::vector<uint8_t> DroppedPatches(const cv::Mat& gray, const cv::Mat& seen) const;

  const WrinkleMap& wrinkle_map() const;  // after FixLayout (W rescaled as in the header)
  const PatchLayout& layout() const;      // after FixLayout
  const PatchLayoutReport& layout_report() const;  // after FixLayout
  const PoissonFill& fill() const;        // after FixLayout
  int frames_added() const;
  int map_size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace crease
