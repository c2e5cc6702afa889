#include "pipeline/capture/shape_regressor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/global_control.h>

#include "core/ibug.h"
#include "core/rng.h"
#include "eval/tracker_training.h"
#include "synth/procedural_rig.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;

// A cheap learnable toy problem (no rendering): 68 points on an ellipse-like
// contour under a random similarity, drawn as bright dots on a noisy dark image.
struct Toy {
  std::vector<cv::Mat> images;
  std::vector<MatX2d> shapes;
};

Toy MakeToy(int count, uint64_t seed) {
  Rng rng(seed);
  MatX2d base(68, 2);
  for (int i = 0; i < 68; ++i) {
    const double a = 2 * std::numbers::pi * i / 68.0;
    base.row(i) << 30 * std::cos(a) + 4 * std::cos(3 * a), 36 * std::sin(a) + 3 * std::sin(2 * a);
  }
  Toy toy;
  for (int k = 0; k < count; ++k) {
    const double s = std::exp(rng.Normal(0, 0.08)), ang = rng.Normal(0, 0.1);
    const double cx = 60 + rng.Normal(0, 5), cy = 60 + rng.Normal(0, 5);
    MatX2d shape(68, 2);
    for (int i = 0; i < 68; ++i) {
      const double x = base(i, 0) + rng.Normal(0, 1.5), y = base(i, 1) + rng.Normal(0, 1.5);
      shape.row(i) << cx + s * (std::cos(ang) * x - std::sin(ang) * y), cy + s * (std::sin(ang) * x + std::cos(ang) * y);
    }
    cv::Mat img(120, 120, CV_32FC1);
    cv::randu(img, 0.0f, 0.15f);
    for (int i = 0; i < 68; ++i) cv::circle(img, cv::Point2d(shape(i, 0), shape(i, 1)), 2, cv::Scalar(0.9), cv::FILLED);
    toy.images.push_back(img);
    toy.shapes.push_back(shape);
  }
  return toy;
}

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

// The toy's images as 8-bit RGB labelled faces named PREFIX0, PREFIX1, …
std::vector<LabelledFace> ToyFaces(const Toy& toy, const std::string& prefix) {
  std::vector<LabelledFace> faces(toy.images.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    faces[i].name = prefix + std::to_string(i);
    cv::Mat rgb;
    cv::cvtColor(toy.images[i], rgb, cv::COLOR_GRAY2RGB);
    rgb.convertTo(faces[i].image, CV_8UC3, 255.0);
    faces[i].landmarks = toy.shapes[i];
  }
  return faces;
}

TEST(ShapeRegressor, LabelledFaceFolderRoundTrip) {
  const Toy toy = MakeToy(2, 7);
  const std::vector<LabelledFace> faces = ToyFaces(toy, "face");
  const auto dir = TestDir();
  WriteLabelledFaces(dir, faces);
  const std::vector<LabelledFace> back = ReadLabelledFaces(dir);
  ASSERT_EQ(back.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(back[i].name, faces[i].name);
    EXPECT_EQ(cv::norm(back[i].image, faces[i].image, cv::NORM_INF), 0.0);
    EXPECT_LT((back[i].landmarks - faces[i].landmarks).cwiseAbs().maxCoeff(), 1e-4);
  }
  testing::WriteText(dir / "face1.pts", "version: 1\nn_points: 68\n{\n1 2\n}\n");
  EXPECT_NE(ErrorOf([&] { ReadLabelledFaces(dir); }).find("face1.pts: point 2"), std::string::npos);
}

// dlib's imglab XML (its 300-W release and example faces): each labelled box becomes
// a crop of known scale whose pixels and landmarks agree; ignored and incomplete
// boxes are skipped; errors name the file and line.
TEST(ShapeRegressor, DlibXmlFacesAreCroppedAroundTheirBoxes) {
  const auto dir = TestDir();
  // A 300×200 image with a bright dot at every part of a face in the box
  // (left 100, top 50, 80×80): a ring of 68 points.
  cv::Mat image(200, 300, CV_8UC3, cv::Scalar::all(0));
  std::string parts;
  MatX2d truth(68, 2);
  for (int k = 0; k < 68; ++k) {
    const double a = 2.0 * std::numbers::pi * k / 68.0;
    const int x = static_cast<int>(std::lround(140 + 30 * std::cos(a))), y = static_cast<int>(std::lround(90 + 30 * std::sin(a)));
    truth.row(k) << x, y;
    image.at<cv::Vec3b>(y, x) = cv::Vec3b(255, 255, 255);
    parts += fmt::format("      <part name='{:02d}' x='{}' y='{}'/>\n", k, x, y);
  }
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  ASSERT_TRUE(cv::imwrite((dir / "photo.png").string(), bgr));
  const std::string xml = "<?xml version='1.0'?>\n<!-- labels -->\n<dataset><images>\n"
                          "  <image file='photo.png'>\n"
                          "    <box top='50' left='100' width='80' height='80'>\n" + parts +
                          "    </box>\n"
                          "    <box top='0' left='0' width='20' height='20' ignore='1'>\n" + parts +
                          "    </box>\n"
                          "    <box top='0' left='200' width='20' height='20'>\n"
                          "      <part name='00' x='205' y='5'/>\n"
                          "    </box>\n"
                          "  </image>\n</images></dataset>\n";
  testing::WriteText(dir / "labels.xml", xml);
  const std::vector<LabelledFace> faces = ReadDlibXmlFaces(dir / "labels.xml", {.crop_scale = 2.0, .box_px = 40});
  ASSERT_EQ(faces.size(), 1u);
  const LabelledFace& f = faces[0];
  EXPECT_EQ(f.name, "photo_0");
  ASSERT_EQ(f.image.cols, 80);
  ASSERT_EQ(f.image.rows, 80);
  // Scale 40 / 80 about the box centre (139.5, 89.5) → the crop centre (39.5, 39.5).
  for (int k = 0; k < 68; ++k) {
    EXPECT_NEAR(f.landmarks(k, 0), 0.5 * (truth(k, 0) - 139.5) + 39.5, 1e-9);
    EXPECT_NEAR(f.landmarks(k, 1), 0.5 * (truth(k, 1) - 89.5) + 39.5, 1e-9);
    // The dot is at the landmark: the crop is brighter there than at the centre.
    const int x = static_cast<int>(std::lround(f.landmarks(k, 0))), y = static_cast<int>(std::lround(f.landmarks(k, 1)));
    EXPECT_GT(f.image.at<cv::Vec3b>(y, x)[0], 20) << k;
  }
  EXPECT_EQ(f.image.at<cv::Vec3b>(40, 40)[0], 0);
  // ReadLabelledFaces takes the XML too (train-tracker --data, eval-landmarks --data).
  EXPECT_EQ(ReadLabelledFaces(dir / "labels.xml").size(), 1u);
  // Errors name the file, the line and the problem.
  testing::WriteText(dir / "bad.xml", "<dataset>\n<image file='photo.png'>\n<box top='x' left='0' width='9' height='9'>\n" +
                                          parts + "</box></image></dataset>\n");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "bad.xml"); }).find("bad.xml:3: <box> top='x' is not a number"),
            std::string::npos);
  testing::WriteText(dir / "missing.xml", "<image file='nowhere.jpg'><box top='0' left='0' width='9' height='9'>" +
                                              parts + "</box></image>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "missing.xml"); }).find("image 'nowhere.jpg' not found"),
            std::string::npos);
  // Issue 19: a box of 1e-300 px scaled the crop to infinite coordinates.
  testing::WriteText(dir / "tiny.xml", "<image file='photo.png'><box top='0' left='0' width='1e-300' height='1e-300'>" +
                                           parts + "</box></image>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "tiny.xml"); }).find("tiny.xml:1: <box> smaller than 1 px"),
            std::string::npos);
  testing::WriteText(dir / "empty.xml", "<dataset><images></images></dataset>");
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "empty.xml"); }).find("no <box> with the 68 <part>s"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadDlibXmlFaces(dir / "none.xml"); }).find("none.xml: cannot open"), std::string::npos);
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
  const TrackerTrainingResult r = TrainTrackerOnFaces(train, test, o);
  const TrackerTrainingReport& rep = r.report;
  std::printf("%s", rep.ToText().c_str());
  EXPECT_EQ(rep.tracking.frames, 32);
  // The HOG detector's box is fitted onto the landmark box on the training renders;
  // dlib's box reaches higher (the forehead) than the 68 points do.
  EXPECT_GT(rep.detector_calibration_faces, 10);
  EXPECT_GT(rep.detector_box.y(), 0.02);
  EXPECT_LT(rep.tracking.final_iod, 0.7 * rep.tracking.initial_iod);
  EXPECT_LT(rep.box.final_iod, 0.8 * rep.box.initial_iod);
  EXPECT_LT(rep.training.train_error_iod.back(), rep.training.train_error_iod.front());
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
