// Embree ray caster on a bumpy latitude-longitude sphere of 1,046,528 triangles
// (radius 100 mm, 512 rings × 1024 segments). Rays per second (items/s) for
// coherent primary rays of a 640×480 pinhole camera (single rays and 16-ray
// packets), incoherent rays (fixed-seed random origins in a box and random
// directions), occlusion rays and signed both-way queries along the normals; plus
// BVH build and UpdateVertices times. First argument: TBB threads
// (tbb::global_control). Run e.g.
//   build/bench/ray_caster_bench --benchmark_out=ray.json --benchmark_out_format=json
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "core/mesh_primitives.h"
#include "core/ray_caster.h"
#include "core/rng.h"

namespace crease {
namespace {

constexpr double kRadius = 100.0;  // mm
constexpr int kWidth = 640, kHeight = 480;
constexpr int kNumRays = kWidth * kHeight;

// Radial bumps of ±2 mm so that the BVH sees a non-trivial surface.
MatX3d Bumpy(const TriMesh& m, double amplitude, double phase) {
  MatX3d V = m.V;
  for (int i = 0; i < m.num_vertices(); ++i) {
    const Eigen::Vector3d n = m.N.row(i);
    const double bump = amplitude * std::sin(23.0 * n.x() + phase) * std::cos(19.0 * n.y()) * std::sin(17.0 * n.z());
    V.row(i) = (kRadius + bump) * n.transpose();
  }
  return V;
}

const TriMesh& Sphere() {
  static const TriMesh mesh = [] {
    TriMesh m = MakeUVSphere(kRadius, 512, 1024);
    m.V = Bumpy(m, 2.0, 0.0);
    return m;
  }();
  return mesh;
}

const RayCaster& Caster() {
  static const RayCaster caster(Sphere());
  return caster;
}

tbb::global_control Threads(const benchmark::State& state) {
  return tbb::global_control(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(state.range(0)));
}

// Pinhole camera 400 mm in front of the sphere; the sphere fills most of the frame.
const std::vector<Ray>& PrimaryRays() {
  static const std::vector<Ray> rays = [] {
    std::vector<Ray> r;
    r.reserve(kNumRays);
    const Eigen::Vector3f eye(0.0f, 0.0f, -400.0f);
    const float f = 1000.0f;  // px
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        const Eigen::Vector3f d((x - 0.5f * (kWidth - 1)) / f, (y - 0.5f * (kHeight - 1)) / f, 1.0f);
        r.push_back(Ray{eye, d.normalized()});
      }
    }
    return r;
  }();
  return rays;
}

Eigen::Vector3f RandomUnit(Rng& rng) {
  const Eigen::Vector3f d(static_cast<float>(rng.Normal()), static_cast<float>(rng.Normal()),
                          static_cast<float>(rng.Normal()));
  return d.norm() > 1e-6f ? d.normalized() : Eigen::Vector3f::UnitX();
}

// Random origins in the box [−1.5 R, 1.5 R]³ and random directions.
const std::vector<Ray>& IncoherentRays() {
  static const std::vector<Ray> rays = [] {
    Rng rng(42);
    std::vector<Ray> r(kNumRays);
    const double b = 1.5 * kRadius;
    for (Ray& ray : r) {
      ray.origin = Eigen::Vector3f(static_cast<float>(rng.Uniform(-b, b)), static_cast<float>(rng.Uniform(-b, b)),
                                   static_cast<float>(rng.Uniform(-b, b)));
      ray.direction = RandomUnit(rng);
    }
    return r;
  }();
  return rays;
}

// Detail-extraction-like queries: points within ±1 mm of the surface, direction =
// the sphere's normal, searched up to 5 mm both ways. `ordered`: the points follow
// a 640×480 latitude-longitude grid in scanline order (like the texels of a map);
// otherwise they are uniformly random on the sphere, in random order.
struct SignedQueries {
  std::vector<Eigen::Vector3f> origins, directions;
};
const SignedQueries& Signed(bool ordered) {
  static const SignedQueries queries[2] = {
      [] {
        Rng rng(43);
        SignedQueries s;
        for (int i = 0; i < kNumRays; ++i) {
          const Eigen::Vector3f n = RandomUnit(rng);
          s.origins.push_back(static_cast<float>(kRadius + rng.Uniform(-1.0, 1.0)) * n);
          s.directions.push_back(n);
        }
        return s;
      }(),
      [] {
        Rng rng(44);
        SignedQueries s;
        for (int r = 0; r < kHeight; ++r) {
          const double theta = std::numbers::pi * (r + 0.5) / kHeight;
          for (int c = 0; c < kWidth; ++c) {
            const double phi = 2.0 * std::numbers::pi * (c + 0.5) / kWidth;
            const Eigen::Vector3f n(static_cast<float>(std::sin(theta) * std::cos(phi)),
                                    static_cast<float>(std::sin(theta) * std::sin(phi)),
                                    static_cast<float>(std::cos(theta)));
            s.origins.push_back(static_cast<float>(kRadius + rng.Uniform(-1.0, 1.0)) * n);
            s.directions.push_back(n);
          }
        }
        return s;
      }()};
  return queries[ordered ? 1 : 0];
}

void BM_PrimaryRays(benchmark::State& state) {
  const RayCaster& caster = Caster();
  const std::vector<Ray>& rays = PrimaryRays();
  const auto coherence = state.range(1) ? RayCoherence::kCoherent : RayCoherence::kIncoherent;
  const auto limit = Threads(state);
  std::vector<Hit> hits;
  for (auto _ : state) {
    caster.IntersectBatch(rays, &hits, coherence);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(state.iterations() * kNumRays);
  state.SetLabel(state.range(1) ? "rtcIntersect16 packets" : "rtcIntersect1");
}
BENCHMARK(BM_PrimaryRays)->ArgNames({"threads", "packets"})->ArgsProduct({{1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_IncoherentRays(benchmark::State& state) {
  const RayCaster& caster = Caster();
  const std::vector<Ray>& rays = IncoherentRays();
  const auto limit = Threads(state);
  std::vector<Hit> hits;
  for (auto _ : state) {
    caster.IntersectBatch(rays, &hits);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(state.iterations() * kNumRays);
}
BENCHMARK(BM_IncoherentRays)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_OccludedRays(benchmark::State& state) {
  const RayCaster& caster = Caster();
  const bool primary = state.range(1) != 0;
  const std::vector<Ray>& rays = primary ? PrimaryRays() : IncoherentRays();
  const auto coherence = primary ? RayCoherence::kCoherent : RayCoherence::kIncoherent;
  const auto limit = Threads(state);
  std::vector<uint8_t> occluded;
  for (auto _ : state) {
    caster.OccludedBatch(rays, &occluded, coherence);
    benchmark::DoNotOptimize(occluded.data());
  }
  state.SetItemsProcessed(state.iterations() * kNumRays);
  state.SetLabel(primary ? "primary, rtcOccluded16 packets" : "incoherent, rtcOccluded1");
}
BENCHMARK(BM_OccludedRays)->ArgNames({"threads", "primary"})->ArgsProduct({{1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SignedBothWays(benchmark::State& state) {
  const RayCaster& caster = Caster();
  const bool ordered = state.range(1) != 0;
  const SignedQueries& q = Signed(ordered);
  const auto limit = Threads(state);
  std::vector<SignedHit> hits;
  for (auto _ : state) {
    caster.IntersectSignedBatch(q.origins, q.directions, 5.0f, &hits);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(state.iterations() * kNumRays);  // queries (up to 2 rays each)
  state.SetLabel(ordered ? "grid order" : "random order");
}
BENCHMARK(BM_SignedBothWays)->ArgNames({"threads", "ordered"})->ArgsProduct({{1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

// Second argument: 0 low, 1 medium, 2 high, 3 dynamic (refittable).
void BM_BuildBvh(benchmark::State& state) {
  const TriMesh& mesh = Sphere();
  RayCasterOptions options;
  const BvhBuildQuality qualities[] = {BvhBuildQuality::kLow, BvhBuildQuality::kMedium, BvhBuildQuality::kHigh,
                                       BvhBuildQuality::kMedium};
  options.build_quality = qualities[state.range(1)];
  options.dynamic = state.range(1) == 3;
  const auto limit = Threads(state);
  for (auto _ : state) {
    RayCaster caster(mesh, options);
    benchmark::DoNotOptimize(&caster);
  }
  state.SetItemsProcessed(state.iterations() * mesh.num_faces());  // triangles
  state.SetLabel(options.dynamic ? "dynamic" : ToString(options.build_quality));
}
BENCHMARK(BM_BuildBvh)->ArgNames({"threads", "quality"})->ArgsProduct({{1, 2}, {0, 1, 2, 3}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

// Moves all vertices (alternating between two bump phases) and recommits:
// a rebuild when dynamic = 0, a refit when dynamic = 1.
void BM_UpdateVertices(benchmark::State& state) {
  const TriMesh& mesh = Sphere();
  RayCasterOptions options;
  options.dynamic = state.range(1) != 0;
  RayCaster caster(mesh, options);
  const MatX3d a = Bumpy(mesh, 2.0, 0.3), b = Bumpy(mesh, 2.0, 0.6);
  const auto limit = Threads(state);
  bool flip = false;
  for (auto _ : state) {
    caster.UpdateVertices(flip ? a : b);
    flip = !flip;
  }
  state.SetItemsProcessed(state.iterations() * mesh.num_faces());  // triangles
  state.SetLabel(options.dynamic ? "refit" : "rebuild");
}
BENCHMARK(BM_UpdateVertices)->ArgNames({"threads", "dynamic"})->ArgsProduct({{1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

// Primary rays on the refitted (dynamic) BVH, to see what refitting costs in ray speed.
void BM_PrimaryRaysDynamicBvh(benchmark::State& state) {
  static const RayCaster caster = [] {
    RayCasterOptions options;
    options.dynamic = true;
    RayCaster c(Sphere(), options);
    c.UpdateVertices(Bumpy(Sphere(), 2.0, 0.6));
    return c;
  }();
  const std::vector<Ray>& rays = PrimaryRays();
  const auto limit = Threads(state);
  std::vector<Hit> hits;
  for (auto _ : state) {
    caster.IntersectBatch(rays, &hits, RayCoherence::kCoherent);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(state.iterations() * kNumRays);
}
BENCHMARK(BM_PrimaryRaysDynamicBvh)->ArgName("threads")->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
