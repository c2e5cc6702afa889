#include "eval/rig_correspondence.h"

#include <gtest/gtest.h>

#include <cmath>

#include "synth/ict_head.h"
#include "synth/procedural_rig.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::SampleRig;

// The sample rig without its last row of vertices and with shifted UVs: another
// topology and UV layout on the same surface (not a part of the sample rig), so
// every vertex's correspondence must give back its own position.
FaceRig CroppedSampleRig() {
  RigImportOptions o;
  o.units_to_mm = 10.0;
  o.face_last = 41 * 52;
  FaceRig rig = ImportObjRig(std::filesystem::path(CREASE_DATA_DIR) / "sample_rig", o);
  rig.neutral.UV.array() *= 0.99;
  return rig;
}

TEST(RigCorrespondence, SameSurfaceMapsEveryVertexOntoItself) {
  const FaceRig& truth = SampleRig();
  const FaceRig tracking = CroppedSampleRig();
  ASSERT_NE(tracking.num_vertices(), truth.num_vertices());
  const RigCorrespondence c = CorrespondRigs(tracking, truth);
  EXPECT_FALSE(c.same_topology);
  EXPECT_FALSE(c.same_uv);
  EXPECT_NEAR(c.scale, 1.0, 1e-6);
  // Rays along the normal from the surface's own border may slip past its edge.
  EXPECT_GT(c.matched, tracking.num_vertices() * 8 / 10);
  // Positions at any expression: the truth's, interpolated, equal the tracking rig's own.
  Eigen::VectorXd e = Eigen::VectorXd::Zero(truth.num_expressions());
  e[truth.ExpressionIndex("jawOpen")] = 0.8;
  const Eigen::MatrixXd mapped = c.Map(truth.EvaluatePositions({}, e));
  const MatX3d own = tracking.EvaluatePositions({}, e);
  double worst = 0;
  for (int v = 0; v < tracking.num_vertices(); ++v) {
    if (c.Has(v)) worst = std::max(worst, (mapped.row(v) - own.row(v)).norm());
  }
  EXPECT_LT(worst, 1e-3);
  // Visibility: a tracking vertex is seen when its truth triangle's corners are.
  FrameTruth t;
  t.vertices = MatX2d::Zero(truth.num_vertices(), 2);
  t.vertex_visible.assign(truth.num_vertices(), 1);
  int hide = 0;  // an interior vertex (row 10, column 20)
  while (truth.original_vertex[hide] != 41 * 10 + 20) ++hide;
  t.vertex_visible[hide] = 0;
  const FrameTruth m = c.MapTruth(t);
  ASSERT_EQ(m.vertex_visible.size(), static_cast<size_t>(tracking.num_vertices()));
  int hidden = 0;
  for (int v = 0; v < tracking.num_vertices(); ++v) hidden += c.Has(v) && !m.vertex_visible[v];
  EXPECT_GE(hidden, 1);
  EXPECT_LE(hidden, 8);
  // Same topology: vertex i is vertex i.
  EXPECT_TRUE(CorrespondRigs(truth, truth).same_topology);
  FaceRig no_landmarks = tracking;
  no_landmarks.landmarks.clear();
  EXPECT_ERROR_HAS(CorrespondRigs(no_landmarks, truth), "no landmark 'ibug_1'");
}

TEST(RigCorrespondence, APartOfTheTruthRigMapsVertexForVertex) {
  const FaceRig truth = BuildIctStudioRig(ReadRig(VendoredIctRigPath()));
  const FaceRig tracking = ExtractParts(truth, {"face", "face_rim", "head_neck", "scalp_hair"});
  ASSERT_LT(tracking.num_vertices(), truth.num_vertices() * 2 / 3);  // eyes, teeth, gums, mouth gone
  const RigCorrespondence c = CorrespondRigs(tracking, truth);
  EXPECT_FALSE(c.same_topology);
  EXPECT_TRUE(c.same_uv);
  EXPECT_EQ(c.matched, tracking.num_vertices());
  Eigen::VectorXd e = Eigen::VectorXd::Zero(truth.num_expressions());
  e[truth.ExpressionIndex("jawOpen")] = 0.6;
  e[truth.ExpressionIndex("mouthSmile_L")] = 1.0;
  const Eigen::MatrixXd mapped = c.Map(truth.EvaluatePositions({}, e));
  EXPECT_LT((mapped - Eigen::MatrixXd(tracking.EvaluatePositions({}, e))).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(c.ToTrackingFrame(tracking.neutral.V), tracking.neutral.V);
}

TEST(RigCorrespondence, ProceduralHeadOnTheIctHead) {
  const FaceRig tracking = BuildProceduralRig();
  const FaceRig truth = BuildIctStudioRig(ReadRig(VendoredIctRigPath()));
  const RigCorrespondence c = CorrespondRigs(tracking, truth);
  EXPECT_FALSE(c.same_topology);
  // Both heads are adult-sized: the similarity scales by little.
  EXPECT_GT(c.scale, 0.8);
  EXPECT_LT(c.scale, 1.25);
  // The inner landmarks (nose, eyes, mouth) land near the truth's own.
  const Eigen::MatrixXd mapped = c.Map(truth.neutral.V);
  for (const char* name : {"ibug_31", "ibug_37", "ibug_46", "ibug_52", "ibug_58"}) {
    const int v = tracking.landmarks[tracking.LandmarkIndex(name)].vertex;
    ASSERT_TRUE(c.Has(v)) << name;
    const Eigen::Vector3d want = truth.neutral.V.row(truth.landmarks[truth.LandmarkIndex(name)].vertex);
    EXPECT_LT((mapped.row(v).transpose() - want).norm(), 12.0) << name;
  }
}

}  // namespace
}  // namespace crease
