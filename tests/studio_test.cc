#include "synth/studio.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <numbers>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/file_util.h"
#include "core/json_io.h"
#include "core/rig_import.h"
#include "core/image_io.h"
#include "synth/dataset.h"
#include "synth/procedural_rig.h"
#include "tests/test_util.h"

namespace crease {
namespace {
namespace fs = std::filesystem;
using testing::ErrorOf;
using testing::TestDir;

using testing::SampleRig;

ActorOptions SmallActor() {
  ActorOptions o;
  o.resolution = 256;
  o.surface_min_vertices = 0;
  return o;
}

SequenceDatasetOptions SmallStudio() {
  SequenceDatasetOptions o;
  o.studio.width = 160;
  o.studio.height = 120;
  o.max_frames = 3;
  o.first_frame = 20;  // the brow is raised
  return o;
}

TEST(Studio, DirectionalLightSpecSweepsTheLightDirection) {
  const LightRig rig = LightRigFromSpec("directional:80:5:0.2");
  EXPECT_EQ(rig.name, "directional:80:5:0.2");
  ASSERT_EQ(rig.lights.size(), 2u);
  const auto& d = std::get<DirectionalLight>(rig.lights[0]);
  EXPECT_LT((d.direction - RigDirection(80.0, 5.0)).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(std::get<AmbientOcclusionLight>(rig.lights[1]).color.x(), 0.2);
  // Without the ambient term: DirectionalRig's.
  EXPECT_DOUBLE_EQ(std::get<AmbientOcclusionLight>(LightRigFromSpec("directional:-30:45").lights[1]).color.x(), 0.05);
  EXPECT_NE(ErrorOf([] { LightRigFromSpec("directional:80"); }).find("directional:AZIMUTH:ELEVATION"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { LightRigFromSpec("directional:80:x"); }).find("'x' is not a number"), std::string::npos);
  EXPECT_NE(ErrorOf([] { LightRigFromSpec("directional:80:5:-1"); }).find("ambient -1"), std::string::npos);
  // A sphere light in the same direction, 10° wide, as bright on a surface facing it.
  const LightRig soft = LightRigFromSpec("sphere:80:5:10:0.1");
  const auto& s = std::get<SphereLight>(soft.lights[0]);
  EXPECT_LT((s.centre.normalized() - RigDirection(80.0, 5.0)).norm(), 1e-12);
  EXPECT_NEAR(2.0 * std::asin(s.radius / s.centre.norm()) * 180.0 / std::numbers::pi, 10.0, 1e-9);
  EXPECT_DOUBLE_EQ(s.color.x(), d.color.x());
  EXPECT_DOUBLE_EQ(std::get<AmbientOcclusionLight>(soft.lights[1]).color.x(), 0.1);
  EXPECT_NE(ErrorOf([] { LightRigFromSpec("sphere:80:5"); }).find("sphere:AZIMUTH:ELEVATION:DIAMETER"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { LightRigFromSpec("sphere:80:5:0"); }).find("diameter 0"), std::string::npos);
}

TEST(Studio, GroundTruthProjectionsLandOnTheRenderedFace) {
  const Actor actor = GenerateActor(SampleRig(), 3, SmallActor());
  StudioOptions so;
  so.width = 320;
  so.height = 240;
  so.background = {0.3, 0.2, 0.1};
  const Studio studio(SampleRig(), actor, so);
  const StudioFrame f = studio.RenderStill(Eigen::VectorXd::Zero(SampleRig().num_expressions()), SequenceFrame{},
                                           nullptr, nullptr, 1);
  // Rays that miss the head see the studio's wall (StudioOptions::background).
  ASSERT_EQ(f.render.alpha.at<float>(0, 0), 0.0f);
  EXPECT_NEAR(f.render.image.at<cv::Vec3f>(0, 0)[0], 0.3f, 1e-6);
  EXPECT_NEAR(f.render.image.at<cv::Vec3f>(0, 0)[2], 0.1f, 1e-6);
  so.background = {0.1, 0.1};
  EXPECT_NE(ErrorOf([&] { so.Check(); }).find("background needs 3"), std::string::npos);
  ASSERT_EQ(f.truth.landmark_pixels.rows(), 68);
  int visible = 0;
  for (int i = 0; i < 68; ++i) {
    if (!f.truth.landmark_visible[i]) continue;
    ++visible;
    const int x = static_cast<int>(std::lround(f.truth.landmark_pixels(i, 0)));
    const int y = static_cast<int>(std::lround(f.truth.landmark_pixels(i, 1)));
    EXPECT_GT(f.render.alpha.at<float>(y, x), 0.0f) << "landmark " << i;
  }
  EXPECT_GE(visible, 60);  // frontal: nearly all landmarks are seen
  // A head turned away hides landmarks on the far side.
  SequenceFrame turned;
  turned.yaw_deg = 70;
  const StudioFrame g = studio.RenderStill(Eigen::VectorXd::Zero(SampleRig().num_expressions()), turned, nullptr,
                                           nullptr, 1);
  int visible_turned = 0;
  for (uint8_t v : g.truth.landmark_visible) visible_turned += v;
  EXPECT_LT(visible_turned, visible);
}

TEST(Studio, SequenceDatasetIsCompleteDeterministicAndRebuildable) {
  const fs::path dir = TestDir();
  const Actor actor = GenerateActor(SampleRig(), 5, SmallActor());
  // The sample rig has a subset of the procedural rig's expressions.
  const Sequence seq = ParseSequenceYaml(
      "name: raise\nkeys:\n  - t: 0\n    expression: {browInnerUp: 0, jawOpen: 0}\n"
      "  - t: 0.8\n    expression: {browInnerUp: 1, jawOpen: 0.3}\n",
      "raise.yaml");
  const DatasetReport r = WriteSequenceDataset(SampleRig(), actor, seq, SmallStudio(), dir / "a");
  EXPECT_EQ(r.frames, 3);
  for (const char* f : {"dataset.json", "rig.crig", "actor.json", "sequence.yaml", "camera.json", "frames/000021.png",
                        "truth/000021.json", "truth/000021_vertices.bin", "maps/000021_expression_displacement.exr",
                        "maps/static_displacement.exr", "maps/mesoscopic_displacement.exr"}) {
    EXPECT_TRUE(fs::exists(dir / "a" / f)) << f;
  }
  EXPECT_EQ(fs::file_size(dir / "a" / "truth/000021_vertices.bin"),
            static_cast<uintmax_t>(SampleRig().num_vertices()) * 3 * sizeof(float));
  const nlohmann::json truth = ReadJsonFile(dir / "a" / "truth/000021.json");
  EXPECT_GT(truth["expression"]["browInnerUp"].get<double>(), 0.0);
  // Same seeds, same bytes.
  WriteSequenceDataset(SampleRig(), actor, seq, SmallStudio(), dir / "b");
  for (const char* f : {"frames/000022.png", "truth/000022.json", "truth/000022_vertices.bin"}) {
    EXPECT_EQ(ReadFileToString(dir / "a" / f), ReadFileToString(dir / "b" / f)) << f;
  }
  // The ground-truth surface of a frame can be rebuilt from the folder alone.
  const TriMesh m = RebuildDatasetFrameMesh(dir / "a", 21);
  const ActorModel model(SampleRig(), actor);
  Eigen::VectorXd w(SampleRig().num_expressions());
  for (int i = 0; i < w.size(); ++i) w[i] = truth["expression"][SampleRig().expression_names[i]].get<double>();
  EXPECT_EQ(m.V, model.Frame(w, true).hires.V);
  // Errors: an existing folder, a frame outside the dataset, an expression the rig lacks.
  EXPECT_NE(ErrorOf([&] { WriteSequenceDataset(SampleRig(), actor, seq, SmallStudio(), dir / "a"); })
                .find("already exists"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { RebuildDatasetFrameMesh(dir / "a", 99); }).find("not in this dataset"), std::string::npos);
  Sequence bad = seq;
  bad.keys[0].values["expression:tongueOut"] = 1.0;
  EXPECT_NE(ErrorOf([&] { WriteSequenceDataset(SampleRig(), actor, bad, SmallStudio(), dir / "c"); })
                .find("'tongueOut', which the rig lacks"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "c"));
  // Presets on a rig with fewer expressions: missing channels are dropped with a warning.
  SequenceDatasetOptions lenient = SmallStudio();
  lenient.ignore_missing_expressions = true;
  lenient.max_frames = 1;
  const DatasetReport lr = WriteSequenceDataset(SampleRig(), actor, MakePresetSequence("wrinkle-workout"), lenient, dir / "d");
  EXPECT_EQ(lr.frames, 1);
  ASSERT_FALSE(lr.warnings.empty());
  EXPECT_NE(lr.warnings[0].find("browOuterUp"), std::string::npos);
}

TEST(Studio, ScanSetHasMeshesCalibratedImagesAndMaps) {
  const fs::path dir = TestDir();
  // An environment map from a file works as a light rig wherever a preset does.
  cv::Mat env(16, 32, CV_32FC3, cv::Scalar(0.3, 0.3, 0.3));
  env.rowRange(0, 4) = cv::Scalar(2.0, 2.0, 2.0);
  WriteImage(dir / "sky.exr", env);
  ScanSetOptions o;
  o.studio.width = 96;
  o.studio.height = 72;
  o.cameras = 2;
  o.light_rigs = {"front", (dir / "sky.exr").string()};
  o.expressions = {"browInnerUp=1"};
  const DatasetReport r = WriteScanSet(SampleRig(), {21}, SmallActor(), o, dir / "scans");
  EXPECT_EQ(r.frames, 2);
  const fs::path a = dir / "scans" / "actor_000";
  for (const char* scan : {"neutral", "01_browInnerUp"}) {
    for (const char* f : {"mesh.ply", "truth.json", "expression_displacement.exr", "cam0.json", "cam1.json",
                          "cam0_front.png", "cam1_sky.png"}) {
      EXPECT_TRUE(fs::exists(a / scan / f)) << scan << "/" << f;
    }
  }
  EXPECT_TRUE(fs::exists(dir / "scans" / "scans.json"));
  EXPECT_TRUE(fs::exists(a / "actor.json"));
  // The two cameras look at the face from different sides.
  const Camera c0 = ReadCamera(a / "neutral" / "cam0.json"), c1 = ReadCamera(a / "neutral" / "cam1.json");
  EXPECT_GT((c0.CentreInHead() - c1.CentreInHead()).norm(), 100.0);
}

// A scan set spans ages: actor a of n draws from the a-th of n parts of the range.
TEST(Studio, ScanSetStratifiesActorAges) {
  const fs::path dir = TestDir();
  ScanSetOptions o;
  o.studio.width = 48;
  o.studio.height = 36;
  o.cameras = 1;
  o.expressions = {"browInnerUp=1"};
  ActorOptions ao = SmallActor();
  ao.age_min = 0.2;
  ao.age_max = 1.0;
  WriteScanSet(SampleRig(), {5, 6}, ao, o, dir / "scans");
  const double young = ReadActor(dir / "scans" / "actor_000" / "actor.json").style.age;
  const double old = ReadActor(dir / "scans" / "actor_001" / "actor.json").style.age;
  EXPECT_GE(young, 0.2);
  EXPECT_LE(young, 0.6);
  EXPECT_GE(old, 0.6);
  EXPECT_LE(old, 1.0);
}

// Golden image of the procedural rig's neutral face (one actor) under a directional
// light; regenerate with CREASE_UPDATE_GOLDEN=1 after an intended change, and look at it.
TEST(Studio, NeutralFaceGoldenImage) {
  const FaceRig rig = BuildProceduralRig();
  const Actor actor = GenerateActor(rig, 2, SmallActor());
  StudioOptions so;
  so.width = 128;
  so.height = 96;
  so.fov_deg = 28;
  so.samples_per_axis = 1;  // the golden predates the 2×2 default (0.4.17)
  so.sensor.noise = false;
  const Studio studio(rig, actor, so);
  LightRig light;
  light.name = "directional";
  light.lights.push_back(DirectionalFromAzimuthElevation(30.0, 25.0, 1.0));
  const StudioFrame f = studio.RenderStill(Eigen::VectorXd::Zero(rig.num_expressions()), SequenceFrame{}, &light,
                                           nullptr, 1);
  const cv::Mat got = f.image.srgb8;
  const fs::path golden = fs::path(CREASE_TEST_DIR) / "data/golden/studio_neutral_face.png";
  if (std::getenv("CREASE_UPDATE_GOLDEN") != nullptr) WriteImage(golden, got, {.srgb = false});
  ASSERT_TRUE(fs::exists(golden)) << golden;
  const cv::Mat expected = ReadImage(golden, /*srgb=*/false);
  ASSERT_EQ(expected.size(), got.size());
  cv::Mat got_f;
  got.convertTo(got_f, CV_32F, 1.0 / 255.0);
  const cv::Mat diff = cv::abs(got_f - expected) * 255.0;
  EXPECT_LT(cv::mean(diff.reshape(1))[0], 1.0) << "mean |difference| in 8-bit levels";
  EXPECT_LT(cv::countNonZero(diff.reshape(1) > 8.0) / static_cast<double>(diff.total() * 3), 0.01);
  // The face fills a good part of the frame and is lit.
  EXPECT_GT(cv::countNonZero(f.render.alpha > 0.5f), static_cast<int>(0.3 * got.total()));
}

}  // namespace
}  // namespace crease
