// The global tracker's rig fit to 68 landmarks (issue 5 part 2), one thread: the
// per-frame fit of a tracked frame (warm-started, temporal prior) with each dense
// linear solver, a (re)initialisation frame, and the identity phase. Run e.g.
//   build/bench/landmark_fit_bench --benchmark_repetitions=5 --benchmark_out=fit.json --benchmark_out_format=json
#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>
#include <string>

#include "core/options.h"
#include "core/rng.h"
#include "pipeline/capture/landmark_fit.h"
#include "synth/procedural_rig.h"

namespace crease {
namespace {

const FaceRig& Rig() {
  static const FaceRig rig = BuildProceduralRig();
  return rig;
}

CameraIntrinsics Intrinsics() { return CameraIntrinsics::FromFov(40.0, 640, 480); }

// A short performance: 64 frames of a head turning and talking, with σ = 1 px
// landmark noise, from a known identity.
struct Sequence {
  Eigen::VectorXd identity;
  std::vector<MatX2d> frames;
};

const Sequence& Performance() {
  static const Sequence s = [] {
    const FaceRig& rig = Rig();
    Sequence seq;
    seq.identity = Eigen::VectorXd::Zero(rig.num_identity());
    seq.identity[0] = 0.8;
    seq.identity[4] = -0.6;
    std::vector<int> vertex(68);
    for (int i = 0; i < 68; ++i) vertex[i] = rig.landmarks[rig.LandmarkIndex("ibug_" + std::to_string(i + 1))].vertex;
    Rng rng(3);
    for (int f = 0; f < 64; ++f) {
      const double phase = 2.0 * std::numbers::pi * f / 64.0;
      Eigen::VectorXd beta = Eigen::VectorXd::Zero(rig.num_expressions());
      beta[rig.ExpressionIndex("jawOpen")] = 0.3 + 0.3 * std::sin(3 * phase);
      beta[rig.ExpressionIndex("mouthSmile_L")] = 0.3 + 0.3 * std::cos(2 * phase);
      beta[rig.ExpressionIndex("browInnerUp_L")] = 0.5 + 0.4 * std::sin(phase);
      const Eigen::Quaterniond q =
          Eigen::Quaterniond(Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX())) *
          Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * std::sin(phase), Eigen::Vector3d::UnitY()));
      const Camera camera(Intrinsics(), Rigid3d(q, Eigen::Vector3d(10 * std::sin(phase), 0.0, 550.0)));
      const MatX3d X = rig.EvaluatePositions(seq.identity, beta);
      MatX2d l(68, 2);
      for (int i = 0; i < 68; ++i) {
        l.row(i) = camera.Project(X.row(vertex[i]).transpose()).transpose();
        l(i, 0) += rng.Normal();
        l(i, 1) += rng.Normal();
      }
      seq.frames.push_back(l);
    }
    return seq;
  }();
  return s;
}

// One tracked frame (identity fixed, warm start and temporal prior from the previous frame).
void BM_FitTrackedFrame(benchmark::State& state, const std::string& solver) {
  const Sequence& seq = Performance();
  LandmarkFitOptions o;
  o.fit_linear_solver = FromString<FitLinearSolver>(solver, "solver");
  LandmarkRigFitter fitter(Rig(), Intrinsics(), o);
  fitter.SetIdentity(seq.identity);
  fitter.Fit(seq.frames[0]);
  size_t f = 1;
  double iterations = 0.0;
  for (auto _ : state) {
    const LandmarkFrameFit fit = fitter.Fit(seq.frames[f]);
    iterations += fit.iterations;
    benchmark::DoNotOptimize(fit.expression.data());
    f = (f + 1) % seq.frames.size();
  }
  state.counters["expressions"] = Rig().num_expressions();
  state.counters["iterations"] = benchmark::Counter(iterations, benchmark::Counter::kAvgIterations);
}
BENCHMARK_CAPTURE(BM_FitTrackedFrame, dense_normal_cholesky, std::string("dense_normal_cholesky"))
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitTrackedFrame, dense_qr, std::string("dense_qr"))->Unit(benchmark::kMillisecond);

// A (re)initialisation frame: closed-form pose, pose-only solve, full solve.
void BM_FitAfterReset(benchmark::State& state) {
  const Sequence& seq = Performance();
  LandmarkRigFitter fitter(Rig(), Intrinsics(), {});
  fitter.SetIdentity(seq.identity);
  size_t f = 0;
  for (auto _ : state) {
    fitter.Reset();
    const LandmarkFrameFit fit = fitter.Fit(seq.frames[f]);
    benchmark::DoNotOptimize(fit.expression.data());
    f = (f + 1) % seq.frames.size();
  }
}
BENCHMARK(BM_FitAfterReset)->Unit(benchmark::kMillisecond);

// The whole identity phase: identity_frames frames, each with a batch fit over the
// frames so far. Time per phase (divide by identity_frames for the mean per frame).
void BM_IdentityPhase(benchmark::State& state) {
  const Sequence& seq = Performance();
  LandmarkFitOptions o;
  o.identity_frames = static_cast<int>(state.range(0));
  for (auto _ : state) {
    LandmarkRigFitter fitter(Rig(), Intrinsics(), o);
    for (int f = 0; f < o.identity_frames; ++f) fitter.Fit(seq.frames[f % seq.frames.size()]);
    benchmark::DoNotOptimize(fitter.identity().data());
  }
  state.counters["frames"] = o.identity_frames;
}
BENCHMARK(BM_IdentityPhase)->Arg(5)->Arg(20)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace crease
