// UV rasterisation of a 1024² map (the paper's map size, Sec. 4.2) for
// latitude-longitude spheres of 19,800 and 200,344 triangles, and the per-frame
// use of the raster (InterpolateToUv of positions, 3 channels). First argument:
// triangles (20k or 200k); second: TBB threads. Run e.g.
//   build/bench/uv_raster_bench --benchmark_out=uv.json --benchmark_out_format=json
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <map>

#include "core/mesh_primitives.h"
#include "core/uv_raster.h"

namespace crease {
namespace {

constexpr int kMapSize = 1024;

const TriMesh& Mesh(int kilo_triangles) {
  static std::map<int, TriMesh> cache;
  auto it = cache.find(kilo_triangles);
  if (it != cache.end()) return it->second;
  const int n = kilo_triangles == 20 ? 100 : 317;  // 2n² − 2n triangles
  return cache.emplace(kilo_triangles, MakeUVSphere(100.0, n, n)).first->second;
}

void BM_RasterizeUv(benchmark::State& state) {
  const TriMesh& mesh = Mesh(static_cast<int>(state.range(0)));
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(1)));
  for (auto _ : state) {
    UvRaster raster = RasterizeUv(mesh, kMapSize, kMapSize);
    benchmark::DoNotOptimize(raster.triangle.data());
  }
  state.SetItemsProcessed(state.iterations() * kMapSize * kMapSize);  // texels
  state.counters["triangles"] = mesh.num_faces();
}
BENCHMARK(BM_RasterizeUv)->ArgNames({"ktris", "threads"})->ArgsProduct({{20, 200}, {1, 2}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_InterpolatePositions(benchmark::State& state) {
  const TriMesh& mesh = Mesh(static_cast<int>(state.range(0)));
  const UvRaster raster = RasterizeUv(mesh, kMapSize, kMapSize);
  const Eigen::MatrixXd positions = mesh.V;
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(1)));
  for (auto _ : state) {
    cv::Mat map = InterpolateToUv(raster, mesh, positions);
    benchmark::DoNotOptimize(map.data);
  }
  state.SetItemsProcessed(state.iterations() * kMapSize * kMapSize);  // texels
  state.counters["triangles"] = mesh.num_faces();
}
BENCHMARK(BM_InterpolatePositions)->ArgNames({"ktris", "threads"})->ArgsProduct({{20, 200}, {1, 2}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
