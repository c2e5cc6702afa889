#include "pipeline/capture/landmark_evaluation.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/ibug.h"
#include "core/rng.h"
#include "core/timer.h"

namespace crease {

namespace {

double Iod(const MatX2d& s) { return std::max(1e-9, InterOcularDistance(s)); }

// The truth under a random similarity about its centroid (as ShapeRegressorOptions'
// tracking-like augmentation).
MatX2d PerturbedTruth(const MatX2d& truth, const ShapeRegressorOptions& o, Rng& rng) {
  const Eigen::RowVector2d g = truth.colwise().mean();
  const double iod = Iod(truth);
  // y, then x: one draw per statement (argument order is unspecified; GCC's kept).
  const double dy = rng.Normal(0, o.perturb_translation * iod);
  const Eigen::RowVector2d shift(rng.Normal(0, o.perturb_translation * iod), dy);
  const double a = rng.Normal(0, o.perturb_rotation_deg) * std::numbers::pi / 180.0;
  const double s = std::exp(rng.Normal(0, o.perturb_scale));
  Eigen::Matrix2d R;
  R << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  MatX2d out(truth.rows(), 2);
  for (int i = 0; i < truth.rows(); ++i) out.row(i) = g + shift + s * (truth.row(i) - g) * R.transpose();
  return out;
}

// The truth's square box, jittered (as the detection-like augmentation).
FaceBox JitteredBox(const MatX2d& truth, const ShapeRegressorOptions& o, Rng& rng) {
  const FaceBox b = BoxOfPoints(truth);
  const double side = std::max(b.width, b.height) * std::exp(rng.Normal(0, o.box_jitter_scale));
  const double cx = b.x + 0.5 * b.width + rng.Normal(0, o.box_jitter_translation * side);
  const double cy = b.y + 0.5 * b.height + rng.Normal(0, o.box_jitter_translation * side);
  return {cx - 0.5 * side, cy - 0.5 * side, side, side, 0.0};
}

void Accumulate(const MatX2d& init, const MatX2d& out, const MatX2d& truth, LandmarkErrorStats* s) {
  const double iod = Iod(truth);
  const double e0 = (init - truth).rowwise().norm().mean(), e1 = (out - truth).rowwise().norm().mean();
  s->initial_px += e0;
  s->initial_iod += e0 / iod;
  s->final_px += e1;
  s->final_iod += e1 / iod;
  ++s->frames;
}

void Finish(LandmarkErrorStats* s) {
  if (s->frames == 0) return;
  s->initial_px /= s->frames;
  s->initial_iod /= s->frames;
  s->final_px /= s->frames;
  s->final_iod /= s->frames;
}

// Mean point-to-point error of `points` against the truth, pixels.
double MeanError(const MatX2d& points, const MatX2d& truth) { return (points - truth).rowwise().norm().mean(); }

}  // namespace

LandmarkSourceEvaluation EvaluateLandmarkSource(LandmarkSource& source, const std::vector<LabelledFace>& faces) {
  LandmarkSourceEvaluation e;
  e.source = source.name();
  double seconds = 0;
  for (const LabelledFace& f : faces) {
    source.Reset();
    const ScopedTimer timer(nullptr, "");
    const LandmarkResult r = source.Track(f.image);
    seconds += timer.Elapsed();
    ++e.faces;
    if (!r.found) continue;
    ++e.found;
    const double err = MeanError(r.points, f.landmarks);
    e.error_px += err;
    e.error_iod += err / Iod(f.landmarks);
  }
  if (e.found > 0) {
    e.error_px /= e.found;
    e.error_iod /= e.found;
  }
  e.ms_per_face = e.faces > 0 ? 1e3 * seconds / e.faces : 0.0;
  return e;
}

ShapeRegressorEvaluation EvaluateShapeRegressor(const ShapeRegressor& regressor, const std::vector<LabelledFace>& faces,
                                                uint64_t seed, int detector_frames) {
  ShapeRegressorEvaluation e;
  Rng rng(seed);
  double predict_s = 0;
  for (const LabelledFace& f : faces) {
    const MatX2d init_t = PerturbedTruth(f.landmarks, regressor.options, rng);
    const ScopedTimer timer(nullptr, "");
    const MatX2d out_t = regressor.Predict(f.image, init_t);
    predict_s += timer.Elapsed();
    Accumulate(init_t, out_t, f.landmarks, &e.tracking);
    const MatX2d init_b = regressor.MeanShapeInBox(JitteredBox(f.landmarks, regressor.options, rng));
    Accumulate(init_b, regressor.Predict(f.image, init_b), f.landmarks, &e.box);
  }
  Finish(&e.tracking);
  Finish(&e.box);
  e.predict_ms = faces.empty() ? 0.0 : 1e3 * predict_s / static_cast<double>(faces.size());
  if (detector_frames > 0) {
    RegressorLandmarkSource source(regressor);
    const size_t n = std::min<size_t>(static_cast<size_t>(detector_frames), faces.size());
    e.detector = EvaluateLandmarkSource(
        source, std::vector<LabelledFace>(faces.begin(), faces.begin() + static_cast<std::ptrdiff_t>(n)));
  }
  return e;
}

SequenceTrackingEvaluation EvaluateSequenceTracking(const ShapeRegressor& regressor,
                                                    const std::vector<LabelledFace>& frames) {
  SequenceTrackingEvaluation e;
  RegressorLandmarkSource source(regressor);
  double sum_iod = 0, sum_px = 0, track_s = 0;
  int tracked = 0;
  for (const LabelledFace& f : frames) {
    const ScopedTimer timer(nullptr, "");
    const LandmarkResult r = source.Track(f.image);
    const double s = timer.Elapsed();
    ++e.frames;
    if (r.detected) {
      ++e.detections;
    } else {
      track_s += s;
      ++tracked;
    }
    if (!r.found) continue;
    ++e.found;
    const double err = MeanError(r.points, f.landmarks);
    sum_px += err;
    sum_iod += err / Iod(f.landmarks);
  }
  if (e.found) {
    e.error_iod = sum_iod / e.found;
    e.error_px = sum_px / e.found;
  }
  e.track_ms = tracked ? 1e3 * track_s / tracked : 0.0;
  return e;
}

}  // namespace crease
