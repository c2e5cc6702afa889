// Training the landmark tracker on labelled photographs (pipeline/capture/tracker_training.h)
// and its held-out evaluation (landmark_evaluation.h). This executable links
// crease_capture and crease_core only: the photo path must not need the studio
// (crease_synth) — a dependency on it fails to link here.
#include "pipeline/capture/tracker_training.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <vector>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "pipeline/capture/landmark_evaluation.h"
#include "tests/test_util.h"
#include "tests/toy_faces.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::MakeToy;
using testing::TestDir;
using testing::ToyFaces;

TrackerTrainingOptions TinyTrackerOptions() {
  TrackerTrainingOptions o;
  o.max_detector_tests = 0;  // no HOG face in the toy images
  o.test_fraction = 0.25;
  o.regressor.num_stages = 6;
  o.regressor.num_ferns = 40;
  o.regressor.fern_depth = 4;
  o.regressor.num_sampled_pixels = 80;
  o.regressor.shrinkage = 20;
  o.regressor.augmentation = 8;
  return o;
}

// A folder of NAME.png + NAME.pts "photographs": the last quarter is held out, and
// the trained regressor moves the mean shape in a jittered box (and the perturbed
// truth) closer to the truth on the held-out faces.
TEST(TrackerTraining, TrainsOnAPhotoFolderAndBeatsTheMeanShapeOnHeldOutFaces) {
  const auto dir = TestDir();
  WriteLabelledFaces(dir, ToyFaces(MakeToy(80, 11, testing::kLevelEyesPhase), "photo"));
  const TrackerTrainingResult r = TrainTrackerOnFolder(dir, TinyTrackerOptions());
  const TrackerTrainingReport& rep = r.report;
  std::printf("%s", rep.ToText().c_str());
  EXPECT_EQ(rep.train_images, 60);
  EXPECT_EQ(rep.test_images, 20);
  EXPECT_EQ(rep.training.train_images, 60);
  EXPECT_EQ(rep.held_out.box.frames, 20);
  EXPECT_EQ(rep.held_out.detector.faces, 0);
  EXPECT_LT(rep.held_out.box.final_iod, 0.85 * rep.held_out.box.initial_iod);
  EXPECT_LT(rep.held_out.tracking.final_iod, 0.75 * rep.held_out.tracking.initial_iod);
  EXPECT_GT(rep.held_out.box.initial_px, rep.held_out.box.final_px);
  // The report's JSON carries the same numbers.
  const nlohmann::json j = nlohmann::json::parse(rep.ToJson());
  EXPECT_EQ(j["held_out_box"]["final_iod"].get<double>(), rep.held_out.box.final_iod);
  EXPECT_EQ(j["test_images"].get<int>(), 20);
  EXPECT_NE(rep.ToText().find("held-out (20 images)"), std::string::npos);
}

// The method alone: same faces and options, same regressor; the training facts
// count the faces; a split folder (train/, test/) is read as it is.
TEST(TrackerTraining, DeterministicMethodAndSplitFolders) {
  const auto dir = TestDir();
  WriteLabelledFaces(dir / "train", ToyFaces(MakeToy(12, 3), "a"));
  WriteLabelledFaces(dir / "test", ToyFaces(MakeToy(3, 4), "b"));
  const LabelledSplit split = ReadLabelledSplit(dir, 0.5);
  ASSERT_EQ(split.train.size(), 12u);
  ASSERT_EQ(split.test.size(), 3u);
  EXPECT_EQ(split.test[0].name, "b0");
  const TrainedTracker a = TrainTrackerOnFaces(split.train, TinyTrackerOptions());
  const TrainedTracker b = TrainTrackerOnFaces(split.train, TinyTrackerOptions());
  EXPECT_TRUE(a.regressor == b.regressor);
  EXPECT_EQ(a.summary.train_images, 12);
  EXPECT_EQ(a.summary.regressor.num_samples, 12 * 8);
  // Held-out evaluation is its own call and repeats for the same seed.
  const ShapeRegressorEvaluation e1 = EvaluateShapeRegressor(a.regressor, split.test, 5, 0);
  const ShapeRegressorEvaluation e2 = EvaluateShapeRegressor(a.regressor, split.test, 5, 0);
  EXPECT_EQ(e1.tracking.frames, 3);
  EXPECT_EQ(e1.box.final_iod, e2.box.final_iod);
  EXPECT_EQ(e1.tracking.initial_px, e2.tracking.initial_px);
}

TEST(TrackerTraining, RefusesTooFewFaces) {
  const auto dir = TestDir();
  WriteLabelledFaces(dir, ToyFaces(MakeToy(1, 2), "one"));
  EXPECT_NE(ErrorOf([&] { ReadLabelledSplit(dir, 0.2); }).find("need at least two labelled faces"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { TrainAndEvaluateTracker(ToyFaces(MakeToy(2, 2), "x"), {}, TinyTrackerOptions()); })
                .find("must not be empty"),
            std::string::npos);
}

// `crease eval-landmarks`' report (EvaluateLandmarks): a source per cold start and the
// regressor's two initialisations, reported as the evaluations computed them.
TEST(TrackerTraining, LandmarkEvaluationReportsTheEvaluationsItRan) {
  const TrainedTracker t = TrainTrackerOnFaces(ToyFaces(MakeToy(12, 3), "a"), TinyTrackerOptions());
  const std::vector<LabelledFace> faces = ToyFaces(MakeToy(4, 4), "b");
  const LandmarkEvaluationReport r = EvaluateLandmarks(faces, "toys", /*dlib=*/false, &t.regressor, 5);
  EXPECT_EQ(r.faces, 4);
  ASSERT_EQ(r.sources.size(), 1u);
  ASSERT_TRUE(r.has_regressor);
  // The same seed, the same draws: the report holds EvaluateShapeRegressor's numbers.
  const ShapeRegressorEvaluation e = EvaluateShapeRegressor(t.regressor, faces, 5, 0);
  EXPECT_EQ(r.regressor.tracking.final_iod, e.tracking.final_iod);
  EXPECT_EQ(r.regressor.box.initial_px, e.box.initial_px);
  const nlohmann::json j = nlohmann::json::parse(r.ToJson());
  EXPECT_EQ(j["data"], "toys");
  EXPECT_EQ(j["faces"], 4);
  const std::string source = r.sources[0].source;
  EXPECT_EQ(j[source]["found"], r.sources[0].found);
  EXPECT_EQ(j[source]["error_px"].get<double>(), r.sources[0].error_px);
  EXPECT_EQ(j["regressor_tracking_init"]["final_iod"].get<double>(), e.tracking.final_iod);
  EXPECT_EQ(j["regressor_box_init"]["initial_px"].get<double>(), e.box.initial_px);
  EXPECT_FALSE(j["regressor_box_init"].contains("frames"));
  EXPECT_FALSE(j.contains("dlib"));
  // One line per source, then the regressor's.
  const std::string text = r.ToText();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 2) << text;
  EXPECT_EQ(text.rfind(fmt::format("{:<10} cold start (detector, then landmarks): found {} of 4 faces", source,
                                   r.sources[0].found),
                       0),
            0u)
      << text;
  EXPECT_NE(text.find(fmt::format("regressor  from the perturbed truth: {:.3f} -> {:.3f} IOD", e.tracking.initial_iod,
                                  e.tracking.final_iod)),
            std::string::npos)
      << text;
  // Nothing evaluated: the face count only.
  const LandmarkEvaluationReport none = EvaluateLandmarks(faces, "toys", false, nullptr, 5);
  EXPECT_EQ(none.ToText(), "");
  EXPECT_EQ(nlohmann::json::parse(none.ToJson()), (nlohmann::json{{"data", "toys"}, {"faces", 4}}));
}

TEST(TrackerTraining, ReportPathDefaultsBesideTheModel) {
  EXPECT_EQ(TrackerReportPath("out/tracker.ctrk", ""), std::filesystem::path("out/tracker_report.json"));
  EXPECT_EQ(TrackerReportPath("tracker.ctrk", ""), std::filesystem::path("tracker_report.json"));
  EXPECT_EQ(TrackerReportPath("out/tracker.ctrk", "r/x.json"), std::filesystem::path("r/x.json"));
}

}  // namespace
}  // namespace crease
