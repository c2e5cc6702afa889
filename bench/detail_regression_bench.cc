// Online detail regression per frame (paper Sec. 5.2, pipeline/capture/detail_regression.h)
// and its Poisson fill (poisson_fill.h) at R = 1024. Run e.g.
//   build/bench/detail_regression_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only
//   CREASE_DETAIL_MODEL=out/model.cdm build/bench/detail_regression_bench     # the trained model
//   CREASE_DETAIL_MODEL=out/model.cdm CREASE_DETAIL_RIG=out/scans/rig.crig
//     CREASE_DETAIL_TEXTURES=out/model_report/texture_actor_002_
//     CREASE_DETAIL_PNG=/tmp/detail.png build/bench/detail_regression_bench   (one command line)
// Without CREASE_DETAIL_MODEL a model of the paper's shape (K = 1280, F = 5, w = 32,
// D = 16) is trained in-process on synthetic line textures. With CREASE_DETAIL_RIG the
// face chart and the regions come from that rig (else a disc chart, no regions);
// CREASE_DETAIL_TEXTURES is a path prefix of textures (PNG/EXR, e.g. the trainer's
// report textures) used as the wrinkle frames and the regressed frame (else synthetic
// line textures). CREASE_DETAIL_PNG=<dir>/<name>.png writes D^t of every frame as <name>_<i>[_gated].png (±0.1 mm)
// (and "<name>_layout.png", the
// wrinkle map with the patch layout).
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/face_rig.h"
#include "core/image_io.h"
#include "core/rng.h"
#include "core/uv_raster.h"
#include "pipeline/capture/detail_regression.h"
#include "pipeline/capture/poisson_fill.h"
#include "pipeline/capture/reference_alignment.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/pca.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
constexpr int kR = 1024;

cv::Mat DiscChart(int S) {
  cv::Mat c(S, S, CV_8U, cv::Scalar(0));
  cv::ellipse(c, cv::Point(S / 2, S / 2), cv::Size(S * 40 / 100, S * 46 / 100), 0, 0, 360, cv::Scalar(255), cv::FILLED);
  cv::circle(c, cv::Point(S * 35 / 100, S * 42 / 100), S / 20, cv::Scalar(0), cv::FILLED);  // eyes
  cv::circle(c, cv::Point(S * 65 / 100, S * 42 / 100), S / 20, cv::Scalar(0), cv::FILLED);
  cv::ellipse(c, cv::Point(S / 2, S * 75 / 100), cv::Size(S / 10, S / 40), 0, 0, 360, cv::Scalar(0), cv::FILLED);
  return c;
}

struct Line {
  double cx, cy, deg, length;
};

// Lines in the upper half of the chart (forehead-like) and around the eyes.
std::vector<Line> SyntheticLines() {
  std::vector<Line> lines;
  Rng rng(17);
  for (int i = 0; i < 10; ++i) lines.push_back({kR * rng.Uniform(0.3, 0.7), kR * (0.12 + 0.018 * i), rng.Uniform(-8, 8), kR * rng.Uniform(0.1, 0.3)});
  for (int i = 0; i < 12; ++i) lines.push_back({kR * rng.Uniform(0.2, 0.8), kR * rng.Uniform(0.45, 0.65), rng.Uniform(0, 180), kR * rng.Uniform(0.05, 0.12)});
  return lines;
}

void LineFrame(const std::vector<Line>& lines, double depth, cv::Mat* texture, cv::Mat* displacement) {
  *texture = cv::Mat(kR, kR, CV_32F, cv::Scalar(0.45f));
  *displacement = cv::Mat(kR, kR, CV_32F, cv::Scalar(0.0f));
  for (const Line& l : lines) {
    const double phi = l.deg * std::numbers::pi / 180.0, tx = std::cos(phi), ty = std::sin(phi);
    const int r = static_cast<int>(l.length / 2 + 20);
    for (int y = std::max(0, int(l.cy) - r); y < std::min(kR, int(l.cy) + r); ++y) {
      for (int x = std::max(0, int(l.cx) - r); x < std::min(kR, int(l.cx) + r); ++x) {
        const double along = (x - l.cx) * tx + (y - l.cy) * ty, across = -(x - l.cx) * ty + (y - l.cy) * tx;
        const double fade = std::exp(-std::pow(std::max(0.0, std::abs(along) - l.length / 2) / 6.0, 2));
        const double g = std::exp(-across * across / (2 * 3.0 * 3.0)) * fade;
        texture->at<float>(y, x) -= static_cast<float>(depth * g);
        displacement->at<float>(y, x) -= static_cast<float>(0.4 * depth * g);
      }
    }
  }
}

struct Setup {
  DetailModel model;
  std::vector<RegionMask> regions;
  cv::Mat chart;
  std::vector<cv::Mat> frames, seen;  // wrinkle frames; the last one is regressed
  std::string source;

  Setup() {
    const char* model_path = std::getenv("CREASE_DETAIL_MODEL");
    const char* rig_path = std::getenv("CREASE_DETAIL_RIG");
    const char* textures = std::getenv("CREASE_DETAIL_TEXTURES");
    const std::vector<Line> lines = SyntheticLines();
    if (model_path) {
      model = ReadDetailModel(model_path);
      source = model_path;
    } else {
      // A model of the paper's shape trained on synthetic lines.
      model.map_resolution = kR;
      model.wrinkle.patch_regions.clear();
      std::vector<cv::Mat> tex, disp;
      for (double depth : {0.08, 0.15, 0.22, 0.3}) {
        cv::Mat t, d;
        LineFrame(lines, depth, &t, &d);
        tex.push_back(t);
        disp.push_back(d);
      }
      std::vector<cv::Mat> responses;
      const WrinkleMap wmap = ComputeWrinkleMap(tex, DiscChart(kR), {}, model.wrinkle, &responses);
      const PatchLayout layout = PlacePatches(wmap, model.patch);
      const TrainingPatches pairs = ExtractTrainingPatches(layout, tex, responses, disp, model.wrinkle);
      model.pca = FitPatchPca(pairs.displacement, PcaOptions{});
      model.cascade = TrainFernCascade(pairs.texture, model.pca.ProjectPatches(pairs.displacement), FernOptions{}).cascade;
      source = "in-process synthetic model";
    }
    Require(model.map_resolution == kR, "the benchmark expects a 1024² model");
    if (rig_path) {
      const FaceRig rig = ReadRig(rig_path);
      regions = rig.regions;
      TriMesh chart_mesh = rig.neutral;
      chart_mesh.F = FaceChartTriangles(rig);
      const UvRaster raster = RasterizeUv(chart_mesh, kR, kR, rig_path);
      chart = cv::Mat(kR, kR, CV_8U, cv::Scalar(0));
      for (int j = 0; j < kR; ++j)
        for (int i = 0; i < kR; ++i)
          if (raster.covered(i, j)) chart.at<uint8_t>(j, i) = 255;
    } else {
      model.wrinkle.patch_regions.clear();
      chart = DiscChart(kR);
    }
    if (textures) {
      const fs::path prefix(textures);
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(prefix.parent_path())) {
        const std::string name = e.path().filename().string();
        if (name.rfind(prefix.filename().string(), 0) == 0) files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
      Require(!files.empty(), std::string("no textures match ") + textures);
      for (const auto& f : files) {
        cv::Mat im = ReadImage(f), gray(kR, kR, CV_32F);
        Require(im.rows == kR && im.cols == kR, f.string() + ": expected a 1024² texture");
        for (int j = 0; j < kR; ++j)
          for (int i = 0; i < kR; ++i) {
            const float* p = im.ptr<float>(j) + i * im.channels();
            gray.at<float>(j, i) = im.channels() >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
          }
        cv::Mat s = (gray > 0.0f) & chart;
        frames.push_back(gray);
        seen.push_back(s);
        std::printf("texture %s: %d seen texels\n", f.string().c_str(), cv::countNonZero(s));
      }
    } else {
      for (double depth : {0.1, 0.25, 0.0, 0.2}) {
        cv::Mat t, d;
        LineFrame(lines, depth, &t, &d);
        frames.push_back(t);
        seen.push_back(chart.clone());
      }
    }
  }
};

const Setup& TheSetup() {
  static const Setup s;
  return s;
}

DetailRegressor MakeRegressor(const DetailRegressionOptions& options) {
  const Setup& s = TheSetup();
  DetailRegressor r(s.model, s.regions, s.chart, options);
  for (size_t i = 0; i < s.frames.size(); ++i) r.AddWrinkleFrame(s.frames[i], s.seen[i]);
  r.FixLayout();
  return r;
}

// A diverging picture of D (blue < 0 < red, ±range mm, here ±0.1), grey outside the chart.
cv::Mat Picture(const cv::Mat& D, const cv::Mat& chart, double range) {
  cv::Mat out(D.size(), CV_8UC3);
  for (int j = 0; j < D.rows; ++j)
    for (int i = 0; i < D.cols; ++i) {
      if (!chart.at<uint8_t>(j, i)) {
        out.at<cv::Vec3b>(j, i) = cv::Vec3b(60, 60, 60);
        continue;
      }
      const double x = std::clamp(D.at<float>(j, i) / range, -1.0, 1.0);
      const double r = x > 0 ? 1.0 : 1.0 + x, b = x < 0 ? 1.0 : 1.0 - x, g = 1.0 - std::abs(x);
      out.at<cv::Vec3b>(j, i) = cv::Vec3b(uint8_t(255 * r), uint8_t(255 * g), uint8_t(255 * b));  // RGB
    }
  return out;
}

void BM_Regress(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  DetailRegressionOptions o;
  o.gate_by_response = state.range(1) != 0;
  o.gate_softness = state.range(1) == 2 ? 0.75 : 0.0;
  o.recentre_radius = static_cast<double>(state.range(2));  // Difference 7, steps of 2 texels
  o.recentre_step = 2.0;
  const DetailRegressor r = MakeRegressor(o);
  const Setup& s = TheSetup();
  // Mean and minimum per sub-step (the minimum is robust to other jobs on the machine).
  DetailTiming sum, t;
  double lo[6] = {1e9, 1e9, 1e9, 1e9, 1e9, 1e9};
  int64_t n = 0;
  cv::Mat D;
  for (auto _ : state) {
    D = r.Regress(s.frames.back(), s.seen.back(), &t);
    sum.sample_ms += t.sample_ms;
    sum.regress_ms += t.regress_ms;
    sum.reconstruct_ms += t.reconstruct_ms;
    sum.merge_ms += t.merge_ms;
    sum.fill_ms += t.fill_ms;
    const double v[6] = {t.sample_ms, t.regress_ms, t.reconstruct_ms, t.merge_ms, t.fill_ms, t.total_ms()};
    for (int i = 0; i < 6; ++i) lo[i] = std::min(lo[i], v[i]);
    ++n;
  }
  state.counters["patches"] = t.patches;
  state.counters["dropped"] = t.dropped;
  state.counters["sample_ms"] = sum.sample_ms / n;
  state.counters["regress_ms"] = sum.regress_ms / n;
  state.counters["reconstruct_ms"] = sum.reconstruct_ms / n;
  state.counters["merge_ms"] = sum.merge_ms / n;
  state.counters["fill_ms"] = sum.fill_ms / n;
  const char* names[6] = {"min_sample", "min_regress", "min_reconstruct", "min_merge", "min_fill", "min_total"};
  for (int i = 0; i < 6; ++i) state.counters[names[i]] = lo[i];
  const char* png = std::getenv("CREASE_DETAIL_PNG");
  static bool written[2] = {false, false};
  if (png && state.range(0) == 2 && state.range(2) == 0 && !written[o.gate_by_response]) {
    written[o.gate_by_response] = true;
    // D^t of every frame, ±range mm (the largest |D| over the frames without the gate).
    const fs::path base(png);
    auto named = [&](const std::string& suffix) {
      std::string name = base.stem().string();
      name.append(suffix);
      name.append(base.extension().string());
      return base.parent_path() / name;
    };
    std::vector<cv::Mat> all;
    double range = 0.02;
    for (size_t i = 0; i < s.frames.size(); ++i) {
      all.push_back(r.Regress(s.frames[i], s.seen[i]));
      double lo, hi;
      cv::minMaxLoc(all.back(), &lo, &hi);
      std::printf("%s, gate %s, frame %zu: %d patches, D^t in [%.4f, %.4f] mm\n", s.source.c_str(),
                  o.gate_by_response ? "on" : "off", i, t.patches, lo, hi);
      range = std::max(range, std::max(-lo, hi));
    }
    if (!o.gate_by_response) std::printf("pictures: ±%.3f mm\n", range);
    for (size_t i = 0; i < all.size(); ++i) {
      char suffix[32];
      std::snprintf(suffix, sizeof(suffix), "_%zu%s", i, o.gate_by_response ? "_gated" : "");
      WriteImage(named(suffix), Picture(all[i], s.chart, 0.1), {.srgb = false});
    }
    if (!o.gate_by_response) {
      cv::Mat layout = DrawPatchLayout(r.wrinkle_map().probability, r.layout(), r.wrinkle_map().valid);
      cv::cvtColor(layout, layout, cv::COLOR_BGR2RGB);
      WriteImage(named("_layout"), layout, {.srgb = false});
    }
  }
}
// Args: threads, the response gate (0 off, 1 hard, 2 soft: gate_softness 0.75), the
// re-centring radius in texels (0 off; steps of 2 texels).
BENCHMARK(BM_Regress)
    ->Args({1, 0, 0})
    ->Args({2, 0, 0})
    ->Args({2, 1, 0})
    ->Args({2, 2, 0})
    ->Args({1, 2, 8})
    ->Args({2, 2, 8})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_FixLayout(benchmark::State& state) {
  const Setup& s = TheSetup();
  for (auto _ : state) {
    state.PauseTiming();
    DetailRegressor r(s.model, s.regions, s.chart, DetailRegressionOptions{});
    for (size_t i = 0; i < s.frames.size(); ++i) r.AddWrinkleFrame(s.frames[i], s.seen[i]);
    state.ResumeTiming();
    r.FixLayout();
  }
}
BENCHMARK(BM_FixLayout)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_AddWrinkleFrame(benchmark::State& state) {
  const Setup& s = TheSetup();
  DetailRegressor r(s.model, s.regions, s.chart, DetailRegressionOptions{});
  size_t i = 0;
  for (auto _ : state) r.AddWrinkleFrame(s.frames[i++ % s.frames.size()], s.seen[0]);
}
BENCHMARK(BM_AddWrinkleFrame)->Unit(benchmark::kMillisecond)->UseRealTime();

// The reference aligned to T^t (ReferenceAligner, reference_alignment.h; the reference
// prepared once) at a flow grid of range(1)²:
// the first wrinkle frame as the reference, the last one shifted by (5, −3) texels.
void BM_AlignReference(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  const Setup& s = TheSetup();
  cv::Mat reference = s.frames.front().clone(), texture;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 5, 0, 1, -3);
  cv::warpAffine(s.frames.back(), texture, shift, s.frames.back().size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  reference.setTo(0.0f, s.chart == 0);
  texture.setTo(0.0f, s.chart == 0);
  ReferenceAlignmentOptions o;
  o.enabled = true;
  o.resolution = static_cast<int>(state.range(1));
  const ReferenceAligner aligner(reference, o);
  for (auto _ : state) benchmark::DoNotOptimize(aligner.AlignReference(texture, s.chart));
}
BENCHMARK(BM_AlignReference)->Args({1, 256})->Args({2, 256})->Args({2, 128})->Unit(benchmark::kMillisecond)->UseRealTime();

// The regressor's own fill (its chart and patch coverage), alone.
void BM_RegressorFill(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  DetailRegressionOptions o;
  o.fill.fill_resolution = static_cast<int>(state.range(1));
  const DetailRegressor r = MakeRegressor(o);
  const Setup& s = TheSetup();
  cv::Mat map = r.Regress(s.frames.back(), s.seen.back());
  double lo = 1e9;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    r.fill().Apply(&map);
    lo = std::min(lo, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  state.counters["min_ms"] = lo;
  state.counters["unknowns"] = r.fill().num_unknown();
  state.counters["coarse_unknowns"] = r.fill().num_coarse_unknown();
  state.counters["band"] = r.fill().num_band();
}
// Args: threads, fill_resolution.
BENCHMARK(BM_RegressorFill)->Args({1, 256})->Args({2, 256})->Args({1, 128})->Args({2, 128})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

// The fill alone on a face-chart-like domain with ~20 % patch coverage (rotated 32² squares).
struct FillCase {
  cv::Mat domain = DiscChart(kR), known = cv::Mat(kR, kR, CV_8U, cv::Scalar(0));
  FillCase() {
    Rng rng(4);
    while (cv::countNonZero(known) < 0.2 * kR * kR) {
      const double angle = rng.Uniform(0, 180), y = kR * rng.Uniform(0.1, 0.9);  // one draw per statement
      const cv::RotatedRect r(cv::Point2f(kR * rng.Uniform(0.15, 0.85), y), cv::Size2f(32, 32), angle);
      cv::Point2f p[4];
      r.points(p);
      std::vector<cv::Point> poly(p, p + 4);
      cv::fillConvexPoly(known, poly, cv::Scalar(255));
    }
    known &= domain;
  }
};

void BM_PoissonFill(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  static const FillCase c;
  PoissonFillOptions o;
  o.fill_resolution = static_cast<int>(state.range(1));
  const PoissonFill fill(c.domain, c.known, o);
  cv::Mat map(kR, kR, CV_32F, cv::Scalar(0.01f));
  double lo = 1e9;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    fill.Apply(&map);
    lo = std::min(lo, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  state.counters["min_ms"] = lo;
  state.counters["unknowns"] = fill.num_unknown();
  state.counters["coarse_unknowns"] = fill.num_coarse_unknown();
  state.counters["band"] = fill.num_band();
  state.counters["domain_pct"] = 100.0 * cv::countNonZero(c.domain) / (kR * kR);
  state.counters["known_pct"] = 100.0 * cv::countNonZero(c.known) / (kR * kR);
}
// Args: threads, fill_resolution.
BENCHMARK(BM_PoissonFill)->Args({1, 256})->Args({2, 256})->Args({2, 128})->Args({2, 512})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PoissonFillBuild(benchmark::State& state) {
  static const FillCase c;
  PoissonFillOptions o;
  o.fill_resolution = static_cast<int>(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(PoissonFill(c.domain, c.known, o));
}
BENCHMARK(BM_PoissonFillBuild)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace crease
