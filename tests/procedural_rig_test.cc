#include "synth/procedural_rig.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <filesystem>
#include <set>

#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/uv_raster.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ExpressionWeights;

namespace fs = std::filesystem;
using Eigen::Vector2d;
using Eigen::Vector3d;

const FaceRig& Rig() {
  static const FaceRig rig = BuildProceduralRig();
  return rig;
}

Vector3d Landmark(const FaceRig& rig, const MatX3d& V, int ibug) {
  const int k = rig.LandmarkIndex("ibug_" + std::to_string(ibug));
  EXPECT_GE(k, 0);
  return V.row(rig.landmarks[k].vertex).transpose();
}

bool InPart(const FaceRig& rig, int v, const std::string& part) {
  return rig.part_names[rig.vertex_part[v]] == part;
}

// The face triangles as their own mesh (same vertex ids).
TriMesh FaceOnly(const FaceRig& rig) {
  TriMesh m = rig.neutral;
  std::vector<int> keep;
  for (int f = 0; f < m.num_faces(); ++f) {
    if (InPart(rig, m.F(f, 0), "face") && InPart(rig, m.F(f, 1), "face") && InPart(rig, m.F(f, 2), "face")) keep.push_back(f);
  }
  MatX3i F(static_cast<Eigen::Index>(keep.size()), 3);
  for (size_t i = 0; i < keep.size(); ++i) F.row(static_cast<Eigen::Index>(i)) = m.F.row(keep[i]);
  m.F = F;
  return m;
}

// Vertex v's mirror image (x → −x) in V, by nearest position; −1 if none within tol.
std::vector<int> MirrorMap(const MatX3d& V, double tol) {
  std::vector<int> map(V.rows(), -1);
  for (Eigen::Index v = 0; v < V.rows(); ++v) {
    const Vector3d m(-V(v, 0), V(v, 1), V(v, 2));
    double best = tol;
    for (Eigen::Index w = 0; w < V.rows(); ++w) {
      const double d = (V.row(w).transpose() - m).norm();
      if (d < best) {
        best = d;
        map[v] = static_cast<int>(w);
      }
    }
  }
  return map;
}

TEST(ProceduralRig, SizePartsAndProportions) {
  const FaceRig& rig = Rig();
  EXPECT_GE(rig.num_vertices(), 2000);
  EXPECT_LE(rig.num_vertices(), 15000);
  for (const char* p : {"face", "cranium", "hair", "neck", "ears", "eyeball_left", "eyeball_right", "iris_left",
                        "iris_right", "pupil_left", "pupil_right", "mouth_cavity", "teeth_upper", "teeth_lower"}) {
    const int k = rig.PartIndex(p);
    ASSERT_GE(k, 0) << p;
    EXPECT_GT(std::count(rig.vertex_part.begin(), rig.vertex_part.end(), k), 20) << p;
  }
  // Adult proportions: chin (ibug_9) to crown ~230 mm, face ~140–150 mm wide.
  const MatX3d& V = rig.neutral.V;
  double top = -1e9, half_width = 0.0;
  for (int v = 0; v < rig.num_vertices(); ++v) {
    if (InPart(rig, v, "cranium") || InPart(rig, v, "hair") || InPart(rig, v, "face")) top = std::max(top, V(v, 1));
    if (InPart(rig, v, "face")) half_width = std::max(half_width, std::abs(V(v, 0)));
  }
  const double chin_to_crown = top - Landmark(rig, V, 9).y();
  EXPECT_GT(chin_to_crown, 215.0);
  EXPECT_LT(chin_to_crown, 250.0);
  EXPECT_GT(2 * half_width, 130.0);
  EXPECT_LT(2 * half_width, 165.0);
  // Eyes at y ≈ 0, in front; the subject's right eye (ibug 37–42) at negative x.
  EXPECT_LT(Landmark(rig, V, 37).x(), -30.0);
  EXPECT_GT(Landmark(rig, V, 46).x(), 30.0);
  EXPECT_GT(Landmark(rig, V, 31).z(), Landmark(rig, V, 28).z());  // the nose tip sticks out
}

TEST(ProceduralRig, NamedIdentityModesAndExpressions) {
  const FaceRig& rig = Rig();
  EXPECT_GE(rig.num_identity(), 20);
  EXPECT_GE(rig.num_expressions(), 24);
  for (const char* n : {"face_width", "face_length", "nose_length", "nose_width", "nose_bridge", "brow_ridge",
                        "cheekbones", "jaw_width", "chin_projection", "lip_fullness", "mouth_width", "eye_spacing",
                        "eye_size", "forehead_slope"}) {
    EXPECT_NE(std::find(rig.identity_names.begin(), rig.identity_names.end(), n), rig.identity_names.end()) << n;
  }
  for (const char* n :
       {"browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R", "browDown_L", "browDown_R", "eyeBlink_L",
        "eyeBlink_R", "eyeSquint_L", "eyeSquint_R", "cheekSquint_L", "cheekSquint_R", "noseSneer_L", "noseSneer_R",
        "mouthSmile_L", "mouthSmile_R", "mouthFrown_L", "mouthFrown_R", "jawOpen", "mouthPucker", "mouthStretch_L",
        "mouthStretch_R", "mouthPress_L", "mouthPress_R", "mouthUpperUp_L", "mouthUpperUp_R"}) {
    EXPECT_GE(rig.ExpressionIndex(n), 0) << n;
  }
  // Identity modes: ±1 moves something by a few millimetres, nothing absurdly.
  for (int k = 0; k < rig.num_identity(); ++k) {
    double mx = 0.0;
    for (int v = 0; v < rig.num_vertices(); ++v) {
      mx = std::max(mx, static_cast<double>(rig.identity_basis.block(3 * v, k, 3, 1).norm()));
    }
    EXPECT_GT(mx, 1.0) << rig.identity_names[k];
    EXPECT_LT(mx, 8.0) << rig.identity_names[k];
  }
}

TEST(ProceduralRig, LandmarksOnTheFaceAndRegions) {
  const FaceRig& rig = Rig();
  ASSERT_EQ(rig.landmarks.size(), 68u);
  const auto names = IbugLandmarkNames();
  for (int i = 0; i < 68; ++i) {
    EXPECT_EQ(rig.landmarks[i].name, names[i]);
    EXPECT_TRUE(InPart(rig, rig.landmarks[i].vertex, "face")) << names[i];
  }
  for (const auto& n : StandardRegionNames()) {
    const RegionMask* r = rig.FindRegion(n);
    ASSERT_NE(r, nullptr) << n;
    EXPECT_GT(cv::countNonZero(r->mask), 100) << n;
  }
  for (const char* n : {"brow_left", "brow_right", "lips"}) EXPECT_NE(rig.FindRegion(n), nullptr) << n;
  // Regions sit where they should: eye corners in their eye region (the subject's
  // left eye is ibug 43–48), brows above the eyes, the nose tip in "nose".
  auto uv = [&](int i) { return Vector2d(rig.neutral.UV.row(rig.landmarks[i - 1].vertex).transpose()); };
  EXPECT_TRUE(rig.InRegion("left_eye", uv(46)));
  EXPECT_TRUE(rig.InRegion("right_eye", uv(37)));
  EXPECT_FALSE(rig.InRegion("left_eye", uv(37)));
  EXPECT_TRUE(rig.InRegion("nose", uv(31)));
  EXPECT_TRUE(rig.InRegion("mouth", uv(63)));
  EXPECT_TRUE(rig.InRegion("chin", uv(9)));
  EXPECT_LT(uv(20).y(), uv(38).y());           // brow above the eye (v grows downwards)
  EXPECT_GT(uv(46).x(), uv(37).x());           // subject's left at larger u
}

TEST(ProceduralRig, FaceChartInsideUnitSquareWithoutOverlapsAndLowDistortion) {
  const FaceRig& rig = Rig();
  for (int v = 0; v < rig.num_vertices(); ++v) {
    const Vector2d uv = rig.neutral.UV.row(v).transpose();
    const bool inside = uv.x() >= 0.0 && uv.x() <= 1.0 && uv.y() >= 0.0 && uv.y() <= 1.0;
    EXPECT_EQ(inside, InPart(rig, v, "face")) << "vertex " << v;
  }
  const TriMesh face = FaceOnly(rig);
  const UvRaster raster = RasterizeUv(face, 1024, 1024);
  EXPECT_EQ(raster.num_overlaps, 0);
  EXPECT_GT(raster.num_covered(), 1024 * 1024 / 3);
  const ChartDistortion d = MeasureFaceChartDistortion(rig);
  EXPECT_EQ(d.flipped, 0);
  // Stated bounds (measured values in procedural_rig.h).
  EXPECT_GT(d.area_ratio_p05, 0.5);
  EXPECT_LT(d.area_ratio_p95, 2.0);
  EXPECT_LT(d.conformal_p95, 1.6);
}

TEST(ProceduralRig, MirrorSymmetricNeutralAndExpressionPairs) {
  const FaceRig& rig = Rig();
  // Separate the lips' coincident vertices with jawOpen, so the map pairs upper with upper.
  const MatX3d open = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"jawOpen", 1.0}}));
  const std::vector<int> mirror = MirrorMap(open, 1e-4);
  for (int v = 0; v < rig.num_vertices(); ++v) ASSERT_GE(mirror[v], 0) << "vertex " << v << " has no mirror";
  int pairs = 0;
  for (const auto& name : rig.expression_names) {
    if (name.size() < 2 || name.substr(name.size() - 2) != "_L") continue;
    const std::string other = name.substr(0, name.size() - 2) + "_R";
    ASSERT_GE(rig.ExpressionIndex(other), 0) << other;
    const MatX3d L = rig.EvaluatePositions({}, ExpressionWeights(rig, {{name, 1.0}}));
    const MatX3d Rr = rig.EvaluatePositions({}, ExpressionWeights(rig, {{other, 1.0}}));
    double err = 0.0, moved = 0.0;
    for (int v = 0; v < rig.num_vertices(); ++v) {
      const Vector3d m(-L(mirror[v], 0), L(mirror[v], 1), L(mirror[v], 2));
      err = std::max(err, (Rr.row(v).transpose() - m).norm());
      moved = std::max(moved, (L.row(v) - rig.neutral.V.row(v)).norm());
    }
    EXPECT_LT(err, 1e-3) << name;
    EXPECT_GT(moved, 1.0) << name;
    ++pairs;
  }
  EXPECT_GE(pairs, 10);
}

TEST(ProceduralRig, BlinkClosesTheEyes) {
  const FaceRig& rig = Rig();
  const MatX3d& N = rig.neutral.V;
  const MatX3d B = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"eyeBlink_L", 1.0}, {"eyeBlink_R", 1.0}}));
  for (auto [up, low] : {std::pair{38, 42}, {39, 41}, {44, 48}, {45, 47}}) {
    EXPECT_GT((Landmark(rig, N, up) - Landmark(rig, N, low)).norm(), 5.0) << up;
    EXPECT_LT((Landmark(rig, B, up) - Landmark(rig, B, low)).norm(), 0.05) << up;
  }
  // One eye only: the other stays open.
  const MatX3d L = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"eyeBlink_L", 1.0}}));
  EXPECT_LT((Landmark(rig, L, 44) - Landmark(rig, L, 48)).norm(), 0.05);
  EXPECT_GT((Landmark(rig, L, 38) - Landmark(rig, L, 42)).norm(), 5.0);
}

TEST(ProceduralRig, JawOpenPartsTheLipsOntoTheCavity) {
  const FaceRig& rig = Rig();
  const MatX3d& N = rig.neutral.V;
  EXPECT_LT((Landmark(rig, N, 63) - Landmark(rig, N, 67)).norm(), 0.5);  // closed at neutral
  const MatX3d J = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"jawOpen", 1.0}}));
  EXPECT_GT((Landmark(rig, J, 63) - Landmark(rig, J, 67)).norm(), 10.0);
  EXPECT_LT((Landmark(rig, J, 63) - Landmark(rig, N, 63)).norm(), 1.0);  // the upper lip stays
  // The chin moves down and back (rotation about the hinge).
  EXPECT_LT(Landmark(rig, J, 9).y(), Landmark(rig, N, 9).y() - 10.0);
  // The cavity lies behind the lips.
  const int cavity = rig.PartIndex("mouth_cavity");
  double front = -1e9;
  for (int v = 0; v < rig.num_vertices(); ++v) {
    if (rig.vertex_part[v] == cavity) front = std::max(front, N(v, 2));
  }
  EXPECT_LT(front, Landmark(rig, N, 63).z());
}

// Largest / smallest ratio of a triangle's extent along an axis (0 = x, 1 = y) after/before.
std::pair<double, double> ExtentRatio(const FaceRig& rig, const MatX3d& V, const std::string& region, int axis) {
  const TriMesh& m = rig.neutral;
  double lo = 1e9, hi = 0.0;
  for (int f = 0; f < m.num_faces(); ++f) {
    Vector2d c = Vector2d::Zero();
    bool face = true;
    for (int k = 0; k < 3; ++k) {
      c += m.UV.row(m.F(f, k)).transpose() / 3.0;
      face = face && InPart(rig, m.F(f, k), "face");
    }
    if (!face || !rig.InRegion(region, c)) continue;
    double a0 = 1e9, a1 = -1e9, b0 = 1e9, b1 = -1e9;
    for (int k = 0; k < 3; ++k) {
      a0 = std::min(a0, m.V(m.F(f, k), axis));
      a1 = std::max(a1, m.V(m.F(f, k), axis));
      b0 = std::min(b0, V(m.F(f, k), axis));
      b1 = std::max(b1, V(m.F(f, k), axis));
    }
    if (a1 - a0 < 0.5) continue;  // triangles nearly flat along the axis say little
    lo = std::min(lo, (b1 - b0) / (a1 - a0));
    hi = std::max(hi, (b1 - b0) / (a1 - a0));
  }
  return {lo, hi};
}

TEST(ProceduralRig, ExpressionsCompressTheSkinWhereWrinklesForm) {
  const FaceRig& rig = Rig();
  // Neutral: unchanged.
  const auto [n0, n1] = ExtentRatio(rig, rig.EvaluatePositions({}, {}), "forehead", 1);
  EXPECT_DOUBLE_EQ(n0, 1.0);
  EXPECT_DOUBLE_EQ(n1, 1.0);
  // Brow raise: the forehead shortens vertically (horizontal forehead lines).
  const MatX3d brow = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"browInnerUp_L", 1.0}, {"browInnerUp_R", 1.0}}));
  EXPECT_LT(ExtentRatio(rig, brow, "forehead", 1).first, 0.85);
  const MatX3d outer = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"browOuterUp_L", 1.0}}));
  EXPECT_LT(ExtentRatio(rig, outer, "forehead", 1).first, 0.85);
  // Frown: the glabella narrows (vertical "11" lines).
  const MatX3d frown = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"browDown_L", 1.0}, {"browDown_R", 1.0}}));
  EXPECT_LT(ExtentRatio(rig, frown, "glabella", 0).first, 0.85);
  // Squint and smile: compression at the outer eye corner (crow's feet).
  for (const char* e : {"eyeSquint_L", "mouthSmile_L", "cheekSquint_L"}) {
    const MatX3d s = rig.EvaluatePositions({}, ExpressionWeights(rig, {{e, 1.0}}));
    EXPECT_LT(std::min(ExtentRatio(rig, s, "left_eye", 0).first, ExtentRatio(rig, s, "left_eye", 1).first), 0.85) << e;
  }
  // Nose wrinkle: the nose bridge shortens vertically (bunny lines).
  const MatX3d sneer = rig.EvaluatePositions({}, ExpressionWeights(rig, {{"noseSneer_L", 1.0}, {"noseSneer_R", 1.0}}));
  EXPECT_LT(ExtentRatio(rig, sneer, "nose", 1).first, 0.85);
}

// The face's seams with the hair (the hairline) and with the cranium under the jaw
// follow smooth curves, not the grid's staircase of whole cells (NodePsi).
TEST(ProceduralRig, HairlineAndJawSeamsHaveNoSteps) {
  const FaceRig& rig = Rig();
  const MatX3d& V = rig.neutral.V;
  auto key = [&](int v) { return std::array<double, 3>{V(v, 0), V(v, 1), V(v, 2)}; };
  for (const std::string other : {"hair", "cranium"}) {
    std::set<std::array<double, 3>> seam;
    for (int v = 0; v < rig.num_vertices(); ++v) {
      if (InPart(rig, v, other)) seam.insert(key(v));
    }
    // (azimuth φ, elevation ψ) of the face's vertices on the seam, degrees.
    std::vector<std::pair<double, double>> edge;
    for (int v = 0; v < rig.num_vertices(); ++v) {
      if (!InPart(rig, v, "face") || !seam.count(key(v))) continue;
      const Vector3d p = V.row(v).transpose();
      const double phi = std::atan2(p.x(), p.z()) * 180.0 / std::numbers::pi;
      const double psi = std::asin(p.y() / p.norm()) * 180.0 / std::numbers::pi;
      // The face's sides are grid columns (vertical by design): only its top and bottom.
      if (std::abs(phi) > 79.0 || (other == "cranium" && psi > -30.0)) continue;
      edge.emplace_back(phi, psi);
    }
    ASSERT_GT(edge.size(), 40u) << other;
    std::sort(edge.begin(), edge.end());
    double max_slope = 0.0;
    for (size_t i = 1; i < edge.size(); ++i) {
      const double dphi = edge[i].first - edge[i - 1].first, dpsi = std::abs(edge[i].second - edge[i - 1].second);
      EXPECT_GT(dphi, 0.3) << other << " seam: two vertices above each other (a step) at φ " << edge[i].first;
      max_slope = std::max(max_slope, dpsi / std::max(dphi, 1e-9));
    }
    std::printf("face-%s seam: %zu vertices, steepest dψ/dφ %.2f\n", other.c_str(), edge.size(), max_slope);
    EXPECT_LT(max_slope, 1.0) << other;
  }
}

TEST(ProceduralRig, DeterministicAndRoundTrips) {
  const FaceRig again = BuildProceduralRig();
  const FaceRig& rig = Rig();
  EXPECT_EQ(again.neutral.V, rig.neutral.V);
  EXPECT_EQ(again.neutral.UV, rig.neutral.UV);
  EXPECT_EQ(again.identity_basis, rig.identity_basis);
  EXPECT_EQ(again.expression_basis, rig.expression_basis);
  const fs::path p = testing::TestDir() / "procedural.crig";
  WriteRig(p, rig);
  const FaceRig back = ReadRig(p);
  EXPECT_EQ(back.neutral.V, rig.neutral.V);
  EXPECT_EQ(back.neutral.F, rig.neutral.F);
  EXPECT_EQ(back.neutral.UV, rig.neutral.UV);
  EXPECT_EQ(back.identity_basis, rig.identity_basis);
  EXPECT_EQ(back.expression_basis, rig.expression_basis);
  EXPECT_EQ(back.expression_names, rig.expression_names);
  EXPECT_EQ(back.identity_names, rig.identity_names);
  EXPECT_EQ(back.part_names, rig.part_names);
  EXPECT_EQ(back.vertex_part, rig.vertex_part);
  ASSERT_EQ(back.landmarks.size(), rig.landmarks.size());
  for (size_t i = 0; i < rig.landmarks.size(); ++i) EXPECT_EQ(back.landmarks[i].vertex, rig.landmarks[i].vertex);
  ASSERT_EQ(back.regions.size(), rig.regions.size());
}

TEST(ProceduralRig, OptionsAreChecked) {
  ProceduralRigOptions o;
  o.face_columns = 87;
  EXPECT_ERROR_HAS(o.Check(), "face_columns");
  o = {};
  o.jaw_open_deg = 0.0;
  EXPECT_ERROR_HAS(BuildProceduralRig(o), "jaw_open_deg");
  // A coarser rig still builds and validates.
  o = {};
  o.face_columns = 60;
  o.face_row_density = 0.7;
  const FaceRig small = BuildProceduralRig(o);
  EXPECT_LT(small.num_vertices(), Rig().num_vertices());
  EXPECT_EQ(small.landmarks.size(), 68u);
}

// The contact sheet (`crease synth rig --preview`): 2 × 3 tiles, each showing the
// head; the smile tile (front view) differs from the neutral front view, and for a
// rig without expressions it is the neutral front view exactly.
TEST(ProceduralRig, ContactSheetShowsViewsAndExpressions) {
  const int tile = 64;
  const cv::Mat sheet = RigContactSheet(Rig(), tile);
  ASSERT_EQ(sheet.type(), CV_32FC3);
  ASSERT_EQ(sheet.size(), cv::Size(3 * tile, 2 * tile));
  const auto tile_at = [&](const cv::Mat& m, int i) {
    return m(cv::Rect((i % 3) * tile, (i / 3) * tile, tile, tile)).clone();
  };
  const auto differ = [](const cv::Mat& a, const cv::Mat& b) { return cv::norm(a, b, cv::NORM_INF) > 0.0; };
  for (int i = 0; i < 6; ++i) {
    cv::Mat gray;
    cv::extractChannel(tile_at(sheet, i), gray, 0);
    const float background = gray.at<float>(0, 0);  // a corner
    EXPECT_GT(cv::countNonZero(gray != background), tile * tile / 10) << "tile " << i;  // the head fills it
  }
  EXPECT_TRUE(differ(tile_at(sheet, 0), tile_at(sheet, 1)));  // front vs three-quarter
  EXPECT_TRUE(differ(tile_at(sheet, 1), tile_at(sheet, 2)));  // three-quarter vs side
  EXPECT_TRUE(differ(tile_at(sheet, 0), tile_at(sheet, 3)));  // the smile shows
  FaceRig still = Rig();
  still.expression_basis.resize(still.expression_basis.rows(), 0);
  still.expression_names.clear();
  const cv::Mat still_sheet = RigContactSheet(still, tile);
  EXPECT_FALSE(differ(tile_at(still_sheet, 3), tile_at(sheet, 0)));
  EXPECT_FALSE(differ(tile_at(still_sheet, 0), tile_at(sheet, 0)));
}

}  // namespace
}  // namespace crease
