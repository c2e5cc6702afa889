#include "core/uv_raster.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"
#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/mesh_primitives.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;

// ---- Independent per-texel reference ---------------------------------------------
//
// For one texel centre and one triangle, decides coverage from scratch with the
// rule documented in uv_raster.h: UVs snapped to 1/kUvSubpixelSteps texel, exact
// orientation tests (128-bit), and centres on an edge resolved by nudging the
// centre to p + ε·(1, η) with 0 < η << ε: the sign of an edge function at the
// nudged point is the lexicographic sign of (E(p), ∂E/∂x, ∂E/∂y).

using Int = __int128;

struct Snapped {
  Int x[3], y[3];
};

Snapped SnapTriangle(const TriMesh& m, int f, int width, int height) {
  Snapped s;
  for (int k = 0; k < 3; ++k) {
    s.x[k] = std::llround(m.UV(m.F(f, k), 0) * width * kUvSubpixelSteps);
    s.y[k] = std::llround(m.UV(m.F(f, k), 1) * height * kUvSubpixelSteps);
  }
  return s;
}

int LexSign(Int a, Int b, Int c) {
  if (a != 0) return a > 0 ? 1 : -1;
  if (b != 0) return b > 0 ? 1 : -1;
  return c > 0 ? 1 : (c < 0 ? -1 : 0);
}

// Orientation of (a, b, p'), p' the nudged point p.
int NudgedOrientation(Int ax, Int ay, Int bx, Int by, Int px, Int py) {
  const Int e = (bx - ax) * (py - ay) - (by - ay) * (px - ax);
  // ∂e/∂px = −(by − ay); ∂e/∂py = bx − ax.
  return LexSign(e, -(by - ay), bx - ax);
}

bool ReferenceCovers(const Snapped& s, int i, int j) {
  const Int px = static_cast<Int>(2 * i + 1) * (kUvSubpixelSteps / 2);
  const Int py = static_cast<Int>(2 * j + 1) * (kUvSubpixelSteps / 2);
  const Int area = (s.x[1] - s.x[0]) * (s.y[2] - s.y[0]) - (s.y[1] - s.y[0]) * (s.x[2] - s.x[0]);
  if (area == 0) return false;
  const int want = area > 0 ? 1 : -1;
  for (int k = 0; k < 3; ++k) {
    const int n = (k + 1) % 3;
    if (NudgedOrientation(s.x[k], s.y[k], s.x[n], s.y[n], px, py) != want) return false;
  }
  return true;
}

// Barycentrics of the texel centre in the unsnapped triangle (double).
Eigen::Vector3d Barycentrics(const TriMesh& m, int f, double u, double v) {
  const Eigen::Vector2d a = m.UV.row(m.F(f, 0)), b = m.UV.row(m.F(f, 1)), c = m.UV.row(m.F(f, 2));
  Eigen::Matrix2d M;
  M << b - a, c - a;
  const Eigen::Vector2d w = M.inverse() * (Eigen::Vector2d(u, v) - a);
  return {1.0 - w.x() - w.y(), w.x(), w.y()};
}

struct ReferenceStats {
  int double_covered = 0;       // texels the rule assigns to two triangles or more
  int missed_interior = 0;      // texels inside a triangle or on a shared edge, not covered
  int mismatched = 0;           // raster disagrees with the reference
  int strictly_inside = 0;      // texels strictly inside one triangle (double precision)
  int on_shared_edge = 0;       // texels on an edge of two triangles (double precision)
  int covered = 0;
};

// Checks every texel of `raster` against the reference, by brute force over all
// triangles. `all_interior`: every texel centre is inside the chart (grid).
ReferenceStats CheckAgainstReference(const TriMesh& m, const UvRaster& raster, bool all_interior) {
  ReferenceStats st;
  std::vector<Snapped> snapped;
  for (int f = 0; f < m.num_faces(); ++f) snapped.push_back(SnapTriangle(m, f, raster.width, raster.height));
  // Strictly inside: all barycentrics > 1e-2, far more than the snapping (1/512
  // texel) can move an edge; on an edge: all barycentrics > -1e-9.
  const double strict_eps = 1e-2, eps = 1e-9;
  for (int j = 0; j < raster.height; ++j) {
    for (int i = 0; i < raster.width; ++i) {
      const double u = (i + 0.5) / raster.width, v = (j + 0.5) / raster.height;
      int count = 0, first = -1, strict = -1, loose = 0;
      for (int f = 0; f < m.num_faces(); ++f) {
        if (ReferenceCovers(snapped[static_cast<size_t>(f)], i, j)) {
          if (count++ == 0) first = f;
        }
        const Eigen::Vector3d w = Barycentrics(m, f, u, v);
        if (w.minCoeff() > strict_eps) strict = f;
        if (w.minCoeff() > -eps) ++loose;
      }
      if (count > 1) ++st.double_covered;
      if (count > 0) ++st.covered;
      const bool interior = all_interior || strict >= 0 || loose >= 2;
      if (strict >= 0) ++st.strictly_inside;
      if (strict < 0 && loose >= 2) ++st.on_shared_edge;
      if (interior && count == 0) ++st.missed_interior;
      if (strict >= 0 && first != strict) ++st.mismatched;
      if (raster.triangle[static_cast<size_t>(raster.index(i, j))] != first) ++st.mismatched;
    }
  }
  return st;
}

void ExpectBarycentricsReproduceTexelCentres(const TriMesh& m, const UvRaster& raster) {
  int checked = 0;
  for (int j = 0; j < raster.height; ++j) {
    for (int i = 0; i < raster.width; ++i) {
      const size_t idx = static_cast<size_t>(raster.index(i, j));
      const int f = raster.triangle[idx];
      if (f < 0) {
        EXPECT_EQ(raster.barycentric[idx], Eigen::Vector3f::Zero());
        continue;
      }
      const Eigen::Vector3d w = raster.barycentric[idx].cast<double>();
      const Eigen::Vector2d uv =
          w[0] * m.UV.row(m.F(f, 0)) + w[1] * m.UV.row(m.F(f, 1)) + w[2] * m.UV.row(m.F(f, 2));
      ASSERT_NEAR(uv.x(), (i + 0.5) / raster.width, 1e-5) << i << "," << j;
      ASSERT_NEAR(uv.y(), (j + 0.5) / raster.height, 1e-5) << i << "," << j;
      ASSERT_NEAR(w.sum(), 1.0, 1e-5);
      ASSERT_GT(w.minCoeff(), -0.01);
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
}

TEST(UvRaster, GridWithCentresOnEdgesAndVerticesIsCoveredExactlyOnce) {
  // 40×40 quads on a 60×60 map: vertex a/40 is at texel coordinate 1.5·a, so the
  // centres of many texels lie exactly on vertical, horizontal and diagonal edges
  // and on vertices: the tie rule decides them.
  for (const bool alternate : {true, false}) {
    const TriMesh grid = MakeGrid(40, 40, 40.0, 40.0, alternate);
    const UvRaster raster = RasterizeUv(grid, 60, 60);
    EXPECT_EQ(raster.width, 60);
    EXPECT_EQ(raster.height, 60);
    EXPECT_EQ(raster.num_triangles, grid.num_faces());
    EXPECT_EQ(raster.num_overlaps, 0);
    EXPECT_EQ(raster.num_covered(), 3600);
    const ReferenceStats st = CheckAgainstReference(grid, raster, /*all_interior=*/true);
    EXPECT_EQ(st.double_covered, 0);
    EXPECT_EQ(st.missed_interior, 0);
    EXPECT_EQ(st.mismatched, 0);
    EXPECT_EQ(st.covered, 3600);
    EXPECT_GT(st.on_shared_edge, 500) << "the test should exercise the tie rule";
    ExpectBarycentricsReproduceTexelCentres(grid, raster);
  }
}

TEST(UvRaster, GenericGridAndMirroredChart) {
  TriMesh grid = MakeGrid(7, 5, 70.0, 50.0);
  for (const bool mirrored : {false, true}) {
    if (mirrored) grid.UV.col(0) = 1.0 - grid.UV.col(0).array();  // clockwise in UV
    const UvRaster raster = RasterizeUv(grid, 64, 48);
    EXPECT_EQ(raster.num_overlaps, 0);
    EXPECT_EQ(raster.num_covered(), 64 * 48);
    const ReferenceStats st = CheckAgainstReference(grid, raster, true);
    EXPECT_EQ(st.double_covered, 0);
    EXPECT_EQ(st.missed_interior, 0);
    EXPECT_EQ(st.mismatched, 0);
    ExpectBarycentricsReproduceTexelCentres(grid, raster);
  }
}

TEST(UvRaster, UvSphereIsCoveredExactlyOnce) {
  // 3 texels per segment and 5 per ring: texel centres fall on the diagonals.
  const TriMesh sphere = MakeUVSphere(10.0, 10, 16);
  const UvRaster raster = RasterizeUv(sphere, 48, 50);
  EXPECT_EQ(raster.num_overlaps, 0);
  const ReferenceStats st = CheckAgainstReference(sphere, raster, false);
  EXPECT_EQ(st.double_covered, 0);
  EXPECT_EQ(st.missed_interior, 0);
  EXPECT_EQ(st.mismatched, 0);
  EXPECT_GT(st.on_shared_edge, 50);
  EXPECT_EQ(st.covered, raster.num_covered());
  // The pole fans leave the triangles between the fans' teeth uncovered.
  EXPECT_LT(raster.num_covered(), 48 * 50);
  EXPECT_GT(raster.num_covered(), 48 * 40);
  ExpectBarycentricsReproduceTexelCentres(sphere, raster);

  const TriMesh fine = MakeUVSphere(10.0, 24, 40);
  const UvRaster fine_raster = RasterizeUv(fine, 101, 77);
  const ReferenceStats fine_st = CheckAgainstReference(fine, fine_raster, false);
  EXPECT_EQ(fine_raster.num_overlaps, 0);
  EXPECT_EQ(fine_st.double_covered, 0);
  EXPECT_EQ(fine_st.missed_interior, 0);
  EXPECT_EQ(fine_st.mismatched, 0);
  ExpectBarycentricsReproduceTexelCentres(fine, fine_raster);
}

TEST(UvRaster, InterpolatedPositionsOfAPlanarGridAreExact) {
  const TriMesh grid = MakeGrid(13, 9, 40.0, 30.0);
  const UvRaster raster = RasterizeUv(grid, 128, 96);
  const cv::Mat positions = InterpolateToUv(raster, grid, grid.V);
  ASSERT_EQ(positions.type(), CV_32FC3);
  ASSERT_EQ(positions.rows, 96);
  ASSERT_EQ(positions.cols, 128);
  for (int j = 0; j < 96; ++j) {
    for (int i = 0; i < 128; ++i) {
      const cv::Vec3f p = positions.at<cv::Vec3f>(j, i);
      EXPECT_NEAR(p[0], 40.0 * (i + 0.5) / 128, 2e-5);
      EXPECT_NEAR(p[1], 30.0 * (j + 0.5) / 96, 2e-5);
      EXPECT_EQ(p[2], 0.0f);
    }
  }
  // 1, 2 and 4 channels of UV-linear data.
  for (const int channels : {1, 2, 4}) {
    Eigen::MatrixXd data(grid.num_vertices(), channels);
    for (int c = 0; c < channels; ++c) data.col(c) = (c + 1.0) * grid.UV.col(0) - c * grid.UV.col(1);
    const cv::Mat map = InterpolateToUv(raster, grid, data);
    ASSERT_EQ(map.type(), CV_32FC(channels));
    for (int j = 0; j < 96; j += 7) {
      for (int i = 0; i < 128; i += 5) {
        const float* px = map.ptr<float>(j) + i * channels;
        for (int c = 0; c < channels; ++c) {
          EXPECT_NEAR(px[c], (c + 1.0) * (i + 0.5) / 128 - c * (j + 0.5) / 96, 1e-6);
        }
      }
    }
  }
}

TEST(UvRaster, UncoveredTexelsAreZeroAndMaskMatches) {
  const TriMesh sphere = MakeUVSphere(10.0, 6, 8);
  const UvRaster raster = RasterizeUv(sphere, 64, 64);
  const cv::Mat mask = CoverageMask(raster);
  ASSERT_EQ(mask.type(), CV_8U);
  EXPECT_EQ(cv::countNonZero(mask), raster.num_covered());
  const cv::Mat positions = InterpolateToUv(raster, sphere, sphere.V);
  int uncovered = 0;
  for (int j = 0; j < 64; ++j) {
    for (int i = 0; i < 64; ++i) {
      EXPECT_EQ(mask.at<uint8_t>(j, i), raster.covered(i, j) ? 255 : 0);
      if (!raster.covered(i, j)) {
        ++uncovered;
        EXPECT_EQ(positions.at<cv::Vec3f>(j, i), cv::Vec3f(0, 0, 0));
      } else {
        // On the coarse polyhedron: between its smallest face-plane distance and R.
        const double r = cv::norm(positions.at<cv::Vec3f>(j, i));
        EXPECT_LE(r, 10.0 + 1e-4);
        EXPECT_GE(r, 10.0 * std::cos(std::numbers::pi / 6) * std::cos(std::numbers::pi / 8));
      }
    }
  }
  EXPECT_GT(uncovered, 0);
}

TEST(UvRaster, OverlapsAreCountedAndTheLowestTriangleWins) {
  TriMesh twice = MakeGrid(3, 3, 1.0, 1.0);
  const int nf = twice.num_faces();
  twice.F.conservativeResize(2 * nf, 3);
  twice.F.bottomRows(nf) = twice.F.topRows(nf);
  const UvRaster raster = RasterizeUv(twice, 32, 32);
  EXPECT_EQ(raster.num_covered(), 32 * 32);
  EXPECT_EQ(raster.num_overlaps, 32 * 32);
  for (const int t : raster.triangle) EXPECT_LT(t, nf);
}

TEST(UvRaster, DeterministicForAnyThreadCount) {
  const TriMesh sphere = MakeUVSphere(10.0, 60, 90);
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    return RasterizeUv(sphere, 300, 200);
  };
  const UvRaster one = run(1), two = run(2), four = run(4);
  EXPECT_EQ(one.triangle, two.triangle);
  EXPECT_EQ(one.triangle, four.triangle);
  EXPECT_EQ(one.barycentric, two.barycentric);
  EXPECT_EQ(one.barycentric, four.barycentric);
}


TEST(UvRaster, ClearErrors) {
  TriMesh no_uv = MakeGrid(2, 2, 1.0, 1.0);
  no_uv.UV.resize(0, 2);
  std::string message = ErrorOf([&] { RasterizeUv(no_uv, 16, 16, "actor_02/neutral.ply"); });
  EXPECT_NE(message.find("actor_02/neutral.ply"), std::string::npos) << message;
  EXPECT_NE(message.find("no UV coordinates"), std::string::npos) << message;

  const TriMesh grid = MakeGrid(2, 2, 1.0, 1.0);
  message = ErrorOf([&] { RasterizeUv(grid, 0, 16); });
  EXPECT_NE(message.find("0×16"), std::string::npos) << message;

  TriMesh far_uv = grid;
  far_uv.UV(4, 0) = 1000.0;
  message = ErrorOf([&] { RasterizeUv(far_uv, 16, 16, "far.obj"); });
  EXPECT_NE(message.find("far.obj: vertex 4 has UV"), std::string::npos) << message;

  const UvRaster raster = RasterizeUv(grid, 16, 16);
  message = ErrorOf([&] { InterpolateToUv(raster, grid, Eigen::MatrixXd::Zero(grid.num_vertices(), 5)); });
  EXPECT_NE(message.find("5 columns"), std::string::npos) << message;
  message = ErrorOf([&] { InterpolateToUv(raster, grid, Eigen::MatrixXd::Zero(3, 3)); });
  EXPECT_NE(message.find("3 rows"), std::string::npos) << message;
  const TriMesh other = MakeGrid(3, 3, 1.0, 1.0);
  message = ErrorOf([&] { InterpolateToUv(raster, other, other.V); });
  EXPECT_NE(message.find("built for a mesh with 8 triangles"), std::string::npos) << message;
}

}  // namespace
}  // namespace crease
