// The high-fidelity mesh H^t (pipeline/capture/hifi_mesh.h, paper Sec. 5.3): a
// dense UV grid over the face chart displaced along the coarse mesh's normals.
#include "pipeline/capture/hifi_mesh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/mesh_ops.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"
#include "pipeline/capture/frame_texture.h"
#include "tests/synth_test_util.h"
#include "tests/test_util.h"

namespace crease {
namespace {

const FaceRig& Rig() { return testing::ProceduralRig(); }

HifiMeshOptions Options(int n) {
  HifiMeshOptions o;
  o.hifi_mesh_resolution = n;
  return o;
}

const HifiMeshBuilder& Builder256() {
  static const HifiMeshBuilder b(Rig(), Options(256));
  return b;
}

// The rig with an open jaw and closed-ish eyes (slits open in 3D), turned and moved:
// "any frame of reference".
MatX3d Posed() {
  const FaceRig& rig = Rig();
  Eigen::VectorXd e = Eigen::VectorXd::Zero(rig.num_expressions());
  e[rig.ExpressionIndex("jawOpen")] = 1.0;
  e[rig.ExpressionIndex("mouthSmile_L")] = 0.7;
  MatX3d V = rig.EvaluatePositions(Eigen::VectorXd(), e);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1, 0.1).normalized()).matrix();
  for (int v = 0; v < V.rows(); ++v) V.row(v) = (R * V.row(v).transpose() + Eigen::Vector3d(10, -20, 400)).transpose();
  return V;
}

TEST(HifiMesh, ZeroDisplacementLiesOnTheCoarseSurface) {
  const HifiMeshBuilder& b = Builder256();
  const MatX3d V = Posed();
  const TriMesh H = b.Build(V, cv::Mat(128, 128, CV_32F, cv::Scalar(0)));
  ASSERT_EQ(H.num_vertices(), b.num_vertices());
  ASSERT_EQ(H.num_faces(), b.num_triangles());
  ASSERT_EQ(H.UV.rows(), H.num_vertices());
  ASSERT_EQ(H.N.rows(), H.num_vertices());
  ValidateMesh(H, "H^t", {.uv = true, .normals = true});  // finite, indices valid
  std::printf("grid 256: %d vertices, %d triangles\n", H.num_vertices(), H.num_faces());
  // The chart covers well over a third of the UV square; ~2 triangles per vertex.
  EXPECT_GT(H.num_vertices(), 0.3 * 256 * 256);
  EXPECT_GT(H.num_faces(), 1.8 * H.num_vertices());
  // Distance to the coarse face surface along the dense normal: ~0.
  TriMesh coarse;
  coarse.V = V;
  coarse.F = FaceChartTriangles(Rig());
  const RayCaster caster(coarse);
  int hits = 0;
  double max_abs = 0.0;
  for (int v = 0; v < H.num_vertices(); v += 7) {
    const SignedHit h = caster.IntersectSigned(H.V.row(v).transpose().cast<float>(),
                                               H.N.row(v).transpose().cast<float>(), 5.0f);
    if (!h.valid()) continue;
    ++hits;
    max_abs = std::max(max_abs, static_cast<double>(std::abs(h.t)));
  }
  std::printf("D = 0: %d probes hit, max |distance| %.2e mm\n", hits, max_abs);
  EXPECT_GT(hits, 0.99 * (H.num_vertices() / 7));
  EXPECT_LT(max_abs, 1e-3);  // float rays
  // Normals point outwards: they agree with the coarse mesh's normals.
  MatX3d coarse_normals;
  RigVertexNormals(Rig().neutral).Compute(V, &coarse_normals);
  const TriMesh chart = [&] {
    TriMesh c = coarse;
    c.UV = Rig().neutral.UV;
    return c;
  }();
  const UvRaster raster = RasterizeUv(chart, 256, 256);
  const cv::Mat n_map = InterpolateToUv(raster, chart, coarse_normals);
  double mean_dot = 0;
  for (int v = 0; v < H.num_vertices(); ++v) {
    const int node = b.grid_node()[static_cast<size_t>(v)];
    const cv::Vec3f n = n_map.at<cv::Vec3f>(node / 256, node % 256);
    mean_dot += H.N.row(v).dot(Eigen::RowVector3d(n[0], n[1], n[2]).normalized());
  }
  mean_dot /= H.num_vertices();
  EXPECT_GT(mean_dot, 0.99);
  // UVs are the grid's texel centres, inside [0, 1] and covered by the chart.
  for (int v = 0; v < H.num_vertices(); ++v) {
    ASSERT_TRUE(H.UV(v, 0) > 0 && H.UV(v, 0) < 1 && H.UV(v, 1) > 0 && H.UV(v, 1) < 1);
    const int i = static_cast<int>(H.UV(v, 0) * 256), j = static_cast<int>(H.UV(v, 1) * 256);
    ASSERT_TRUE(raster.covered(i, j));
  }
}

// Difference 3: a Phong base (the studio's α = 0.75) leaves the coarse vertices in
// place and bulges the flat triangles outwards on the convex face by a fraction of a
// millimetre; α = 0 is the flat base, byte for byte.
TEST(HifiMesh, PhongBaseRoundsTheFacetsOutwardsOnAConvexFace) {
  const MatX3d V = Posed();
  const cv::Mat zero(128, 128, CV_32F, cv::Scalar(0));
  const TriMesh flat = Builder256().Build(V, zero);
  HifiMeshOptions explicit_flat = Options(256);
  explicit_flat.phong_alpha = 0.0;
  EXPECT_EQ(HifiMeshBuilder(Rig(), explicit_flat).Build(V, zero).V, flat.V);
  HifiMeshOptions rounded = Options(256);
  rounded.phong_alpha = 0.75;
  const TriMesh phong = HifiMeshBuilder(Rig(), rounded).Build(V, zero);
  ASSERT_EQ(phong.num_vertices(), flat.num_vertices());
  double mean_out = 0.0, max_move = 0.0;
  for (int v = 0; v < flat.num_vertices(); ++v) {
    const Eigen::RowVector3d d = phong.V.row(v) - flat.V.row(v);
    mean_out += d.dot(flat.N.row(v));
    max_move = std::max(max_move, d.norm());
  }
  mean_out /= flat.num_vertices();
  std::printf("Phong base (alpha 0.75): mean offset along the normal %.4f mm, max move %.4f mm\n", mean_out, max_move);
  EXPECT_GT(mean_out, 0.0);
  EXPECT_GT(max_move, 1e-3);
  EXPECT_LT(max_move, 2.0);
  rounded.phong_alpha = 1.5;
  EXPECT_THROW(HifiMeshBuilder(Rig(), rounded), Error);
}

TEST(HifiMesh, ConstantDisplacementMovesEveryVertexAlongTheNormal) {
  const HifiMeshBuilder& b = Builder256();
  const MatX3d V = Posed();
  const TriMesh H0 = b.Build(V, cv::Mat(64, 64, CV_32F, cv::Scalar(0)));
  const double c = 0.4;
  const TriMesh Hc = b.Build(V, cv::Mat(1024, 1024, CV_32F, cv::Scalar(c)));
  ASSERT_EQ(Hc.num_vertices(), H0.num_vertices());
  double max_len_err = 0.0, mean_dot = 0.0;
  for (int v = 0; v < H0.num_vertices(); ++v) {
    const Eigen::RowVector3d d = Hc.V.row(v) - H0.V.row(v);
    max_len_err = std::max(max_len_err, std::abs(d.norm() - static_cast<float>(c)));  // the map holds floats
    mean_dot += d.dot(H0.N.row(v)) / c;
  }
  mean_dot /= H0.num_vertices();
  std::printf("D = %.1f mm: max | |H_c − H_0| − c | = %.2e mm, mean cos to the normal %.5f\n", c, max_len_err,
              mean_dot);
  EXPECT_LT(max_len_err, 1e-9);
  EXPECT_GT(mean_dot, 0.995);  // outwards, along the (Phong vs. facet) normal
  // A displacement of another sign goes inwards.
  const TriMesh Hn = b.Build(V, cv::Mat(64, 64, CV_32F, cv::Scalar(-c)));
  EXPECT_NEAR((Hn.V.row(0) - H0.V.row(0)).dot(H0.N.row(0)), -c, 0.05);
}

TEST(HifiMesh, DisplacementIsSampledBilinearlyInUv) {
  // D(u, v) = 2u − v (linear): bilinear sampling reproduces it at every grid vertex
  // away from the map border.
  const HifiMeshBuilder& b = Builder256();
  const MatX3d V = Posed();
  const int R = 300;
  cv::Mat D(R, R, CV_32F);
  for (int j = 0; j < R; ++j) {
    for (int i = 0; i < R; ++i) D.at<float>(j, i) = static_cast<float>(2.0 * (i + 0.5) / R - (j + 0.5) / R);
  }
  const TriMesh H0 = b.Build(V, cv::Mat(8, 8, CV_32F, cv::Scalar(0)));
  TriMesh H;
  b.BuildInto(V, D, &H);
  b.BuildInto(V, D, &H);  // reuses F and UV
  double max_err = 0.0;
  for (int v = 0; v < H.num_vertices(); ++v) {
    const double expected = 2.0 * H.UV(v, 0) - H.UV(v, 1);
    const double moved = (H.V.row(v) - H0.V.row(v)).norm() * (expected < 0 ? -1 : 1);
    max_err = std::max(max_err, std::abs(moved - expected));
  }
  EXPECT_LT(max_err, 1e-5);
}

TEST(HifiMesh, DoesNotBridgeTheLipsOrEyelids) {
  // With the jaw open the lips part by ~20 mm: no dense edge may span the gap.
  const HifiMeshBuilder& b = Builder256();
  const MatX3d V = Posed();
  const TriMesh H = b.Build(V, cv::Mat(8, 8, CV_32F, cv::Scalar(0)));
  double longest = 0.0;
  int worst = -1;
  for (int f = 0; f < H.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const double len = (H.V.row(H.F(f, k)) - H.V.row(H.F(f, (k + 1) % 3))).norm();
      if (len > longest) {
        longest = len;
        worst = H.F(f, k);
      }
    }
  }
  const MatX3i CF = FaceChartTriangles(Rig());
  double coarse_longest = 0.0;
  for (int f = 0; f < CF.rows(); ++f) {
    for (int k = 0; k < 3; ++k) coarse_longest = std::max(coarse_longest, (V.row(CF(f, k)) - V.row(CF(f, (k + 1) % 3))).norm());
  }
  std::printf("longest dense edge %.2f mm at uv (%.3f, %.3f); longest coarse chart edge %.2f mm\n", longest,
              H.UV(worst, 0), H.UV(worst, 1), coarse_longest);
  EXPECT_LT(longest, coarse_longest);
  // The segments between the inner upper and lower lip landmarks cross the open
  // mouth: a dense mesh bridging the lips would block them.
  const RayCaster caster(H);
  const FaceRig& rig = Rig();
  for (const auto& [upper, lower] : {std::pair{62, 68}, std::pair{63, 67}, std::pair{64, 66}}) {
    const Eigen::Vector3d a = V.row(rig.landmarks[rig.LandmarkIndex("ibug_" + std::to_string(upper))].vertex);
    const Eigen::Vector3d b = V.row(rig.landmarks[rig.LandmarkIndex("ibug_" + std::to_string(lower))].vertex);
    const double gap = (b - a).norm();
    ASSERT_GT(gap, 5.0) << "the mouth should be open";
    Ray ray;
    ray.origin = (a + 0.1 * (b - a)).cast<float>();
    ray.direction = ((b - a) / gap).cast<float>();
    ray.tfar = static_cast<float>(0.8 * gap);
    EXPECT_FALSE(caster.Occluded(ray)) << "lips bridged between ibug_" << upper << " and ibug_" << lower;
  }
  // Triangles are counter-clockwise from outside: their normals agree with the vertex normals.
  int agree = 0;
  for (int f = 0; f < H.num_faces(); ++f) {
    const Eigen::Vector3d p0 = H.V.row(H.F(f, 0)).transpose();
    const Eigen::Vector3d n = (H.V.row(H.F(f, 1)).transpose() - p0).cross(H.V.row(H.F(f, 2)).transpose() - p0);
    agree += n.dot(H.N.row(H.F(f, 0)).transpose()) > 0;
  }
  EXPECT_GT(agree, 0.999 * H.num_faces());
}

TEST(HifiMesh, DefaultResolutionAndErrors) {
  const HifiMeshBuilder b(Rig(), HifiMeshOptions{});
  EXPECT_EQ(b.grid_resolution(), 512);
  std::printf("grid 512: %d vertices, %d triangles\n", b.num_vertices(), b.num_triangles());
  EXPECT_GT(b.num_vertices(), 0.3 * 512 * 512);
  const HifiMeshBuilder& s = Builder256();
  const MatX3d V = Posed();
  const cv::Mat D(16, 16, CV_32F, cv::Scalar(0));
  MatX3d bad = V;
  bad(123, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_ERROR_HAS(s.Build(bad, D), "row 123");
  EXPECT_ERROR_HAS(s.Build(MatX3d::Zero(10, 3), D), "10 rows");
  EXPECT_ERROR_HAS(s.Build(V, cv::Mat(16, 16, CV_64F, cv::Scalar(0))), "CV_32FC1");
  EXPECT_ERROR_HAS(s.Build(V, cv::Mat(16, 8, CV_32F, cv::Scalar(0))), "square");
  EXPECT_ERROR_HAS(s.Build(V, cv::Mat()), "CV_32FC1");
  cv::Mat nan_map(16, 16, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  EXPECT_ERROR_HAS(s.Build(V, nan_map), "non-finite");
  EXPECT_ERROR_HAS(HifiMeshBuilder(Rig(), Options(1)), "hifi_mesh_resolution");
}

}  // namespace
}  // namespace crease
