#include "pipeline/training/fern_cascade.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fmt/format.h>
#include <numeric>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "core/error.h"
#include "core/options.h"
#include "core/rng.h"

namespace crease {
namespace {

// ---------------------------------------------------------------------------
// Training helpers
// ---------------------------------------------------------------------------

// Samples per reduction block. Fixed, so that every sum over samples is the same
// for any number of threads: blocks are summed independently, then in block order.
constexpr int kSampleBlock = 2048;

int NumSampleBlocks(int N) { return (N + kSampleBlock - 1) / kSampleBlock; }

// Calls f(block, i0, i1) for every sample block [i0, i1), in parallel.
template <class Function>
void ForSampleBlocks(int N, const Function& f) {
  tbb::parallel_for(0, NumSampleBlocks(N), [&](int block) {
    const int i0 = block * kSampleBlock;
    f(block, i0, std::min(N, i0 + kSampleBlock));
  });
}

// Throws naming the first non-finite entry of an N × cols matrix.
void RequireFinite(const Eigen::MatrixXf& m, const char* what, const char* column_name) {
  if (m.allFinite()) return;
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j)
      if (!std::isfinite(m(i, j)))
        throw Error(fmt::format("TrainFernCascade: {} row {} has a non-finite value ({}) at {} {}", what, i,
                                m(i, j), column_name, j));
}

// Per-bin residual sums (double) and counts, reduced in fixed blocks.
void BinSums(const std::vector<int>& bin_of_sample, const RowMatrixXf& residuals, int num_bins,
             Eigen::MatrixXd* sums, std::vector<int64_t>* counts) {
  const int N = static_cast<int>(residuals.rows());
  const int D = static_cast<int>(residuals.cols());
  const int blocks = NumSampleBlocks(N);
  std::vector<Eigen::MatrixXd> block_sums(blocks);
  std::vector<std::vector<int64_t>> block_counts(blocks);
  ForSampleBlocks(N, [&](int block, int i0, int i1) {
    Eigen::MatrixXd& s = block_sums[block];
    std::vector<int64_t>& c = block_counts[block];
    s.setZero(D, num_bins);  // column b = bin b, contiguous
    c.assign(num_bins, 0);
    for (int i = i0; i < i1; ++i) {
      const int b = bin_of_sample[i];
      const float* e = residuals.row(i).data();
      double* out = s.col(b).data();
      for (int d = 0; d < D; ++d) out[d] += e[d];
      ++c[b];
    }
  });
  sums->setZero(D, num_bins);
  counts->assign(num_bins, 0);
  for (int block = 0; block < blocks; ++block) {
    *sums += block_sums[block];
    for (int b = 0; b < num_bins; ++b) (*counts)[b] += block_counts[block][b];
  }
}

// Eq. 4 from the sums: δc_b = sum_b / (|Ω_b| + β); num_bins × D floats.
Eigen::MatrixXf ShrunkOutputs(const Eigen::MatrixXd& sums, const std::vector<int64_t>& counts, double shrinkage) {
  const int D = static_cast<int>(sums.rows());
  const int num_bins = static_cast<int>(sums.cols());
  Eigen::MatrixXf outputs(num_bins, D);
  for (int b = 0; b < num_bins; ++b) {
    const double denominator = static_cast<double>(counts[b]) + shrinkage;
    for (int d = 0; d < D; ++d)
      outputs(b, d) = denominator > 0.0 ? static_cast<float>(sums(d, b) / denominator) : 0.f;
  }
  return outputs;
}

// Largest n for which the trainer computes the full n × n pixel scatter once
// (8 bytes · n² of memory: 32 MB at 2048) instead of a P × P scatter per fern.
// Fixed, not dependent on K, so that shorter cascades stay prefixes of longer ones.
constexpr int kGlobalScatterMaxPixels = 2048;

// Σ_i (t_i − t̄)(t_i − t̄)ᵀ over all N patches (n × n, double): rows in blocks of
// kSampleBlock, centred in float, multiplied tile by tile (upper triangle, float
// GEMM per tile) and accumulated in double. Tiles run in parallel and each adds its
// row blocks in order, so the result does not depend on the thread count.
Eigen::MatrixXd PixelScatter(const Eigen::MatrixXf& patches) {
  constexpr int kTile = 128;
  const int N = static_cast<int>(patches.rows());
  const int n = static_cast<int>(patches.cols());
  Eigen::VectorXf mean(n);
  tbb::parallel_for(0, n, [&](int j) {
    double sum = 0.0;
    const float* col = patches.col(j).data();
    for (int i = 0; i < N; ++i) sum += col[i];
    mean[j] = static_cast<float>(sum / N);
  });
  const int tiles = (n + kTile - 1) / kTile;
  std::vector<std::pair<int, int>> tile_pairs;
  for (int I = 0; I < tiles; ++I)
    for (int J = I; J < tiles; ++J) tile_pairs.emplace_back(I, J);
  Eigen::MatrixXd scatter = Eigen::MatrixXd::Zero(n, n);
  Eigen::MatrixXf block;
  for (int r0 = 0; r0 < N; r0 += kSampleBlock) {
    const int rows = std::min(kSampleBlock, N - r0);
    block = patches.middleRows(r0, rows);
    block.rowwise() -= mean.transpose();
    tbb::parallel_for(0, static_cast<int>(tile_pairs.size()), [&](int t) {
      const int i0 = tile_pairs[t].first * kTile, j0 = tile_pairs[t].second * kTile;
      const int ni = std::min(kTile, n - i0), nj = std::min(kTile, n - j0);
      const Eigen::MatrixXf product = block.middleCols(i0, ni).transpose() * block.middleCols(j0, nj);
      scatter.block(i0, j0, ni, nj) += product.cast<double>();
    });
  }
  return scatter.selfadjointView<Eigen::Upper>();
}

// out[f] = Σ_i x_i · Y(i, f) for every column f of Y (N rows): float partial sums
// in 8 lanes within each sample block (the block of x stays in L1 across the
// columns), the blocks added in double in order (deterministic).
void BlockedDots(const float* x, const Eigen::MatrixXf& Y, double* out) {
  const int N = static_cast<int>(Y.rows());
  const int F = static_cast<int>(Y.cols());
  for (int f = 0; f < F; ++f) out[f] = 0.0;
  for (int i0 = 0; i0 < N; i0 += kSampleBlock) {
    const int i1 = std::min(N, i0 + kSampleBlock);
    for (int f = 0; f < F; ++f) {
      const float* y = Y.col(f).data();
      float lanes[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      int i = i0;
      for (; i + 8 <= i1; i += 8)
        for (int l = 0; l < 8; ++l) lanes[l] += x[i + l] * y[i + l];
      double block_sum = 0.0;
      for (int l = 0; l < 8; ++l) block_sum += lanes[l];
      for (; i < i1; ++i) block_sum += static_cast<double>(x[i]) * y[i];
      out[f] += block_sum;
    }
  }
}

// sqrt(Σ_i ‖ε_i‖² / (N·D)).
double Rmse(const RowMatrixXf& residuals) {
  const int N = static_cast<int>(residuals.rows());
  std::vector<double> partial(NumSampleBlocks(N), 0.0);
  ForSampleBlocks(N, [&](int block, int i0, int i1) {
    double s = 0.0;
    for (int i = i0; i < i1; ++i)
      for (Eigen::Index d = 0; d < residuals.cols(); ++d) s += static_cast<double>(residuals(i, d)) * residuals(i, d);
    partial[block] = s;
  });
  const double total = std::accumulate(partial.begin(), partial.end(), 0.0);
  return std::sqrt(total / (static_cast<double>(N) * static_cast<double>(residuals.cols())));
}

// ---------------------------------------------------------------------------
// Evaluation kernel (Eq. 6)
// ---------------------------------------------------------------------------

// Evaluation layout. PredictBatch works on blocks of kBatchBlock patches: the block
// is transposed to pixel-major (so a feature compares 8 patches per instruction),
// then the ferns are visited in groups of kFernGroup: bin indices of the group for
// all patches, then each patch's D accumulators (in registers) receive the group's
// bin outputs in fern order. With n = 1024 a transposed block takes
// n · kRowStride · 4 bytes = 576 KB (L2); the accumulators kBatchBlock · D · 4 = 8 KB
// and one group's tables kFernGroup · 2^F · D · 4 = 16 KB stay in L1, and the whole
// table (2.6 MB at K = 1280, more than L2) is streamed once per block instead of
// once per patch. kBatchBlock = 128 measured faster than 256 (4.1 vs 4.8 µs/patch).
constexpr int kBatchBlock = 128;
constexpr int kFernGroup = 8;
constexpr int kTransposeLanes = 16;   // divides kBatchBlock
// Row stride of the transposed block, padded by one cache line: a stride of
// exactly 512 bytes maps every row to the same 8 of L1's 64 sets.
constexpr int kRowStride = kBatchBlock + 16;
constexpr int kTransposePixels = 512;

// 8 floats as a GCC vector (compiles to the target's SIMD width; no intrinsics, so
// the same code serves the generic and the AVX2 path).
typedef float V8 __attribute__((vector_size(32)));

struct BatchScratch {
  std::vector<float> transposed;  // n × kRowStride: pixel j of lane p at j·kRowStride + p
  std::vector<float> accumulators;  // kBatchBlock × D
  std::vector<int32_t> bins;        // kFernGroup × kBatchBlock
};

// Transposes `count` ≤ kBatchBlock patches (count × n, row-major) into T (n rows of
// kRowStride floats: pixel j of lane p at j·kRowStride + p) and zeroes lanes
// [count, kBatchBlock) (computed, never written out). Tiled: kTransposeLanes
// patches (one 64-byte line of T per pixel) × kTransposePixels pixels, so the
// touched lines of T stay in L1 while each patch is read sequentially (which
// hardware prefetchers follow within its 4 KB page).
void TransposeBlockScalar(const float* patches, int count, int n, float* T, int first_lane = 0) {
  for (int p0 = first_lane - first_lane % kTransposeLanes; p0 < kBatchBlock; p0 += kTransposeLanes) {
    for (int j0 = 0; j0 < n; j0 += kTransposePixels) {
      const int j1 = std::min(n, j0 + kTransposePixels);
      for (int p = std::max(p0, first_lane); p < p0 + kTransposeLanes; ++p) {
        if (p < count) {
          const float* src = patches + static_cast<size_t>(p) * n;
          for (int j = j0; j < j1; ++j) T[static_cast<size_t>(j) * kRowStride + p] = src[j];
        } else {
          for (int j = j0; j < j1; ++j) T[static_cast<size_t>(j) * kRowStride + p] = 0.f;
        }
      }
    }
  }
}

// Bin indices of all kBatchBlock lanes for fern k: bins[p] = Σ_f (T[a_f][p] − T[b_f][p] > θ_f) · 2^f,
// 8 lanes at a time in GCC vectors (the index stays in a register across the F features).
[[gnu::always_inline]] inline void FernBins(const FernCascade& fc, int k, const float* T, int32_t* bins) {
  typedef int32_t V8i __attribute__((vector_size(32)));
  const int F = fc.depth();
  for (int p = 0; p < kBatchBlock; p += 8) {
    V8i b = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int f = 0; f < F; ++f) {
      const size_t idx = static_cast<size_t>(k) * F + f;
      V8 ta, tb;
      __builtin_memcpy(&ta, T + static_cast<size_t>(fc.pixel_a[idx]) * kRowStride + p, sizeof(V8));
      __builtin_memcpy(&tb, T + static_cast<size_t>(fc.pixel_b[idx]) * kRowStride + p, sizeof(V8));
      const float theta = fc.thresholds[idx];
      b |= ((ta - tb) > theta) & (int32_t{1} << f);  // comparison gives −1 (true) or 0 per lane
    }
    __builtin_memcpy(bins + p, &b, sizeof(V8i));
  }
}

// Adds the bin outputs of `group` ferns (tables at `tables`, fern g's bin b at
// (g·2^F + b)·D) to one patch's accumulator `a`, fern by fern. kGroup > 0: the group
// size is known at compile time (fully unrolled); kD = 16: two 8-float registers.
template <int kD, int kGroup>
[[gnu::always_inline]] inline void AccumulateGroup(const float* tables, const int32_t* bins, int group, int num_bins,
                                                   int D, float* a) {
  const int G = kGroup > 0 ? kGroup : group;
  if constexpr (kD == 16) {
    V8 r0, r1;
    __builtin_memcpy(&r0, a, sizeof(V8));
    __builtin_memcpy(&r1, a + 8, sizeof(V8));
    for (int g = 0; g < G; ++g) {
      const float* o = tables + (static_cast<size_t>(g) * num_bins + bins[g * kBatchBlock]) * kD;
      V8 o0, o1;
      __builtin_memcpy(&o0, o, sizeof(V8));
      __builtin_memcpy(&o1, o + 8, sizeof(V8));
      r0 += o0;
      r1 += o1;
    }
    __builtin_memcpy(a, &r0, sizeof(V8));
    __builtin_memcpy(a + 8, &r1, sizeof(V8));
  } else {
    for (int g = 0; g < G; ++g) {
      const float* o = tables + (static_cast<size_t>(g) * num_bins + bins[g * kBatchBlock]) * D;
      for (int d = 0; d < D; ++d) a[d] += o[d];
    }
  }
}

// Eq. 6 for one transposed block of `count` ≤ kBatchBlock patches: fern-major over
// groups of kFernGroup ferns (bins of the group for all lanes, then each patch's
// accumulator gets the group's outputs in fern order). The sum for each patch is
// c̄ + δc^1 + δc^2 + … exactly as in Predict. kD is 16 or 0 (any D).
template <int kD>
[[gnu::always_inline]] inline void PredictTransposedBlock(const FernCascade& fc, int count, float* out,
                                                          BatchScratch& s) {
  const int K = fc.num_ferns();
  const int num_bins = fc.num_bins();
  const int D = kD > 0 ? kD : fc.dimensions;
  const float* T = s.transposed.data();
  float* acc = s.accumulators.data();
  int32_t* bins = s.bins.data();
  const size_t fern_floats = static_cast<size_t>(num_bins) * D;

  for (int p = 0; p < count; ++p)
    for (int d = 0; d < D; ++d) acc[p * D + d] = fc.mean[d];

  for (int k0 = 0; k0 < K; k0 += kFernGroup) {
    const int group = std::min(kFernGroup, K - k0);
    for (int g = 0; g < group; ++g) FernBins(fc, k0 + g, T, bins + g * kBatchBlock);
    // Meanwhile prefetch the next group's tables (a few lines per patch): with
    // K = 1280 the whole table (2.6 MB) does not fit L2, and this hides the L3
    // latency of its first touch in the block.
    const float* tables = fc.outputs.data() + static_cast<size_t>(k0) * fern_floats;
    const char* next_tables = reinterpret_cast<const char*>(tables + group * fern_floats);
    const size_t next_bytes = static_cast<size_t>(std::min(kFernGroup, K - k0 - group)) * fern_floats * sizeof(float);
    const size_t prefetch_stride = (next_bytes / static_cast<size_t>(count) + 63) / 64 * 64;
    for (int p = 0; p < count; ++p) {
      for (size_t q = p * prefetch_stride; q < std::min(next_bytes, (p + 1) * prefetch_stride); q += 64)
        __builtin_prefetch(next_tables + q);
      if (group == kFernGroup) {
        AccumulateGroup<kD, kFernGroup>(tables, bins + p, group, num_bins, D, acc + p * D);
      } else {
        AccumulateGroup<kD, 0>(tables, bins + p, group, num_bins, D, acc + p * D);
      }
    }
  }
  std::memcpy(out, acc, sizeof(float) * static_cast<size_t>(count) * D);
}

// One patch, ferns in order: c = c̄ + δc^1 + δc^2 + … (Eq. 6). The sum is kept in a
// local array (registers for kD = 16) rather than in `c`, which may alias nothing
// the compiler can prove.
template <int kD>
void PredictOne(const FernCascade& fc, const float* patch, float* c) {
  const int K = fc.num_ferns();
  const int F = fc.depth();
  const int num_bins = fc.num_bins();
  const int D = kD > 0 ? kD : fc.dimensions;
  const uint16_t* pixel_a = fc.pixel_a.data();
  const uint16_t* pixel_b = fc.pixel_b.data();
  const float* thresholds = fc.thresholds.data();
  const float* outputs = fc.outputs.data();
  constexpr int kLocal = kD > 0 ? kD : 64;
  float r[kLocal];
  std::vector<float> heap;
  float* sum = r;
  if (D > kLocal) {
    heap.resize(D);
    sum = heap.data();
  }
  for (int d = 0; d < D; ++d) sum[d] = fc.mean[d];
  for (int k = 0; k < K; ++k) {
    int b = 0;
    for (int f = 0; f < F; ++f) {
      const size_t idx = static_cast<size_t>(k) * F + f;
      // Branch-free: with random patches a branch here mispredicts half the time.
      b |= static_cast<int>(patch[pixel_a[idx]] - patch[pixel_b[idx]] > thresholds[idx]) << f;
    }
    const float* o = outputs + (static_cast<size_t>(k) * num_bins + b) * D;
    for (int d = 0; d < D; ++d) sum[d] += o[d];
  }
  for (int d = 0; d < D; ++d) c[d] = sum[d];
}

void PredictBlockGeneric(const FernCascade& fc, const float* patches, int count, float* out, BatchScratch& s) {
  TransposeBlockScalar(patches, count, fc.patch_pixels, s.transposed.data());
  if (fc.dimensions == 16) {
    PredictTransposedBlock<16>(fc, count, out, s);
  } else {
    PredictTransposedBlock<0>(fc, count, out, s);
  }
}

#if defined(__GNUC__) && defined(__x86_64__)
// AVX2 transpose: 8 patches × 8 pixels per step (8 row loads, 24 shuffles, 8 stores
// instead of 64 scalar moves); tails in pixels and patches go through the scalar code.
__attribute__((target("avx2"))) void TransposeBlockAvx2(const float* patches, int count, int n, float* T) {
  const int full_lanes = count / 8 * 8;
  const int full_pixels = n / 8 * 8;
  for (int p0 = 0; p0 < full_lanes; p0 += 8) {
    const float* src = patches + static_cast<size_t>(p0) * n;
    for (int j0 = 0; j0 < full_pixels; j0 += 8) {
      __m256 r[8];
      for (int i = 0; i < 8; ++i) r[i] = _mm256_loadu_ps(src + static_cast<size_t>(i) * n + j0);
      const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
      const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
      const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
      const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
      const __m256 u0 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
      const __m256 u1 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
      const __m256 u2 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
      const __m256 u3 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
      const __m256 u4 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(1, 0, 1, 0));
      const __m256 u5 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(3, 2, 3, 2));
      const __m256 u6 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(1, 0, 1, 0));
      const __m256 u7 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(3, 2, 3, 2));
      const __m256 c[8] = {_mm256_permute2f128_ps(u0, u4, 0x20), _mm256_permute2f128_ps(u1, u5, 0x20),
                           _mm256_permute2f128_ps(u2, u6, 0x20), _mm256_permute2f128_ps(u3, u7, 0x20),
                           _mm256_permute2f128_ps(u0, u4, 0x31), _mm256_permute2f128_ps(u1, u5, 0x31),
                           _mm256_permute2f128_ps(u2, u6, 0x31), _mm256_permute2f128_ps(u3, u7, 0x31)};
      for (int j = 0; j < 8; ++j) _mm256_storeu_ps(T + static_cast<size_t>(j0 + j) * kRowStride + p0, c[j]);
    }
    for (int p = p0; p < p0 + 8; ++p)
      for (int j = full_pixels; j < n; ++j)
        T[static_cast<size_t>(j) * kRowStride + p] = src[(p - p0) * static_cast<size_t>(n) + j];
  }
  TransposeBlockScalar(patches, count, n, T, full_lanes);
}

// The same evaluation compiled for AVX2 (8 lanes per feature comparison, one
// register per 8 accumulated floats), chosen at run time. Only IEEE subtraction,
// comparison and addition, in the same order: the bytes equal the generic path's.
__attribute__((target("avx2"))) void PredictBlockAvx2(const FernCascade& fc, const float* patches, int count,
                                                      float* out, BatchScratch& s) {
  TransposeBlockAvx2(patches, count, fc.patch_pixels, s.transposed.data());
  if (fc.dimensions == 16) {
    PredictTransposedBlock<16>(fc, count, out, s);
  } else {
    PredictTransposedBlock<0>(fc, count, out, s);
  }
}
std::atomic<bool> g_avx2_allowed{true};
bool HasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has && g_avx2_allowed.load(std::memory_order_relaxed);
}
#else
std::atomic<bool> g_avx2_allowed{true};
bool HasAvx2() { return false; }
void PredictBlockAvx2(const FernCascade& fc, const float* patches, int count, float* out, BatchScratch& s) {
  PredictBlockGeneric(fc, patches, count, out, s);
}
#endif

}  // namespace

namespace internal {
void SetFernAvx2Allowed(bool allowed) { g_avx2_allowed.store(allowed, std::memory_order_relaxed); }
}  // namespace internal

// ---------------------------------------------------------------------------
// Options
// ---------------------------------------------------------------------------

void FernOptions::VisitFields(OptionVisitor& v) {
  v.Field("num_ferns", num_ferns);
  v.Field("depth", fern_depth);
  v.Field("num_sampled_pixels", num_sampled_pixels);
  v.Field("shrinkage", shrinkage);
  v.Field("seed", fern_seed);
  v.Field("threshold_rule", fern_threshold_rule);
  v.Field("threshold_range", fern_threshold_range);
  v.Field("pair_selection", fern_pair_selection);
  v.Field("texture_normalization", fern_texture_normalization);
}

void FernOptions::Check() const {
  const char* o = "FernOptions";
  CheckGe(o, "num_ferns", num_ferns, 1);
  CheckGe(o, "fern_depth", fern_depth, 1);
  CheckLe(o, "fern_depth", fern_depth, 16);
  CheckGe(o, "num_sampled_pixels", num_sampled_pixels, 2);
  CheckLe(o, "num_sampled_pixels", num_sampled_pixels, 65536);
  CheckGe(o, "shrinkage", shrinkage, 0.0);
  Require(std::isfinite(shrinkage), fmt::format("FernOptions.shrinkage = {} must be finite", shrinkage));
  CheckGt(o, "fern_threshold_range", fern_threshold_range, 0.0);
  CheckLe(o, "fern_threshold_range", fern_threshold_range, 1.0);
}

// ---------------------------------------------------------------------------
// Feature selection (Cao et al. 2012) and Eq. 4
// ---------------------------------------------------------------------------

PixelPair SelectCorrelatedPair(const Eigen::MatrixXd& pixel_scatter, const Eigen::VectorXd& target_pixel_scatter,
                               double target_scatter) {
  const int P = static_cast<int>(pixel_scatter.rows());
  Require(P >= 2 && pixel_scatter.cols() == P && target_pixel_scatter.size() == P,
          fmt::format("SelectCorrelatedPair: expected a P×P scatter and a P-vector with P >= 2, got {}×{} and {}",
                      pixel_scatter.rows(), pixel_scatter.cols(), target_pixel_scatter.size()));
  PixelPair best;
  bool found = false;
  double best_abs = -1.0;
  for (int m = 0; m < P; ++m) {
    for (int n = m + 1; n < P; ++n) {
      const double var_sum = pixel_scatter(m, m) + pixel_scatter(n, n);
      const double var_diff = var_sum - 2.0 * pixel_scatter(m, n);
      // Zero-variance differences (constant, or identical pixels up to float
      // rounding of the scatter) carry no information (Differences, item 3).
      if (!(var_diff > 1e-6 * var_sum)) continue;
      double corr = 0.0;
      if (target_scatter > 0.0)
        corr = (target_pixel_scatter[m] - target_pixel_scatter[n]) / std::sqrt(target_scatter * var_diff);
      if (!found || std::abs(corr) > best_abs) {
        best = {m, n, corr};
        best_abs = std::abs(corr);
        found = true;
      }
    }
  }
  return best;
}

Eigen::MatrixXf FernBinOutputs(const std::vector<int>& bin_of_sample, const RowMatrixXf& residuals, int num_bins,
                               double shrinkage) {
  Require(static_cast<Eigen::Index>(bin_of_sample.size()) == residuals.rows(),
          fmt::format("FernBinOutputs: {} bin indices for {} residual rows", bin_of_sample.size(), residuals.rows()));
  Require(num_bins >= 1 && shrinkage >= 0.0,
          fmt::format("FernBinOutputs: num_bins = {} must be >= 1 and shrinkage = {} >= 0", num_bins, shrinkage));
  for (size_t i = 0; i < bin_of_sample.size(); ++i)
    Require(bin_of_sample[i] >= 0 && bin_of_sample[i] < num_bins,
            fmt::format("FernBinOutputs: sample {} has bin {}, expected [0, {})", i, bin_of_sample[i], num_bins));
  Eigen::MatrixXd sums;
  std::vector<int64_t> counts;
  BinSums(bin_of_sample, residuals, num_bins, &sums, &counts);
  return ShrunkOutputs(sums, counts, shrinkage);
}

// ---------------------------------------------------------------------------
// Training (Eqs. 2–4)
// ---------------------------------------------------------------------------

namespace {

// Throws unless TrainFernCascade's inputs are usable: N ≥ 1 finite patches of
// n ≤ 65536 pixels, N finite targets of D ≥ 1 coefficients, P ≤ n.
void RequireTrainingInputs(const Eigen::MatrixXf& patches, const Eigen::MatrixXf& targets,
                           const FernOptions& options) {
  const int N = static_cast<int>(patches.rows());
  const int n = static_cast<int>(patches.cols());
  const int D = static_cast<int>(targets.cols());
  const int P = options.num_sampled_pixels;
  Require(N >= 1, "TrainFernCascade: the training set is empty (0 patches)");
  Require(targets.rows() == N, fmt::format("TrainFernCascade: {} patches but {} target rows", N, targets.rows()));
  Require(D >= 1, "TrainFernCascade: targets have 0 coefficients (columns)");
  Require(n <= 65536, fmt::format("TrainFernCascade: patches have n = {} pixels, at most 65536 supported", n));
  Require(P <= n, fmt::format("FernOptions.num_sampled_pixels = P = {} must be <= the patch pixel count n = {}", P, n));
  RequireFinite(patches, "patch", "pixel");
  RequireFinite(targets, "target", "coefficient");
}

// One run of TrainFernCascade: the training set, the current estimates c_i and
// residuals ε_i = ĉ_i − c_i (Eq. 3), and the scratch of one fern, with one
// method per step of a fern. The random draws of fern k come from one stream
// (FernOptions::fern_seed forked by k), in the order of the steps.
class FernCascadeTrainer {
 public:
  FernCascadeTrainer(const Eigen::MatrixXf& patches, const Eigen::MatrixXf& targets, const FernOptions& options,
                     FernTrainingResult* result);

  // Trains fern k (steps 1–4) and records the training RMSE at a checkpoint.
  void TrainFern(int k);
  // The report's mean |correlation| and empty-bin fraction, after the last fern.
  void FinishReport();

 private:
  void StartCascade(const Eigen::MatrixXf& targets);
  void SamplePixels(Rng& rng);
  void SampledPixelScatter();
  void ProjectResiduals(Rng& rng);
  void ChooseFeature(int k, int f, Rng& rng);
  float RandomThreshold(Rng& rng) const;
  void UpdateResiduals(int k);

  const Eigen::MatrixXf& patches_;
  const FernOptions& options_;
  FernCascade& cascade_;
  FernTrainingReport& report_;
  const int N, n, D, K, F, P, num_bins;
  const bool correlation_;
  const bool sample_threshold_;
  const int blocks_;
  const RowMatrixXf c_hat_;  // ĉ_i, the targets
  RowMatrixXf c_;            // c_i
  RowMatrixXf eps_;          // ε_i = ĉ_i − c_i
  size_t next_checkpoint_ = 1;
  // The P × P pixel covariances of every fern, from one n × n scatter of all pixels
  // when n ≤ kGlobalScatterMaxPixels (cheaper than K scatters of P pixels once
  // n² < 2·K·P², e.g. n = 1024, K = 1280, P = 50), otherwise computed per fern.
  const bool global_scatter_;
  const Eigen::MatrixXd all_pixel_scatter_;
  std::vector<int> pool_;
  std::vector<int> sampled_;
  Eigen::MatrixXf X_;  // per-fern scatter only: the sampled pixels, centred
  Eigen::MatrixXd pixel_scatter_;
  Eigen::MatrixXf directions_;  // column f: the unit direction of feature f
  Eigen::MatrixXf Y_;           // column f: y_i = ε_i · v_f, centred
  Eigen::MatrixXd target_pixel_scatter_;
  Eigen::VectorXd target_scatter_;
  Eigen::VectorXf feature_;
  std::vector<int> bins_;
  std::vector<Eigen::MatrixXf> block_scatter_;
  std::vector<Eigen::VectorXd> block_vector_;
  double abs_correlation_sum_ = 0.0;
  int64_t empty_bins_ = 0;
  Eigen::MatrixXd sums_;
  std::vector<int64_t> counts_;
};

FernCascadeTrainer::FernCascadeTrainer(const Eigen::MatrixXf& patches, const Eigen::MatrixXf& targets,
                                       const FernOptions& options, FernTrainingResult* result)
    : patches_(patches),
      options_(options),
      cascade_(result->cascade),
      report_(result->report),
      N(static_cast<int>(patches.rows())),
      n(static_cast<int>(patches.cols())),
      D(static_cast<int>(targets.cols())),
      K(options.num_ferns),
      F(options.fern_depth),
      P(options.num_sampled_pixels),
      num_bins(1 << F),
      correlation_(options.fern_pair_selection == FernPairSelection::kCorrelation),
      sample_threshold_(options.fern_threshold_rule == FernThresholdRule::kSample),
      blocks_(NumSampleBlocks(N)),
      c_hat_(targets),
      global_scatter_(correlation_ && n <= kGlobalScatterMaxPixels),
      all_pixel_scatter_(global_scatter_ ? PixelScatter(patches) : Eigen::MatrixXd()),
      pool_(n),
      sampled_(P),
      pixel_scatter_(P, P),
      directions_(D, F),
      Y_(N, F),
      target_pixel_scatter_(P, F),
      target_scatter_(F),
      feature_(N),
      bins_(N),
      block_scatter_(blocks_),
      block_vector_(blocks_) {
  StartCascade(targets);
}

// The cascade's arrays, c^0 = c̄ = avg(ĉ_i) (Sec. 4.3), ε^0 = ĉ − c^0, and the
// checkpoints k = 0 and every tenth of the cascade.
void FernCascadeTrainer::StartCascade(const Eigen::MatrixXf& targets) {
  cascade_.options = options_;
  cascade_.patch_pixels = n;
  cascade_.dimensions = D;
  cascade_.pixel_a.resize(static_cast<size_t>(K) * F);
  cascade_.pixel_b.resize(static_cast<size_t>(K) * F);
  cascade_.thresholds.resize(static_cast<size_t>(K) * F);
  cascade_.outputs.resize(static_cast<size_t>(K) * num_bins * D);
  report_.num_samples = N;
  report_.patch_pixels = n;
  report_.dimensions = D;

  const Eigen::VectorXd mean = targets.cast<double>().colwise().sum().transpose() / static_cast<double>(N);
  cascade_.mean.resize(D);
  for (int d = 0; d < D; ++d) cascade_.mean[d] = static_cast<float>(mean[d]);
  c_.resize(N, D);
  for (int i = 0; i < N; ++i)
    for (int d = 0; d < D; ++d) c_(i, d) = cascade_.mean[d];
  eps_ = c_hat_ - c_;

  for (int j = 0; j <= 10; ++j) {
    const int k = static_cast<int>(static_cast<int64_t>(K) * j / 10);
    if (report_.checkpoint_ferns.empty() || report_.checkpoint_ferns.back() != k) report_.checkpoint_ferns.push_back(k);
  }
  report_.train_rmse.push_back(Rmse(eps_));
}

void FernCascadeTrainer::TrainFern(int k) {
  Rng base(options_.fern_seed);
  Rng rng = base.Fork(static_cast<uint64_t>(k));
  SamplePixels(rng);
  if (correlation_) {
    SampledPixelScatter();
    ProjectResiduals(rng);
  }
  std::fill(bins_.begin(), bins_.end(), 0);
  for (int f = 0; f < F; ++f) ChooseFeature(k, f, rng);
  UpdateResiduals(k);
  if (next_checkpoint_ < report_.checkpoint_ferns.size() && report_.checkpoint_ferns[next_checkpoint_] == k + 1) {
    report_.train_rmse.push_back(Rmse(eps_));
    ++next_checkpoint_;
  }
}

// 1. P pixel positions, uniformly without replacement (partial Fisher–Yates).
void FernCascadeTrainer::SamplePixels(Rng& rng) {
  std::iota(pool_.begin(), pool_.end(), 0);
  for (int m = 0; m < P; ++m) {
    const int j = m + static_cast<int>(rng.UniformInt(static_cast<uint64_t>(n - m)));
    std::swap(pool_[m], pool_[j]);
    sampled_[m] = pool_[m];
  }
}

// P × P pixel covariance (as a scatter) of the sampled pixels, once per fern.
void FernCascadeTrainer::SampledPixelScatter() {
  if (global_scatter_) {
    for (int m = 0; m < P; ++m)
      for (int q = 0; q < P; ++q) pixel_scatter_(m, q) = all_pixel_scatter_(sampled_[m], sampled_[q]);
    return;
  }
  X_.resize(N, P);
  tbb::parallel_for(0, P, [&](int m) {
    const float* src = patches_.col(sampled_[m]).data();
    double sum = 0.0;
    for (int i = 0; i < N; ++i) sum += src[i];
    const float mu = static_cast<float>(sum / N);
    float* dst = X_.col(m).data();
    for (int i = 0; i < N; ++i) dst[i] = src[i] - mu;
  });
  ForSampleBlocks(N, [&](int block, int i0, int i1) {
    const auto Xb = X_.middleRows(i0, i1 - i0);
    block_scatter_[block].noalias() = Xb.transpose() * Xb;
  });
  pixel_scatter_.setZero();
  for (int block = 0; block < blocks_; ++block) pixel_scatter_ += block_scatter_[block].cast<double>();
}

// 2. F random unit directions v_f (uniform on the sphere) and the projected
// residuals y_f = ε · v_f, all before the features: ε does not change within a
// fern. Then their scatters and their covariances with the sampled pixels.
void FernCascadeTrainer::ProjectResiduals(Rng& rng) {
  for (int f = 0; f < F; ++f) {
    double norm = 0.0;
    Eigen::VectorXd v(D);
    while (!(norm > 0.0)) {
      for (int d = 0; d < D; ++d) v[d] = rng.Normal();
      norm = v.norm();
    }
    directions_.col(f) = (v / norm).cast<float>();
  }
  ForSampleBlocks(N, [&](int block, int i0, int i1) {
    Y_.middleRows(i0, i1 - i0).noalias() = eps_.middleRows(i0, i1 - i0) * directions_;
    block_vector_[block] = Y_.middleRows(i0, i1 - i0).cast<double>().colwise().sum().transpose();
  });
  Eigen::VectorXd y_sum = Eigen::VectorXd::Zero(F);
  for (int block = 0; block < blocks_; ++block) y_sum += block_vector_[block];
  const Eigen::RowVectorXf y_mean = (y_sum / N).cast<float>().transpose();
  ForSampleBlocks(N, [&](int block, int i0, int i1) {
    Y_.middleRows(i0, i1 - i0).rowwise() -= y_mean;
    block_vector_[block] = Y_.middleRows(i0, i1 - i0).cast<double>().colwise().squaredNorm().transpose();
  });
  target_scatter_.setZero();
  for (int block = 0; block < blocks_; ++block) target_scatter_ += block_vector_[block];
  // Σ_i y_if (p_im − p̄_m) = Σ_i y_if p_im since Σ_i y_if = 0: one pass over the
  // P raw pixel columns for all F directions, parallel over pixels.
  tbb::parallel_for(0, P, [&](int m) {
    double dots[16];  // F ≤ 16
    BlockedDots(patches_.col(sampled_[m]).data(), Y_, dots);
    for (int f = 0; f < F; ++f) target_pixel_scatter_(m, f) = dots[f];
  });
}

// Feature f of fern k: a pixel pair (Cao et al. 2012 selection for direction f,
// or a random pair), its values t_i[a] − t_i[b], a threshold, and bit f of every
// sample's bin.
void FernCascadeTrainer::ChooseFeature(int k, int f, Rng& rng) {
  int a = 0, b = 0;
  if (correlation_) {
    const PixelPair pair = SelectCorrelatedPair(pixel_scatter_, target_pixel_scatter_.col(f), target_scatter_[f]);
    abs_correlation_sum_ += std::abs(pair.correlation);
    a = sampled_[pair.m];
    b = sampled_[pair.n];
  } else {
    const int m = static_cast<int>(rng.UniformInt(static_cast<uint64_t>(P)));
    int m2 = static_cast<int>(rng.UniformInt(static_cast<uint64_t>(P - 1)));
    if (m2 >= m) ++m2;
    a = sampled_[m];
    b = sampled_[m2];
  }

  // Feature values t_i[a] − t_i[b], in float exactly as at evaluation.
  const float* pa = patches_.col(a).data();
  const float* pb = patches_.col(b).data();
  tbb::parallel_for(0, blocks_, [&](int block) {
    const int i0 = block * kSampleBlock, i1 = std::min(N, i0 + kSampleBlock);
    for (int i = i0; i < i1; ++i) feature_[i] = pa[i] - pb[i];
  });
  const float theta = RandomThreshold(rng);
  const size_t idx = static_cast<size_t>(k) * F + f;
  cascade_.pixel_a[idx] = static_cast<uint16_t>(a);
  cascade_.pixel_b[idx] = static_cast<uint16_t>(b);
  cascade_.thresholds[idx] = theta;
  tbb::parallel_for(0, blocks_, [&](int block) {
    const int i0 = block * kSampleBlock, i1 = std::min(N, i0 + kSampleBlock);
    for (int i = i0; i < i1; ++i) bins_[i] |= static_cast<int>(feature_[i] > theta) << f;
  });
}

// 3. Random threshold of the current feature values (Differences from the
// paper, item 1): one sample's value, or uniform in the middle of their range.
float FernCascadeTrainer::RandomThreshold(Rng& rng) const {
  if (sample_threshold_) return feature_[static_cast<int>(rng.UniformInt(static_cast<uint64_t>(N)))];
  const float lo = feature_.minCoeff();
  const float hi = feature_.maxCoeff();
  const double u = rng.Uniform() - 0.5;
  return static_cast<float>(0.5 * (static_cast<double>(lo) + hi) +
                            u * options_.fern_threshold_range * (static_cast<double>(hi) - lo));
}

// 4. Eq. 4 bin outputs, then c_i ← c_i + δc_b and ε_i = ĉ_i − c_i (Eq. 3).
void FernCascadeTrainer::UpdateResiduals(int k) {
  BinSums(bins_, eps_, num_bins, &sums_, &counts_);
  const Eigen::MatrixXf delta = ShrunkOutputs(sums_, counts_, options_.shrinkage);
  for (int bin = 0; bin < num_bins; ++bin) {
    empty_bins_ += counts_[bin] == 0;
    float* dst = cascade_.outputs.data() + (static_cast<size_t>(k) * num_bins + bin) * D;
    for (int d = 0; d < D; ++d) dst[d] = delta(bin, d);
  }
  ForSampleBlocks(N, [&](int, int i0, int i1) {
    for (int i = i0; i < i1; ++i) {
      const float* o = cascade_.BinOutput(k, bins_[i]);
      for (int d = 0; d < D; ++d) {
        c_(i, d) += o[d];
        eps_(i, d) = c_hat_(i, d) - c_(i, d);
      }
    }
  });
}

void FernCascadeTrainer::FinishReport() {
  report_.mean_abs_correlation = correlation_ ? abs_correlation_sum_ / (static_cast<double>(K) * F) : 0.0;
  report_.empty_bin_fraction = static_cast<double>(empty_bins_) / (static_cast<double>(K) * num_bins);
}

}  // namespace

FernTrainingResult TrainFernCascade(const Eigen::MatrixXf& patches, const Eigen::MatrixXf& targets,
                                    const FernOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.Check();
  RequireTrainingInputs(patches, targets, options);
  FernTrainingResult result;
  FernCascadeTrainer trainer(patches, targets, options, &result);
  for (int k = 0; k < options.num_ferns; ++k) trainer.TrainFern(k);
  trainer.FinishReport();
  result.report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

// ---------------------------------------------------------------------------
// Evaluation (Eq. 6)
// ---------------------------------------------------------------------------

int FernCascade::BinIndex(int k, const float* patch) const {
  const int F = depth();
  int b = 0;
  for (int f = 0; f < F; ++f) {
    const size_t idx = static_cast<size_t>(k) * F + f;
    b |= static_cast<int>(patch[pixel_a[idx]] - patch[pixel_b[idx]] > thresholds[idx]) << f;
  }
  return b;
}

void FernCascade::Predict(const float* patch, float* c) const {
  if (dimensions == 16) {
    PredictOne<16>(*this, patch, c);
  } else {
    PredictOne<0>(*this, patch, c);
  }
}

void FernCascade::PredictBatch(const float* patches, int count, float* out) const {
  if (count <= 0) return;
  const int blocks = (count + kBatchBlock - 1) / kBatchBlock;
  const bool avx2 = HasAvx2();
  tbb::parallel_for(tbb::blocked_range<int>(0, blocks, 1), [&](const tbb::blocked_range<int>& range) {
    thread_local BatchScratch scratch;
    scratch.transposed.resize(static_cast<size_t>(patch_pixels) * kRowStride);
    scratch.accumulators.resize(static_cast<size_t>(kBatchBlock) * dimensions);
    scratch.bins.resize(static_cast<size_t>(kFernGroup) * kBatchBlock);
    for (int block = range.begin(); block != range.end(); ++block) {
      const int p0 = block * kBatchBlock;
      const int m = std::min(kBatchBlock, count - p0);
      const float* src = patches + static_cast<size_t>(p0) * patch_pixels;
      float* dst = out + static_cast<size_t>(p0) * dimensions;
      if (avx2) {
        PredictBlockAvx2(*this, src, m, dst, scratch);
      } else {
        PredictBlockGeneric(*this, src, m, dst, scratch);
      }
    }
  });
}

Eigen::MatrixXf FernCascade::PredictMatrix(const Eigen::MatrixXf& patches) const {
  Require(patches.cols() == patch_pixels,
          fmt::format("FernCascade::PredictMatrix: patches have {} pixels, the cascade expects {}", patches.cols(),
                      patch_pixels));
  const RowMatrixXf rows = patches;
  RowMatrixXf result(patches.rows(), dimensions);
  PredictBatch(rows.data(), static_cast<int>(rows.rows()), result.data());
  return result;
}

FernCascade FernCascade::Truncated(int k) const {
  Require(k >= 1 && k <= num_ferns(),
          fmt::format("FernCascade::Truncated: k = {} must be in [1, K = {}]", k, num_ferns()));
  FernCascade t = *this;
  const size_t features = static_cast<size_t>(k) * depth();
  t.options.num_ferns = k;
  t.pixel_a.resize(features);
  t.pixel_b.resize(features);
  t.thresholds.resize(features);
  t.outputs.resize(static_cast<size_t>(k) * num_bins() * dimensions);
  return t;
}

void FernCascade::Check(const std::string& what) const {
  try {
    options.Check();
  } catch (const Error& e) {
    throw Error(fmt::format("{}: {}", what, e.what()));
  }
  Require(patch_pixels >= 2 && patch_pixels <= 65536,
          fmt::format("{}: patch_pixels = {} must be in [2, 65536]", what, patch_pixels));
  Require(dimensions >= 1, fmt::format("{}: dimensions = {} must be >= 1", what, dimensions));
  const size_t features = static_cast<size_t>(num_ferns()) * depth();
  const size_t table = static_cast<size_t>(num_ferns()) * num_bins() * dimensions;
  auto size_is = [&](const char* name, size_t size, size_t expected) {
    Require(size == expected, fmt::format("{}: {} has {} entries, expected {}", what, name, size, expected));
  };
  size_is("mean", mean.size(), static_cast<size_t>(dimensions));
  size_is("pixel_a", pixel_a.size(), features);
  size_is("pixel_b", pixel_b.size(), features);
  size_is("thresholds", thresholds.size(), features);
  size_is("outputs", outputs.size(), table);
  for (size_t i = 0; i < features; ++i) {
    Require(pixel_a[i] < patch_pixels && pixel_b[i] < patch_pixels,
            fmt::format("{}: feature {} (fern {}) has pixel pair ({}, {}) outside the {} patch pixels", what,
                        i, i / depth(), pixel_a[i], pixel_b[i], patch_pixels));
    Require(std::isfinite(thresholds[i]),
            fmt::format("{}: threshold {} (fern {}) is not finite", what, i, i / depth()));
  }
  for (int d = 0; d < dimensions; ++d)
    Require(std::isfinite(mean[d]), fmt::format("{}: mean coefficient {} is not finite", what, d));
  for (size_t i = 0; i < table; ++i)
    Require(std::isfinite(outputs[i]),
            fmt::format("{}: bin output entry {} (fern {}) is not finite", what, i,
                        i / (static_cast<size_t>(num_bins()) * dimensions)));
}

void NormalizeTexturePatch(float* patch, int n, TextureNormalization mode) {
  if (mode == TextureNormalization::kNone || n <= 0) return;
  double sum = 0.0;
  for (int i = 0; i < n; ++i) sum += patch[i];
  const double mean = sum / n;
  double scale = mean, offset = 0.0;
  if (mode == TextureNormalization::kStandardize) {
    double ss = 0.0;
    for (int i = 0; i < n; ++i) ss += (patch[i] - mean) * (patch[i] - mean);
    scale = std::sqrt(ss / n);
    offset = mean;
  }
  if (!(std::abs(scale) >= 1e-6)) {
    std::fill(patch, patch + n, 0.0f);
    return;
  }
  for (int i = 0; i < n; ++i) patch[i] = static_cast<float>((patch[i] - offset) / scale);
}

Eigen::MatrixXf NormalizeTexturePatches(const Eigen::MatrixXf& patches, TextureNormalization mode) {
  using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  RowMatrixXf rows = patches;
  const int n = static_cast<int>(rows.cols());
  for (Eigen::Index i = 0; i < rows.rows(); ++i) NormalizeTexturePatch(rows.row(i).data(), n, mode);
  return rows;
}

}  // namespace crease
