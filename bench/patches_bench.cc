// Wrinkle map and local wrinkle patches at the paper's map size (1024², Sec. 4.2):
// the wrinkle map from 5 textures (capture builds it from the first N frames,
// Sec. 5.2), the greedy patch placement, and the per-frame work of capture —
// sampling every patch of the layout from a 1024² texture and merging the
// regressed patches back into a displacement map (Sec. 5.2). The textures are
// synthetic: 0.5 gray with 40 dark arcs (σ 2–5 texels) inside a disc-shaped
// coverage, so the layout has several hundred patches. Argument: TBB threads.
// Run e.g.
//   build/bench/patches_bench --benchmark_out=patches.json --benchmark_out_format=json
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numbers>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/rng.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/wrinkle_map.h"

namespace crease {
namespace {

constexpr int kMapSize = 1024;
constexpr int kTextures = 5;

struct Data {
  cv::Mat coverage;
  std::vector<cv::Mat> textures;
  WrinkleMap map;
  PatchLayout layout;
};

WrinkleMapOptions Options() {
  WrinkleMapOptions o;
  o.patch_regions.clear();  // no rig here: the whole coverage is searched
  return o;
}

const Data& GetData() {
  static const Data data = [] {
    Data d;
    d.coverage = cv::Mat(kMapSize, kMapSize, CV_8U, cv::Scalar(0));
    cv::circle(d.coverage, cv::Point(512, 512), 480, cv::Scalar(255), cv::FILLED);
    Rng rng(42);
    struct Arc {
      double cx, cy, r, a0, a1, sigma, depth;
    };
    std::vector<Arc> arcs;
    for (int i = 0; i < 40; ++i) {
      const double a0 = rng.Uniform(0, 2 * std::numbers::pi);
      arcs.push_back({rng.Uniform(200, 824), rng.Uniform(200, 824), rng.Uniform(60, 300), a0,
                      a0 + rng.Uniform(0.3, 1.2), rng.Uniform(2, 5), rng.Uniform(0.05, 0.2)});
    }
    for (int j = 0; j < kTextures; ++j) {
      cv::Mat t(kMapSize, kMapSize, CV_32F, cv::Scalar(0.5));
      for (size_t i = 0; i < arcs.size(); ++i) {
        if ((i + j) % 3 == 0) continue;  // each expression shows about two thirds of the wrinkles
        const Arc& a = arcs[i];
        const int x0 = std::max(0, static_cast<int>(a.cx - a.r - 20)), x1 = std::min(kMapSize, static_cast<int>(a.cx + a.r + 20));
        const int y0 = std::max(0, static_cast<int>(a.cy - a.r - 20)), y1 = std::min(kMapSize, static_cast<int>(a.cy + a.r + 20));
        for (int y = y0; y < y1; ++y) {
          float* row = t.ptr<float>(y);
          for (int x = x0; x < x1; ++x) {
            double ang = std::atan2(y - a.cy, x - a.cx);
            while (ang < a.a0) ang += 2 * std::numbers::pi;
            if (ang > a.a1) continue;
            const double dist = std::hypot(x - a.cx, y - a.cy) - a.r;
            row[x] -= static_cast<float>(a.depth * std::exp(-dist * dist / (2 * a.sigma * a.sigma)));
          }
        }
      }
      d.textures.push_back(t);
    }
    d.map = ComputeWrinkleMap(d.textures, d.coverage, {}, Options());
    d.layout = PlacePatches(d.map, PatchLayoutOptions());
    return d;
  }();
  return data;
}

void BM_WrinkleMap(benchmark::State& state) {
  const Data& d = GetData();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
  for (auto _ : state) {
    WrinkleMap map = ComputeWrinkleMap(d.textures, d.coverage, {}, Options());
    benchmark::DoNotOptimize(map.probability.data);
  }
  state.counters["textures"] = kTextures;
}
BENCHMARK(BM_WrinkleMap)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PlacePatches(benchmark::State& state) {
  const Data& d = GetData();
  PatchLayoutReport report;
  for (auto _ : state) {
    PatchLayout layout = PlacePatches(d.map, PatchLayoutOptions(), &report);
    benchmark::DoNotOptimize(layout.patches.data());
  }
  state.counters["patches"] = report.placed;
  state.counters["candidates"] = report.candidates;
}
BENCHMARK(BM_PlacePatches)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PatchSamplerBuild(benchmark::State& state) {
  const Data& d = GetData();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
  for (auto _ : state) {
    PatchSampler sampler(d.layout);
    benchmark::DoNotOptimize(&sampler);
  }
  state.counters["patches"] = d.layout.num_patches();
}
BENCHMARK(BM_PatchSamplerBuild)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SamplePatches(benchmark::State& state) {
  const Data& d = GetData();
  const PatchSampler sampler(d.layout);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
  Eigen::MatrixXf patches;
  for (auto _ : state) {
    sampler.Sample(d.textures[0], &patches);
    benchmark::DoNotOptimize(patches.data());
  }
  state.SetItemsProcessed(state.iterations() * patches.size());  // samples
  state.counters["patches"] = d.layout.num_patches();
}
BENCHMARK(BM_SamplePatches)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SplatPatches(benchmark::State& state) {
  const Data& d = GetData();
  const PatchSampler sampler(d.layout);
  const Eigen::MatrixXf patches = sampler.Sample(d.textures[0]);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
  for (auto _ : state) {
    cv::Mat map = sampler.Splat(patches);
    benchmark::DoNotOptimize(map.data);
  }
  state.SetItemsProcessed(state.iterations() * patches.size());  // samples
  state.counters["patches"] = d.layout.num_patches();
}
BENCHMARK(BM_SplatPatches)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
