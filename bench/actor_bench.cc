// Synthetic actor: building one frame's ground truth (coarse rig surface,
// expression wrinkle map, ≥ 250k-vertex hi-res surface) must take ≤ 0.2 s
// (issue 3, Speed). The second argument is ActorOptions::subdivision_levels (0: the
// Phong-tessellated coarse facets, 3: the rig's Loop subdivision surface). Run:
//   build/bench/actor_bench --benchmark_repetitions=5 --benchmark_out=actor.json --benchmark_out_format=json
#include <benchmark/benchmark.h>

#include <filesystem>
#include <map>
#include <memory>
#include <utility>

#include "core/rig_import.h"
#include "synth/actor.h"

namespace crease {
namespace {

const FaceRig& SampleRig() {
  static const FaceRig rig = [] {
    RigImportOptions opt;
    opt.units_to_mm = 10.0;
    return ImportObjRig(std::filesystem::path(CREASE_DATA_DIR) / "sample_rig", opt);
  }();
  return rig;
}

const ActorModel& Model(int resolution, int subdivision_levels) {
  static std::map<std::pair<int, int>, std::unique_ptr<ActorModel>> models;
  auto& m = models[{resolution, subdivision_levels}];
  if (!m) {
    ActorOptions opt;
    opt.resolution = resolution;
    opt.subdivision_levels = subdivision_levels;
    opt.age_min = 0.7;
    m = std::make_unique<ActorModel>(SampleRig(), GenerateActor(SampleRig(), 5, opt));
  }
  return *m;
}

Eigen::VectorXd Smile(const FaceRig& rig, double w) {
  Eigen::VectorXd e = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const char* name : {"mouthSmile_L", "mouthSmile_R", "browInnerUp"}) {
    const int k = rig.ExpressionIndex(name);
    if (k >= 0) e[k] = w;
  }
  return e;
}

// Full frame: coarse surface, wrinkle map, hi-res surface.
void BM_ActorFrame(benchmark::State& state) {
  const ActorModel& model = Model(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  int k = 0;
  for (auto _ : state) {
    const ActorFrame f = model.Frame(Smile(model.rig(), 0.5 + 0.5 * ((k++) % 2)));
    benchmark::DoNotOptimize(f.hires.V.data());
  }
  state.counters["hires_vertices"] = model.layout().num_vertices();
  state.counters["hires_faces"] = model.layout().num_faces();
  state.counters["wrinkle_samples"] = static_cast<double>(model.wrinkles().samples().size());
}
BENCHMARK(BM_ActorFrame)->Args({1024, 0})->Args({1024, 3})->Unit(benchmark::kMillisecond)->UseRealTime();

// Ground-truth maps only (no hi-res mesh): what a dataset writer needs per frame.
void BM_ActorFrameMapsOnly(benchmark::State& state) {
  const ActorModel& model = Model(static_cast<int>(state.range(0)), 0);
  for (auto _ : state) {
    const ActorFrame f = model.Frame(Smile(model.rig(), 0.8), false);
    benchmark::DoNotOptimize(f.expression_displacement.data);
  }
}
BENCHMARK(BM_ActorFrameMapsOnly)->Arg(1024)->Unit(benchmark::kMillisecond)->UseRealTime();

// Per-actor precomputation (layout, strain raster, wrinkle footprints, maps).
void BM_ActorModel(benchmark::State& state) {
  ActorOptions opt;
  opt.resolution = static_cast<int>(state.range(0));
  opt.subdivision_levels = static_cast<int>(state.range(1));
  const Actor actor = GenerateActor(SampleRig(), 5, opt);
  for (auto _ : state) {
    ActorModel model(SampleRig(), actor);
    benchmark::DoNotOptimize(&model);
  }
}
BENCHMARK(BM_ActorModel)->Args({1024, 0})->Args({1024, 3})->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

}  // namespace
}  // namespace crease
