// Landmark regressor (pipeline/capture/shape_regressor.h, issue 5 part 1): the
// per-frame cost of Predict on a 640×480 frame, the budget being ≤ 2 ms so the
// tracker runs ≥ 100 fps including the rig fit. Predict's cost does not depend on
// the table values, so the regressor is built directly with random pixels, pairs,
// thresholds and bin outputs (T stages, K ferns, F = 5, P = 400, 68 landmarks).
//   BM_PredictColdBins/T/K — another image every call (bins not in cache)
//   BM_Predict/T/K/input — one Predict from the previous frame's shape, one thread;
//                          input 0 = linear float RGB (what the studio and the tracker
//                          pass), 1 = 8-bit sRGB RGB (a camera file)
// Run e.g.
//   build/bench/shape_regressor_bench --benchmark_repetitions=5 --benchmark_out=reg.json --benchmark_out_format=json
#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>

#include <opencv2/core.hpp>

#include "core/rng.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease {
namespace {

ShapeRegressor RandomRegressor(int T, int K) {
  Rng rng(static_cast<uint64_t>(T * 1000 + K));
  ShapeRegressor r;
  r.options.num_stages = T;
  r.options.num_ferns = K;
  r.num_landmarks = 68;
  r.mean_shape.resize(68, 2);
  for (int i = 0; i < 68; ++i) {
    const double a = 2 * std::numbers::pi * i / 68.0;
    r.mean_shape.row(i) << 1.2 * std::cos(a), 1.5 * std::sin(a);
  }
  const int P = r.num_pixels(), F = r.depth(), B = 1 << F;
  for (int i = 0; i < T * P; ++i) {
    r.pixel_landmark.push_back(static_cast<uint16_t>(rng.UniformInt(68)));
    r.pixel_offset.push_back(static_cast<float>(rng.Uniform(-0.3, 0.3)));
    r.pixel_offset.push_back(static_cast<float>(rng.Uniform(-0.3, 0.3)));
  }
  for (int i = 0; i < T * K * F; ++i) {
    r.fern_pixel_a.push_back(static_cast<uint16_t>(rng.UniformInt(static_cast<uint64_t>(P))));
    r.fern_pixel_b.push_back(static_cast<uint16_t>(rng.UniformInt(static_cast<uint64_t>(P))));
    r.fern_threshold.push_back(static_cast<float>(rng.Normal(0, 0.05)));
  }
  r.fern_output.resize(static_cast<size_t>(T) * K * B * 136);
  for (float& v : r.fern_output) v = static_cast<float>(rng.Normal(0, 1e-4));
  r.Check();
  return r;
}

void BM_Predict(benchmark::State& state) {
  const ShapeRegressor r = RandomRegressor(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  cv::Mat image(480, 640, CV_32FC3);
  cv::randu(image, 0.0f, 1.0f);
  if (state.range(2) == 1) image.convertTo(image, CV_8UC3, 255.0);
  const MatX2d init = r.MeanShapeInBox(FaceBox{200, 120, 240, 240, 0});
  for (auto _ : state) benchmark::DoNotOptimize(r.Predict(image, init));
}
BENCHMARK(BM_Predict)
    ->ArgNames({"T", "K", "input"})
    ->Args({10, 100, 0})  // the defaults
    ->Args({10, 100, 1})
    ->Args({10, 200, 0})
    ->Args({10, 500, 0})  // ESR's K
    ->Args({5, 100, 0})
    ->Unit(benchmark::kMicrosecond);

// Worst case for the bin tables: every call sees another image (and shape), so the
// K·T bins it reads are rarely in cache (a tracker's consecutive frames mostly hit
// the same bins). Cycles over 64 random images and shifted initial shapes.
void BM_PredictColdBins(benchmark::State& state) {
  const ShapeRegressor r = RandomRegressor(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  std::vector<cv::Mat> images(64);
  std::vector<MatX2d> inits(64);
  for (int i = 0; i < 64; ++i) {
    images[i].create(480, 640, CV_32FC3);
    cv::randu(images[i], 0.0f, 1.0f);
    inits[i] = r.MeanShapeInBox(FaceBox{150.0 + i, 100.0 + i, 240, 240, 0});
  }
  size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(r.Predict(images[i % 64], inits[i % 64]));
    ++i;
  }
}
BENCHMARK(BM_PredictColdBins)->ArgNames({"T", "K"})->Args({10, 100})->Args({10, 200})->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace crease
