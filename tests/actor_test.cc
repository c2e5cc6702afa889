#include "synth/actor.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>

#include <fmt/format.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/image_io.h"
#include "core/mesh_ops.h"
#include "core/rig_import.h"
#include "core/uv_raster.h"
#include "synth/procedural_rig.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ExpressionWeights;

namespace fs = std::filesystem;
using testing::TestDir;
using testing::WriteText;

using testing::SampleRig;

bool SameBytes(const cv::Mat& a, const cv::Mat& b) {
  if (a.size != b.size || a.type() != b.type() || !a.isContinuous() || !b.isContinuous()) return false;
  return std::memcmp(a.data, b.data, a.total() * a.elemSize()) == 0;
}

// An actor with plenty of lines (age fixed) at a reduced resolution for speed.
ActorOptions TestOptions(int resolution = 512) {
  ActorOptions o;
  o.resolution = resolution;
  o.age_min = o.age_max = 0.8;
  o.style_min = o.style_max = -0.3;
  o.static_lines = false;
  return o;
}

double SumAbsOverFamily(const ActorModel& model, const cv::Mat& D, WrinkleFamily family) {
  double sum = 0;
  const float* d = D.ptr<float>();
  for (const auto& s : model.wrinkles().samples()) {
    if (model.wrinkles().lines()[s.line].family == family) sum += std::abs(d[s.texel]);
  }
  return sum;
}

TEST(Actor, SameSeedGivesIdenticalBytes) {
  const FaceRig& rig = SampleRig();
  const ActorOptions opt = TestOptions();
  const Actor a = GenerateActor(rig, 7, opt);
  const Actor b = GenerateActor(rig, 7, opt);
  EXPECT_EQ(ActorToJson(a), ActorToJson(b));
  const ActorModel ma(rig, a), mb(rig, b);
  const Eigen::VectorXd e = ExpressionWeights(rig, {{"browInnerUp", 1.0}, {"mouthSmile_L", 0.7}});
  const ActorFrame fa = ma.Frame(e), fb = mb.Frame(e);
  EXPECT_TRUE(SameBytes(fa.expression_displacement, fb.expression_displacement));
  EXPECT_TRUE(SameBytes(fa.static_displacement, fb.static_displacement));
  EXPECT_TRUE(SameBytes(fa.mesoscopic_displacement, fb.mesoscopic_displacement));
  EXPECT_TRUE(SameBytes(ma.skin().albedo, mb.skin().albedo));
  EXPECT_TRUE(SameBytes(ma.skin().specular, mb.skin().specular));
  EXPECT_TRUE(SameBytes(ma.skin().roughness, mb.skin().roughness));
  EXPECT_EQ(fa.hires.V, fb.hires.V);
  EXPECT_EQ(fa.hires.F, fb.hires.F);
  EXPECT_EQ(fa.hires.N, fb.hires.N);
}

TEST(Actor, DifferentSeedsGiveDifferentLayouts) {
  const FaceRig& rig = SampleRig();
  ActorOptions opt = TestOptions(128);
  opt.age_min = 0.0;
  opt.age_max = 1.0;
  opt.style_min = -1.0;
  opt.style_max = 1.0;
  const Actor a = GenerateActor(rig, 1, opt);
  const Actor b = GenerateActor(rig, 2, opt);
  EXPECT_NE(a.identity, b.identity);
  EXPECT_NE(a.style.age, b.style.age);
  ASSERT_FALSE(a.wrinkles.empty());
  ASSERT_FALSE(b.wrinkles.empty());
  EXPECT_TRUE(a.wrinkles.size() != b.wrinkles.size() || a.wrinkles[0].points != b.wrinkles[0].points);
  EXPECT_NE(a.skin.seed, b.skin.seed);
  EXPECT_NE(a.skin.tone, b.skin.tone);
  const ActorModel ma(rig, a), mb(rig, b);
  EXPECT_GT(cv::norm(ma.static_displacement(), mb.static_displacement(), cv::NORM_INF), 0.05);
  EXPECT_GT(cv::norm(ma.mesoscopic_displacement(), mb.mesoscopic_displacement(), cv::NORM_INF), 0.005);
  // Ages span the range: a young actor has fewer lines than an old one.
  ActorOptions young = opt, old = opt;
  young.age_min = young.age_max = 0.0;
  old.age_min = old.age_max = 1.0;
  size_t young_lines = 0, old_lines = 0;
  for (uint64_t seed = 0; seed < 8; ++seed) {
    young_lines += GenerateActor(rig, seed, young).wrinkles.size();
    old_lines += GenerateActor(rig, seed, old).wrinkles.size();
  }
  EXPECT_LT(2 * young_lines, old_lines);
  // Every family appears for old actors.
  std::set<WrinkleFamily> families;
  for (const auto& w : GenerateActor(rig, 3, old).wrinkles) families.insert(w.family);
  EXPECT_EQ(families.size(), 6u);
}

TEST(Actor, WrinkleDepthGrowsWithCompressionAndVanishesAtNeutral) {
  // The response itself.
  WrinkleLine line;
  line.max_depth_mm = 0.5;
  line.saturation = 0.1;
  EXPECT_EQ(WrinkleDepth(line, 0.0), 0.0);
  EXPECT_EQ(WrinkleDepth(line, -0.2), 0.0);
  double prev = 0.0;
  for (double c = 0.01; c < 0.5; c += 0.01) {
    const double d = WrinkleDepth(line, c);
    EXPECT_GT(d, prev);
    EXPECT_LE(d, line.max_depth_mm);
    prev = d;
  }
  EXPECT_NEAR(WrinkleDepth(line, 0.5), 0.5, 1e-6);

  const FaceRig& rig = SampleRig();
  const ActorModel model(rig, GenerateActor(rig, 11, TestOptions()));
  // Neutral: no expression displacement at all (no static lines).
  const ActorFrame neutral = model.Frame(Eigen::VectorXd(), false);
  EXPECT_LT(cv::norm(neutral.expression_displacement, cv::NORM_INF), 1e-9);
  // Brow raise: forehead lines deepen monotonically with the weight, and so does the
  // compression across them.
  double prev_sum = 0.0;
  int forehead_line = -1;
  for (size_t l = 0; l < model.wrinkles().lines().size(); ++l) {
    if (model.wrinkles().lines()[l].family == WrinkleFamily::kForehead) forehead_line = static_cast<int>(l);
  }
  ASSERT_GE(forehead_line, 0);
  const WrinkleLine& fl = model.wrinkles().lines()[forehead_line];
  const Eigen::Vector2d mid = fl.points[fl.points.size() / 2];
  const int R = model.wrinkles().resolution();
  const int mi = static_cast<int>(mid.x() * R), mj = static_cast<int>(mid.y() * R);
  double prev_c = 0.0;
  for (double w : {0.25, 0.5, 0.75, 1.0}) {
    const Eigen::VectorXd e = ExpressionWeights(rig, {{"browInnerUp", w}});
    const MatX3d V = rig.EvaluatePositions(model.actor().identity, e);
    const cv::Mat metric = model.strain().MetricMap(V);
    const cv::Mat D = model.wrinkles().Displacement(metric);
    const double sum = SumAbsOverFamily(model, D, WrinkleFamily::kForehead);
    EXPECT_GT(sum, prev_sum) << "weight " << w;
    prev_sum = sum;
    const double c = model.wrinkles().CompressionAt(metric, forehead_line, mi, mj);
    EXPECT_GT(c, prev_c) << "weight " << w;
    prev_c = c;
  }
  // Full brow raise: clearly visible furrows (≥ 0.1 mm deep).
  const ActorFrame raised = model.Frame(ExpressionWeights(rig, {{"browInnerUp", 1.0}}), false);
  double min_forehead = 0;
  for (const auto& s : model.wrinkles().samples()) {
    if (model.wrinkles().lines()[s.line].family == WrinkleFamily::kForehead)
      min_forehead = std::min(min_forehead, static_cast<double>(raised.expression_displacement.ptr<float>()[s.texel]));
  }
  EXPECT_LT(min_forehead, -0.1);
  // The compression measure itself: shrinking the neutral by 10 % compresses
  // every line by 0.1; squashing it along the head's up axis (+y), which the
  // forehead lines cross, compresses them by up to 0.1 (less where the forehead
  // slopes away from the axis); squashing along x (along the lines) hardly at all.
  const MatX3d V0 = rig.EvaluatePositions(model.actor().identity, {});
  const auto compression = [&](const MatX3d& V) {
    return model.wrinkles().CompressionAt(model.strain().MetricMap(V), forehead_line, mi, mj);
  };
  EXPECT_NEAR(compression(V0 * 0.9), 0.1, 1e-4);
  MatX3d Vy = V0, Vx = V0;
  Vy.col(1) *= 0.9;
  Vx.col(0) *= 0.9;
  EXPECT_GT(compression(Vy), 0.06);
  EXPECT_LE(compression(Vy), 0.1 + 1e-4);
  EXPECT_LT(std::abs(compression(Vx)), 0.02);
}

// Checks hi-res − coarse = S + D + M along the interpolated coarse normal at
// every hi-res vertex; returns the number of hi-res vertices.
int CheckHiResAgainstMaps(const ActorModel& model, const ActorFrame& f) {
  const HiResLayout& L = model.layout();
  EXPECT_EQ(f.hires.num_vertices(), L.num_vertices());
  EXPECT_GT(f.hires.num_faces(), f.hires.num_vertices());
  ValidateMesh(f.hires, "hires", {.uv = true, .normals = true});
  MatX3d P, N;
  InterpolateCoarse(L, f.coarse, &P, &N, model.actor().options.phong_alpha);
  double max_err = 0, max_tangential = 0, max_disp = 0;
  for (int v = 0; v < L.num_vertices(); ++v) {
    const double expect = L.SampleMap(f.expression_displacement, v) + L.SampleMap(f.static_displacement, v) +
                          L.SampleMap(f.mesoscopic_displacement, v);
    const Eigen::RowVector3d d = f.hires.V.row(v) - P.row(v);
    const double along = d.dot(N.row(v));
    max_err = std::max(max_err, std::abs(along - expect));
    max_tangential = std::max(max_tangential, (d - along * N.row(v)).norm());
    max_disp = std::max(max_disp, std::abs(expect));
  }
  EXPECT_LT(max_err, 1e-3);  // mm: 1 µm
  EXPECT_LT(max_tangential, 1e-3);
  EXPECT_GT(max_disp, 0.1);  // not trivially zero
  // Normals are unit and face the same side as the coarse normals.
  for (int v = 0; v < L.num_vertices(); v += 97) {
    EXPECT_NEAR(f.hires.N.row(v).norm(), 1.0, 1e-9);
    EXPECT_GT(f.hires.N.row(v).dot(N.row(v)), 0.0);
  }
  return L.num_vertices();
}

TEST(Actor, HiResSurfaceMinusCoarseEqualsDisplacementMaps) {
  const FaceRig& rig = SampleRig();
  const Eigen::VectorXd e = ExpressionWeights(rig, {{"browInnerUp", 0.8}, {"mouthSmile_R", 1.0}, {"jawOpen", 0.3}});
  // Grid = map texels (the sample rig's chart fills the unit square: 512² ≥ 250k vertices).
  ActorOptions opt = TestOptions(512);
  opt.surface_min_vertices = 250000;
  const ActorModel model(rig, GenerateActor(rig, 5, opt));
  EXPECT_EQ(model.layout().resolution, 512);
  EXPECT_GE(CheckHiResAgainstMaps(model, model.Frame(e)), 250000);
  // A finer grid than the maps (bilinear samples between texel centres).
  opt.resolution = 256;
  const ActorModel fine(rig, GenerateActor(rig, 5, opt));
  EXPECT_GT(fine.layout().resolution, 256);
  EXPECT_EQ(fine.layout().map_resolution, 256);
  EXPECT_GE(CheckHiResAgainstMaps(fine, fine.Frame(e)), 250000);
}

// The largest few angles (degrees, the 99.9th percentile) between the normals of the
// base surface B at horizontally and vertically neighbouring grid vertices: where the
// base creases along the coarse edges, these are its creases.
double BaseCreasePercentile(const ActorModel& model, const ActorFrame& f) {
  const HiResLayout& L = model.layout();
  MatX3d P, N;
  InterpolateCoarse(L, f.coarse, &P, &N, model.actor().options.phong_alpha);
  TriMesh base;
  base.V = P;
  base.F = L.F;
  const MatX3d n = VertexNormals(base);
  const int R = L.resolution;
  std::vector<double> angles;
  for (int v = 0; v < L.num_vertices(); ++v) {
    const int i = L.texel[v] % R, j = L.texel[v] / R;
    for (const auto [di, dj] : {std::pair{1, 0}, std::pair{0, 1}}) {
      if (i + di >= R || j + dj >= R) continue;
      const int u = L.vertex_of_texel[(j + dj) * R + i + di];
      if (u < 0) continue;
      angles.push_back(std::acos(std::clamp(n.row(v).dot(n.row(u)), -1.0, 1.0)) * 180.0 / M_PI);
    }
  }
  std::sort(angles.begin(), angles.end());
  return angles[static_cast<size_t>(0.999 * (angles.size() - 1))];
}

// actor.subdivision_levels: the hi-res surface on the rig's Loop subdivision surface
// is smooth across the coarse edges where the Phong-tessellated facets crease, stays
// within a fraction of a millimetre of them, and still carries the maps exactly.
TEST(Actor, SubdividedBaseDoesNotCreaseAtTheCoarseEdges) {
  const FaceRig& rig = SampleRig();
  const Eigen::VectorXd e = ExpressionWeights(rig, {{"mouthSmile_L", 1.0}, {"browInnerUp", 0.6}});
  ActorOptions opt = TestOptions(256);
  opt.surface_min_vertices = 120000;
  const ActorModel phong(rig, GenerateActor(rig, 5, opt));
  opt.subdivision_levels = 3;
  const ActorModel smooth(rig, GenerateActor(rig, 5, opt));
  ASSERT_TRUE(smooth.layout().smooth);
  EXPECT_FALSE(phong.layout().smooth);
  const ActorFrame fp = phong.Frame(e), fs = smooth.Frame(e);
  EXPECT_GE(CheckHiResAgainstMaps(smooth, fs), 120000);
  const double crease_phong = BaseCreasePercentile(phong, fp), crease_smooth = BaseCreasePercentile(smooth, fs);
  EXPECT_LT(crease_smooth, 0.5 * crease_phong) << crease_smooth << " vs " << crease_phong;  // 11° vs 29°
  MatX3d Pp, Ps, N;
  InterpolateCoarse(phong.layout(), fp.coarse, &Pp, &N, opt.phong_alpha);
  InterpolateCoarse(smooth.layout(), fs.coarse, &Ps, &N, opt.phong_alpha);
  const Eigen::VectorXd gap = (Pp - Ps).rowwise().norm();
  EXPECT_LT(gap.mean(), 0.4);  // mm (0.19 on this rig; the boundary rule pulls open rims in)
  EXPECT_GT(gap.mean(), 1e-4);  // not the same surface
}

// Any rig with UVs and the standard regions: without landmarks the anchors come
// from the region masks, and the lines still land in their regions.
TEST(Actor, WorksWithoutLandmarksFromRegionMasks) {
  FaceRig rig = SampleRig();
  // The sample rig numbers the left eye's corners in reverse (43 outer, 46
  // inner); put them in iBUG order so that the derived eye masks are right.
  auto swap_landmarks = [&](int a, int b) {
    std::swap(rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", a))].vertex,
              rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", b))].vertex);
  };
  if (rig.neutral.V(rig.landmarks[rig.LandmarkIndex("ibug_43")].vertex, 0) >
      rig.neutral.V(rig.landmarks[rig.LandmarkIndex("ibug_46")].vertex, 0)) {
    swap_landmarks(43, 46);
    swap_landmarks(44, 45);
    swap_landmarks(47, 48);
  }
  rig.regions = RegionsFromLandmarks(rig);
  const FaceAnchors with = ComputeFaceAnchors(rig);
  rig.landmarks.clear();
  const FaceAnchors without = ComputeFaceAnchors(rig);
  EXPECT_TRUE(with.from_landmarks);
  EXPECT_FALSE(without.from_landmarks);
  EXPECT_GT(with.lateral.dot(without.lateral), 0.99);
  EXPECT_GT(with.up.dot(without.up), 0.99);
  // Eye centres within 10 mm of the landmark estimate.
  for (int k = 0; k < 2; ++k) {
    EXPECT_LT((with.eye_center[k] - without.eye_center[k]).norm() * with.mm_per_uv, 10.0) << k;
  }
  ActorOptions opt = TestOptions(128);
  opt.age_min = opt.age_max = 1.0;
  const Actor actor = GenerateActor(rig, 4, opt);
  int forehead = 0, inside = 0;
  for (const auto& w : actor.wrinkles) {
    if (w.family != WrinkleFamily::kForehead) continue;
    ++forehead;
    inside += rig.InRegion("forehead", w.points[w.points.size() / 2]) ? 1 : 0;
  }
  EXPECT_GT(forehead, 0);
  EXPECT_EQ(inside, forehead);
  const ActorModel model(rig, actor);
  const ActorFrame f = model.Frame(ExpressionWeights(rig, {{"browInnerUp", 1.0}}), false);
  EXPECT_LT(SumAbsOverFamily(model, model.Frame(Eigen::VectorXd(), false).expression_displacement,
                             WrinkleFamily::kForehead), 1e-6);
  EXPECT_GT(SumAbsOverFamily(model, f.expression_displacement, WrinkleFamily::kForehead), 1.0);
  // Without landmarks and without regions there is nothing to anchor on.
  rig.regions.clear();
  EXPECT_ERROR_HAS(ComputeFaceAnchors(rig), "neither the 68 iBUG landmarks nor the region");
}

// The studio's own procedural head (synth/procedural_rig.h).
TEST(Actor, ProceduralRigActor) {
  const FaceRig rig = BuildProceduralRig();
  ActorOptions opt = TestOptions(256);
  opt.surface_min_vertices = 0;
  const ActorModel model(rig, GenerateActor(rig, 8, opt));
  EXPECT_TRUE(model.anchors().from_landmarks);
  Eigen::VectorXd raise = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const char* name : {"browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R"}) {
    if (rig.ExpressionIndex(name) >= 0) raise[rig.ExpressionIndex(name)] = 1.0;
  }
  ASSERT_GT(raise.sum(), 0.0);
  const ActorFrame neutral = model.Frame(Eigen::VectorXd());
  const ActorFrame raised = model.Frame(raise);
  EXPECT_LT(cv::norm(neutral.expression_displacement, cv::NORM_INF), 1e-9);
  EXPECT_GT(SumAbsOverFamily(model, raised.expression_displacement, WrinkleFamily::kForehead), 1.0);
  CheckHiResAgainstMaps(model, raised);
}

TEST(Actor, StaticShapeFadesOutAtTheFaceChartRim) {
  // The face meets the cranium (no displacement) without a step: S × ChartRimFade.
  const FaceRig rig = BuildProceduralRig();
  constexpr int kSize = 256;
  ActorOptions opt = TestOptions(kSize);
  opt.surface_min_vertices = 0;
  const ActorModel model(rig, GenerateActor(rig, 5, opt));
  const cv::Mat fade = ChartRimFade(rig, kSize, model.anchors().mm_per_uv, kStaticShapeRimFadeMm);
  TriMesh chart = rig.neutral;
  chart.F = FaceChartTriangles(rig);
  const UvRaster raster = RasterizeUv(chart, kSize, kSize);
  const cv::Mat S = model.Frame(Eigen::VectorXd()).static_displacement;
  int rim = 0, inside = 0;
  double rim_max = 0.0, inside_sq = 0.0;
  for (int j = 0; j < kSize; ++j) {
    for (int i = 0; i < kSize; ++i) {
      const float w = fade.at<float>(j, i);
      ASSERT_GE(w, 0.0f);
      ASSERT_LE(w, 1.0f);
      if (!raster.covered(i, j)) {
        EXPECT_EQ(w, 0.0f);
        continue;
      }
      const double s = S.at<float>(j, i);
      if (w < 0.05f) {
        ++rim;
        rim_max = std::max(rim_max, std::abs(s));
      } else if (w == 1.0f) {
        ++inside;
        inside_sq += s * s;
      }
    }
  }
  ASSERT_GT(rim, 100);
  ASSERT_GT(inside, raster.num_covered() / 2);  // 10 mm is a thin band of the face
  const double inside_rms = std::sqrt(inside_sq / inside);
  EXPECT_GT(inside_rms, 0.3 * model.actor().static_shape.rms_mm);
  EXPECT_LT(rim_max, 0.05 * inside_rms * 3.0 + 1e-6);  // ≤ 5 % of the ±3 RMS clamp
}

TEST(Actor, PersonalExpressionsDeviateFromTheRigWhereItMoves) {
  const FaceRig& rig = SampleRig();
  ActorOptions opt = TestOptions(256);
  const Actor a = GenerateActor(rig, 5, opt);
  EXPECT_EQ(a.expression_deviation.amount, opt.expression_deviation);
  const FaceRig personal = PersonalRig(rig, a);
  EXPECT_EQ(personal.neutral.V, rig.neutral.V);
  EXPECT_EQ(personal.identity_basis, rig.identity_basis);
  // Each shape changes, but only where the rig's shape moves, and by a factor in [0, 2].
  for (int b = 0; b < rig.num_expressions(); ++b) {
    const Eigen::VectorXf B = rig.expression_basis.col(b), P = personal.expression_basis.col(b);
    EXPECT_GT((P - B).norm(), 0.02 * B.norm()) << rig.expression_names[b];
    for (Eigen::Index i = 0; i < B.size(); ++i) {
      if (B[i] == 0.0f) {
        EXPECT_EQ(P[i], 0.0f);
      }
      EXPECT_LE(std::abs(P[i]), 2.0f * std::abs(B[i]) + 1e-6f);
      EXPECT_GE(P[i] * B[i], 0.0f);
    }
  }
  // Not a rescaling of the rig's shape: no single weight on the rig's shape fits a
  // shape of a few mm (one that moves far, like jawOpen, keeps mostly its gain).
  const int brow = rig.ExpressionIndex("browInnerUp");
  const Eigen::VectorXf B = rig.expression_basis.col(brow), P = personal.expression_basis.col(brow);
  const float w = B.dot(P) / B.squaredNorm();
  EXPECT_GT((P - w * B).norm(), 0.03 * P.norm());
  // The actor's model moves with it; amount 0 gives the rig back exactly.
  const ActorModel model(rig, a);
  const Eigen::VectorXd e = ExpressionWeights(rig, {{"jawOpen", 1.0}});
  EXPECT_EQ(model.Frame(e, false).coarse.V, personal.EvaluatePositions(a.identity, e));
  Actor none = a;
  none.expression_deviation.amount = 0.0;
  EXPECT_EQ(PersonalRig(rig, none).expression_basis, rig.expression_basis);
  // Actor files from before the deviations existed read as "none".
  nlohmann::json j = nlohmann::json::parse(ActorToJson(a));
  j.erase("expression_deviation");
  EXPECT_EQ(ActorFromJson(j.dump(), "old.json").expression_deviation.amount, 0.0);
}

TEST(Actor, JsonRoundTripRebuildsIdentically) {
  const FaceRig& rig = SampleRig();
  ActorOptions opt = TestOptions(256);
  opt.age_max = 1.0;
  opt.age_min = 0.2;
  opt.static_lines = true;
  const Actor a = GenerateActor(rig, 99, opt);
  const fs::path p = TestDir() / "actor.json";
  WriteActor(p, a);
  const Actor b = ReadActor(p);
  EXPECT_EQ(ActorToJson(a), ActorToJson(b));
  EXPECT_EQ(a.identity, b.identity);
  ASSERT_EQ(a.wrinkles.size(), b.wrinkles.size());
  for (size_t k = 0; k < a.wrinkles.size(); ++k) {
    EXPECT_EQ(a.wrinkles[k].points, b.wrinkles[k].points);
    EXPECT_EQ(a.wrinkles[k].strength, b.wrinkles[k].strength);
    EXPECT_EQ(a.wrinkles[k].max_depth_mm, b.wrinkles[k].max_depth_mm);
  }
  const ActorModel ma(rig, a), mb(rig, b);
  const Eigen::VectorXd e = ExpressionWeights(rig, {{"browDown", 1.0}});
  const ActorFrame fa = ma.Frame(e), fb = mb.Frame(e);
  EXPECT_TRUE(SameBytes(fa.expression_displacement, fb.expression_displacement));
  EXPECT_TRUE(SameBytes(fa.static_displacement, fb.static_displacement));
  EXPECT_TRUE(SameBytes(fa.mesoscopic_displacement, fb.mesoscopic_displacement));
  EXPECT_TRUE(SameBytes(ma.skin().albedo, mb.skin().albedo));
  EXPECT_EQ(fa.hires.V, fb.hires.V);
  // Maps are written as float EXR and read back unchanged.
  WriteActorFrameMaps(p.parent_path() / "maps", fa);
  const cv::Mat back = ReadImage(p.parent_path() / "maps" / "expression_displacement.exr");
  EXPECT_TRUE(SameBytes(back, fa.expression_displacement));
}

TEST(Actor, MalformedJsonNamesFileAndField) {
  const FaceRig& rig = SampleRig();
  const std::string good = ActorToJson(GenerateActor(rig, 3, TestOptions(128)));
  const fs::path dir = TestDir();
  auto read_with = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    WriteText(dir / "actor.json", text);
    return testing::ErrorOf([&] { ReadActor(dir / "actor.json"); });
  };
  const std::string file = (dir / "actor.json").string();
  EXPECT_NE(read_with("\"width_mm\":", "\"width_mm\": \"wide\", \"x\":").find(file + ": field 'wrinkles[0].width_mm' must be a number"),
            std::string::npos);
  EXPECT_NE(read_with("\"tone\":", "\"tone_\":").find(file + ": field 'skin.tone' is missing"), std::string::npos);
  EXPECT_NE(read_with("\"family\": \"", "\"family\": \"x").find("wrinkles[0].family"), std::string::npos);
  EXPECT_NE(read_with("\"age\":", "\"age\": 3, \"y\":").find(file + ": field 'style.age' = 3 must be in [0, 1]"),
            std::string::npos);
  EXPECT_NE(read_with("\"resolution\":", "\"resolutoin\":").find("resolutoin"), std::string::npos);
  EXPECT_NE(read_with("\"version\": 1", "\"version\": 2").find(file + ": field 'version' = 2 is not supported"),
            std::string::npos);
  EXPECT_NE(read_with("{", "{{").find(file + ": malformed JSON"), std::string::npos);
  // Issue 19 (fuzz/actor_json_fuzzer): a number beyond double's range was nlohmann's
  // out_of_range, an internal error without the file.
  EXPECT_NE(read_with("\"age\":", "\"age\": 1e400, \"z\":").find(file + ": malformed JSON"), std::string::npos);
  EXPECT_NE(testing::ErrorOf([&] { ReadActor(dir / "absent.json"); }).find("absent.json"), std::string::npos);
  // Issue 19: an actor with fewer identity coefficients than its rig has modes was
  // rendered with the rest as zero; the model refuses it.
  Actor few = GenerateActor(rig, 3, TestOptions(128));
  few.identity.conservativeResize(3);
  EXPECT_NE(testing::ErrorOf([&] { ActorModel model(rig, few); }).find("the actor has 3 identity coefficients but"),
            std::string::npos);
  // Read from a file, the error names the file (the actor is what the user must fix).
  const fs::path few_file = dir / "few.json";
  WriteText(few_file, ActorToJson(few));
  const Actor few_read = ReadActor(few_file);
  EXPECT_EQ(few_read.source, few_file.string());
  EXPECT_NE(testing::ErrorOf([&] { ActorModel model(rig, few_read); })
                .find(few_file.string() + ": the actor has 3 identity coefficients but"),
            std::string::npos);
}

}  // namespace
}  // namespace crease
