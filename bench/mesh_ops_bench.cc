// Mesh operators on a ~20k-vertex (140×140 quads) and a ~250k-vertex (500×500
// quads) height-field grid of 1 mm / 0.4 mm spacing. Run e.g.
//   build/bench/mesh_ops_bench --benchmark_out=mesh_ops.json --benchmark_out_format=json
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>

#include "core/mesh_ops.h"
#include "core/mesh_primitives.h"

namespace crease {
namespace {

// A gently curved open sheet (like a face region): z = 3 sin(x/10) cos(y/13) mm.
const TriMesh& Sheet(int n) {
  static std::map<int, TriMesh> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  const double size = n == 140 ? 140.0 : 200.0;
  TriMesh m = MakeGrid(n, n, size, size);
  for (int i = 0; i < m.num_vertices(); ++i) {
    m.V(i, 2) = 3.0 * std::sin(m.V(i, 0) / 10.0) * std::cos(m.V(i, 1) / 13.0);
  }
  m.N.resize(0, 3);
  return cache.emplace(n, std::move(m)).first->second;
}

void SetCounters(benchmark::State& state, const TriMesh& m) {
  state.counters["vertices"] = m.num_vertices();
}

void BM_VertexNormals(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(VertexNormals(m));
  SetCounters(state, m);
}

void BM_CotangentLaplacian(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(CotangentLaplacian(m));
  SetCounters(state, m);
}

void BM_MassMatrixVoronoi(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(MassMatrix(m, MassMatrixType::kVoronoi));
  SetCounters(state, m);
}

void BM_LowpassFactorize(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(MeshLowpass(m));
  SetCounters(state, m);
}

// Default options: σ = 3 mm, 8 backward-Euler steps, #V×3 positions.
void BM_LowpassApplyPositions(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  const MeshLowpass lowpass(m);
  for (auto _ : state) benchmark::DoNotOptimize(lowpass.Apply(m.V));
  SetCounters(state, m);
}

// Open mesh with "averaged" boundaries: three factorisations (Neumann heat,
// Dirichlet heat, pinned Poisson).
void BM_GeodesicPrecompute(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(GeodesicDistance(m));
  SetCounters(state, m);
}

void BM_GeodesicQuery(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  const GeodesicDistance geo(m);
  const int centre = m.num_vertices() / 2;
  for (auto _ : state) benchmark::DoNotOptimize(geo.From({centre}));
  SetCounters(state, m);
}

void BM_DijkstraQuery(benchmark::State& state) {
  const TriMesh& m = Sheet(static_cast<int>(state.range(0)));
  const int centre = m.num_vertices() / 2;
  for (auto _ : state) benchmark::DoNotOptimize(DijkstraDistance(m, {centre}));
  SetCounters(state, m);
}

BENCHMARK(BM_VertexNormals)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CotangentLaplacian)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassMatrixVoronoi)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LowpassFactorize)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LowpassApplyPositions)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_GeodesicPrecompute)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_GeodesicQuery)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DijkstraQuery)->Arg(140)->Arg(500)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace crease
