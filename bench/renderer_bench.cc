// Studio renderer (synth/renderer.h) on a bumpy latitude-longitude sphere of
// 1,046,528 triangles (radius 100 mm, 512 rings × 1024 segments) with 512² skin
// maps, seen by a 640×480 camera 400 mm away. First argument: TBB threads
// (tbb::global_control). Counters: frames_per_s, rays_per_s (primary + shadow).
//   fast    1 sample per pixel (pixel centre), one directional light, one shadow
//           ray per hit: the "≥ 10 frames/s on 2 cores" setting; with the
//           refittable BVH (dynamic = 1, the default) and a static one (0)
//   studio  2×2 supersampling, the "studio" rig (two sphere lights × 8 samples,
//           directional rim, ambient occlusion × 4) plus an environment light
//           (8 samples) and the screen-space subsurface blur
//   refit   UpdateGeometry (refit + normals) alone, and refit followed by a fast frame
// Run e.g.
//   build/bench/renderer_bench --benchmark_out=render.json --benchmark_out_format=json
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cmath>
#include <memory>

#include "core/mesh_primitives.h"
#include "synth/renderer.h"

namespace crease {
namespace {

constexpr double kRadius = 100.0;  // mm

MatX3d Bumpy(const TriMesh& m, double phase) {
  MatX3d V = m.V;
  for (int i = 0; i < m.num_vertices(); ++i) {
    const Eigen::Vector3d n = m.V.row(i).normalized();
    const double bump = 2.0 * std::sin(23.0 * n.x() + phase) * std::cos(19.0 * n.y()) * std::sin(17.0 * n.z());
    V.row(i) = (kRadius + bump) * n.transpose();
  }
  return V;
}

struct Scene {
  TriMesh mesh;
  MatX3d V_other;  // a second frame for the refit benchmarks
  std::unique_ptr<Renderer> renderer;
  Camera camera;
};

// `dynamic`: refittable BVH (the default; RendererOptions::dynamic) or a static one.
Scene& GetScene(bool dynamic = true) {
  static Scene scenes[2];
  Scene& scene = scenes[dynamic ? 1 : 0];
  if (!scene.renderer) {
    Scene& s = scene;
    s.mesh = MakeUVSphere(kRadius, 512, 1024);
    s.V_other = Bumpy(s.mesh, 0.7);
    s.mesh.V = Bumpy(s.mesh, 0.0);
    SceneMaterials m;
    m.albedo = cv::Mat(512, 512, CV_32FC3, cv::Scalar(0.6f, 0.42f, 0.34f));
    m.specular = cv::Mat(512, 512, CV_32FC1, cv::Scalar(0.5f));
    m.roughness = cv::Mat(512, 512, CV_32FC1, cv::Scalar(0.45f));
    RendererOptions options;
    options.dynamic = dynamic;
    s.renderer = std::make_unique<Renderer>(s.mesh, m, options);
    s.camera = LookAtCamera(CameraIntrinsics::FromFov(40.0, 640, 480), Eigen::Vector3d(0, 0, 400),
                            Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  }
  return scene;
}

tbb::global_control Threads(const benchmark::State& state) {
  return tbb::global_control(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
}

LightRig FastRig() {
  LightRig rig;
  rig.name = "one-directional";
  rig.lights = {DirectionalFromAzimuthElevation(-30.0, 30.0, 0.9)};
  return rig;
}

LightRig StudioRig() {
  LightRig rig = MakeLightRig("studio");
  EnvironmentLight env;
  env.map = ProceduralEnvironment("overcast");
  env.scale = 0.2;
  env.samples = 8;
  rig.lights.push_back(env);
  return rig;
}

void Report(benchmark::State& state, int64_t rays) {
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["rays_per_s"] = benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsRate);
}

void BM_FastFrame(benchmark::State& state) {
  Scene& s = GetScene(state.range(1) != 0);
  const auto limit = Threads(state);
  const LightRig rig = FastRig();
  int64_t rays = 0;
  for (auto _ : state) {
    Rng rng(1);
    const RenderResult r = s.renderer->Render(s.camera, rig, RenderOptions{}, rng);
    rays += r.stats.primary_rays + r.stats.shadow_rays;
    benchmark::DoNotOptimize(r.image.data);
  }
  Report(state, rays);
}
BENCHMARK(BM_FastFrame)->ArgNames({"threads", "dynamic"})->ArgsProduct({{1, 2}, {1, 0}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_StudioFrame(benchmark::State& state) {
  Scene& s = GetScene();
  const auto limit = Threads(state);
  const LightRig rig = StudioRig();
  RenderOptions options;
  options.samples_per_axis = 2;
  options.subsurface_mm = 1.0;
  int64_t rays = 0;
  for (auto _ : state) {
    Rng rng(1);
    const RenderResult r = s.renderer->Render(s.camera, rig, options, rng);
    rays += r.stats.primary_rays + r.stats.shadow_rays;
    benchmark::DoNotOptimize(r.image.data);
  }
  Report(state, rays);
}
BENCHMARK(BM_StudioFrame)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()
    ->Iterations(2);

void BM_Refit(benchmark::State& state) {
  Scene& s = GetScene();
  const auto limit = Threads(state);
  bool flip = false;
  for (auto _ : state) {
    s.renderer->UpdateGeometry(flip ? s.mesh.V : s.V_other);
    flip = !flip;
  }
  s.renderer->UpdateGeometry(s.mesh.V);
}
BENCHMARK(BM_Refit)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RefitAndFastFrame(benchmark::State& state) {
  Scene& s = GetScene();
  const auto limit = Threads(state);
  const LightRig rig = FastRig();
  bool flip = false;
  int64_t rays = 0;
  for (auto _ : state) {
    s.renderer->UpdateGeometry(flip ? s.mesh.V : s.V_other);
    flip = !flip;
    Rng rng(1);
    const RenderResult r = s.renderer->Render(s.camera, rig, RenderOptions{}, rng);
    rays += r.stats.primary_rays + r.stats.shadow_rays;
    benchmark::DoNotOptimize(r.image.data);
  }
  s.renderer->UpdateGeometry(s.mesh.V);
  Report(state, rays);
}
BENCHMARK(BM_RefitAndFastFrame)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
