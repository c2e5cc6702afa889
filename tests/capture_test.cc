// Online capture end to end (pipeline/capture/capture.h, paper Sec. 5; issue 6):
// a tiny studio sequence of one actor with deep wrinkles (brow raise, frown,
// neutral, 320×240, a key light from above that shows the wrinkles) goes through
// CaptureSession — flow refinement (Sec. 5.1), texture T^t, wrinkle map of the
// first N frames, detail regression D^t (Sec. 5.2), mesoscopic map and H^t
// (Sec. 5.3) — with a tiny detail model trained in-process (Sec. 4.2–4.3) on the
// SAME actor's textures at other expression intensities paired with its true
// expression displacement D. This tests the capture machinery (UV layout, texture
// alignment, patch sampling, regression, merge and fill, H^t), not generalisation
// across actors.
//
// The global tracker is simulated: each frame's fit is the truth perturbed like a
// strong-prior tracker's coarse mesh (expression weights damped, a spurious
// expression, the pose off by a few mm), and its landmarks are the truth's with
// 1 px noise. The first frame of every tracked run (the start, and after the lost
// frame) gets only a small perturbation: the flow refinement has no flow there
// (Sec. 5.1; ũ^t = u^t) and later frames carry its error forward.
//
// Checks: (a) the mean 2D error of L~^t is below that of L^t; (b) D^t correlates
// with the true D over the patch-covered texels of the wrinkle regions, and not
// with a misaligned truth; (c) H^t exists with finite vertices for every tracked
// frame; (d) a lost frame in the middle gives a frame without mesh and the session
// goes on.
//
// Measured (Release, this 2-vCPU machine): L^t 2.04 px → L~^t 0.99 px (frames with
// flow 2.76 → 1.09 px); correlation of D^t with the true D 0.57; ~3.5 s in all.
#include "pipeline/capture/capture.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/rng.h"
#include "pipeline/training/detail_extraction.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/fern_cascade.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/pca.h"
#include "pipeline/training/wrinkle_map.h"
#include "synth/lights.h"
#include "synth/studio.h"
#include "tests/detail_model_test_util.h"
#include "tests/synth_test_util.h"

namespace crease {
namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

const FaceRig& Rig() { return testing::ProceduralRig(); }

constexpr int kR = 256;  // map resolution of the model and the session

// Expression weights of a brow raise (both brows, inner and outer) and a frown.
Eigen::VectorXd Weights(double brow_raise, double frown) {
  const FaceRig& rig = Rig();
  Eigen::VectorXd e = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const char* side : {"_L", "_R"}) {
    e[rig.ExpressionIndex(std::string("browInnerUp") + side)] = brow_raise;
    e[rig.ExpressionIndex(std::string("browOuterUp") + side)] = 0.8 * brow_raise;
    e[rig.ExpressionIndex(std::string("browDown") + side)] = frown;
  }
  return e;
}

SequenceFrame Pose(double yaw_deg, double pitch_deg, double tx_mm, double ty_mm) {
  SequenceFrame f;
  f.yaw_deg = yaw_deg;
  f.pitch_deg = pitch_deg;
  f.tx_mm = tx_mm;
  f.ty_mm = ty_mm;
  return f;
}

// The actor, its studio (320×240, sensor noise on) and the light.
struct Fixture {
  Actor actor;
  std::unique_ptr<Studio> studio;
  LightRig light;
  Fixture() {
    ActorOptions ao;
    ao.resolution = kR;
    ao.surface_min_vertices = 1000;
    ao.age_min = 0.8;  // deep wrinkles
    actor = GenerateActor(Rig(), 5, ao);
    StudioOptions so;
    so.width = 320;
    so.height = 240;
    so.samples_per_axis = 1;
    so.distance_mm = 330.0;  // the face ~150 px wide, the forehead inside the image
    studio = std::make_unique<Studio>(Rig(), actor, so);
    // A key light from 50° above (15° to the side) and weak ambient occlusion:
    // wrinkles across the forehead cast clear shading lines (under the soft
    // "studio" rig they barely show at this image size).
    light = DirectionalRig(15.0, 50.0);
  }
  StudioFrame Render(const Eigen::VectorXd& weights, const SequenceFrame& pose, uint64_t seed) const {
    return studio->RenderStill(weights, pose, &light, nullptr, seed);
  }
};

// The true coarse mesh of a frame in the camera frame (#V×3, mm).
MatX3d TrueCamVertices(const StudioFrame& f) {
  const MatX3d& V = f.actor.coarse.V;
  MatX3d out(V.rows(), 3);
  for (int v = 0; v < V.rows(); ++v) {
    out.row(v) = (f.truth.cam_from_head * Eigen::Vector3d(V.row(v).transpose())).transpose();
  }
  return out;
}

// The tiny detail model: Sec. 4.2 wrinkle map and layout on the actor's textures
// (extracted with FrameTextureExtractor from renders with the true pose, coverage
// = the texels every texture saw, as the trainer does), paired with its true D
// maps; Sec. 4.3 PCA and fern cascade. The training shots are other expression
// intensities (and poses) than the test frames. Lowpass G = 0: the studio's D is
// relative to the rig surface itself, so the compatible rig is the rig
// (MakeRigCompatible returns it unchanged).
DetailModel TrainTinyModel(const Fixture& fx, const CameraIntrinsics& K, int* training_pairs) {
  const FaceRig& rig = Rig();
  DetailModel m;
  m.map_resolution = kR;
  m.detail.lowpass_bandwidth_mm = 0.0;
  m.detail.map_resolution = kR;
  // DoG σ 6 / 8 at 1024² (the paper's) → 1.5 / 2 texels at 256².
  m.wrinkle.dog_reference_resolution = 1024;
  // α below the paper's 0.005: at 320×240 (~1.3 texels per pixel at R = 256) the
  // image blurs the wrinkle shading; with 0.005 few forehead texels pass.
  m.wrinkle.wrinkle_threshold = 0.003;
  // w: the paper's 32 at 1024² would be 8 here; 12 covers ~12 mm of skin.
  m.patch.patch_size = 12;
  FrameTextureOptions to;
  to.map_resolution = kR;
  const FrameTextureExtractor extractor(rig, K, to);
  struct Shot {
    double brow, frown, yaw;
  };
  const std::vector<Shot> shots = {{0.3, 0.0, -3.0}, {0.6, 0.0, 2.0}, {1.0, 0.0, 0.0},   {0.0, 0.35, 3.0},
                                   {0.0, 0.7, -2.0}, {0.0, 1.0, 1.0}, {0.15, 0.0, -1.0}, {0.7, 0.3, -1.0}};
  std::vector<cv::Mat> textures, displacements;
  cv::Mat coverage = extractor.coverage().clone();
  uint64_t seed = 100;
  for (const Shot& s : shots) {
    const StudioFrame f = fx.Render(Weights(s.brow, s.frown), Pose(s.yaw, 0.0, 0.0, 0.0), seed++);
    const FrameTexture t = extractor.Extract(TrueCamVertices(f), f.image.decoded);
    textures.push_back(t.gray);
    cv::bitwise_and(coverage, t.seen, coverage);
    displacements.push_back(f.actor.expression_displacement);
  }
  WrinkleMapBuilder builder(kR, coverage, rig.regions, m.wrinkle);
  std::vector<cv::Mat> responses;
  for (const cv::Mat& t : textures) responses.push_back(builder.Add(t));
  const PatchLayout layout = PlacePatches(builder.Finish(), m.patch);
  *training_pairs =
      testing::FitTinyRegressor(layout, textures, responses, displacements, /*pca_dimensions=*/8, /*num_ferns=*/200, &m);
  std::printf("model: %zu training textures, %d patches, %d training pairs, PCA %d dimensions\n", textures.size(),
              layout.num_patches(), *training_pairs, m.pca.dimensions());
  return m;
}

std::vector<int> IbugVertices() {
  const FaceRig& rig = Rig();
  std::vector<int> v(68);
  for (int i = 0; i < 68; ++i) v[i] = rig.landmarks[rig.LandmarkIndex("ibug_" + std::to_string(i + 1))].vertex;
  return v;
}

// The simulated global tracker's output for a frame: the truth's landmarks with
// σ = 1 px noise and the truth's fit perturbed by `amount` (1 = a strong-prior
// tracker's coarse mesh: brow / frown weights damped by 40 %, a spurious cheek
// squint, the head ~2–3 mm and ~1° off).
TrackedFrame SimulatedTracker(const StudioFrame& f, int index, double amount, Rng& rng) {
  const FaceRig& rig = Rig();
  TrackedFrame t;
  t.frame = index;
  t.tracked = true;
  t.confidence = 1.0;
  const std::vector<int> ibug = IbugVertices();
  t.landmarks.resize(68, 2);
  for (int i = 0; i < 68; ++i) {
    t.landmarks.row(i) = f.truth.vertex_pixels.row(ibug[i]);
    t.landmarks(i, 0) += rng.Normal();
    t.landmarks(i, 1) += rng.Normal();
  }
  Eigen::VectorXd beta = f.truth.expression;
  beta *= 1.0 - 0.4 * amount;
  for (const char* name : {"cheekSquint_L", "mouthSmile_R"}) beta[rig.ExpressionIndex(name)] += 0.25 * amount;
  t.fit.expression = beta.cwiseMax(0.0).cwiseMin(1.0);
  // The pose: turned by ~1° about the head's origin, moved by ~2.5 mm.
  const double dz = rng.Uniform(-3.0, 3.0), dy = rng.Uniform(-1.5, -0.5);  // one draw per statement
  const Eigen::Vector3d dt(rng.Uniform(1.0, 2.0), dy, dz);
  const Eigen::Quaterniond dR(
      Eigen::AngleAxisd(amount * std::numbers::pi / 180.0, Eigen::Vector3d(0.3, 1.0, 0.1).normalized()));
  t.fit.cam_from_head = f.truth.cam_from_head * Rigid3d(dR, Eigen::Vector3d::Zero());
  t.fit.cam_from_head.translation += amount * dt;
  return t;
}

// Mean 2D distance (px) of the projections of `cam_vertices` to the truth over the
// truly visible face-chart vertices.
double MeanError2d(const CameraIntrinsics& K, const MatX3d& cam_vertices, const StudioFrameTruth& truth,
                   const std::vector<uint8_t>& chart) {
  const Camera cam(K, Rigid3d());
  double sum = 0.0;
  int n = 0;
  for (int v = 0; v < cam_vertices.rows(); ++v) {
    if (!chart[v] || !truth.vertex_visible[v]) continue;
    sum += (cam.ProjectCamPoint(cam_vertices.row(v).transpose()) - truth.vertex_pixels.row(v).transpose()).norm();
    ++n;
  }
  return n ? sum / n : 0.0;
}

// Pooled Pearson correlation of pairs (x, y).
struct Moments {
  double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  long n = 0;
  void Add(double x, double y) { sx += x, sy += y, sxx += x * x, syy += y * y, sxy += x * y, ++n; }
  double Correlation() const {
    const double cov = sxy / n - sx / n * sy / n;
    return cov / std::sqrt((sxx / n - sx * sx / n / n) * (syy / n - sy * sy / n / n));
  }
};

// Rung R1's wrinkle texture: a groove of the displacement is a dark line, flat skin
// mid-grey, NaN neutral; resampled to the map size and clamped to [0, 1].
TEST(Capture, WrinkleTextureFromDisplacementDrawsGroovesDark) {
  cv::Mat d(64, 64, CV_32F, cv::Scalar(0.0f));
  d.row(20).setTo(-0.3f);
  d.row(21).setTo(-0.3f);
  d.at<float>(40, 40) = std::numeric_limits<float>::quiet_NaN();
  d.at<float>(50, 50) = 5.0f;
  const cv::Mat same = WrinkleTextureFromDisplacement(d, 64);
  EXPECT_NEAR(same.at<float>(20, 10), 0.35f, 1e-6);
  EXPECT_NEAR(same.at<float>(5, 10), 0.5f, 1e-6);
  EXPECT_NEAR(same.at<float>(40, 40), 0.5f, 1e-6);
  EXPECT_NEAR(same.at<float>(50, 50), 1.0f, 1e-6);
  const cv::Mat half = WrinkleTextureFromDisplacement(d, 32);
  ASSERT_EQ(half.rows, 32);
  EXPECT_NEAR(half.at<float>(10, 5), 0.35f, 1e-5);  // rows 20–21 average into row 10
  EXPECT_THROW(WrinkleTextureFromDisplacement(cv::Mat(4, 8, CV_32F), 4), Error);
}

TEST(Capture, EndToEndOnAStudioSequence) {
  const auto t_start = Clock::now();
  const FaceRig& rig = Rig();
  const Fixture fx;
  const CameraIntrinsics K = fx.studio->camera().intrinsics;
  auto t0 = Clock::now();
  int training_pairs = 0;
  const DetailModel model = TrainTinyModel(fx, K, &training_pairs);
  const double train_s = Seconds(t0);
  ASSERT_GT(training_pairs, 50);

  // The test sequence, other intensities and poses than the training shots. The
  // first N = 3 frames (near neutral, brow raise, frown: the extremes, Sec. 5.2)
  // build the wrinkle map; frame 4 is lost.
  struct Shot {
    double brow, frown;
    SequenceFrame pose;
  };
  const std::vector<Shot> shots = {{0.1, 0.0, Pose(0.0, 0.0, 0.0, 0.0)},  {0.85, 0.0, Pose(1.5, 1.0, 1.0, 0.0)},
                                   {0.0, 0.85, Pose(3.0, 0.5, 2.0, -1.0)}, {0.5, 0.0, Pose(2.0, -1.0, 1.0, -1.0)},
                                   {0.5, 0.0, Pose(2.0, -1.0, 1.0, -1.0)}, {0.0, 0.55, Pose(0.5, 0.0, -1.0, 0.0)},
                                   {0.0, 0.0, Pose(-1.5, 0.5, -2.0, 1.0)}};
  constexpr int kN = 3, kLost = 4;
  t0 = Clock::now();
  std::vector<StudioFrame> frames;
  for (size_t i = 0; i < shots.size(); ++i) {
    if (static_cast<int>(i) == kLost) {
      frames.push_back(frames.back());  // the lost frame: its image does not matter
      continue;
    }
    frames.push_back(fx.Render(Weights(shots[i].brow, shots[i].frown), shots[i].pose, 10 + i));
  }
  const double render_s = Seconds(t0);

  t0 = Clock::now();
  const FaceRig capture_rig = CompatibleRig(rig, model);
  EXPECT_EQ((capture_rig.expression_basis - rig.expression_basis).norm(), 0.0f);  // G = 0: the rig itself
  CaptureOptions co;
  co.detail.wrinkle_frames = kN;
  co.detail.fill.fill_resolution = 64;
  co.hifi.hifi_mesh_resolution = 128;
  CaptureSession session(capture_rig, model, K, co);
  const double setup_s = Seconds(t0);

  t0 = Clock::now();
  Rng rng(17);
  std::vector<CapturedFrame> out;
  std::vector<size_t> returned_per_call;
  bool first_of_run = true;
  for (size_t i = 0; i < frames.size(); ++i) {
    TrackedFrame t;
    if (static_cast<int>(i) == kLost) {
      t.frame = static_cast<int>(i);  // the tracker lost the face: no fit, no landmarks
      first_of_run = true;
    } else {
      t = SimulatedTracker(frames[i], static_cast<int>(i), first_of_run ? 0.25 : 1.0, rng);
      first_of_run = false;
    }
    std::vector<CapturedFrame> done =
        session.Process(static_cast<int>(i), frames[i].image.decoded, t, fx.actor.identity);
    returned_per_call.push_back(done.size());
    for (CapturedFrame& c : done) out.push_back(std::move(c));
  }
  EXPECT_TRUE(session.Flush().empty());  // all frames were returned already
  const double capture_s = Seconds(t0);

  // Nothing during the first N − 1 calls, then N frames at once, then one per call, in order.
  ASSERT_EQ(out.size(), frames.size());
  EXPECT_EQ(returned_per_call, (std::vector<size_t>{0, 0, 3, 1, 1, 1, 1}));
  for (size_t i = 0; i < out.size(); ++i) EXPECT_EQ(out[i].frame, static_cast<int>(i));
  ASSERT_TRUE(session.layout_fixed());
  ASSERT_FALSE(session.mesoscopic().empty());
  const PatchLayout& layout = session.detail().layout();
  ASSERT_GT(layout.num_patches(), 10);

  // (d) The lost frame has no mesh and no detail; the session goes on: the next
  // frame restarts the refinement from L^t (no flow source), the one after has
  // flow again, and every later frame has a mesh and D^t.
  EXPECT_FALSE(out[kLost].tracked.tracked);
  EXPECT_FALSE(out[kLost].has_mesh);
  EXPECT_FALSE(out[kLost].has_detail);
  EXPECT_EQ(out[kLost].refined.rows(), 0);
  EXPECT_TRUE(out[kLost].displacement.empty());
  EXPECT_THROW(session.HifiMesh(out[kLost]), Error);
  for (size_t i = kLost + 1; i < out.size(); ++i) {
    EXPECT_TRUE(out[i].has_mesh) << i;
    EXPECT_TRUE(out[i].has_detail) << i;
  }
  EXPECT_EQ(out[kLost + 1].refinement.trusted, 0);
  EXPECT_GT(out[kLost + 2].refinement.trusted, 50);

  std::vector<uint8_t> chart(rig.num_vertices(), 0);
  const MatX3i F = FaceChartTriangles(rig);
  for (int f = 0; f < F.rows(); ++f)
    for (int c = 0; c < 3; ++c) chart[F(f, c)] = 1;
  // The texels compared in (b): the wrinkle regions (the model's patch regions)
  // covered by a patch of the session's layout, where the frame saw the skin.
  const cv::Mat wrinkle_regions =
      ValidRegionMask(rig.regions, model.wrinkle.patch_regions, kR, session.texture_extractor().coverage());
  const cv::Mat patch_covered = PatchSampler(layout).splat_weight() > 0;
  // H^t without displacement: the same grid on L~^t, to measure H^t's offset.
  const HifiMeshBuilder flat(capture_rig, co.hifi);
  const cv::Mat no_displacement = cv::Mat::zeros(kR, kR, CV_32F);

  double coarse_px = 0, refined_px = 0, coarse_flow_px = 0, refined_flow_px = 0;
  int tracked = 0, flow_frames = 0;
  Moments patches, regions, shifted, flipped_u, flipped_v;
  for (size_t i = 0; i < out.size(); ++i) {
    const CapturedFrame& c = out[i];
    if (!c.has_mesh) continue;
    ++tracked;
    // (a) 2D error of L^t and L~^t against the true projections.
    const StudioFrameTruth& truth = frames[i].truth;
    const double ec = MeanError2d(K, c.coarse, truth, chart), er = MeanError2d(K, c.refined, truth, chart);
    coarse_px += ec;
    refined_px += er;
    if (c.refinement.trusted > 0) {  // frames with flow (not the first of a tracked run)
      coarse_flow_px += ec;
      refined_flow_px += er;
      ++flow_frames;
    }

    // (c) H^t: a dense mesh with finite vertices, each offset from L~^t along the
    // normal by the combined map D^t + D^HF.
    const TriMesh H = session.HifiMesh(c);
    ASSERT_GT(H.num_vertices(), 5000) << i;
    EXPECT_GT(H.F.rows(), 5000) << i;
    EXPECT_TRUE(H.V.allFinite()) << i;
    EXPECT_TRUE(H.N.allFinite()) << i;
    const TriMesh L = flat.Build(c.refined, no_displacement);
    ASSERT_EQ(L.num_vertices(), H.num_vertices());
    const double max_offset = (H.V - L.V).rowwise().norm().maxCoeff();
    const double mean_offset = (H.V - L.V).rowwise().norm().mean();
    EXPECT_LE(max_offset, cv::norm(session.CombinedDisplacement(c), cv::NORM_INF) + 1e-4) << i;
    EXPECT_GT(mean_offset, 1e-3) << i;

    // (b) D^t against the true D.
    ASSERT_TRUE(c.has_detail) << i;
    const cv::Mat& D = c.displacement;
    const cv::Mat& G = frames[i].actor.expression_displacement;
    ASSERT_EQ(D.size(), cv::Size(kR, kR));
    ASSERT_EQ(G.size(), cv::Size(kR, kR));
    EXPECT_TRUE(cv::checkRange(D)) << i;
    Moments frame_patches;
    for (int y = 0; y < kR; ++y) {
      for (int x = 0; x < kR; ++x) {
        if (!wrinkle_regions.at<uint8_t>(y, x) || !c.texture.seen.at<uint8_t>(y, x)) continue;
        const double d = D.at<float>(y, x), g = G.at<float>(y, x);
        regions.Add(d, g);
        if (!patch_covered.at<uint8_t>(y, x)) continue;
        patches.Add(d, g);
        frame_patches.Add(d, g);
        // Controls: the truth misaligned by 3 texels (~3 mm) in v, or flipped.
        shifted.Add(d, G.at<float>(std::min(y + 3, kR - 1), x));
        flipped_u.Add(d, G.at<float>(y, kR - 1 - x));
        flipped_v.Add(d, G.at<float>(kR - 1 - y, x));
      }
    }
    double d_lo, d_hi, g_lo, g_hi;
    cv::minMaxLoc(D, &d_lo, &d_hi, nullptr, nullptr, wrinkle_regions);
    cv::minMaxLoc(G, &g_lo, &g_hi, nullptr, nullptr, wrinkle_regions);
    std::printf("frame %zu: 2D error L^t %.2f px, L~^t %.2f px (flow points: %d trusted, %d recovered, %d reset); "
                "D^t in [%.3f, %.3f] mm, true D in [%.3f, %.3f] mm (wrinkle regions), correlation %.3f over %ld "
                "texels; H^t %d vertices, offset mean %.3f max %.3f mm; %.1f ms (refine %.1f, texture %.1f, "
                "detail %.1f, hifi %.1f)\n",
                i, ec, er, c.refinement.trusted, c.refinement.recovered, c.refinement.reset, d_lo, d_hi, g_lo, g_hi,
                frame_patches.Correlation(), frame_patches.n, H.num_vertices(), mean_offset, max_offset,
                c.timing.total_ms(), c.timing.refine_ms, c.timing.texture_ms, c.timing.detail_ms, c.timing.hifi_ms);
  }
  ASSERT_EQ(tracked, static_cast<int>(frames.size()) - 1);
  coarse_px /= tracked;
  refined_px /= tracked;
  coarse_flow_px /= std::max(flow_frames, 1);
  refined_flow_px /= std::max(flow_frames, 1);
  std::printf("(a) mean 2D error over %d tracked frames: L^t %.2f px → L~^t %.2f px; over the %d frames with flow: "
              "%.2f → %.2f px\n",
              tracked, coarse_px, refined_px, flow_frames, coarse_flow_px, refined_flow_px);
  std::printf("(b) D^t vs true D: correlation %.3f over %ld patch-covered texels of the wrinkle regions (%d patches; "
              "%.3f over all %ld seen wrinkle-region texels); controls: truth shifted 3 texels in v %.3f, flipped in "
              "u %.3f, flipped in v %.3f\n",
              patches.Correlation(), patches.n, layout.num_patches(), regions.Correlation(), regions.n,
              shifted.Correlation(), flipped_u.Correlation(), flipped_v.Correlation());
  std::printf("time: fixture + training %.1f s, rendering %.1f s, session setup %.2f s, capture %.2f s; total %.1f s\n",
              train_s, render_s, setup_s, capture_s, Seconds(t_start));
  // (a) Measured 2.04 → 0.99 px over all tracked frames, 2.76 → 1.09 px over the
  // frames with flow (on the first frame of a run L^t is nearly the truth and the
  // landmarks' 1 px noise makes L~^t a little worse: 0.6 → 0.8 px).
  EXPECT_LT(refined_px, coarse_px);
  EXPECT_EQ(flow_frames, 4);
  EXPECT_LT(refined_flow_px, 0.6 * coarse_flow_px);
  // (b) Measured 0.57 (0.40–0.59 for actor seeds 3–8); the truth misaligned by 3
  // texels gives 0.03, flipped in v 0.02, and flipped in u 0.47: this actor's
  // wrinkles (horizontal forehead lines) are nearly mirror-symmetric, so a u flip
  // is not what this check can see.
  EXPECT_GT(patches.Correlation(), 0.3);
  EXPECT_LT(shifted.Correlation(), patches.Correlation() - 0.2);
  EXPECT_LT(flipped_v.Correlation(), patches.Correlation() - 0.2);
}

}  // namespace
}  // namespace crease
