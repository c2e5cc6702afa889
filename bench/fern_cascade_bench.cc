// Fern cascade (paper Sec. 4.3 / 5.2): evaluation of Eq. 6 per patch and training
// time. Evaluation cost does not depend on the table values, so the evaluated
// cascades are built directly with random pairs, thresholds and bin outputs
// (F = 5, D = 16, w = 32 as in the paper), for K = 1280 / 640 / 320.
//   BM_PredictBatch/K/threads — PredictBatch on 600 patches (a frame's worth),
//                               us_per_patch = wall time per patch
//   BM_PredictSingle/K        — Predict, one patch at a time, one thread
//   BM_PredictBatchGeneric/K  — PredictBatch with the generic (SSE2) kernel, one thread
//   BM_Train/N/threads        — TrainFernCascade with the paper's K, F, P, β on N
//                               random 32×32 patches (D = 16)
//   BM_FitPatchPca/N/threads  — FitPatchPca on N 32×32 patches (D = 16)
// Run e.g.
//   build/bench/fern_cascade_bench --benchmark_min_time=0.2 --benchmark_out=fern.json --benchmark_out_format=json
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <map>
#include <vector>

#include "core/rng.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/pca.h"

namespace crease {
namespace {

constexpr int kPatchSize = 32;  // w, Sec. 4.2
constexpr int kPixels = kPatchSize * kPatchSize;
constexpr int kDimensions = 16;  // D, Sec. 4.3
constexpr int kBatch = 600;      // patches per frame

FernCascade RandomCascade(int K) {
  Rng rng(static_cast<uint64_t>(K));
  FernCascade fc;
  fc.options.num_ferns = K;
  fc.options.fern_depth = 5;
  fc.patch_pixels = kPixels;
  fc.dimensions = kDimensions;
  fc.mean.assign(kDimensions, 0.f);
  const size_t features = static_cast<size_t>(K) * fc.depth();
  for (size_t i = 0; i < features; ++i) {
    fc.pixel_a.push_back(static_cast<uint16_t>(rng.UniformInt(kPixels)));
    fc.pixel_b.push_back(static_cast<uint16_t>(rng.UniformInt(kPixels)));
    fc.thresholds.push_back(static_cast<float>(rng.Uniform(-0.3, 0.3)));
  }
  fc.outputs.resize(static_cast<size_t>(K) * fc.num_bins() * kDimensions);
  for (float& v : fc.outputs) v = static_cast<float>(rng.Normal(0.0, 1e-3));
  fc.Check("bench cascade");
  return fc;
}

const FernCascade& Cascade(int K) {
  static std::map<int, FernCascade> cache;
  auto it = cache.find(K);
  if (it == cache.end()) it = cache.emplace(K, RandomCascade(K)).first;
  return it->second;
}

const std::vector<float>& Patches() {
  static const std::vector<float> patches = [] {
    Rng rng(99);
    std::vector<float> p(static_cast<size_t>(kBatch) * kPixels);
    for (float& v : p) v = static_cast<float>(rng.Uniform());
    return p;
  }();
  return patches;
}

void SetPerPatch(benchmark::State& state, int64_t patches) {
  state.SetItemsProcessed(state.iterations() * patches);
  state.counters["us_per_patch"] =
      benchmark::Counter(static_cast<double>(state.iterations() * patches) * 1e-6,
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_PredictBatch(benchmark::State& state) {
  const FernCascade& fc = Cascade(static_cast<int>(state.range(0)));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(1)));
  const std::vector<float>& patches = Patches();
  std::vector<float> out(static_cast<size_t>(kBatch) * kDimensions);
  for (auto _ : state) {
    fc.PredictBatch(patches.data(), kBatch, out.data());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  SetPerPatch(state, kBatch);
  state.counters["table_MB"] = static_cast<double>(fc.outputs.size() * sizeof(float)) / 1e6;
}
BENCHMARK(BM_PredictBatch)->ArgNames({"K", "threads"})->ArgsProduct({{1280, 640, 320}, {1, 2}})
    ->Unit(benchmark::kMicrosecond)->UseRealTime();

// The same with the generic (SSE2) kernel instead of the AVX2 one, one thread.
void BM_PredictBatchGeneric(benchmark::State& state) {
  const FernCascade& fc = Cascade(static_cast<int>(state.range(0)));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
  const std::vector<float>& patches = Patches();
  std::vector<float> out(static_cast<size_t>(kBatch) * kDimensions);
  internal::SetFernAvx2Allowed(false);
  for (auto _ : state) {
    fc.PredictBatch(patches.data(), kBatch, out.data());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  internal::SetFernAvx2Allowed(true);
  SetPerPatch(state, kBatch);
}
BENCHMARK(BM_PredictBatchGeneric)->ArgName("K")->Arg(1280)->Unit(benchmark::kMicrosecond)->UseRealTime();

void BM_PredictSingle(benchmark::State& state) {
  const FernCascade& fc = Cascade(static_cast<int>(state.range(0)));
  const std::vector<float>& patches = Patches();
  std::vector<float> out(static_cast<size_t>(kBatch) * kDimensions);
  for (auto _ : state) {
    for (int p = 0; p < kBatch; ++p)
      fc.Predict(patches.data() + static_cast<size_t>(p) * kPixels, out.data() + static_cast<size_t>(p) * kDimensions);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  SetPerPatch(state, kBatch);
}
BENCHMARK(BM_PredictSingle)->ArgName("K")->Arg(1280)->Arg(320)->Unit(benchmark::kMicrosecond)->UseRealTime();

// Random patches with targets that depend on pixel differences (so the correlation
// search and the bins do real work).
void BM_Train(benchmark::State& state) {
  const int N = static_cast<int>(state.range(0));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(1)));
  Rng rng(5);
  Eigen::MatrixXf patches(N, kPixels);
  for (int j = 0; j < kPixels; ++j)
    for (int i = 0; i < N; ++i) patches(i, j) = static_cast<float>(rng.Uniform());
  Eigen::MatrixXf targets(N, kDimensions);
  for (int i = 0; i < N; ++i)
    for (int d = 0; d < kDimensions; ++d)
      targets(i, d) = patches(i, 31 * d + 7) - patches(i, 1000 - 29 * d) + 0.1f * static_cast<float>(rng.Normal());
  FernOptions options;  // the paper's K = 1280, F = 5, P = 50, β = 1000
  double rmse_ratio = 0.0;
  for (auto _ : state) {
    const FernTrainingResult result = TrainFernCascade(patches, targets, options);
    rmse_ratio = result.report.train_rmse.back() / result.report.train_rmse.front();
    benchmark::DoNotOptimize(result.cascade.outputs.data());
  }
  state.counters["final_over_initial_rmse"] = rmse_ratio;
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(N));
}
BENCHMARK(BM_Train)->ArgNames({"N", "threads"})->Args({20000, 1})->Args({20000, 2})
    ->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

// PCA of N displacement patches of 32×32 (Sec. 4.3): 1024 × 1024 covariance in
// double and its eigen decomposition.
void BM_FitPatchPca(benchmark::State& state) {
  const int N = static_cast<int>(state.range(0));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(1)));
  Rng rng(6);
  Eigen::MatrixXf patches(N, kPixels);
  for (int j = 0; j < kPixels; ++j)
    for (int i = 0; i < N; ++i) patches(i, j) = static_cast<float>(rng.Normal());
  double energy16 = 0.0;
  for (auto _ : state) {
    const PatchPca pca = FitPatchPca(patches, PcaOptions{});
    energy16 = pca.energy[15];
    benchmark::DoNotOptimize(pca.basis.data());
  }
  state.counters["energy_16"] = energy16;
}
BENCHMARK(BM_FitPatchPca)->ArgNames({"N", "threads"})->Args({20000, 1})->Args({20000, 2})
    ->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

}  // namespace
}  // namespace crease
