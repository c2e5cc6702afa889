// Boosted random-fern cascade Φ* (paper Sec. 4.3 training, Sec. 5.2 evaluation).
//
// Maps a texture patch t (w×w grey values, n = w² floats, pixel (x, y) at index
// y·w + x) to D PCA coefficients c of its displacement patch (pca.h):
//
//   training (Eqs. 2–4): c_i^0 = c̄ = avg(ĉ_i); for k = 1 … K, fern R^k is fitted
//     to the residuals ε_i^{k−1} = ĉ_i − c_i^{k−1} (Eq. 3) and c_i^k = c_i^{k−1} + R^k(t_i);
//   evaluation (Eq. 6):  c = c̄ + Σ_k R^k(t), the ferns independent of each other.
//
// A fern R^k has F features, each the intensity difference t[a] − t[b] of a pixel
// pair compared with a threshold θ: bit f = (t[a_f] − t[b_f] > θ_f). The F bits form
// the bin index b = Σ_f bit_f · 2^f ∈ [0, 2^F), and the fern outputs that bin's
// D-vector δc_b (Eq. 4).
//
// Training a fern (Sec. 4.3, with the correlation-based feature selection of Cao et
// al. 2012, "Face alignment by explicit shape regression"):
//   1. P pixel positions are drawn uniformly without replacement from the patch;
//      their P×P covariance is taken once for the fern.
//   2. For each of the F features, a random unit direction v in coefficient space
//      (uniform on the sphere) projects the residuals, y_i = ε_i · v, and the pair
//      (m, n) of the P sampled pixels maximising |corr(y, p_m − p_n)| is chosen, with
//        corr = (cov(y, p_m) − cov(y, p_n)) / sqrt(var(y) · (var p_m + var p_n − 2 cov(p_m, p_n)))
//      (SelectCorrelatedPair).
//   3. The threshold θ is random (FernOptions::fern_threshold_rule).
//   4. Bin outputs by Eq. 4 with shrinkage β (FernBinOutputs), then c_i += δc_{b(i)}.
//
// Determinism: fern k draws its random numbers from Rng(fern_seed).Fork(k) only, and
// every sum over samples is reduced in fixed blocks in a fixed order, so the same
// inputs and options give byte-identical cascades for any TBB thread count. Because
// fern k's randomness does not depend on K, the cascade trained with K' < K ferns is
// exactly the first K' ferns of the one trained with K (Truncated), which makes K
// ablations cheap. Predict and PredictBatch add the bin outputs to c̄ in fern order,
// so they give identical bytes for any batch size, thread count or SIMD path, and
// the training-time estimates c_i^K equal Predict(t_i).
//
// Differences from the paper:
//   1. The paper does not specify how the thresholds are drawn. Default: θ = the
//      feature value of a uniformly random training sample ("sample", so θ follows the
//      data distribution and never lies outside it); alternative "range": uniform in the
//      central fraction fern_threshold_range of [min, max] of the feature over the
//      training set (a choice seen in explicit-shape-regression implementations).
//   2. Pairs are unordered (m < n): the feature p_n − p_m is the negation of p_m − p_n, so
//      |corr| is the same and a random threshold splits either equally well.
//   3. Pairs whose difference has zero variance over the training set are never chosen;
//      when the projected residual has zero variance (all residuals equal along v) the
//      first pair with non-zero variance is used.
//   4. The paper sums Eq. 6 over ferns in parallel; we add the ferns in order in float,
//      which fixes the rounding and makes results reproducible.
//   5. The option fern_pair_selection = "random" (not in the paper) picks a uniformly
//      random pair of the P pixels instead of the correlation-based one, for ablations.
//   6. Same mathematics, cheaper: for n ≤ 2048 pixels the P×P covariance of each fern
//      is sliced from one n×n pixel covariance computed once before the cascade (for
//      n = 1024, K = 1280, P = 50 this is ~6× less work than K separate P×P
//      covariances); larger patches compute it per fern. The F directions of a fern
//      are drawn together, since the residuals do not change within a fern.
//   7. fern_texture_normalization (not in the paper; default "none", the paper's raw
//      gray levels) divides each texture patch by its mean ("gain") or standardises it,
//      so the features respond to shading rather than to an actor's skin tone.
//      Measured (issue 17, rung R0: the quickstart's 4 training actors, leave one actor
//      out, pair level): held-out correlation 0.29 → 0.31 for either; seen pairs 0.91
//      with or without. It does not close the gap between seen and held-out actors.
//
// Speed (bench/fern_cascade_bench, 2-vCPU Sapphire Rapids, shared with other jobs):
// PredictBatch on one core at F = 5, D = 16, w = 32: 4.2 / 2.5 / 1.5 µs per patch at
// K = 1280 / 640 / 320 (fern-major over blocks of 128 patches transposed to
// pixel-major, AVX2 when available; the generic SSE2 kernel: 10 µs at K = 1280);
// Predict one patch at a time: 19 µs at K = 1280 (the 2.6 MB table misses L2).
// Training N = 20,000, K = 1280, P = 50: 4.4 s on one core, 2.3 s on two.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace crease {

class OptionVisitor;

// FernOptions::fern_threshold_rule and fern_pair_selection (see there).
enum class FernThresholdRule { kSample, kRange };
constexpr std::array<const char*, 2> OptionEnumNames(FernThresholdRule) { return {"sample", "range"}; }
enum class FernPairSelection { kCorrelation, kRandom };
constexpr std::array<const char*, 2> OptionEnumNames(FernPairSelection) { return {"correlation", "random"}; }
enum class TextureNormalization { kNone, kGain, kStandardize };
constexpr std::array<const char*, 3> OptionEnumNames(TextureNormalization) { return {"none", "gain", "standardize"}; }

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct FernOptions {
  int num_ferns = 1280;          // K, Sec. 4.3: weak regressors in the cascade
  int fern_depth = 5;            // F, Sec. 4.3: features per fern (2^F bins), 1 … 16
  int num_sampled_pixels = 50;   // P, Sec. 4.3: pixels sampled per fern (P² candidate pairs), ≥ 2
  double shrinkage = 1000.0;     // β, Eq. 4: shrinkage of the bin outputs (samples), ≥ 0
  uint64_t fern_seed = 1;        // seed of the pixel, direction and threshold draws
  // How a feature's threshold θ is drawn (the paper: "randomly selected thresholds"):
  //   "sample" — the feature value of a uniformly random training sample;
  //   "range"  — uniform in the central fern_threshold_range fraction of the feature's
  //              [min, max] over the training set.
  FernThresholdRule fern_threshold_rule = FernThresholdRule::kSample;
  double fern_threshold_range = 0.2;  // "range" rule: central fraction of [min, max], (0, 1]
  // "correlation" (Cao et al. 2012, the paper) or "random" (ablation: a random pair of the P pixels).
  FernPairSelection fern_pair_selection = FernPairSelection::kCorrelation;
  // The texture patch t_i the features read (NormalizeTexturePatch; not in the paper,
  // which feeds raw gray levels): "none" (the paper), "gain" (divided by the patch's
  // mean: shading = albedo × irradiance, so an actor's lighter or darker skin and the
  // exposure cancel) or "standardize" (zero mean, unit standard deviation: contrast
  // cancels too). Applies to the baselines as well.
  TextureNormalization fern_texture_normalization = TextureNormalization::kNone;

  void VisitFields(OptionVisitor& v);
  void Check() const;
  bool operator==(const FernOptions&) const = default;
};

// The patch features' input (FernOptions::fern_texture_normalization) applied in
// place to one patch of n gray levels; a patch with no light (mean or deviation
// under 1e-6) becomes 0.
void NormalizeTexturePatch(float* patch, int n, TextureNormalization mode);
// The same for every row of an N × n matrix (a copy).
Eigen::MatrixXf NormalizeTexturePatches(const Eigen::MatrixXf& patches, TextureNormalization mode);

// The trained cascade: plain data, so it can be serialised member by member.
// K = options.num_ferns, F = options.fern_depth, D = dimensions, n = patch_pixels.
struct FernCascade {
  FernOptions options;          // the options it was trained with (K and F are read from here)
  int patch_pixels = 0;         // n = w²: floats per input patch
  int dimensions = 0;           // D: coefficients per output
  std::vector<float> mean;      // c̄ (D): the average target over the training set, Eq. 6
  std::vector<uint16_t> pixel_a;  // K·F: feature f of fern k is t[pixel_a[k·F+f]] − t[pixel_b[k·F+f]]
  std::vector<uint16_t> pixel_b;  // K·F
  std::vector<float> thresholds;  // K·F: θ; bit f is (t[a] − t[b] > θ)
  std::vector<float> outputs;     // K·2^F·D: δc_b of fern k, bin b at ((k·2^F) + b)·D (Eq. 4)

  int num_ferns() const { return options.num_ferns; }
  int depth() const { return options.fern_depth; }
  int num_bins() const { return 1 << options.fern_depth; }
  // δc_b of fern k (D floats).
  const float* BinOutput(int k, int b) const {
    return outputs.data() + (static_cast<size_t>(k) * num_bins() + b) * dimensions;
  }
  // The bin b of fern k that `patch` (n floats) falls into.
  int BinIndex(int k, const float* patch) const;

  // Eq. 6: c = c̄ + Σ_k R^k(t). patch: n floats; c: D floats.
  void Predict(const float* patch, float* c) const;
  // Eq. 6 for `count` patches stored one after another (count × n floats, row-major);
  // out: count × D floats. Fern-major over blocks of patches (each fern's table stays
  // in L1 across a block), parallel over blocks with TBB; the bytes equal Predict's.
  void PredictBatch(const float* patches, int count, float* out) const;
  // Convenience: patches N × n (one patch per row, any storage order) → N × D.
  Eigen::MatrixXf PredictMatrix(const Eigen::MatrixXf& patches) const;

  // The first k ferns (1 ≤ k ≤ K): equal to the cascade trained with num_ferns = k.
  FernCascade Truncated(int k) const;
  // Throws Error (message starts with `what`, e.g. the model file name) unless the
  // arrays have the sizes above, pixel indices are < n and all values are finite.
  // Call after loading a cascade from a file; Predict does not check.
  void Check(const std::string& what = "fern cascade") const;

  bool operator==(const FernCascade&) const = default;
};

struct FernTrainingReport {
  int num_samples = 0;                  // N
  int patch_pixels = 0;                 // n
  int dimensions = 0;                   // D
  // RMSE of the coefficients on the training set, sqrt(Σ_i ‖ĉ_i − c_i^k‖² / (N·D)),
  // after k = checkpoint_ferns[j] ferns: k = 0 (c̄ only) and every tenth of the cascade.
  std::vector<int> checkpoint_ferns;
  std::vector<double> train_rmse;
  double mean_abs_correlation = 0.0;    // mean |corr| of the selected pairs (selection quality)
  double empty_bin_fraction = 0.0;      // fraction of all K·2^F bins no training sample fell into
  double seconds = 0.0;                 // wall-clock training time
};

struct FernTrainingResult {
  FernCascade cascade;
  FernTrainingReport report;
};

// Trains the cascade (Eqs. 2–4, Sec. 4.3).
//   patches: N × n texture patches {t_i} (one per row; column-major Eigen storage, the
//            same matrix layout FitPatchPca takes);
//   targets: N × D PCA coefficients {ĉ_i} (PatchPca::ProjectPatches of the displacement patches).
// Throws Error for invalid options, N = 0, mismatched row counts, P > n, n > 65536,
// D = 0, or a non-finite pixel or target (naming the row).
FernTrainingResult TrainFernCascade(const Eigen::MatrixXf& patches, const Eigen::MatrixXf& targets,
                                    const FernOptions& options);

// Cao et al. 2012 correlation-based feature selection for one projected target y.
// pixel_scatter: P×P, Σ_i (p_i − p̄)(p_i − p̄)ᵀ of the sampled pixels;
// target_pixel_scatter: P, Σ_i (y_i − ȳ)(p_i − p̄); target_scatter: Σ_i (y_i − ȳ)².
// (Any common scale of the three, e.g. covariances, gives the same answer.)
// Returns the unordered pair m < n maximising |corr(y, p_m − p_n)| and that correlation
// (signed); the first maximum in (m, n) order wins ties.
struct PixelPair {
  int m = 0;
  int n = 1;
  double correlation = 0.0;
};
PixelPair SelectCorrelatedPair(const Eigen::MatrixXd& pixel_scatter, const Eigen::VectorXd& target_pixel_scatter,
                               double target_scatter);

// Eq. 4: δc_b = Σ_{i∈Ω_b} ε_i / (|Ω_b| + β) for every bin b < num_bins (num_bins × D).
// bin_of_sample: N bin indices; residuals: N × D, ε_i = ĉ_i − c_i. Sums in double over
// fixed blocks of samples (deterministic for any thread count). Empty bins output 0.
Eigen::MatrixXf FernBinOutputs(const std::vector<int>& bin_of_sample, const RowMatrixXf& residuals, int num_bins,
                               double shrinkage);

namespace internal {
// For tests and benchmarks: false makes PredictBatch use the generic (SSE2) kernel
// even where AVX2 is available. Both give the same bytes.
void SetFernAvx2Allowed(bool allowed);
}  // namespace internal

}  // namespace crease
