// The studio's dataset writer (synth/dataset.h): expression specs, a tiny sequence
// dataset whose truth the readers and RebuildDatasetFrameMesh reproduce, and the
// frame-truth files round-tripping through eval's reader (ReadFrameTruth).
#include "synth/dataset.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/camera.h"
#include "core/dataset_info.h"
#include "core/rng.h"
#include "eval/tracking_metrics.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using testing::ErrorOf;
using testing::ProceduralRig;
using testing::TestDir;

TEST(SynthDataset, ExpressionSpecsParseAndNameTheirProblems) {
  const FaceRig& rig = ProceduralRig();
  const auto index = [&](const char* name) { return rig.ExpressionIndex(name); };
  // A name without _L/_R drives both sides; sides and unsided names stand alone.
  const Eigen::VectorXd w = ParseExpressionSpec("browInnerUp=1,jawOpen=0.25,,browDown_L=0.5", rig);
  ASSERT_EQ(w.size(), rig.num_expressions());
  EXPECT_EQ(w[index("browInnerUp_L")], 1.0);
  EXPECT_EQ(w[index("browInnerUp_R")], 1.0);
  EXPECT_EQ(w[index("jawOpen")], 0.25);
  EXPECT_EQ(w[index("browDown_L")], 0.5);
  EXPECT_EQ(w[index("browDown_R")], 0.0);
  EXPECT_DOUBLE_EQ(w.sum(), 2.75);
  EXPECT_EQ(ParseExpressionSpec("", rig), Eigen::VectorXd::Zero(rig.num_expressions()));
  const auto error = [&](const std::string& spec) { return ErrorOf([&] { ParseExpressionSpec(spec, rig); }); };
  EXPECT_NE(error("jawOpen").find("expression 'jawOpen': expected NAME=WEIGHT"), std::string::npos);
  EXPECT_NE(error("jawOpen=wide").find("expression 'jawOpen=wide': 'wide' is not a number"), std::string::npos);
  EXPECT_NE(error("jawOpen=0.5x").find("'0.5x' is not a number"), std::string::npos);
  EXPECT_NE(error("jawOpen=nan").find("'nan' is not a number"), std::string::npos);
  EXPECT_NE(error("tongueOut=1").find("'tongueOut', which the rig lacks"), std::string::npos);
}

// The tiny dataset's truth agrees with the folder's own rig, actor and camera: each
// frame's vertex projections are the posed coarse surface seen by camera.json, its
// landmarks are the projections of their vertices, and RebuildDatasetFrameMesh
// gives the actor's high-resolution surface for the truth's expression (last frame).
TEST(SynthDataset, TinySequenceTruthIsReproducibleFromTheFolder) {
  const fs::path d = testing::TinySequenceDataset("synth_dataset", "talking", 2);
  const SequenceDatasetInfo info = ReadSequenceDatasetInfo(d);
  ASSERT_EQ(info.frames, 2);
  const FaceRig rig = ReadRig(info.RigPath());
  ASSERT_EQ(rig.num_vertices(), ProceduralRig().num_vertices());
  const Actor actor = ReadActor(d / "actor.json");
  const Camera camera = ReadCamera(d / "camera.json");
  const ActorModel model(rig, actor);
  for (int f = info.first_frame; f <= info.last_frame(); ++f) {
    EXPECT_TRUE(fs::is_regular_file(info.FramePath(f))) << f;
    const FrameTruth t = ReadFrameTruth(d, f, rig.num_vertices());
    const Eigen::VectorXd w = ExpressionVector(rig, t.expression);
    const bool hires = f == info.last_frame();  // one frame's high-resolution surface is enough
    const ActorFrame frame = model.Frame(w, hires);
    const MatX2d projected = Camera(camera.intrinsics, t.cam_from_head).ProjectAll(frame.coarse.V);
    ASSERT_EQ(projected.rows(), t.vertices.rows());
    EXPECT_LT((projected - t.vertices).cwiseAbs().maxCoeff(), 1e-3) << f;  // float32 on disk
    for (int i = 0; i < 68; ++i) {
      EXPECT_LT((t.landmarks.row(i) - t.vertices.row(rig.landmarks[i].vertex)).norm(), 1e-3) << f << " " << i;
    }
    int visible = 0;
    for (char v : t.vertex_visible) visible += v;
    EXPECT_GT(visible, 0) << f;
    EXPECT_LT(visible, rig.num_vertices()) << f;  // the back of the head is hidden
    if (hires) {
      EXPECT_EQ(RebuildDatasetFrameMesh(d, f).V, frame.hires.V) << f;
    }
  }
  EXPECT_NE(ErrorOf([&] { RebuildDatasetFrameMesh(d, info.last_frame() + 1); }).find("not in this dataset"),
            std::string::npos);
}

TEST(SynthDataset, FrameTruthRoundTripsThroughTheReader) {
  const FaceRig& rig = ProceduralRig();
  const int V = rig.num_vertices();
  Rng rng(9);
  StudioFrameTruth t;
  t.index = 7;
  t.expression = Eigen::VectorXd::Zero(rig.num_expressions());
  t.expression[rig.ExpressionIndex("jawOpen")] = 0.375;
  t.expression[rig.ExpressionIndex("mouthSmile_L")] = 0.8;
  t.cam_from_head = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
                            Eigen::Vector3d(4.5, -2.0, 600.0));
  t.vertex_pixels.resize(V, 2);
  t.vertex_visible.resize(V);
  for (int v = 0; v < V; ++v) {
    t.vertex_pixels.row(v) << rng.Uniform(0, 320), rng.Uniform(0, 240);
    t.vertex_visible[v] = v % 3 == 0;
  }
  t.landmark_pixels.resize(68, 2);
  t.landmark_visible.resize(68);
  for (int i = 0; i < 68; ++i) {
    t.landmark_pixels.row(i) = t.vertex_pixels.row(rig.landmarks[i].vertex);
    t.landmark_visible[i] = i % 2;
  }
  Actor actor;
  actor.identity = Eigen::VectorXd::LinSpaced(5, -1.0, 1.0);
  const fs::path dir = TestDir();
  WriteFrameTruth(dir / "truth", "000007", t, rig, actor);
  const FrameTruth back = ReadFrameTruth(dir, 7, V);
  EXPECT_EQ(back.landmarks, t.landmark_pixels);  // JSON keeps doubles exactly
  EXPECT_LT((back.vertices - t.vertex_pixels).cwiseAbs().maxCoeff(), 1e-4);  // float32
  for (int v = 0; v < V; ++v) ASSERT_EQ(back.vertex_visible[v] != 0, t.vertex_visible[v] != 0) << v;
  for (int i = 0; i < 68; ++i) EXPECT_EQ(back.landmark_visible[i] != 0, t.landmark_visible[i] != 0) << i;
  EXPECT_LT((back.cam_from_head.translation - t.cam_from_head.translation).norm(), 1e-12);
  EXPECT_LT(back.cam_from_head.rotation.angularDistance(t.cam_from_head.rotation), 1e-12);
  EXPECT_EQ(back.identity, actor.identity);
  EXPECT_EQ(ExpressionVector(rig, back.expression), t.expression);
  // A vertex file of the wrong size is refused, naming it.
  EXPECT_NE(ErrorOf([&] { ReadFrameTruth(dir, 7, V + 1); }).find("000007_vertices.bin"), std::string::npos);
}

}  // namespace
}  // namespace crease
