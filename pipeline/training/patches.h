// Local wrinkle patches (paper Sec. 4.2): w × w rectangles centred on wrinkles
// and oriented across them, placed greedily by decreasing wrinkle probability;
// their texture and displacement samples (t, d) are the regressor's training
// pairs (Sec. 4.3), and at capture time the same layout samples every frame's
// texture and merges the regressed displacement patches back into a map by
// averaging (Sec. 5.2).
//
// Coordinates. A patch centre is given in texel coordinates: (x, y) = (i, j) is
// the centre of texel (i, j) of the S×S map (u = (x + 0.5)/S, v = (y + 0.5)/S,
// DESIGN.md), x to the right, y downwards. A patch's frame has its x axis
// e1 = (cos θ, sin θ) along the wrinkle map's gradient (across the wrinkle) and
// its y axis e2 = (−sin θ, cos θ) (along the wrinkle). Patch sample (a, b),
// a, b ∈ [0, w), lies at
//   centre + (a − (w−1)/2) · e1 + (b − (w−1)/2) · e2
// and is stored at index b·w + a (row-major, x along the gradient), so a wrinkle
// through the centre appears as a column in the middle of the patch. Samples are
// bilinear with the texel convention above; positions beyond the map clamp to
// its border.
//
// Placement (Sec. 4.2): list ℓ = all valid texels with W > 0 sorted by decreasing
// W (ties by increasing texel index j·S + i); repeatedly take the best remaining
// texel p, place a w × w patch centred at p oriented with the gradient at p, then
// remove from ℓ every texel whose centre lies strictly inside the ρw × ρw
// sub-rectangle centred at p. Until ℓ is empty.
//
// Differences from the paper:
//   1. The ρw × ρw sub-rectangle is oriented like the patch (the paper does not
//      say); a later patch centre q then satisfies |(q − p)·e1| ≥ ρw/2 or
//      |(q − p)·e2| ≥ ρw/2 for every earlier centre p.
//   2. A candidate whose patch would sample texels outside the textures'
//      coverage (more than patch_max_outside_fraction of its samples with a
//      bilinear tap on an uncovered texel or beyond the map) is skipped and only
//      that texel leaves ℓ, so patches never read undefined texels. The paper
//      does not discuss the face boundary.
//   3. Merging (Sec. 5.2 "pixels which belong to multiple patches average the
//      predicted displacements") splats each patch sample with its bilinear
//      weights (the adjoint of sampling) and divides by the accumulated weight;
//      texels with weight 0 are uncovered and left to the Poisson fill.
//   4. θ is known modulo π only (a wrinkle has no preferred side); θ ∈ [0, π), so
//      two nearly vertical wrinkles can get patches rotated by ~180° relative to
//      each other. Training and capture share the rule, so pairs stay consistent.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "pipeline/training/wrinkle_map.h"

namespace crease {

class OptionVisitor;

struct PatchLayoutOptions {
  // w: side of a square patch, texels (Sec. 4.2: 32). Fixed by the trained model;
  // it does not scale with the map resolution.
  int patch_size = 32;
  // ρ: after a patch is placed, candidates within the ρw × ρw sub-rectangle
  // around its centre are dropped (Sec. 4.2: 0.5). Smaller = denser patches.
  double patch_density = 0.5;
  // Largest fraction of a patch's samples allowed to touch texels outside the
  // coverage (or beyond the map); candidates above it are skipped (Difference 2;
  // not in the paper). 0 = patches lie entirely on defined texels.
  double patch_max_outside_fraction = 0.0;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct PatchFrame {
  Eigen::Vector2f center_texel;  // (i, j) of the centre texel (texel coordinates, see above)
  float angle = 0.0f;            // θ ∈ [0, π), radians: patch x axis = gradient direction
};

struct PatchLayout {
  int map_size = 0;    // S of the maps the layout samples (S×S)
  int patch_size = 0;  // w
  std::vector<PatchFrame> patches;

  int num_patches() const { return static_cast<int>(patches.size()); }
  int samples_per_patch() const { return patch_size * patch_size; }
  // Throws Error starting with `what` unless sizes are positive and every centre
  // is finite and inside the map.
  void Validate(const std::string& what) const;
};

struct PatchLayoutReport {
  int candidates = 0;        // |ℓ| at the start: valid texels with W > 0
  int skipped_outside = 0;   // candidates skipped for leaving the coverage (Difference 2)
  int placed = 0;
};

// The greedy placement of Sec. 4.2 on a wrinkle map W (CV_32F S×S, ≥ 0),
// its angle map θ (CV_32F S×S), the valid region (CV_8U S×S or empty = all) and
// the textures' coverage (CV_8U S×S or empty = all). Deterministic.
PatchLayout PlacePatches(const cv::Mat& probability, const cv::Mat& angle, const cv::Mat& valid,
                         const cv::Mat& coverage, const PatchLayoutOptions& options,
                         PatchLayoutReport* report = nullptr);
// Same with the maps of a WrinkleMap.
PatchLayout PlacePatches(const WrinkleMap& map, const PatchLayoutOptions& options,
                         PatchLayoutReport* report = nullptr);

// Bilinear sample of one w × w patch of `map` (CV_32FC1) in the frame `frame`
// (see the coordinate comment above) into out[0 .. w·w), row-major, x along the
// gradient.
void SamplePatch(const cv::Mat& map, const PatchFrame& frame, int w, float* out);

// The per-frame sampler of a fixed layout (Sec. 5.2): the bilinear stencils of all
// samples of all patches are computed once; Sample() then reads any S×S map, and
// Splat() merges patches back into a map. Both run in parallel with TBB and give
// the same bytes for any number of threads.
class PatchSampler {
 public:
  explicit PatchSampler(const PatchLayout& layout);
  ~PatchSampler();
  PatchSampler(PatchSampler&&) noexcept;
  PatchSampler& operator=(PatchSampler&&) noexcept;

  int num_patches() const;
  int patch_size() const;
  int map_size() const;

  // All patches of `map` (CV_32FC1 S×S): an N×w² matrix, row k = patch k (sample
  // b·w + a in column b·w + a). Identical to SamplePatch per patch.
  Eigen::MatrixXf Sample(const cv::Mat& map) const;
  void Sample(const cv::Mat& map, Eigen::MatrixXf* patches) const;

  // The inverse used at capture time (Sec. 5.2, Difference 3): patches (N×w², as
  // returned by Sample) splatted with bilinear weights and divided by the
  // accumulated weight: CV_32F S×S, 0 where splat_weight() is 0.
  cv::Mat Splat(const Eigen::MatrixXf& patches) const;
  // The accumulated bilinear weight of every texel (CV_32F S×S): 0 = no patch
  // covers it (to be filled, e.g. by a Poisson solve). Depends only on the layout.
  const cv::Mat& splat_weight() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Patches placed anew in every frame (the capture's re-centring,
// DetailRegressionOptions::recentre_radius; not in the paper), without a precomputed
// sampler. SamplePatches: SamplePatch of every frame into rows[k·w² …] (row k = patch k,
// row-major N × w²), in parallel. SplatPatches: with the bilinear weights w_k(t) of patch
// k's samples (the adjoint of sampling, as PatchSampler::Splat), the S×S sums (CV_32F)
//   value(t) = Σ_k Σ_samples w_k(t) d_k,   gain(t) = Σ_k g_k w_k(t),   weight(t) = Σ_k w_k(t)
// of the rows d_k (N × w², row-major) and per-patch gains g_k; sequential in patch order, so
// deterministic. Throws Error on a bad map, size or a gain count unlike the patch count.
void SamplePatches(const cv::Mat& map, const std::vector<PatchFrame>& frames, int w, float* rows);
struct SplatSums {
  cv::Mat value, gain, weight;
};
SplatSums SplatPatches(const std::vector<PatchFrame>& frames, int w, int S, const float* rows,
                       const std::vector<float>& gain);

// Training-pair augmentation (not in the paper; TrainingOptions::pair_shift_texels and
// pair_shift_steps): the layout followed by every patch repeated with its centre moved
// across its line, along its x axis e1, by k · shift texels for k = ±1 … ±steps (same
// angle). A capture places its own patches, so a wrinkle sits off their centres by
// amounts the training layout never shows; the copies show them. Copies whose centre
// leaves the map are skipped. steps = 0 returns the layout. Throws Error for steps < 0
// or a shift that is not finite and > 0 when steps > 0.
PatchLayout ShiftedLayout(const PatchLayout& layout, double shift_texels, int steps);

// The training pairs of Sec. 4.2: for each patch k of the layout (in order) and
// each expression j (in order) with r_j(centre of k) > α, the pair
// t = patch of T^j, d = patch of D^j.
struct TrainingPatches {
  Eigen::MatrixXf texture;       // N×w²: t_i, one per row
  Eigen::MatrixXf displacement;  // N×w²: d_i, one per row (units of D^j, mm)
  std::vector<int> patch_index;       // N: the layout patch of row i
  std::vector<int> expression_index;  // N: the expression j of row i

  int size() const { return static_cast<int>(patch_index.size()); }
};

// `textures` T^j, `responses` r_j (DogResponse of T^j) and `displacements` D^j:
// J ≥ 1 each, all CV_32FC1 of the layout's map size. α = options.wrinkle_threshold.
// Throws Error naming the list and index on a count or size mismatch.
TrainingPatches ExtractTrainingPatches(const PatchLayout& layout, const std::vector<cv::Mat>& textures,
                                       const std::vector<cv::Mat>& responses,
                                       const std::vector<cv::Mat>& displacements,
                                       const WrinkleMapOptions& options);

// A picture like the paper's Fig. 6 (bottom): the wrinkle map as a heat map
// (inferno, scaled to its 99.5th percentile of positive values), texels outside
// `valid` (when given) dimmed, and every patch as an oriented w × w rectangle
// with a tick from its centre along +e1 (the gradient): cyan rectangles, green ticks.
// CV_8UC3, channels R, G, B (for WriteImage; until crease 0.4.2 it returned B, G, R and
// the pictures it wrote had red and blue swapped).
cv::Mat DrawPatchLayout(const cv::Mat& wrinkle_map, const PatchLayout& layout, const cv::Mat& valid = cv::Mat());

// Training pairs to look at (issue 17: the raw wrinkle map's pairs turned out to be
// brow and hair edges): `count` rows of N × w² `texture` and `displacement`, evenly
// spread over the rows, each texture patch (gray, stretched to its own range) beside
// its displacement patch (DisplacementPicture, ±its own largest |d|), 8 pairs a row,
// `scale`× enlarged. CV_8UC3, channels R, G, B.
cv::Mat PairMosaic(const Eigen::MatrixXf& texture, const Eigen::MatrixXf& displacement, int patch_size, int count,
                   int scale = 3);

}  // namespace crease
