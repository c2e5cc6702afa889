// Training-stage costs of detail extraction (paper Sec. 4.1): the per-actor set-up
// (G^HF on the full scan, G and the deformation transfer on the operator grid), the
// per-scan extraction of D^j, and the compatible rig. Run e.g.
//   build/bench/detail_extraction_bench --benchmark_min_time=1
#include <benchmark/benchmark.h>

#include <cmath>

#include "core/mesh_primitives.h"
#include "pipeline/training/deformation_transfer.h"
#include "pipeline/training/detail_extraction.h"
#include "synth/procedural_rig.h"

namespace crease {
namespace {

// An n×n grid (face-sized, 180 mm) and an "expression": a broad bend plus furrows.
TriMesh Grid(int n) { return MakeGrid(n, n, 180.0, 180.0); }

MatX3d Expression(const TriMesh& g) {
  MatX3d V = g.V;
  for (int i = 0; i < V.rows(); ++i) {
    const double x = g.V(i, 0), y = g.V(i, 1);
    V(i, 2) += 0.002 * (x - 90) * (x - 90) - 0.3 * std::exp(-0.5 * std::pow(std::fmod(y, 10.0) - 5.0, 2) / 0.64);
  }
  return V;
}

// Set-up per actor: n² full-resolution vertices (n = 840 is ~700k, the studio's scans).
void BM_DetailExtractorSetup(benchmark::State& state) {
  const TriMesh g = Grid(static_cast<int>(state.range(0)));
  DetailExtractionOptions o;
  for (auto _ : state) {
    DetailExtractor e(g, o);
    benchmark::DoNotOptimize(e.operator_grid_vertices());
  }
  state.counters["vertices"] = g.num_vertices();
}
BENCHMARK(BM_DetailExtractorSetup)->Arg(420)->Arg(840)->Unit(benchmark::kMillisecond)->Iterations(2);

// Per scan: G^HF, G + transfer on the grid, M_0^j, rays into a 1024² map.
void BM_DetailExtract(benchmark::State& state) {
  const TriMesh g = Grid(static_cast<int>(state.range(0)));
  const DetailExtractor e(g, {});
  const MatX3d expr = Expression(g);
  for (auto _ : state) {
    const ExtractedDetail d = e.Extract(expr, "expression");
    benchmark::DoNotOptimize(d.displacement.data);
  }
  state.counters["vertices"] = g.num_vertices();
}
BENCHMARK(BM_DetailExtract)->Arg(420)->Arg(840)->Unit(benchmark::kMillisecond)->Iterations(3);

// Deformation transfer alone: factorisation and one transfer on an n² grid.
void BM_DeformationTransferFactor(benchmark::State& state) {
  const TriMesh g = Grid(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    DeformationTransfer dt(g, g);
    benchmark::DoNotOptimize(dt.num_vertices());
  }
}
BENCHMARK(BM_DeformationTransferFactor)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);

void BM_DeformationTransferSolve(benchmark::State& state) {
  const TriMesh g = Grid(static_cast<int>(state.range(0)));
  const DeformationTransfer dt(g, g);
  const MatX3d expr = Expression(g);
  for (auto _ : state) benchmark::DoNotOptimize(dt.Transfer(expr).data());
}
BENCHMARK(BM_DeformationTransferSolve)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);

// The compatible rig: every blendshape of the procedural rig through G and the transfer.
void BM_MakeRigCompatible(benchmark::State& state) {
  const FaceRig rig = BuildProceduralRig();
  for (auto _ : state) benchmark::DoNotOptimize(MakeRigCompatible(rig, {}).expression_basis.data());
  state.counters["expressions"] = rig.num_expressions();
}
BENCHMARK(BM_MakeRigCompatible)->Unit(benchmark::kMillisecond)->Iterations(2);

}  // namespace
}  // namespace crease
