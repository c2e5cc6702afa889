// The global tracker per frame at 640×480 (issue 5: ≥ 100 frames/s when the face is
// not lost, landmarks + rig fit; detection stated separately). A studio frame of a
// talking actor is tracked over and over (steady state: the identity phase is run
// first). Run e.g.
//   build/bench/tracker_bench --benchmark_min_time=1
//   CREASE_TRACKER_MODEL=tracker.ctrk build/bench/tracker_bench   # also the regressor
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "pipeline/capture/shape_regressor.h"
#include "pipeline/capture/tracker.h"
#include "synth/procedural_rig.h"
#include "synth/studio.h"

namespace crease {
namespace {

struct Scene {
  FaceRig rig = BuildProceduralRig();
  cv::Mat frame;
  CameraIntrinsics intrinsics;
  Scene() {
    ActorOptions ao;
    ao.resolution = 256;
    ao.surface_min_vertices = 1000;
    StudioOptions so;
    so.samples_per_axis = 1;
    const Studio studio(rig, GenerateActor(rig, 21, ao), so);
    Eigen::VectorXd e = Eigen::VectorXd::Zero(rig.num_expressions());
    e[rig.ExpressionIndex("jawOpen")] = 0.2;
    frame = studio.RenderStill(e, SequenceFrame{}, nullptr, nullptr, 1).image.decoded;
    intrinsics = studio.camera().intrinsics;
  }
};

const Scene& TheScene() {
  static const Scene scene;
  return scene;
}

void RunTracker(benchmark::State& state, std::unique_ptr<LandmarkSource> source, const TrackerOptions& options) {
  const Scene& s = TheScene();
  FaceTracker tracker(s.rig, s.intrinsics, std::move(source), options);
  for (int i = 0; i < 25; ++i) tracker.Track(s.frame);  // detection + identity phase
  double landmarks_ms = 0, fit_ms = 0;
  int64_t n = 0, lost = 0;
  for (auto _ : state) {
    const TrackedFrame t = tracker.Track(s.frame);
    landmarks_ms += t.landmarks_ms;
    fit_ms += t.fit_ms;
    lost += !t.tracked;
    ++n;
  }
  state.counters["landmarks_ms"] = landmarks_ms / n;
  state.counters["fit_ms"] = fit_ms / n;
  state.counters["lost"] = static_cast<double>(lost);
  state.counters["fps"] = benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsRate);
}

void BM_TrackDlib(benchmark::State& state) {
  TrackerOptions o;
  o.dlib.redetect_interval = static_cast<int>(state.range(0));
  RunTracker(state, std::make_unique<DlibLandmarkSource>(o.dlib), o);
}
// 0: no periodic verification (landmarks + fit only); 30: the default.
BENCHMARK(BM_TrackDlib)->Arg(0)->Arg(30)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_TrackRegressor(benchmark::State& state) {
  const char* path = std::getenv("CREASE_TRACKER_MODEL");
  if (!path) {
    state.SkipWithError("set CREASE_TRACKER_MODEL to a model from `crease train-tracker`");
    return;
  }
  TrackerOptions o;
  o.landmark_source = LandmarkSourceKind::kRegressor;
  o.tracker_model = path;
  RunTracker(state, MakeLandmarkSource(o), o);
}
BENCHMARK(BM_TrackRegressor)->Unit(benchmark::kMillisecond)->UseRealTime();

// Detection alone (start and recovery).
void BM_DetectDlib(benchmark::State& state) {
  const Scene& s = TheScene();
  const DlibLandmarkSource source;
  for (auto _ : state) benchmark::DoNotOptimize(source.Detect(s.frame).size());
}
BENCHMARK(BM_DetectDlib)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
