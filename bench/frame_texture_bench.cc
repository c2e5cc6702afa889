// Per-frame texture T^t (Sec. 5.1), the mesoscopic map D^HF and the
// high-fidelity mesh H^t (Sec. 5.3) on a 640×480 frame of the procedural rig
// (face ~250 px wide, 450 mm from the camera). Targets: Extract at R = 1024
// ≤ 5 ms, VisibleVertices ≤ 2 ms, HifiMeshBuilder::Build at 512 ≤ 5 ms. Run e.g.
//   build/bench/frame_texture_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <tbb/global_control.h>

#include "core/mesh_ops.h"
#include "pipeline/capture/frame_texture.h"
#include "pipeline/capture/hifi_mesh.h"
#include "synth/procedural_rig.h"
#include "synth/renderer.h"

namespace crease {
namespace {

struct Scene {
  FaceRig rig = BuildProceduralRig();
  Camera camera;
  MatX3d cam_vertices;
  cv::Mat image;
  Scene() {
    const MatX3i F = FaceChartTriangles(rig);
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int f = 0; f < F.rows(); ++f) c += rig.neutral.V.row(F(f, 0)).transpose();
    c /= F.rows();
    camera = LookAtCamera(CameraIntrinsics::FromFov(50.0, 640, 480), c + Eigen::Vector3d(0, 0, 450), c,
                          Eigen::Vector3d::UnitY());
    cam_vertices.resize(rig.num_vertices(), 3);
    for (int v = 0; v < rig.num_vertices(); ++v) {
      cam_vertices.row(v) = (camera.cam_from_head * Eigen::Vector3d(rig.neutral.V.row(v).transpose())).transpose();
    }
    TriMesh mesh = rig.neutral;
    Renderer renderer(mesh, SceneMaterials{});
    RenderOptions ro;
    Rng rng(1);
    image = renderer.Render(camera, MakeLightRig("front"), ro, rng).image;
  }
};

const Scene& TheScene() {
  static const Scene scene;
  return scene;
}

// Argument: TBB threads (1 or 2).
std::unique_ptr<tbb::global_control> Threads(const benchmark::State& state) {
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               static_cast<size_t>(state.range(0)));
}

const FrameTextureExtractor& Extractor() {
  static const FrameTextureExtractor ex(TheScene().rig, TheScene().camera.intrinsics, FrameTextureOptions{});
  return ex;
}

void BM_DepthBuffer(benchmark::State& state) {
  const auto threads = Threads(state);
  const Scene& s = TheScene();
  for (auto _ : state) benchmark::DoNotOptimize(Extractor().DepthBuffer(s.cam_vertices));
}
BENCHMARK(BM_DepthBuffer)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_VisibleVertices(benchmark::State& state) {
  const auto threads = Threads(state);
  const Scene& s = TheScene();
  for (auto _ : state) benchmark::DoNotOptimize(Extractor().VisibleVertices(s.cam_vertices));
}
BENCHMARK(BM_VisibleVertices)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// A fresh FrameTexture per frame (allocates 5 MB).
void BM_Extract(benchmark::State& state) {
  const auto threads = Threads(state);
  const Scene& s = TheScene();
  int seen = 0;
  for (auto _ : state) {
    const FrameTexture t = Extractor().Extract(s.cam_vertices, s.image);
    seen = t.num_seen;
    benchmark::DoNotOptimize(t.gray.data);
  }
  state.counters["seen_texels"] = seen;
}
BENCHMARK(BM_Extract)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// The capture loop's form: one FrameTexture reused.
void BM_ExtractReuse(benchmark::State& state) {
  const auto threads = Threads(state);
  const Scene& s = TheScene();
  FrameTexture t;
  for (auto _ : state) {
    Extractor().Extract(s.cam_vertices, s.image, &t);
    benchmark::DoNotOptimize(t.gray.data);
  }
}
BENCHMARK(BM_ExtractReuse)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// Difference 4 of frame_texture.h: the blend with the previous frames (temporal_weight).
void BM_BlendTextureHistory(benchmark::State& state) {
  const auto threads = Threads(state);
  const FrameTexture first = Extractor().Extract(TheScene().cam_vertices, TheScene().image);
  FrameTexture history, t = first;
  BlendTextureHistory(0.5, &t, &history);
  for (auto _ : state) {
    first.gray.copyTo(t.gray);  // the extraction's output, as the capture loop hands it over
    BlendTextureHistory(0.5, &t, &history);
    benchmark::DoNotOptimize(t.gray.data);
  }
}
BENCHMARK(BM_BlendTextureHistory)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_MesoscopicMap(benchmark::State& state) {
  const auto threads = Threads(state);
  const FrameTexture t = Extractor().Extract(TheScene().cam_vertices, TheScene().image);
  for (auto _ : state) benchmark::DoNotOptimize(MesoscopicMap(t.gray, t.seen, MesoscopicOptions{}));
}
BENCHMARK(BM_MesoscopicMap)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

const HifiMeshBuilder& Hifi() {
  static const HifiMeshBuilder b(TheScene().rig, HifiMeshOptions{});
  return b;
}

void BM_HifiBuild(benchmark::State& state) {
  const auto threads = Threads(state);
  const cv::Mat D(1024, 1024, CV_32F, cv::Scalar(0.1f));
  const MatX3d& V = TheScene().cam_vertices;  // built outside the timed loop
  const HifiMeshBuilder& b = Hifi();
  for (auto _ : state) benchmark::DoNotOptimize(b.Build(V, D));
  state.counters["vertices"] = Hifi().num_vertices();
  state.counters["triangles"] = Hifi().num_triangles();
}
BENCHMARK(BM_HifiBuild)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_HifiBuildInto(benchmark::State& state) {
  const auto threads = Threads(state);
  const cv::Mat D(1024, 1024, CV_32F, cv::Scalar(0.1f));
  const MatX3d& V = TheScene().cam_vertices;  // built outside the timed loop
  const HifiMeshBuilder& b = Hifi();
  TriMesh mesh;
  for (auto _ : state) {
    b.BuildInto(V, D, &mesh);
    benchmark::DoNotOptimize(mesh.V.data());
  }
}
BENCHMARK(BM_HifiBuildInto)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// The same on a Phong-tessellated base (HifiMeshOptions::phong_alpha, Difference 3 of
// pipeline/capture/hifi_mesh.h; the studio's α = 0.75).
void BM_HifiBuildIntoPhong(benchmark::State& state) {
  const auto threads = Threads(state);
  HifiMeshOptions o;
  o.phong_alpha = 0.75;
  static const HifiMeshBuilder phong(TheScene().rig, o);
  const cv::Mat D(1024, 1024, CV_32F, cv::Scalar(0.1f));
  const MatX3d& V = TheScene().cam_vertices;
  TriMesh mesh;
  for (auto _ : state) {
    phong.BuildInto(V, D, &mesh);
    benchmark::DoNotOptimize(mesh.V.data());
  }
}
BENCHMARK(BM_HifiBuildIntoPhong)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace crease
