// Per-frame texture T^t with visibility and the mesoscopic map D^HF
// (pipeline/capture/frame_texture.h; paper Sec. 5.1, 5.3), on frames rendered
// by the studio renderer from the procedural rig itself (exact geometry), and on
// a full studio frame (high-resolution actor, skin maps).
#include "pipeline/capture/frame_texture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>

#include "core/image_io.h"
#include "core/mesh_ops.h"
#include "core/uv_raster.h"
#include "synth/renderer.h"
#include "synth/studio.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

const FaceRig& Rig() { return testing::ProceduralRig(); }

constexpr int kR = 1024;

// A gray albedo pattern without symmetries, periods of ~45 and ~60 texels at
// R = 1024 (~11 and ~15 px in a 640×480 frame of the face).
double Pattern(double u, double v) {
  constexpr double k2pi = 2.0 * std::numbers::pi;
  return 0.45 + 0.2 * std::sin(k2pi * (23.0 * u + 3.0 * v)) + 0.1 * std::cos(k2pi * (5.0 * u - 17.0 * v + 0.3));
}

cv::Mat PatternAlbedo(int size) {
  cv::Mat a(size, size, CV_32FC3);
  for (int j = 0; j < size; ++j) {
    for (int i = 0; i < size; ++i) {
      const float g = static_cast<float>(Pattern((i + 0.5) / size, (j + 0.5) / size));
      a.at<cv::Vec3f>(j, i) = cv::Vec3f(g, g, g);
    }
  }
  return a;
}

// The neutral rig turned by `yaw_deg` about the vertical axis through the face centre.
struct Scene {
  TriMesh mesh;            // head frame, with normals
  Camera camera;
  MatX3d cam_vertices;     // camera frame
  RenderResult render;     // linear RGB + passes
  Eigen::Vector3d light;   // head frame, towards the light
};

Eigen::Vector3d FaceCentre() {
  const MatX3i F = FaceChartTriangles(Rig());
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int f = 0; f < F.rows(); ++f) c += Rig().neutral.V.row(F(f, 0)).transpose();
  return c / F.rows();
}

// Rendered without shadows and specular under one directional light from the
// camera: pixel = albedo · max(0, n·l) exactly (Lambert, renderer's intensity convention).
Scene RenderRig(double yaw_deg) {
  Scene s;
  const FaceRig& rig = Rig();
  const Eigen::Vector3d c = FaceCentre();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw_deg * std::numbers::pi / 180.0, Eigen::Vector3d::UnitY()).matrix();
  s.mesh = rig.neutral;
  for (int v = 0; v < s.mesh.num_vertices(); ++v) {
    s.mesh.V.row(v) = (c + R * (rig.neutral.V.row(v).transpose() - c)).transpose();
  }
  s.mesh.N = VertexNormals(s.mesh);
  s.camera = LookAtCamera(CameraIntrinsics::FromFov(50.0, 640, 480), c + Eigen::Vector3d(0, 0, 450), c,
                          Eigen::Vector3d::UnitY());
  s.cam_vertices.resize(s.mesh.num_vertices(), 3);
  for (int v = 0; v < s.mesh.num_vertices(); ++v) {
    s.cam_vertices.row(v) = (s.camera.cam_from_head * Eigen::Vector3d(s.mesh.V.row(v).transpose())).transpose();
  }
  SceneMaterials materials;
  materials.albedo = PatternAlbedo(kR);
  materials.vertex_part.assign(rig.vertex_part.begin(), rig.vertex_part.end());
  for (const std::string& name : rig.part_names) {
    Material m = MaterialPreset("grey");
    if (name == "face") {
      m.specular = 0.0f;
      m.textured = true;
    }
    materials.part_materials.push_back(m);
  }
  Renderer renderer(s.mesh, materials);
  s.light = Eigen::Vector3d::UnitZ();
  LightRig lights;
  lights.name = "frontal";
  lights.attached_to_camera = false;
  DirectionalLight d;
  d.direction = s.light;
  lights.lights = {d};
  RenderOptions ro;
  ro.shadows = false;
  ro.passes = true;
  Rng rng(1);
  s.render = renderer.Render(s.camera, lights, ro, rng);
  return s;
}

const Scene& Frontal() {
  static const Scene s = RenderRig(0.0);
  return s;
}

const FrameTextureExtractor& Extractor() {
  static const FrameTextureExtractor ex(Rig(), Frontal().camera.intrinsics, FrameTextureOptions{});
  return ex;
}

// The seen mask eroded by `texels` (borders of visibility excluded from comparisons).
cv::Mat Interior(const cv::Mat& seen, int texels) {
  cv::Mat out;
  cv::erode(seen, out, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * texels + 1, 2 * texels + 1)));
  return out;
}

// Expected gray texel values: pattern · max(0, n·l), n interpolated from the render normals.
cv::Mat ExpectedTexture(const Scene& s, const FrameTextureExtractor& ex, double shift_u_texels = 0.0,
                        bool flip_u = false) {
  TriMesh chart = ex.chart_mesh();
  chart.V = s.mesh.V;
  const cv::Mat normals = InterpolateToUv(ex.raster(), chart, s.mesh.N);
  cv::Mat expected(kR, kR, CV_32F, cv::Scalar(0));
  for (int j = 0; j < kR; ++j) {
    for (int i = 0; i < kR; ++i) {
      if (!ex.raster().covered(i, j)) continue;
      const cv::Vec3f n = normals.at<cv::Vec3f>(j, i);
      const Eigen::Vector3d nn = Eigen::Vector3d(n[0], n[1], n[2]).normalized();
      double u = (i + 0.5 + shift_u_texels) / kR;
      if (flip_u) u = 1.0 - u;
      expected.at<float>(j, i) = static_cast<float>(Pattern(u, (j + 0.5) / kR) * std::max(0.0, nn.dot(s.light)));
    }
  }
  return expected;
}

double RmsOver(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask, double* max_abs = nullptr,
               double* p999 = nullptr) {
  double sum = 0, mx = 0;
  long n = 0;
  std::vector<double> errors;
  for (int j = 0; j < a.rows; ++j) {
    for (int i = 0; i < a.cols; ++i) {
      if (!mask.at<uint8_t>(j, i)) continue;
      const double d = a.at<float>(j, i) - b.at<float>(j, i);
      sum += d * d;
      mx = std::max(mx, std::abs(d));
      errors.push_back(std::abs(d));
      ++n;
    }
  }
  if (max_abs) *max_abs = mx;
  if (p999 && !errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + static_cast<long>(0.999 * errors.size()), errors.end());
    *p999 = errors[static_cast<size_t>(0.999 * errors.size())];
  }
  return n > 0 ? std::sqrt(sum / n) : 0.0;
}

TEST(FrameTexture, MatchesAlbedoTimesShadingOfARenderedFrame) {
  const Scene& s = Frontal();
  const FrameTextureExtractor& ex = Extractor();
  const FrameTexture t = ex.Extract(s.cam_vertices, s.render.image);
  ASSERT_EQ(t.gray.type(), CV_32F);
  ASSERT_EQ(t.gray.rows, kR);
  ASSERT_EQ(t.seen.type(), CV_8U);
  const int covered = cv::countNonZero(ex.coverage());
  EXPECT_EQ(t.num_seen, cv::countNonZero(t.seen));
  // A frontal face: most of the chart is seen (the temples and under the chin are beyond 75°).
  EXPECT_GT(t.num_seen, 0.6 * covered) << t.num_seen << " of " << covered;
  // Seen ⊂ covered, and 0 where unseen.
  cv::Mat outside;
  cv::bitwise_and(t.seen, ~ex.coverage(), outside);
  EXPECT_EQ(cv::countNonZero(outside), 0);
  cv::Mat unseen_values;
  t.gray.copyTo(unseen_values);
  unseen_values.setTo(0.0f, t.seen);
  EXPECT_EQ(cv::countNonZero(unseen_values), 0);

  const cv::Mat interior = Interior(t.seen, 4);
  double max_err = 0, p999 = 0;
  const double rms = RmsOver(t.gray, ExpectedTexture(s, ex), interior, &max_err, &p999);
  std::printf("T vs albedo·(n·l): RMS %.5f, 99.9th percentile %.4f, max %.4f over %d texels (pattern amplitude 0.3)\n",
              rms, p999, max_err, cv::countNonZero(interior));
  // The worst texels lie in the fold of the upper lids, where the lid hangs over
  // itself at equal depth (a depth test cannot separate the layers).
  EXPECT_LT(rms, 0.006);
  EXPECT_LT(p999, 0.035);
  // The check is sharp enough to see UVs shifted by 3 texels or flipped.
  const double rms_shift = RmsOver(t.gray, ExpectedTexture(s, ex, 3.0), interior);
  const double rms_flip = RmsOver(t.gray, ExpectedTexture(s, ex, 0.0, true), interior);
  std::printf("shifted by 3 texels: RMS %.4f; flipped in u: RMS %.4f\n", rms_shift, rms_flip);
  EXPECT_GT(rms_shift, 4 * rms);
  EXPECT_GT(rms_flip, 10 * rms);

  // A gray (CV_32FC1) image gives the same texture.
  cv::Mat gray_image;
  cv::cvtColor(s.render.image, gray_image, cv::COLOR_RGB2GRAY);  // any weights: R = G = B here
  const FrameTexture t1 = ex.Extract(s.cam_vertices, gray_image);
  EXPECT_EQ(t1.num_seen, t.num_seen);
  EXPECT_LT(RmsOver(t1.gray, t.gray, t.seen), 1e-5);
  // Buffers are reused and results identical; the vertex visibility from the same
  // depth buffer equals VisibleVertices.
  FrameTexture reuse = t;
  std::vector<uint8_t> visible;
  ex.Extract(s.cam_vertices, s.render.image, &reuse, &visible);
  EXPECT_EQ(cv::norm(reuse.gray, t.gray, cv::NORM_INF), 0.0);
  EXPECT_EQ(visible, ex.VisibleVertices(s.cam_vertices));

  // Optional erosion: a subset of the seen texels, shrunk only towards unseen ones
  // (texels on the chart's own boundary that were seen stay seen).
  FrameTextureOptions eo;
  eo.erode_seen_texels = 3;
  const FrameTexture te = FrameTextureExtractor(Rig(), s.camera.intrinsics, eo).Extract(s.cam_vertices, s.render.image);
  cv::Mat extra;
  cv::bitwise_and(te.seen, ~t.seen, extra);
  EXPECT_EQ(cv::countNonZero(extra), 0);
  EXPECT_LT(te.num_seen, t.num_seen);
  EXPECT_GT(te.num_seen, 0.9 * t.num_seen);
  EXPECT_EQ(te.num_seen, cv::countNonZero(te.seen));
  const int j_forehead = 200;  // a row through the forehead: its chart-boundary texels stay seen
  int first = -1;
  for (int i = 0; i < kR && first < 0; ++i) {
    if (ex.coverage().at<uint8_t>(j_forehead, i)) first = i;
  }
  ASSERT_GE(first, 0);
  EXPECT_EQ(t.seen.at<uint8_t>(j_forehead, first + 1), te.seen.at<uint8_t>(j_forehead, first + 1));
}

// Per texel: whether the render sees the texel's own surface point at its
// projection (render UV within `tol_texels` of the texel's UV), 255/0, and
// whether the texel projects inside the image at all.
cv::Mat TrulyVisible(const Scene& s, const FrameTextureExtractor& ex, double tol_texels) {
  TriMesh chart = ex.chart_mesh();
  chart.V = s.cam_vertices;
  const cv::Mat pos = InterpolateToUv(ex.raster(), chart, s.cam_vertices);
  cv::Mat truth(kR, kR, CV_8U, cv::Scalar(0));
  for (int j = 0; j < kR; ++j) {
    for (int i = 0; i < kR; ++i) {
      if (!ex.raster().covered(i, j)) continue;
      const cv::Vec3f p = pos.at<cv::Vec3f>(j, i);
      const Eigen::Vector2d px = s.camera.ProjectCamPoint(Eigen::Vector3d(p[0], p[1], p[2]));
      const int x = static_cast<int>(std::lround(px.x())), y = static_cast<int>(std::lround(px.y()));
      if (x < 0 || y < 0 || x >= s.render.uv.cols || y >= s.render.uv.rows) continue;
      const cv::Vec2f uv = s.render.uv.at<cv::Vec2f>(y, x);
      const double du = (uv[0] * kR - (i + 0.5)), dv = (uv[1] * kR - (j + 0.5));
      if (std::hypot(du, dv) < tol_texels) truth.at<uint8_t>(j, i) = 255;
    }
  }
  return truth;
}

TEST(FrameTexture, OccludedTexelsOfATurnedHeadAreUnseen) {
  const Scene s = RenderRig(60.0);
  const FrameTextureExtractor& ex = Extractor();
  const FrameTexture t = ex.Extract(s.cam_vertices, s.render.image);
  // A pixel is ~4 texels: the render's UV at the nearest pixel centre is within
  // ~3 texels of a visible texel's own UV (more on oblique surfaces).
  const cv::Mat truth = TrulyVisible(s, ex, 12.0);
  // The truth is unreliable within a few texels of the chart's boundary (the
  // nearest pixel may show the neighbouring part, whose UVs lie outside the chart).
  const cv::Mat chart_interior = Interior(ex.coverage(), 4);
  cv::Mat false_seen;
  cv::bitwise_and(t.seen, ~truth, false_seen);
  cv::bitwise_and(false_seen, chart_interior, false_seen);
  std::printf("turned 60°: %d seen, %d truly visible, %d seen but not visible\n", t.num_seen,
              cv::countNonZero(truth), cv::countNonZero(false_seen));
  EXPECT_LT(cv::countNonZero(false_seen), 0.002 * t.num_seen);
  // Occlusion happened: visible-looking (front-facing) texels hidden by the nose
  // exist and are unseen — the half of the chart turned away is mostly unseen.
  const int R = kR;
  int seen_near = 0, seen_far = 0, cov_near = 0, cov_far = 0;
  // Yaw +60° turns the subject's left (+x, larger u) towards the camera's right… decide
  // by the data: the half with more seen texels is the near one.
  for (int j = 0; j < R; ++j) {
    for (int i = 0; i < R; ++i) {
      if (!ex.coverage().at<uint8_t>(j, i)) continue;
      const bool left = i < R / 2;
      (left ? cov_near : cov_far) += 1;
      if (t.seen.at<uint8_t>(j, i)) (left ? seen_near : seen_far) += 1;
    }
  }
  double a = static_cast<double>(seen_near) / cov_near, b = static_cast<double>(seen_far) / cov_far;
  if (a < b) std::swap(a, b);
  std::printf("seen fraction of the near half %.3f, far half %.3f\n", a, b);
  EXPECT_GT(a, 0.7);
  EXPECT_LT(b, 0.35);
  // Seen texels still match albedo · shading.
  const double rms = RmsOver(t.gray, ExpectedTexture(s, ex), Interior(t.seen, 4));
  EXPECT_LT(rms, 0.01);
  // Against the frontal view: the far cheek is occluded, its texels are unseen even
  // where they face the camera within 75° (the nose hides them).
  MatX3d N;
  RigVertexNormals(Rig().neutral).Compute(s.cam_vertices, &N);
  TriMesh chart = ex.chart_mesh();
  const cv::Mat normal_map = InterpolateToUv(ex.raster(), chart, N);
  const cv::Mat pos = InterpolateToUv(ex.raster(), chart, s.cam_vertices);
  int facing_but_hidden = 0, facing_hidden_seen = 0;
  const double cos_limit = std::cos(75.0 * std::numbers::pi / 180.0);
  for (int j = 0; j < R; ++j) {
    for (int i = 0; i < R; ++i) {
      if (!chart_interior.at<uint8_t>(j, i)) continue;
      const cv::Vec3f n = normal_map.at<cv::Vec3f>(j, i), p = pos.at<cv::Vec3f>(j, i);
      const Eigen::Vector3d nn = Eigen::Vector3d(n[0], n[1], n[2]).normalized();
      const Eigen::Vector3d pp(p[0], p[1], p[2]);
      if (-nn.dot(pp.normalized()) < cos_limit + 0.1) continue;  // clearly within the view-angle limit
      if (truth.at<uint8_t>(j, i)) continue;
      ++facing_but_hidden;
      if (t.seen.at<uint8_t>(j, i)) ++facing_hidden_seen;
    }
  }
  std::printf("front-facing but hidden texels: %d, of them seen: %d\n", facing_but_hidden, facing_hidden_seen);
  EXPECT_GT(facing_but_hidden, 1000);
  EXPECT_LT(facing_hidden_seen, 0.01 * facing_but_hidden);
}

TEST(FrameTexture, VisibleVerticesAndDepthBuffer) {
  const Scene& s = Frontal();
  const FrameTextureExtractor& ex = Extractor();
  const FaceRig& rig = Rig();
  const std::vector<uint8_t> vis = ex.VisibleVertices(s.cam_vertices);
  ASSERT_EQ(static_cast<int>(vis.size()), rig.num_vertices());
  // The back of the head (behind the ears) is never visible from the front.
  const Eigen::Vector3d c = FaceCentre();
  int back = 0, back_visible = 0;
  for (int v = 0; v < rig.num_vertices(); ++v) {
    if (rig.neutral.V(v, 2) < c.z() - 120.0) {
      ++back;
      back_visible += vis[static_cast<size_t>(v)] != 0;
    }
  }
  EXPECT_GT(back, 500);
  EXPECT_EQ(back_visible, 0);
  const int nose = rig.LandmarkIndex("ibug_31");  // nose tip
  ASSERT_GE(nose, 0);
  EXPECT_EQ(vis[static_cast<size_t>(rig.landmarks[static_cast<size_t>(nose)].vertex)], 255);
  // Visible vertices agree with the render's depth pass (z within a few mm at the
  // nearest pixel; checked where the view angle is below 60°, since on grazing
  // surfaces the nearest pixel centre may be several mm deeper or nearer).
  MatX3d N;
  RigVertexNormals(rig.neutral).Compute(s.cam_vertices, &N);
  int visible = 0, agree = 0, all_visible = 0;
  for (int v = 0; v < rig.num_vertices(); ++v) {
    if (!vis[static_cast<size_t>(v)]) continue;
    ++all_visible;
    const Eigen::Vector3d p = s.cam_vertices.row(v).transpose();
    if (-N.row(v).dot(p.normalized().transpose()) < 0.5) continue;
    ++visible;
    const Eigen::Vector2d px = s.camera.ProjectCamPoint(p);
    const int x = std::clamp(static_cast<int>(std::lround(px.x())), 0, 639);
    const int y = std::clamp(static_cast<int>(std::lround(px.y())), 0, 479);
    const float d = s.render.depth.at<float>(y, x);
    if (d == 0.0f || d > p.z() - 3.0) ++agree;
  }
  std::printf("visible vertices %d of %d; of the %d within 60° of the view, %d agree with the render's depth\n",
              all_visible, rig.num_vertices(), visible, agree);
  EXPECT_GT(all_visible, rig.num_vertices() / 4);
  EXPECT_GT(agree, 0.995 * visible);
  // Depth buffer against the render's depth pass where both see the mesh.
  const cv::Mat depth = ex.DepthBuffer(s.cam_vertices);
  int both = 0, close = 0;
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) {
      const float a = depth.at<float>(y, x), b = s.render.depth.at<float>(y, x);
      if (!std::isfinite(a) || b == 0.0f) continue;
      ++both;
      close += std::abs(a - b) < 0.05f;
    }
  }
  EXPECT_GT(both, 20000);
  EXPECT_GT(close, 0.99 * both) << close << " of " << both;
}

TEST(FrameTexture, Errors) {
  const Scene& s = Frontal();
  const FrameTextureExtractor& ex = Extractor();
  EXPECT_ERROR_HAS(ex.Extract(s.cam_vertices, cv::Mat(100, 120, CV_32FC3, cv::Scalar::all(0))), "120×100");
  EXPECT_ERROR_HAS(ex.Extract(s.cam_vertices, cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(0))), "CV_32FC3");
  MatX3d bad = s.cam_vertices;
  bad(17, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_ERROR_HAS(ex.Extract(bad, s.render.image), "row 17");
  EXPECT_ERROR_HAS(ex.VisibleVertices(MatX3d::Zero(5, 3)), "5 rows");
  FrameTextureOptions o;
  o.max_view_angle_deg = 95;
  EXPECT_ERROR_HAS(FrameTextureExtractor(Rig(), s.camera.intrinsics, o), "max_view_angle_deg");
}

// Difference 4: the blend with the previous frames lowers independent noise's
// variance to (1 − a)/(1 + a) of a frame's, follows a step within a^k after k frames,
// and never mixes in texels that one of the two frames did not see.
TEST(FrameTexture, TemporalBlendLowersNoiseAndKeepsUnseenTexelsApart) {
  constexpr int kN = 64;
  constexpr double kA = 0.5, kSigma = 0.02;
  Rng rng(7);
  auto frame = [&](double level) {
    FrameTexture t;
    t.gray.create(kN, kN, CV_32F);
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) t.gray.at<float>(j, i) = static_cast<float>(level + kSigma * rng.Normal());
    t.seen = cv::Mat(kN, kN, CV_8U, cv::Scalar(255));
    t.num_seen = kN * kN;
    return t;
  };
  FrameTexture history;
  double sum = 0, sum2 = 0;
  int n = 0;
  for (int f = 0; f < 40; ++f) {
    FrameTexture t = frame(0.3);
    BlendTextureHistory(kA, &t, &history);
    if (f < 10) continue;  // the blend's start-up
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        const double v = t.gray.at<float>(j, i);
        sum += v;
        sum2 += v * v;
        ++n;
      }
  }
  const double var = sum2 / n - (sum / n) * (sum / n);
  EXPECT_NEAR(var / (kSigma * kSigma), (1 - kA) / (1 + kA), 0.03);  // 1/3 at a = 0.5
  EXPECT_NEAR(sum / n, 0.3, 1e-3);

  // A step to 0.5 (noise-free): after k frames the blend is 0.5 − 0.2 a^k.
  for (int k = 1; k <= 3; ++k) {
    FrameTexture t = frame(0.5);
    t.gray.setTo(0.5);
    BlendTextureHistory(kA, &t, &history);
    EXPECT_NEAR(cv::mean(t.gray)[0], 0.5 - 0.2 * std::pow(kA, k), 2e-3) << k;
  }

  // A texel the history did not see keeps its own value; one unseen now stays 0.
  FrameTexture prev = frame(0.3);
  prev.seen.at<uint8_t>(5, 5) = 0;
  prev.gray.at<float>(5, 5) = 0;
  FrameTexture h;
  BlendTextureHistory(kA, &prev, &h);
  FrameTexture cur = frame(0.5);
  cur.gray.at<float>(5, 5) = 0.9f;
  cur.seen.at<uint8_t>(6, 6) = 0;
  cur.gray.at<float>(6, 6) = 0;
  BlendTextureHistory(kA, &cur, &h);
  EXPECT_FLOAT_EQ(cur.gray.at<float>(5, 5), 0.9f);
  EXPECT_FLOAT_EQ(cur.gray.at<float>(6, 6), 0.0f);
  EXPECT_EQ(h.seen.at<uint8_t>(6, 6), 0);

  FrameTexture small = frame(0.3);
  small.gray = cv::Mat(8, 8, CV_32F, cv::Scalar(0));
  small.seen = cv::Mat(8, 8, CV_8U, cv::Scalar(255));
  EXPECT_ERROR_HAS(BlendTextureHistory(kA, &small, &h), "the history is 64x64, the texture 8x8");
  FrameTextureOptions o;
  o.temporal_weight = 0.99;
  EXPECT_ERROR_HAS(o.Check(), "temporal_weight");
}

// A studio frame (high-resolution actor with pores and wrinkles, skin albedo,
// front light) textured with the actor's coarse mesh looks like the albedo.
TEST(FrameTexture, StudioFrameLooksLikeTheSkinAlbedo) {
  const FaceRig& rig = Rig();
  ActorOptions ao;
  ao.resolution = 512;
  ao.surface_min_vertices = 1000;
  const Actor actor = GenerateActor(rig, 7, ao);
  StudioOptions so;
  so.light = "front";
  so.samples_per_axis = 1;
  so.sensor.noise = false;
  so.sensor.jpeg_quality = 0;
  const Studio studio(rig, actor, so);
  const StudioFrame frame = studio.RenderStill(Eigen::VectorXd(), SequenceFrame{}, nullptr, nullptr, 1);
  MatX3d cam_vertices(rig.num_vertices(), 3);
  for (int v = 0; v < rig.num_vertices(); ++v) {
    cam_vertices.row(v) =
        (frame.truth.cam_from_head * Eigen::Vector3d(frame.actor.coarse.V.row(v).transpose())).transpose();
  }
  const FrameTextureExtractor ex(rig, studio.camera().intrinsics, FrameTextureOptions{});
  const FrameTexture t = ex.Extract(cam_vertices, frame.render.image);
  EXPECT_GT(t.num_seen, 0.5 * cv::countNonZero(ex.coverage()));
  // Albedo luminance at R. T = albedo · shading: on a band of detail (DoG of log,
  // σ 1.5 and 6 texels: brows, lip border, freckles against smooth coarse shading
  // and fine pores) log T follows log albedo where the UVs are right, and not when
  // the albedo is shifted by 12 texels.
  cv::Mat albedo;
  cv::resize(studio.model().skin().albedo, albedo, cv::Size(kR, kR), 0, 0, cv::INTER_LINEAR);
  cv::Mat albedo_gray(kR, kR, CV_32F);
  for (int j = 0; j < kR; ++j) {
    for (int i = 0; i < kR; ++i) {
      const cv::Vec3f a = albedo.at<cv::Vec3f>(j, i);
      albedo_gray.at<float>(j, i) = 0.2126f * a[0] + 0.7152f * a[1] + 0.0722f * a[2];
    }
  }
  auto band = [](const cv::Mat& gray) {
    cv::Mat l, a, b;
    cv::log(cv::max(gray, 1e-3f), l);
    cv::GaussianBlur(l, a, cv::Size(0, 0), 1.5);
    cv::GaussianBlur(l, b, cv::Size(0, 0), 6.0);
    return cv::Mat(a - b);
  };
  const cv::Mat interior = Interior(t.seen, 16);
  const cv::Mat bt = band(t.gray), ba = band(albedo_gray);
  auto correlation = [&](int shift) {
    double sxy = 0, sxx = 0, syy = 0;
    for (int j = 0; j < kR; ++j) {
      for (int i = 0; i + shift < kR; ++i) {
        if (!interior.at<uint8_t>(j, i)) continue;
        const double x = bt.at<float>(j, i), y = ba.at<float>(j, i + shift);
        sxy += x * y, sxx += x * x, syy += y * y;
      }
    }
    return sxy / std::sqrt(sxx * syy);
  };
  const double corr = correlation(0), corr_shifted = correlation(12);
  std::printf("studio frame: %d seen; band-pass correlation with the albedo %.3f (albedo shifted 12 texels: %.3f)\n",
              t.num_seen, corr, corr_shifted);
  EXPECT_GT(corr, 0.5);
  EXPECT_LT(corr_shifted, 0.5 * corr);
  // For looking at: T^t and the albedo luminance as sRGB PNGs.
  const auto dir = testing::TestDir();
  WriteImage(dir / "frame_texture.png", t.gray);
  WriteImage(dir / "albedo_gray.png", albedo_gray);
  WriteImage(dir / "frame.png", frame.render.image);
  WriteImage(dir / "seen.png", t.seen);
  std::printf("wrote %s\n", (dir / "frame_texture.png").c_str());
}

// ---------------------------------------------------------------------------
// Mesoscopic map, Sec. 5.3.

TEST(MesoscopicMap, DarkDotGivesInwardDisplacementScaledByGamma) {
  const int R = 64;
  cv::Mat T(R, R, CV_32F, cv::Scalar(0.5f));
  const float delta = -0.2f;
  T.at<float>(32, 32) += delta;
  const cv::Mat seen(R, R, CV_8U, cv::Scalar(255));
  MesoscopicOptions o;
  o.meso_reference_resolution = 0;  // kernels in texels of this map
  const cv::Mat d = MesoscopicMap(T, seen, o);
  ASSERT_EQ(d.type(), CV_32F);
  // Expected centre value: γ·δ·(k_small(0)² − k_large(0)²), OpenCV's Gaussian windows 3 and 9.
  const cv::Mat ks = cv::getGaussianKernel(3, 0.8, CV_64F), kl = cv::getGaussianKernel(9, 1.7, CV_64F);
  const double expected = 5.0 * delta * (ks.at<double>(1) * ks.at<double>(1) - kl.at<double>(4) * kl.at<double>(4));
  EXPECT_LT(d.at<float>(32, 32), 0.0f);
  EXPECT_NEAR(d.at<float>(32, 32), expected, 1e-5);
  o.meso_scale = 10.0;
  EXPECT_NEAR(MesoscopicMap(T, seen, o).at<float>(32, 32), 2 * expected, 2e-5);
  // Far from the dot: 0.
  EXPECT_NEAR(d.at<float>(10, 10), 0.0f, 1e-6);
  // A bright dot goes outwards.
  T.at<float>(32, 32) = 0.5f - delta;
  EXPECT_GT(MesoscopicMap(T, seen, o).at<float>(32, 32), 0.0f);
}

TEST(MesoscopicMap, LinearRampGivesZeroAndUnseenIsZero) {
  const int R = 128;
  cv::Mat T(R, R, CV_32F);
  for (int j = 0; j < R; ++j) {
    for (int i = 0; i < R; ++i) T.at<float>(j, i) = 0.2f + 0.002f * i + 0.001f * j;
  }
  cv::Mat seen(R, R, CV_8U, cv::Scalar(0));
  cv::circle(seen, cv::Point(64, 64), 50, cv::Scalar(255), cv::FILLED);
  T.setTo(std::numeric_limits<float>::quiet_NaN(), seen == 0);  // unseen texels may hold anything
  MesoscopicOptions o;
  o.meso_reference_resolution = 0;
  const cv::Mat d = MesoscopicMap(T, seen, o);
  double interior_max = 0, border_max = 0;
  for (int j = 0; j < R; ++j) {
    for (int i = 0; i < R; ++i) {
      const double r = std::hypot(i - 64, j - 64);
      const float v = d.at<float>(j, i);
      ASSERT_TRUE(std::isfinite(v));
      if (!seen.at<uint8_t>(j, i)) {
        EXPECT_EQ(v, 0.0f);
      } else if (r < 45) {
        interior_max = std::max(interior_max, std::abs(static_cast<double>(v)));
      } else {
        border_max = std::max(border_max, std::abs(static_cast<double>(v)));
      }
    }
  }
  std::printf("ramp: max |D^HF| interior %.2e mm, at the seen border %.2e mm\n", interior_max, border_max);
  EXPECT_LT(interior_max, 5e-5);  // float blurs: ~1e-5 of intensity times γ
  // Normalised convolution of a ramp is biased at the border by less than the ramp over a few texels.
  EXPECT_LT(border_max, 5.0 * 0.003 * 4);
}

TEST(MesoscopicMap, KernelsScaleWithResolutionAndErrors) {
  // The same dot pattern at R = 1024 and 2048 (twice as wide) gives the same
  // displacement at the dot's centre, within the discretisation.
  auto dot = [](int R, double radius) {
    cv::Mat T(R, R, CV_32F, cv::Scalar(0.5f));
    cv::circle(T, cv::Point(R / 2, R / 2), static_cast<int>(radius), cv::Scalar(0.3f), cv::FILLED);
    return T;
  };
  const MesoscopicOptions o;
  const cv::Mat T1 = dot(1024, 2), T2 = dot(2048, 4);
  const cv::Mat d1 = MesoscopicMap(T1, cv::Mat(1024, 1024, CV_8U, cv::Scalar(255)), o);
  const cv::Mat d2 = MesoscopicMap(T2, cv::Mat(2048, 2048, CV_8U, cv::Scalar(255)), o);
  EXPECT_LT(d1.at<float>(512, 512), -0.05f);
  EXPECT_NEAR(d2.at<float>(1024, 1024), d1.at<float>(512, 512), 0.25 * std::abs(d1.at<float>(512, 512)));
  EXPECT_ERROR_HAS(MesoscopicMap(cv::Mat(8, 8, CV_64F, cv::Scalar(0)), cv::Mat(8, 8, CV_8U), o), "CV_32FC1");
  EXPECT_ERROR_HAS(MesoscopicMap(cv::Mat(8, 8, CV_32F, cv::Scalar(0)), cv::Mat(4, 4, CV_8U), o), "seen mask");
  MesoscopicOptions bad;
  bad.meso_small_kernel = 4;
  EXPECT_ERROR_HAS(bad.Check(), "meso_small_kernel");
}

}  // namespace
}  // namespace crease
