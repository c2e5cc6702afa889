// The global tracker's rig fit to 2D landmarks (issue 5 part 2) and the
// ground-truth-prior control (part 4), on landmarks made by the procedural rig itself
// with a known identity, known expressions and a known pose.
#include "pipeline/capture/landmark_fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/options.h"
#include "core/rng.h"
#include "synth/procedural_rig.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ExpressionWeights;

constexpr double kDeg = std::numbers::pi / 180.0;

const FaceRig& Rig() { return testing::ProceduralRig(); }

CameraIntrinsics Intrinsics() { return CameraIntrinsics::FromFov(40.0, 640, 480); }

Eigen::VectorXd TrueIdentity(const FaceRig& rig) {
  Eigen::VectorXd a = Eigen::VectorXd::Zero(rig.num_identity());
  a[0] = 1.0;
  a[2] = -0.8;
  a[8] = 0.7;
  return a;
}

// A head ~550 mm in front of the camera (face ~230 px wide), facing it, turned by
// (yaw, pitch) degrees and shifted by (dx, dy, dz) mm.
Rigid3d Pose(double yaw_deg, double pitch_deg, const Eigen::Vector3d& shift = Eigen::Vector3d::Zero()) {
  const Eigen::Quaterniond facing(Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()));  // y, z flipped
  const Eigen::Quaterniond turn = Eigen::AngleAxisd(yaw_deg * kDeg, Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(pitch_deg * kDeg, Eigen::Vector3d::UnitX());
  return Rigid3d(facing * turn, Eigen::Vector3d(5.0, 10.0, 550.0) + shift);
}

// The 68 landmarks of the rig with `identity`, `expression`, seen with `pose`.
MatX2d Landmarks(const FaceRig& rig, const Eigen::VectorXd& identity, const Eigen::VectorXd& expression,
                 const Rigid3d& pose) {
  const MatX3d X = rig.EvaluatePositions(identity, expression);
  const Camera camera(Intrinsics(), pose);
  MatX2d out(68, 2);
  for (int i = 0; i < 68; ++i) {
    const int v = rig.landmarks[rig.LandmarkIndex("ibug_" + std::to_string(i + 1))].vertex;
    out.row(i) = camera.Project(X.row(v).transpose()).transpose();
  }
  return out;
}

double RotationErrorDeg(const Rigid3d& a, const Rigid3d& b) { return a.rotation.angularDistance(b.rotation) / kDeg; }

// Identity phase over a few varied frames: returns the fitter with its identity fixed.
void RunIdentityPhase(LandmarkRigFitter* fitter, const Eigen::VectorXd& identity) {
  const FaceRig& rig = Rig();
  const std::vector<Eigen::VectorXd> expressions = {
      Eigen::VectorXd::Zero(rig.num_expressions()), ExpressionWeights(rig, {{"jawOpen", 0.5}}),
      ExpressionWeights(rig, {{"mouthSmile_L", 0.7}, {"mouthSmile_R", 0.7}}), ExpressionWeights(rig, {{"browInnerUp_L", 0.6}}),
      Eigen::VectorXd::Zero(rig.num_expressions())};
  const double yaw[] = {0, 15, -15, 5, -5}, pitch[] = {0, 5, -5, 10, 0};
  for (int j = 0; j < 5; ++j) fitter->Fit(Landmarks(rig, identity, expressions[j], Pose(yaw[j], pitch[j])));
}

TEST(LandmarkFit, RecoversExpressionsAndPoseAfterTheIdentityPhase) {
  const FaceRig& rig = Rig();
  const Eigen::VectorXd identity = TrueIdentity(rig);
  LandmarkFitOptions o;
  o.identity_frames = 5;
  o.fit_expression_prior_weight = 0.5;
  LandmarkRigFitter fitter(rig, Intrinsics(), o);
  EXPECT_FALSE(fitter.identity_fixed());
  RunIdentityPhase(&fitter, identity);
  ASSERT_TRUE(fitter.identity_fixed());

  const Eigen::VectorXd beta =
      ExpressionWeights(rig, {{"browInnerUp_L", 0.8}, {"browInnerUp_R", 0.8}, {"jawOpen", 0.4}, {"mouthSmile_L", 0.6}});
  const Rigid3d pose = Pose(12.0, -6.0, Eigen::Vector3d(-8.0, 4.0, 20.0));
  // A few tracked frames of the target (the temporal prior needs a few frames to
  // catch up with this sudden jump of 17° and 22 mm).
  LandmarkFrameFit fit;
  for (int k = 0; k < 8; ++k) fit = fitter.Fit(Landmarks(rig, identity, beta, pose));
  // The identity estimated over the phase is closer to the truth than the mean identity.
  EXPECT_LT((fitter.identity() - identity).norm(), 0.5 * identity.norm());
  for (const char* name : {"browInnerUp_L", "browInnerUp_R", "jawOpen", "mouthSmile_L"}) {
    EXPECT_NEAR(fit.expression[rig.ExpressionIndex(name)], beta[rig.ExpressionIndex(name)], 0.1) << name;
  }
  EXPECT_GE(fit.expression.minCoeff(), 0.0);
  EXPECT_LE(fit.expression.maxCoeff(), 1.0);
  EXPECT_LT(RotationErrorDeg(fit.cam_from_head, pose), 1.0);
  const Eigen::Vector3d dt = fit.cam_from_head.translation - pose.translation;
  EXPECT_LT(dt.head<2>().norm(), 3.0) << dt.transpose();
  // Depth trades off against the identity's overall size: ~3 % of the distance.
  EXPECT_LT(std::abs(dt.z()), 0.03 * pose.translation.z()) << dt.transpose();
  EXPECT_LT(fit.rms_px, 1.0);
  // The projected fit and the rig's head vertices are consistent.
  EXPECT_NEAR((fitter.ProjectLandmarks(fit) - Landmarks(rig, identity, beta, pose)).rowwise().norm().maxCoeff(), 0.0,
              3.0);
  EXPECT_EQ(fitter.HeadVertices(fit).rows(), rig.num_vertices());
}

// Jitter of consecutive fits of a static face under σ = 1 px landmark noise.
double Jitter(const LandmarkFitOptions& o, double* rotation_jitter_deg) {
  const FaceRig& rig = Rig();
  const Eigen::VectorXd identity = TrueIdentity(rig);
  LandmarkRigFitter fitter(rig, Intrinsics(), o);
  fitter.SetIdentity(identity);
  const Eigen::VectorXd beta = ExpressionWeights(rig, {{"jawOpen", 0.3}, {"mouthSmile_L", 0.4}, {"browInnerUp_R", 0.5}});
  const MatX2d clean = Landmarks(rig, identity, beta, Pose(5.0, 3.0));
  Rng rng(11);
  LandmarkFrameFit prev;
  double sum = 0.0, rot = 0.0;
  const int frames = 25;
  for (int f = 0; f < frames; ++f) {
    MatX2d noisy = clean;
    for (int i = 0; i < noisy.rows(); ++i)
      for (int c = 0; c < 2; ++c) noisy(i, c) += rng.Normal();
    const LandmarkFrameFit fit = fitter.Fit(noisy);
    if (f > 0) {
      sum += (fit.expression - prev.expression).cwiseAbs().sum();
      rot += RotationErrorDeg(fit.cam_from_head, prev.cam_from_head);
    }
    prev = fit;
  }
  *rotation_jitter_deg = rot / (frames - 1);
  return sum / (frames - 1);
}

TEST(LandmarkFit, TemporalPriorReducesJitter) {
  LandmarkFitOptions with, without;
  without.fit_temporal_expression_weight = 0.0;
  without.fit_temporal_rotation_weight = 0.0;
  without.fit_temporal_translation_weight = 0.0;
  without.fit_temporal_depth_weight = 0.0;
  double rot_with = 0.0, rot_without = 0.0;
  const double j_with = Jitter(with, &rot_with);
  const double j_without = Jitter(without, &rot_without);
  EXPECT_LT(j_with, 0.6 * j_without) << j_with << " vs " << j_without;
  EXPECT_LT(rot_with, 0.8 * rot_without) << rot_with << " vs " << rot_without;
}

// Moves each inner jaw-contour point (iBUG 2–16) along the detected outline by a
// fraction of the way towards its next neighbour.
MatX2d SlideContour(const MatX2d& l, double fraction) {
  MatX2d out = l;
  for (int i = 1; i < 16; ++i) out.row(i) = l.row(i) + fraction * (l.row(i + 1) - l.row(i));
  return out;
}

TEST(LandmarkFit, JawContourPointsSlideAlongTheOutline) {
  const FaceRig& rig = Rig();
  const Eigen::VectorXd identity = TrueIdentity(rig);
  const Eigen::VectorXd beta = ExpressionWeights(rig, {{"jawOpen", 0.3}, {"mouthSmile_R", 0.5}});
  const Rigid3d pose = Pose(-10.0, 4.0);
  const MatX2d clean = Landmarks(rig, identity, beta, pose);
  const MatX2d slid = SlideContour(clean, 0.4);
  // The points moved by several pixels.
  EXPECT_GT((slid - clean).rowwise().norm().maxCoeff(), 5.0);
  auto fit_once = [&](const LandmarkFitOptions& o, const MatX2d& l) {
    LandmarkRigFitter fitter(rig, Intrinsics(), o);
    fitter.SetIdentity(identity);
    return fitter.Fit(l);
  };
  LandmarkFitOptions sliding;  // defaults: sliding correspondences
  LandmarkFitOptions fixed_points;
  fixed_points.contour_weight = 1.0;
  fixed_points.contour_tangent_weight = 1.0;
  const LandmarkFrameFit a = fit_once(sliding, clean), b = fit_once(sliding, slid);
  const LandmarkFrameFit c = fit_once(fixed_points, clean), d = fit_once(fixed_points, slid);
  const double slide_beta = (a.expression - b.expression).cwiseAbs().maxCoeff();
  const double fixed_beta = (c.expression - d.expression).cwiseAbs().maxCoeff();
  const double slide_rot = RotationErrorDeg(a.cam_from_head, b.cam_from_head);
  const double fixed_rot = RotationErrorDeg(c.cam_from_head, d.cam_from_head);
  EXPECT_LT(slide_beta, 0.1);
  EXPECT_LT(slide_rot, 0.3);
  // Ordinary point correspondences are pulled much more (measured: ~1.0 and ~3°).
  EXPECT_LT(slide_beta, 0.2 * fixed_beta);
  EXPECT_LT(slide_rot, 0.2 * fixed_rot);
  // The recovered expression still matches the truth.
  EXPECT_NEAR(b.expression[rig.ExpressionIndex("jawOpen")], 0.3, 0.1);
}

TEST(LandmarkFit, ResetReinitialisesThePoseAndKeepsTheIdentity) {
  const FaceRig& rig = Rig();
  const Eigen::VectorXd identity = TrueIdentity(rig);
  LandmarkFitOptions o;
  // A temporal prior so strong that a tracked frame barely moves.
  o.fit_temporal_expression_weight = 1e8;
  o.fit_temporal_rotation_weight = 1e10;
  o.fit_temporal_translation_weight = 1e8;
  o.fit_temporal_depth_weight = 1e8;
  LandmarkRigFitter fitter(rig, Intrinsics(), o);
  fitter.SetIdentity(identity);
  const Eigen::VectorXd beta0 = Eigen::VectorXd::Zero(rig.num_expressions());
  const Eigen::VectorXd beta1 = ExpressionWeights(rig, {{"jawOpen", 0.6}});
  const Rigid3d pose0 = Pose(0.0, 0.0), pose1 = Pose(25.0, -8.0, Eigen::Vector3d(30.0, -20.0, 40.0));
  const LandmarkFrameFit first = fitter.Fit(Landmarks(rig, identity, beta0, pose0));
  EXPECT_LT(RotationErrorDeg(first.cam_from_head, pose0), 1.0);
  // Without a reset the prior holds the fit near the previous frame.
  const LandmarkFrameFit held = fitter.Fit(Landmarks(rig, identity, beta1, pose1));
  EXPECT_GT(RotationErrorDeg(held.cam_from_head, pose1), 10.0);
  fitter.Reset();
  EXPECT_TRUE(fitter.identity_fixed());
  EXPECT_LT((fitter.identity() - identity).norm(), 1e-12);
  const LandmarkFrameFit after = fitter.Fit(Landmarks(rig, identity, beta1, pose1));
  EXPECT_LT(RotationErrorDeg(after.cam_from_head, pose1), 1.0);
  EXPECT_LT((after.cam_from_head.translation - pose1.translation).head<2>().norm(), 3.0);
  EXPECT_NEAR(after.expression[rig.ExpressionIndex("jawOpen")], 0.6, 0.1);

  // A reset during the identity phase restarts it.
  LandmarkFitOptions phase;
  phase.identity_frames = 3;
  phase.identity_fit_interval = 1;
  LandmarkRigFitter learner(rig, Intrinsics(), phase);
  learner.Fit(Landmarks(rig, identity, beta0, pose0));
  EXPECT_EQ(learner.identity_phase_frames(), 1);
  EXPECT_GT(learner.identity().norm(), 0.0);
  learner.Reset();
  EXPECT_FALSE(learner.identity_fixed());
  EXPECT_EQ(learner.identity_phase_frames(), 0);
  EXPECT_EQ(learner.identity().norm(), 0.0);
}

TEST(LandmarkFit, BadInput) {
  const FaceRig& rig = Rig();
  LandmarkRigFitter fitter(rig, Intrinsics(), {});
  const MatX2d good = Landmarks(rig, Eigen::VectorXd(), Eigen::VectorXd(), Pose(0.0, 0.0));
  EXPECT_ERROR_HAS(fitter.Fit(good.topRows(67)), "expected 68 landmarks");
  MatX2d nan = good;
  nan(30, 1) = std::nan("");
  EXPECT_ERROR_HAS(fitter.Fit(nan), "landmark 30 (iBUG 31) is not finite");
  EXPECT_ERROR_HAS(fitter.Fit(good, std::vector<double>(10, 1.0)), "expected 68 point weights");
  std::vector<double> negative(68, 1.0);
  negative[3] = -1.0;
  EXPECT_ERROR_HAS(fitter.Fit(good, negative), "point weight 3");
  EXPECT_ERROR_HAS(fitter.Fit(good, std::vector<double>(68, 0.0)), "only 0 landmarks");

  FaceRig few = rig;
  few.landmarks.resize(20);
  EXPECT_ERROR_HAS(LandmarkRigFitter(few, Intrinsics(), {}), "ibug_21");
  FaceRig none = rig;
  none.landmarks.clear();
  EXPECT_ERROR_HAS(LandmarkRigFitter(none, Intrinsics(), {}), "68 iBUG landmarks");
  CameraIntrinsics bad = Intrinsics();
  bad.fx = 0.0;
  EXPECT_ERROR_HAS(LandmarkRigFitter(rig, bad, {}), "focal");
  LandmarkFitOptions o;
  o.contour_tangent_weight = 2.0;
  EXPECT_ERROR_HAS(o.Check(), "contour_tangent_weight");
  o = {};
  EXPECT_ERROR_HAS(SetOptionsFromJson(R"({"linear_solver": "sparse"})", "fit.json", &o),
                   "fit.json: option 'linear_solver' must be one of: dense_normal_cholesky, dense_qr");
}

TEST(LandmarkFit, GroundTruthPriorIsTheRigsBestExplanation) {
  const FaceRig& rig = Rig();
  const Eigen::VectorXd identity = TrueIdentity(rig);
  const Eigen::VectorXd beta = ExpressionWeights(rig, {{"jawOpen", 0.5}, {"browInnerUp_L", 0.7}});
  const Rigid3d pose = Pose(8.0, 2.0);
  // Ground truth: the projections of all rig vertices (NaN-free here).
  const MatX3d X = rig.EvaluatePositions(identity, beta);
  const MatX2d all = Camera(Intrinsics(), pose).ProjectAll(X);
  LandmarkFitOptions fit_options;
  fit_options.identity_frames = 0;
  GroundTruthPriorOptions clean;
  GroundTruthPriorFitter gt(rig, Intrinsics(), fit_options, clean);
  gt.fitter().SetIdentity(identity);
  const LandmarkFrameFit a = gt.Fit(all);
  EXPECT_LT(a.rms_px, 0.5);
  EXPECT_NEAR(a.expression[rig.ExpressionIndex("jawOpen")], 0.5, 0.1);
  EXPECT_LT(RotationErrorDeg(a.cam_from_head, pose), 1.0);
  // 68-row input gives the same fit as the all-vertex input.
  GroundTruthPriorFitter gt68(rig, Intrinsics(), fit_options, clean);
  gt68.fitter().SetIdentity(identity);
  const LandmarkFrameFit b = gt68.Fit(gt.last_landmarks());
  EXPECT_LT((a.expression - b.expression).norm(), 1e-9);

  // Noise: deterministic per seed, different across seeds; the fit explains the noisy
  // landmarks with the rig (residual about the noise level), not exactly.
  GroundTruthPriorOptions noisy;
  noisy.gt_prior_noise_px = 1.0;
  noisy.gt_prior_noise_seed = 5;
  GroundTruthPriorFitter n1(rig, Intrinsics(), fit_options, noisy), n2(rig, Intrinsics(), fit_options, noisy);
  noisy.gt_prior_noise_seed = 6;
  GroundTruthPriorFitter n3(rig, Intrinsics(), fit_options, noisy);
  for (GroundTruthPriorFitter* g : {&n1, &n2, &n3}) g->fitter().SetIdentity(identity);
  const LandmarkFrameFit f1 = n1.Fit(all), f2 = n2.Fit(all), f3 = n3.Fit(all);
  EXPECT_EQ(f1.expression, f2.expression);
  EXPECT_NE(n1.last_landmarks(), n3.last_landmarks());
  EXPECT_GT(f1.rms_px, 0.3);
  EXPECT_LT(f1.rms_px, 2.0);
  // Rows behind the camera are ignored.
  MatX2d missing = all;
  missing.row(rig.landmarks[rig.LandmarkIndex("ibug_9")].vertex).setConstant(std::nan(""));
  GroundTruthPriorFitter gtm(rig, Intrinsics(), fit_options, clean);
  EXPECT_NO_THROW(gtm.Fit(missing));
  EXPECT_ERROR_HAS(gtm.Fit(all.topRows(100)), "expected the projections");
  GroundTruthPriorOptions bad;
  bad.gt_prior_noise_px = -1.0;
  EXPECT_ERROR_HAS(GroundTruthPriorFitter(rig, Intrinsics(), fit_options, bad), "gt_prior_noise_px");
}

}  // namespace
}  // namespace crease
