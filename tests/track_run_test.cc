// The tracking run (eval/track_run.h; issue 18): RunTracking on a tiny studio sequence
// (5 frames of 160×120) with the ground-truth-prior control writes the folder
// `crease track` writes, counts its frames, and measures the landmark error it was
// given: none without noise, σ·√(π/2) with Gaussian noise of σ px per axis. The
// ground-truth-fit and ground-truth-surface controls (eval/frame_tracker.h) give
// L^t with and without the actor's personal expression deviations.
#include "eval/track_run.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/camera.h"
#include "core/error.h"
#include "core/json_io.h"
#include "eval/tracking_metrics.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 5;

const FaceRig& Rig() { return testing::ProceduralRig(); }

fs::path TinySequence() {
  static const fs::path dir = testing::TinySequenceDataset("track_run_sequence", "talking", kFrames);
  return dir;
}

// RunTracking of the tiny sequence under the ground-truth-prior control with `noise_px`.
TrackSummary Track(const fs::path& out, double noise_px, bool meshes) {
  auto frames = OpenFrameSource(TinySequence().string());
  const CameraIntrinsics K = ResolveIntrinsics("", frames->info(), 50.0);
  TrackerOptions options;
  TrackingControl control;
  control.ground_truth_prior = true;
  control.noise_px = noise_px;
  FrameTracker tracker(Rig(), K, options, control, TinySequence());
  TrackRunOptions run;
  run.out = out;
  run.write_meshes = meshes;
  run.input = TinySequence().string();
  return RunTracking(run, options, Rig(), K, frames.get(), &tracker);
}

TEST(TrackRun, WritesTheFolderAndMeasuresTheLandmarkErrorItWasGiven) {
  const fs::path out = testing::TestDir() / "exact";
  const TrackSummary s = Track(out, 0.0, true);
  EXPECT_EQ(s.frames, kFrames);
  EXPECT_EQ(s.tracked_frames, kFrames);
  EXPECT_EQ(s.landmark_source, "ground-truth-prior");
  EXPECT_EQ(s.correspondence_matched, -1);  // tracked with the dataset's own rig
  ASSERT_EQ(s.error.frames, kFrames);
  EXPECT_LT(s.error.landmark_px, 1e-9);  // the truth's landmarks themselves
  EXPECT_GT(s.error.fit_landmark_px, 0.0);  // the rig fit to them is not exact (the actor's deviations)
  for (int f = 0; f < kFrames; ++f) {
    EXPECT_TRUE(fs::exists(out / "frames" / fmt::format("{:06d}.json", f))) << f;
    EXPECT_TRUE(fs::exists(out / "meshes" / fmt::format("{:06d}.vtp", f))) << f;
  }
  EXPECT_TRUE(fs::exists(out / "tracking.pvd"));
  const nlohmann::json summary = ReadJsonFile(out / "summary.json");
  EXPECT_EQ(summary.dump(2), s.ToJson());
  EXPECT_EQ(summary["error"]["frames"], kFrames);

  // σ = 2 px per axis: the mean distance is σ·√(π/2) = 2.51 px (340 draws: ±0.07).
  const TrackSummary noisy = Track(testing::TestDir() / "noisy", 2.0, false);
  EXPECT_NEAR(noisy.error.landmark_px, 2.0 * std::sqrt(std::numbers::pi / 2.0), 0.3);
  EXPECT_GT(noisy.error.fit_landmark_px, s.error.fit_landmark_px);
  EXPECT_FALSE(fs::exists(testing::TestDir() / "noisy" / "meshes"));
}

// The mean distance, px, of the projected L^t of every frame that `control` gives
// (on ControlRig: the dataset's rig, or the actor's own shapes) to the truth's vertices.
double ControlVertexPx(const TrackingControl& control) {
  auto frames = OpenFrameSource(TinySequence().string());
  const CameraIntrinsics K = ResolveIntrinsics("", frames->info(), 50.0);
  const FaceRig rig = ControlRig(Rig(), control, TinySequence());
  FrameTracker tracker(rig, K, TrackerOptions(), control, TinySequence());
  double sum = 0.0;
  cv::Mat image;
  while (frames->Next(&image)) {
    const TrackedFrame t = tracker.Track(image, frames->index());
    const MatX2d projected = Camera(K, t.fit.cam_from_head).ProjectAll(rig.EvaluatePositions(tracker.identity(), t.fit.expression));
    const FrameTruth truth = ReadFrameTruth(TinySequence(), t.frame, rig.num_vertices());
    sum += CompareToTruth(truth, t.landmarks, t.landmarks, projected).vertex_px;
  }
  return sum / kFrames;
}

// Issue 17's exact-geometry control: the truth's weights on the dataset's rig
// (--ground-truth-fit) leave the actor's personal expression deviations as model
// error; on the actor's own expression shapes (--ground-truth-surface) L^t is the
// true coarse surface.
TEST(TrackRun, TheGroundTruthSurfaceIsExactWhereTheFitKeepsTheDeviations) {
  TrackingControl fit;
  fit.ground_truth_fit = true;
  TrackingControl surface;
  surface.ground_truth_surface = true;
  const double fit_px = ControlVertexPx(fit);
  const double surface_px = ControlVertexPx(surface);
  EXPECT_LT(surface_px, 1e-3);
  EXPECT_GT(fit_px, 20.0 * surface_px + 0.01);
  EXPECT_EQ(ControlRig(Rig(), fit, TinySequence()).expression_basis, Rig().expression_basis);
  TrackingControl both = fit;
  both.ground_truth_surface = true;
  EXPECT_NE(testing::ErrorOf([&] { FrameTracker(Rig(), CameraIntrinsics::FromFov(50, 160, 120), TrackerOptions(), both,
                                                TinySequence()); })
                .find("--ground-truth-fit and --ground-truth-surface exclude each other"), std::string::npos);
}

TEST(TrackRun, NoFramesAndAnUnwritablePreviewAreErrors) {
  auto frames = OpenFrameSource(TinySequence().string());
  const CameraIntrinsics K = ResolveIntrinsics("", frames->info(), 50.0);
  TrackerOptions options;
  TrackingControl control;
  control.ground_truth_prior = true;
  FrameTracker tracker(Rig(), K, options, control, TinySequence());
  TrackRunOptions run;
  run.out = testing::TestDir() / "none";
  run.max_frames = 0;
  run.input = "tiny-input";
  EXPECT_NE(testing::ErrorOf([&] { RunTracking(run, options, Rig(), K, frames.get(), &tracker); })
                .find("tiny-input: no frames"), std::string::npos);
  run.max_frames = -1;
  run.preview = (testing::TestDir() / "missing" / "folder" / "p.avi").string();
  EXPECT_NE(testing::ErrorOf([&] { RunTracking(run, options, Rig(), K, frames.get(), &tracker); })
                .find("cannot write this video"), std::string::npos);
  run.out.clear();
  EXPECT_NE(testing::ErrorOf([&] { RunTracking(run, options, Rig(), K, frames.get(), &tracker); })
                .find("output folder is empty"), std::string::npos);
}

}  // namespace
}  // namespace crease
