// Rig fit to scans (paper Sec. 4.1): UV and closest-point correspondences, and
// the UV transfer to scans without the rig's chart.
#include "pipeline/training/rig_fit.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/options.h"
#include "synth/procedural_rig.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ExpressionWeights;

const FaceRig& Rig() { return testing::ProceduralRig(); }

// Scans made by the rig itself: a known identity, known expressions, moved by a
// known pose (scan_from_head).
struct KnownScans {
  Eigen::VectorXd identity;
  std::vector<Eigen::VectorXd> expressions;
  std::vector<TriMesh> scans;
  std::vector<std::string> names;
};

KnownScans MakeScans(const FaceRig& rig, const Rigid3d& pose, bool with_uv) {
  KnownScans k;
  k.identity = Eigen::VectorXd::Zero(rig.num_identity());
  k.identity[0] = 1.2;
  k.identity[3] = -0.8;
  k.expressions = {Eigen::VectorXd::Zero(rig.num_expressions()),
                   ExpressionWeights(rig, {{"browInnerUp_L", 0.9}, {"browInnerUp_R", 0.9}}),
                   ExpressionWeights(rig, {{"mouthSmile_L", 0.6}, {"jawOpen", 0.3}})};
  for (size_t j = 0; j < k.expressions.size(); ++j) {
    TriMesh m = rig.Evaluate(k.identity, k.expressions[j]);
    for (int v = 0; v < m.num_vertices(); ++v) m.V.row(v) = (pose * Eigen::Vector3d(m.V.row(v))).transpose();
    if (!with_uv) m.UV.resize(0, 2);
    k.scans.push_back(m);
    k.names.push_back("scan" + std::to_string(j));
  }
  return k;
}

TEST(RigFit, UvCorrespondencesRecoverIdentityAndExpressions) {
  const FaceRig& rig = Rig();
  const KnownScans k = MakeScans(rig, Rigid3d(), true);
  EXPECT_TRUE(ScanHasRigUvs(rig, k.scans[0]));
  RigFitOptions o;
  o.identity_prior = 1e-5;
  o.expression_prior = 0.0;
  o.max_fit_vertices = 800;
  const RigFitResult r = FitRigToScans(rig, k.scans, k.names, o);
  EXPECT_EQ(r.correspondence, RigCorrespondence::kUv);
  for (double rms : r.rms_mm) EXPECT_LT(rms, 0.05);
  EXPECT_LT((r.identity - k.identity).cwiseAbs().maxCoeff(), 0.1);
  for (size_t j = 0; j < k.expressions.size(); ++j) {
    EXPECT_NEAR(r.expressions[j][rig.ExpressionIndex("browInnerUp_L")], k.expressions[j][rig.ExpressionIndex("browInnerUp_L")], 0.05);
    EXPECT_NEAR(r.expressions[j][rig.ExpressionIndex("mouthSmile_L")], k.expressions[j][rig.ExpressionIndex("mouthSmile_L")], 0.05);
    EXPECT_GE(r.expressions[j].minCoeff(), 0.0);
    EXPECT_LE(r.expressions[j].maxCoeff(), 1.0);
  }
}

TEST(RigFit, ClosestPointsRecoverAPoseFromRoughAlignment) {
  const FaceRig& rig = Rig();
  const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(3.0 * M_PI / 180.0, Eigen::Vector3d(0.3, 1, 0.1).normalized())),
                     Eigen::Vector3d(2.0, -1.5, 1.0));
  const KnownScans k = MakeScans(rig, pose, false);
  EXPECT_FALSE(ScanHasRigUvs(rig, k.scans[0]));
  RigFitOptions o;
  o.identity_prior = 1e-4;
  o.max_fit_vertices = 600;
  o.closest_point_iterations = 4;
  const RigFitResult r = FitRigToScans(rig, k.scans, k.names, o);
  EXPECT_EQ(r.correspondence, RigCorrespondence::kClosest);
  for (size_t j = 0; j < k.scans.size(); ++j) {
    // Point-to-plane against the nearest vertex of a coarse (2 mm) mesh: ~0.1 mm of
    // curvature error remains even at the exact pose.
    EXPECT_LT(r.rms_mm[j], 0.25) << j;
    EXPECT_LT((r.scan_from_head[j].translation - pose.translation).norm(), 0.5) << j;
    EXPECT_LT(r.scan_from_head[j].rotation.angularDistance(pose.rotation) * 180.0 / M_PI, 0.5) << j;
  }
}

TEST(RigFit, UvTransferGivesTheRigsChart) {
  const FaceRig& rig = Rig();
  TriMesh scan = rig.neutral;
  scan.UV.resize(0, 2);
  std::vector<int> kept;
  const TriMesh out = TransferUvsFromRig(rig, rig.neutral.V, scan, 2.0, &kept);
  ASSERT_GT(out.num_vertices(), 1000);
  ASSERT_EQ(static_cast<int>(kept.size()), out.num_vertices());
  // Vertices inside the face chart get their own UV back (a ray from a vertex hits
  // one of its own triangles at the vertex) — except where two chart vertices share
  // a position (the corners of the lips' and eyelids' slits), which is ambiguous.
  int checked = 0, exact = 0;
  const int face = rig.PartIndex("face");
  for (int i = 0; i < out.num_vertices(); ++i) {
    const int v = kept[i];
    if (face >= 0 && rig.vertex_part[v] != face) continue;
    exact += (out.UV.row(i) - rig.neutral.UV.row(v)).norm() < 1e-4;
    ++checked;
  }
  EXPECT_GT(checked, 1000);
  EXPECT_GT(exact, 0.99 * checked);
}

TEST(RigFit, BadInput) {
  const FaceRig& rig = Rig();
  KnownScans k = MakeScans(rig, Rigid3d(), true);
  RigFitOptions o;
  EXPECT_ERROR_HAS(SetOptionsFromJson(R"({"correspondence": "nearest"})", "test", &o),
                   "test: option 'correspondence' must be one of: auto, uv, closest, got \"nearest\"");
  RigFitOptions far;
  far.correspondence = RigCorrespondence::kClosest;
  for (auto& m : k.scans) m.V.array() += 500.0;  // nowhere near the rig
  EXPECT_ERROR_HAS(FitRigToScans(rig, k.scans, k.names, far), "roughly aligned");
}

}  // namespace
}  // namespace crease
