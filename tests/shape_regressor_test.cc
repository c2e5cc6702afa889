#include "pipeline/capture/shape_regressor.h"

#include <gtest/gtest.h>

#include <fstream>

#include <opencv2/core.hpp>
#include <tbb/global_control.h>

#include "core/ibug.h"
#include "eval/tracker_renders.h"
#include "synth/procedural_rig.h"
#include "tests/test_util.h"
#include "tests/toy_faces.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::MakeToy;
using testing::TestDir;
using testing::Toy;
using testing::ToyFaces;

ShapeRegressorOptions TinyOptions() {
  ShapeRegressorOptions o;
  o.num_stages = 3;
  o.num_ferns = 20;
  o.fern_depth = 4;
  o.num_sampled_pixels = 60;
  o.shrinkage = 20;
  o.augmentation = 4;
  return o;
}

TEST(ShapeRegressor, OptionsAreChecked) {
  ShapeRegressorOptions o;
  EXPECT_NO_THROW(o.Check());
  o.fern_depth = 0;
  EXPECT_NE(ErrorOf([&] { o.Check(); }).find("fern_depth"), std::string::npos);
  o = {};
  o.tracking_fraction = 1.5;
  EXPECT_NE(ErrorOf([&] { o.Check(); }).find("tracking_fraction"), std::string::npos);
}

TEST(ShapeRegressor, MeanShapeIsNormalised) {
  const Toy toy = MakeToy(10, 3);
  const MatX2d mean = MeanShapeOf(toy.shapes);
  EXPECT_NEAR(mean.colwise().mean().norm(), 0.0, 1e-9);
  EXPECT_NEAR(InterOcularDistance(mean), 1.0, 1e-9);
  EXPECT_NEAR(mean(kIbugLeftEyeOuter, 1) - mean(kIbugRightEyeOuter, 1), 0.0, 1e-9);  // eyes horizontal
}

TEST(ShapeRegressor, DeterministicSaveLoadRoundTripAndVersionCheck) {
  const Toy toy = MakeToy(30, 1);
  const ShapeRegressorOptions o = TinyOptions();
  const ShapeRegressorTrainingResult a = TrainShapeRegressor(toy.images, toy.shapes, o);
  const ShapeRegressorTrainingResult b = TrainShapeRegressor(toy.images, toy.shapes, o);
  EXPECT_TRUE(a.regressor == b.regressor);  // same seed, same model
  ShapeRegressorOptions o2 = o;
  o2.seed = 2;
  EXPECT_FALSE(TrainShapeRegressor(toy.images, toy.shapes, o2).regressor == a.regressor);
  // Training error falls stage by stage on this easy problem.
  ASSERT_EQ(a.report.train_error_iod.size(), 4u);
  EXPECT_LT(a.report.train_error_iod.back(), 0.8 * a.report.train_error_iod.front());

  const auto dir = TestDir();
  ShapeRegressor calibrated = a.regressor;
  calibrated.detector_box = Eigen::Vector3d(-0.01, 0.11, 0.94);
  SaveShapeRegressor(dir / "c.ctrk", calibrated);
  EXPECT_TRUE(LoadShapeRegressor(dir / "c.ctrk") == calibrated);  // the detector box travels in the header
  const FaceBox moved = calibrated.FromDetectorBox({100, 50, 80, 80, 1.0});
  EXPECT_NEAR(moved.x + 0.5 * moved.width, 140.0 - 0.8, 1e-9);
  EXPECT_NEAR(moved.y + 0.5 * moved.height, 90.0 + 8.8, 1e-9);
  EXPECT_NEAR(moved.width, 75.2, 1e-9);
  SaveShapeRegressor(dir / "r.ctrk", a.regressor);
  const ShapeRegressor loaded = LoadShapeRegressor(dir / "r.ctrk");
  EXPECT_TRUE(loaded == a.regressor);
  const Toy test = MakeToy(5, 99);
  for (size_t i = 0; i < test.images.size(); ++i) {
    const MatX2d init = a.regressor.MeanShapeInBox(BoxOfPoints(test.shapes[i]));
    const MatX2d p = a.regressor.Predict(test.images[i], init), q = loaded.Predict(test.images[i], init);
    EXPECT_TRUE(p == q) << "image " << i;  // bit-identical
  }

  // Another format version is a clear error naming the file and both versions.
  std::fstream f(dir / "r.ctrk", std::ios::in | std::ios::out | std::ios::binary);
  f.seekp(8);
  const uint32_t other = kShapeRegressorFileVersion + 1;
  f.write(reinterpret_cast<const char*>(&other), 4);
  f.close();
  const std::string e = ErrorOf([&] { LoadShapeRegressor(dir / "r.ctrk"); });
  EXPECT_NE(e.find("r.ctrk"), std::string::npos) << e;
  EXPECT_NE(e.find("version " + std::to_string(other)), std::string::npos) << e;
  EXPECT_NE(e.find("version " + std::to_string(kShapeRegressorFileVersion)), std::string::npos) << e;
  // Another kind of file.
  testing::WriteText(dir / "bad.ctrk", "CREASDML and more bytes");
  EXPECT_NE(ErrorOf([&] { LoadShapeRegressor(dir / "bad.ctrk"); }).find("bad magic"), std::string::npos);
}

TEST(ShapeRegressor, SameModelForAnyThreadCount) {
  const Toy toy = MakeToy(20, 4);
  ShapeRegressor one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = TrainShapeRegressor(toy.images, toy.shapes, TinyOptions()).regressor;
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = TrainShapeRegressor(toy.images, toy.shapes, TinyOptions()).regressor;
  }
  EXPECT_TRUE(one == two);
}

TEST(ShapeRegressor, LandmarkSourceFlagsLostShapes) {
  const Toy toy = MakeToy(12, 5);
  const ShapeRegressorTrainingResult t = TrainShapeRegressor(toy.images, toy.shapes, TinyOptions());
  RegressorLandmarkSource source(t.regressor);
  const cv::Size size(120, 120);
  EXPECT_FALSE(source.IsLost(toy.shapes[0], size, nullptr));
  MatX2d outside = toy.shapes[0];
  outside.col(0).array() += 200.0;
  EXPECT_TRUE(source.IsLost(outside, size, nullptr));
  MatX2d big = toy.shapes[0];
  big.col(0).array() = (big.col(0).array() - 60) * 1.8 + 60;
  big.col(1).array() = (big.col(1).array() - 60) * 1.8 + 60;
  EXPECT_TRUE(source.IsLost(big, cv::Size(1000, 1000), &toy.shapes[0]));  // scale jump
  MatX2d scrambled = toy.shapes[0];
  scrambled.row(0).swap(scrambled.row(34));
  scrambled.row(10).swap(scrambled.row(50));
  scrambled.row(20).swap(scrambled.row(60));
  scrambled.row(5).swap(scrambled.row(40));
  EXPECT_TRUE(source.IsLost(scrambled, size, nullptr));  // degenerate
  // No face in noise: not found, and the detector ran.
  cv::Mat noise(120, 160, CV_32FC1);
  cv::randu(noise, 0.0f, 1.0f);
  const LandmarkResult r = source.Track(noise);
  EXPECT_FALSE(r.found);
  EXPECT_TRUE(r.detected);
}

// The test: trained on a small set of studio renders, the regressor
// reduces the landmark error of its initialisation on renders of held-out actors.
TEST(ShapeRegressor, ReducesErrorOnHeldOutRenders) {
  const FaceRig rig = BuildProceduralRig();
  TrackerTrainingOptions o;
  o.width = 160;
  o.height = 120;
  o.fov_deg = 32;
  o.renders_per_actor = 16;
  o.actor_resolution = 128;
  o.max_detector_tests = 0;
  o.regressor.num_stages = 5;
  o.regressor.num_ferns = 40;
  o.regressor.fern_depth = 4;
  o.regressor.num_sampled_pixels = 150;
  o.regressor.shrinkage = 40;
  o.regressor.augmentation = 8;
  const std::vector<LabelledFace> train = RenderLabelledFaces(rig, {11, 12, 13, 14, 15, 16}, o);
  const std::vector<LabelledFace> test = RenderLabelledFaces(rig, {21, 22}, o);
  ASSERT_EQ(train.size(), 96u);
  const TrackerTrainingResult r = TrainAndEvaluateTracker(train, test, o);
  const TrackerTrainingReport& rep = r.report;
  std::printf("%s", rep.ToText().c_str());
  EXPECT_EQ(rep.held_out.tracking.frames, 32);
  // The HOG detector's box is fitted onto the landmark box on the training renders;
  // dlib's box reaches higher (the forehead) than the 68 points do.
  EXPECT_GT(rep.training.detector_calibration_faces, 10);
  EXPECT_GT(rep.training.detector_box.y(), 0.02);
  EXPECT_LT(rep.held_out.tracking.final_iod, 0.7 * rep.held_out.tracking.initial_iod);
  EXPECT_LT(rep.held_out.box.final_iod, 0.8 * rep.held_out.box.initial_iod);
  EXPECT_LT(rep.training.regressor.train_error_iod.back(), rep.training.regressor.train_error_iod.front());
}

// Labelled photographs (here two toy faces) join the studio renders for training.
TEST(ShapeRegressor, ExtraLabelledFacesJoinTheTrainingRenders) {
  const FaceRig rig = BuildProceduralRig();
  TrackerTrainingOptions o;
  o.width = 96;
  o.height = 72;
  o.train_actors = 1;
  o.test_actors = 1;
  o.renders_per_actor = 2;
  o.actor_resolution = 64;
  o.max_detector_tests = 0;
  o.regressor.num_stages = 1;
  o.regressor.num_ferns = 4;
  o.regressor.augmentation = 2;
  const std::vector<LabelledFace> extra = ToyFaces(MakeToy(2, 3), "photo");
  const auto dir = TestDir();
  const TrackerTrainingResult r = TrainTrackerOnRenders(rig, o, dir, extra);
  EXPECT_EQ(r.report.train_images, 4);
  EXPECT_EQ(r.report.test_images, 2);
  EXPECT_EQ(ReadLabelledFaces(dir / "train").size(), 4u);  // saved with the renders
}

}  // namespace
}  // namespace crease
