// The global face tracker (issue 5): frame sources, and the tracker on a studio
// sequence measured against its ground truth.
#include "pipeline/capture/tracker.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <opencv2/videoio.hpp>
#include <unistd.h>

#include "core/image_io.h"
#include "core/options.h"
#include "eval/tracking_metrics.h"
#include "pipeline/capture/frame_source.h"
#include "synth/dataset.h"
#include "synth/procedural_rig.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using testing::WriteText;

const FaceRig& Rig() { return testing::ProceduralRig(); }

// 24 frames of the `talking` preset at 320×240 under front light, no maps: written once per process.
const fs::path& Talking() {
  static const fs::path dir = [] {
    const fs::path d = testing::FixtureDir("tracker_talking");
    ActorOptions ao;
    ao.resolution = 256;
    ao.surface_min_vertices = 1000;
    const Actor actor = GenerateActor(Rig(), 5, ao);
    SequenceDatasetOptions o;
    o.studio.samples_per_axis = 1;
    o.studio.light = "front";  // directional: fast to render
    o.studio.width = 320;
    o.studio.height = 240;
    o.write_maps = false;
    o.max_frames = 24;
    o.overwrite = true;
    o.ignore_missing_expressions = true;
    WriteSequenceDataset(Rig(), actor, MakePresetSequence("talking"), o, d);
    return d;
  }();
  return dir;
}

TEST(FrameSource, ImageFoldersVideosAndErrors) {
  const fs::path dir = testing::TestDir();
  cv::Mat im(48, 64, CV_32FC3, cv::Scalar(0.2, 0.4, 0.6));
  fs::create_directories(dir / "images");
  for (int i = 0; i < 3; ++i) WriteImage(dir / "images" / ("f" + std::to_string(i) + ".png"), im);
  auto images = OpenFrameSource(dir / "images");
  EXPECT_EQ(images->info().kind, "images");
  EXPECT_EQ(images->info().frame_count, 3);
  cv::Mat f;
  int n = 0;
  while (images->Next(&f)) {
    ++n;
    EXPECT_EQ(f.type(), CV_32FC3);
    EXPECT_NEAR(f.at<cv::Vec3f>(10, 10)[1], 0.4f, 0.01f);
  }
  EXPECT_EQ(n, 3);
  // A video written with OpenCV reads back frame by frame.
  {
    cv::VideoWriter w((dir / "clip.avi").string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25, cv::Size(64, 48));
    ASSERT_TRUE(w.isOpened());
    for (int i = 0; i < 5; ++i) w.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(40 * i, 100, 200)));
  }
  auto video = OpenFrameSource(dir / "clip.avi");
  EXPECT_EQ(video->info().kind, "video");
  EXPECT_EQ(video->info().width, 64);
  n = 0;
  while (video->Next(&f)) ++n;
  EXPECT_EQ(n, 5);
  // Errors.
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "none.mp4"), "does not exist");
  fs::create_directories(dir / "empty");
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "empty"), "no images");
  WriteText(dir / "not_a_video.mp4", "hello");
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "not_a_video.mp4"), "not_a_video.mp4");
  // Issue 19 (fuzz/dataset_json_fuzzer): a dataset.json that is not an object, or whose
  // fps is not a positive number, is an error naming the file (nlohmann's type_error,
  // an internal error, before); core/dataset_info.h reads it.
  WriteImage(dir / "ds" / "frames" / "000000.png", im);
  const std::string ds_json = (dir / "ds" / "dataset.json").string();
  const std::string head = R"({"format": "crease synthetic sequence", "version": 1, "frames": 1, "width": 64, "height": 48)";
  WriteText(dir / "ds" / "dataset.json", head + R"(, "fps": 24})");
  EXPECT_EQ(OpenFrameSource(dir / "ds")->info().fps, 24.0);
  WriteText(dir / "ds" / "dataset.json", "[1, 2]");
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "ds"), ds_json + ": must be a JSON object");
  WriteText(dir / "ds" / "dataset.json", head + R"(, "fps": "fast"})");
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "ds"), ds_json + ": fps must be a number in (0, 1000], not \"fast\"");
  WriteText(dir / "ds" / "dataset.json", head + R"(, "fps": 0})");
  EXPECT_ERROR_HAS(OpenFrameSource(dir / "ds"), ds_json + ": fps must be a number in (0, 1000], not 0");
}

// Runs the tracker over the talking sequence and returns the mean errors.
FrameTrackingError TrackTalking(std::unique_ptr<LandmarkSource> source, int* tracked) {
  auto frames = OpenFrameSource(Talking());
  EXPECT_EQ(frames->info().kind, "dataset");
  EXPECT_TRUE(frames->info().camera.has_value());
  TrackerOptions options;
  FaceTracker tracker(Rig(), frames->info().camera->intrinsics, std::move(source), options);
  FrameTrackingError sum;
  cv::Mat f;
  *tracked = 0;
  while (frames->Next(&f)) {
    const TrackedFrame t = tracker.Track(f);
    if (!t.tracked) continue;
    ++*tracked;
    const Camera cam(frames->info().camera->intrinsics, t.fit.cam_from_head);
    const FrameTruth truth = ReadFrameTruth(Talking(), t.frame, Rig().num_vertices());
    const FrameTrackingError e = CompareToTruth(truth, t.landmarks, tracker.fitter().ProjectLandmarks(t.fit),
                                                cam.ProjectAll(tracker.fitter().HeadVertices(t.fit)));
    sum.landmark_px += e.landmark_px;
    sum.fit_landmark_px += e.fit_landmark_px;
    sum.vertex_px += e.vertex_px;
  }
  if (*tracked > 0) {
    sum.landmark_px /= *tracked;
    sum.fit_landmark_px /= *tracked;
    sum.vertex_px /= *tracked;
  }
  return sum;
}

// The studio's truth landmarks as the source: the rig's best explanation of the
// truth must be close to it (this bounds the fit, independent of any detector).
class TruthSource final : public LandmarkSource {
 public:
  LandmarkResult Track(const cv::Mat&) override {
    LandmarkResult r;
    r.found = true;
    r.points = ReadFrameTruth(Talking(), frame_++, Rig().num_vertices()).landmarks;
    return r;
  }
  void Reset() override {}
  std::string name() const override { return "truth"; }

 private:
  int frame_ = 0;
};

// Records what the tracker hands the source for the next frame.
class RecordingSource final : public LandmarkSource {
 public:
  LandmarkResult Track(const cv::Mat& image) override { return truth_.Track(image); }
  void Reset() override {}
  void SetNextInitialisation(const MatX2d& shape) override { inits.push_back(shape); }
  std::string name() const override { return "recording"; }
  std::vector<MatX2d> inits;

 private:
  TruthSource truth_;
};

// DDE: with init_from_fit the next frame starts from the rig fit's projected
// landmarks; without it the source is left alone.
TEST(Tracker, PassesTheFittedLandmarksOnAsTheNextInitialisation) {
  for (const bool init_from_fit : {true, false}) {
    auto frames = OpenFrameSource(Talking());
    TrackerOptions options;
    options.init_from_fit = init_from_fit;
    auto source = std::make_unique<RecordingSource>();
    const RecordingSource* recording = source.get();
    FaceTracker tracker(Rig(), frames->info().camera->intrinsics, std::move(source), options);
    cv::Mat f;
    for (int i = 0; i < 3 && frames->Next(&f); ++i) {
      const TrackedFrame t = tracker.Track(f);
      ASSERT_TRUE(t.tracked);
      if (!init_from_fit) continue;
      ASSERT_EQ(recording->inits.size(), static_cast<size_t>(i + 1));
      const MatX2d& init = recording->inits.back();
      ASSERT_EQ(init.rows(), 68);
      EXPECT_LT((init - tracker.fitter().ProjectLandmarks(t.fit)).cwiseAbs().maxCoeff(), 1e-9);
    }
    if (!init_from_fit) {
      EXPECT_TRUE(recording->inits.empty());
    }
  }
}

TEST(Tracker, FitsTheTruthLandmarksOfAStudioSequence) {
  int tracked = 0;
  const FrameTrackingError e = TrackTalking(std::make_unique<TruthSource>(), &tracked);
  std::printf("truth landmarks: fitted landmarks %.2f px, visible vertices %.2f px over %d frames\n", e.fit_landmark_px,
              e.vertex_px, tracked);
  EXPECT_EQ(tracked, 24);
  EXPECT_LT(e.fit_landmark_px, 2.0);
  EXPECT_LT(e.vertex_px, 4.0);
}

TEST(Tracker, DlibOnAStudioSequence) {
  int tracked = 0;
  const FrameTrackingError e = TrackTalking(std::make_unique<DlibLandmarkSource>(), &tracked);
  std::printf("dlib: landmarks %.2f px, fitted landmarks %.2f px, visible vertices %.2f px over %d frames\n",
              e.landmark_px, e.fit_landmark_px, e.vertex_px, tracked);
  EXPECT_GE(tracked, 20);
  EXPECT_LT(e.landmark_px, 15.0);
  EXPECT_LT(e.vertex_px, 15.0);
}

// The `occlusion` preset, 2 s: a ball passes in front of the face (frames ~15–45 of 60).
// Whatever the tracker does while the face is hidden, it must be back on the face,
// with the error of an unoccluded frame, once the ball has gone.
TEST(Tracker, RecoversAfterTheOcclusionPreset) {
  const fs::path d = testing::TestDir() / "occlusion";
  ActorOptions ao;
  ao.resolution = 256;
  ao.surface_min_vertices = 1000;
  SequenceDatasetOptions o;
  o.studio.samples_per_axis = 1;
  o.studio.light = "front";
  o.studio.width = 320;
  o.studio.height = 240;
  o.write_maps = false;
  o.ignore_missing_expressions = true;
  WriteSequenceDataset(Rig(), GenerateActor(Rig(), 8, ao), MakePresetSequence("occlusion", 2.0), o, d);
  auto frames = OpenFrameSource(d);
  ASSERT_TRUE(frames->info().camera.has_value()) << d / "camera.json";
  FaceTracker tracker(Rig(), frames->info().camera->intrinsics, std::make_unique<DlibLandmarkSource>(), TrackerOptions{});
  cv::Mat f;
  int lost_while_occluded = 0, occluded = 0, recovered = 0, late = 0, early = 0, max_hidden = 0;
  double late_error = 0.0, early_error = 0.0;
  while (frames->Next(&f)) {
    const TrackedFrame t = tracker.Track(f);
    const FrameTruth truth = ReadFrameTruth(d, t.frame, Rig().num_vertices());
    int hidden = 0;
    for (char v : truth.landmark_visible) hidden += !v;
    max_hidden = std::max(max_hidden, hidden);
    if (hidden > 34) {
      ++occluded;
      lost_while_occluded += !t.tracked;
    }
    if (t.frame < 10 && t.tracked) {
      ++early;
      early_error += (t.landmarks - truth.landmarks).rowwise().norm().mean();
    }
    if (t.frame >= 48) {
      ++late;
      if (t.tracked) {
        ++recovered;
        late_error += (t.landmarks - truth.landmarks).rowwise().norm().mean();
      }
    }
  }
  std::printf("occlusion: %d occluded frames (%d of them lost), %d of the last %d frames tracked, error %.2f px "
              "(before the occlusion %.2f px)\n",
              occluded, lost_while_occluded, recovered, late, recovered ? late_error / recovered : 0.0,
              early ? early_error / early : 0.0);
  EXPECT_GT(occluded, 3);
  EXPECT_EQ(max_hidden, 68);  // mid-pass the ball hides the whole face
  ASSERT_EQ(early, 10);
  EXPECT_EQ(recovered, late);
  // As good as before the ball came (dlib's own error on this face is ~11 px at 320×240).
  EXPECT_LT(late_error / std::max(recovered, 1), 1.3 * early_error / early + 2.0);
}

TEST(Tracker, NoFaceIsALossNotACrash) {
  TrackerOptions options;
  FaceTracker tracker(Rig(), CameraIntrinsics::FromFov(50, 320, 240), std::make_unique<DlibLandmarkSource>(), options);
  const cv::Mat blank(240, 320, CV_32FC3, cv::Scalar(0.3, 0.3, 0.3));
  for (int i = 0; i < 3; ++i) {
    const TrackedFrame t = tracker.Track(blank);
    EXPECT_FALSE(t.tracked);
    EXPECT_TRUE(t.detected);
    EXPECT_EQ(t.confidence, 0.0);
  }
  TrackerOptions bad;
  bad.landmark_source = LandmarkSourceKind::kRegressor;
  EXPECT_ERROR_HAS(bad.Check(), "tracker_model");
  EXPECT_ERROR_HAS(SetOptionsFromJson(R"({"landmark_source": "oracle"})", "test", &bad),
                   "test: option 'landmark_source' must be one of: dlib, regressor, got \"oracle\"");
}

}  // namespace
}  // namespace crease
