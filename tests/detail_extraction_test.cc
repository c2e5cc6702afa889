// Detail extraction (paper Sec. 4.1): deformation transfer, the extracted
// displacement map D^j, the compatible rig, and map comparison.
#include "pipeline/training/detail_extraction.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/mesh_ops.h"
#include "core/mesh_primitives.h"
#include "pipeline/training/deformation_transfer.h"
#include "tests/test_util.h"

namespace crease {
namespace {

using testing::ErrorOf;

// A smooth, non-rigid deformation: bend the grid around the y axis and swell it.
MatX3d Bend(const MatX3d& V, double amount) {
  MatX3d out = V;
  for (int i = 0; i < V.rows(); ++i) {
    const double x = V(i, 0), y = V(i, 1);
    out(i, 2) += amount * (0.02 * (x - 20) * (x - 20) + 2.0 * std::sin(y / 12.0));
    out(i, 0) += amount * 0.05 * y;
  }
  return out;
}

TEST(DeformationTransfer, ReproducesADeformationAppliedToTheSameMesh) {
  const TriMesh grid = MakeGrid(40, 30, 40.0, 30.0);
  const DeformationTransfer dt(grid, grid);
  const MatX3d target = Bend(grid.V, 1.0);
  const MatX3d out = dt.Transfer(target);
  EXPECT_LT((out - target).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(DeformationTransfer, CarriesTheSourceDeformationOntoADetailedTarget) {
  // Source: a flat grid; target: the same grid with a ridge. Transferring the
  // source's bend must bend the target and keep its ridge (along the bent normal).
  const TriMesh flat = MakeGrid(60, 40, 40.0, 30.0);
  TriMesh ridged = flat;
  for (int i = 0; i < ridged.num_vertices(); ++i) {
    ridged.V(i, 2) += 0.5 * std::exp(-std::pow(ridged.V(i, 0) - 20.0, 2) / 2.0);
  }
  const DeformationTransfer dt(flat, ridged);
  const MatX3d bent = Bend(flat.V, 1.0);
  const MatX3d out = dt.Transfer(bent);
  // Away from the ridge the transferred target follows the bent source, up to a
  // translation; at the ridge it sits 0.5 mm above it.
  double offset = 0.0;
  int n = 0;
  for (int i = 0; i < flat.num_vertices(); ++i) {
    if (std::abs(flat.V(i, 0) - 20.0) > 8.0) {
      offset += out(i, 2) - bent(i, 2);
      ++n;
    }
  }
  offset /= n;
  double worst_far = 0.0, ridge = 0.0;
  int nr = 0;
  for (int i = 0; i < flat.num_vertices(); ++i) {
    const double d = out(i, 2) - bent(i, 2) - offset;
    if (std::abs(flat.V(i, 0) - 20.0) > 8.0) worst_far = std::max(worst_far, std::abs(d));
    if (std::abs(flat.V(i, 0) - 20.0) < 0.01 && flat.V(i, 1) > 5 && flat.V(i, 1) < 25) {
      ridge += d;
      ++nr;
    }
  }
  ASSERT_GT(nr, 0);
  EXPECT_LT(worst_far, 0.05);
  EXPECT_NEAR(ridge / nr, 0.5, 0.05);
}

TEST(DeformationTransfer, RejectsMismatchedTopology) {
  const TriMesh a = MakeGrid(4, 4, 1, 1), b = MakeGrid(5, 4, 1, 1);
  EXPECT_ERROR_HAS((DeformationTransfer(a, b)), "share their topology");
  const DeformationTransfer dt(a, a);
  EXPECT_ERROR_HAS(dt.Transfer(MatX3d::Zero(3, 3)), "vertices");
  MatX3d bad = a.V;
  bad(2, 1) = std::nan("");
  EXPECT_ERROR_HAS(dt.Transfer(bad), "vertex 2 is not finite");
}

// A smooth surface with a narrow bump added in the "expression": detail extraction
// must recover the bump (medium frequency) and ignore the large-scale change.
class DetailExtractionBump : public ::testing::TestWithParam<int> {};

TEST_P(DetailExtractionBump, RecoversAKnownBump) {
  const TriMesh neutral = MakeGrid(160, 160, 40.0, 40.0);  // 0.25 mm spacing
  DetailExtractionOptions o;
  o.map_resolution = 128;
  o.lowpass_bandwidth_mm = 3.0;
  o.high_frequency_bandwidth_mm = 0.0;
  o.operator_resolution = GetParam();  // 0: G and the transfer on the full mesh; 64: on a 0.6 mm grid
  const DetailExtractor extractor(neutral, o);
  EXPECT_EQ(extractor.operator_grid_vertices() > 0, GetParam() > 0);
  // The expression: a global bend (low frequency) plus a furrow 0.4 mm deep, σ 0.8 mm,
  // along y at x = 20 mm.
  MatX3d expr = neutral.V;
  const double depth = 0.4, sigma = 0.8;
  for (int i = 0; i < expr.rows(); ++i) {
    const double x = neutral.V(i, 0), y = neutral.V(i, 1);
    expr(i, 2) += 0.004 * (x - 20) * (x - 20) + 0.003 * (y - 20) * (y - 20);
    expr(i, 2) -= depth * std::exp(-0.5 * std::pow((x - 20.0) / sigma, 2));
  }
  const ExtractedDetail d = extractor.Extract(expr, "bump");
  // Texel column at x = 20 mm (u = 0.5) and rows in the middle (away from the
  // boundary, where the lowpass slides the surface).
  const int R = o.map_resolution;
  double centre = 0.0, far = 0.0;
  int nc = 0, nf = 0;
  for (int j = R / 4; j < 3 * R / 4; ++j) {
    for (int i = R / 4; i < 3 * R / 4; ++i) {
      if (!d.valid.at<uint8_t>(j, i)) continue;
      const double x = (i + 0.5) / R * 40.0;
      const double v = d.displacement.at<float>(j, i);
      if (std::abs(x - 20.0) < 0.16) {
        centre += v;
        ++nc;
      } else if (std::abs(x - 20.0) > 6.0) {
        far = std::max(far, std::abs(v));
        ++nf;
      }
    }
  }
  ASSERT_GT(nc, 0);
  ASSERT_GT(nf, 0);
  // G (σ = 3 mm) keeps part of a σ0 = 0.8 mm furrow in the lowpass: a Gaussian
  // lowpass leaves σ0/√(σ0² + σ²) of its depth, so the detail is the rest; the
  // large-scale bend must not show up.
  const double expected = -depth * (1.0 - sigma / std::sqrt(sigma * sigma + 9.0));
  EXPECT_NEAR(centre / nc, expected, 0.08 * std::abs(expected));
  EXPECT_LT(far, 0.03);
  EXPECT_EQ(d.rays_missed, 0);
}

INSTANTIATE_TEST_SUITE_P(OperatorGrid, DetailExtractionBump, ::testing::Values(0, 64));

TEST(DetailExtraction, NeutralGivesZeroDetail) {
  const TriMesh neutral = MakeUVSphere(40.0, 40, 60);
  DetailExtractionOptions o;
  o.map_resolution = 64;
  o.operator_resolution = 32;
  const DetailExtractor extractor(neutral, o);
  const ExtractedDetail d = extractor.Extract(neutral.V, "neutral");
  double worst = 0.0;
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 64; ++i)
      if (d.valid.at<uint8_t>(j, i)) worst = std::max(worst, std::abs(double(d.displacement.at<float>(j, i))));
  EXPECT_LT(worst, 0.02);  // G^HF of a smooth sphere moves it by µm only
}

TEST(DetailExtraction, BadInput) {
  TriMesh no_uv = MakeGrid(4, 4, 1, 1);
  no_uv.UV.resize(0, 2);
  EXPECT_ERROR_HAS((DetailExtractor(no_uv, {}, "scan.ply")), "scan.ply");
  DetailExtractionOptions bad;
  bad.map_resolution = 3;
  EXPECT_ERROR_HAS((DetailExtractor(MakeGrid(4, 4, 1, 1), bad)), "map_resolution");
  const DetailExtractor e(MakeGrid(10, 10, 10, 10), {.map_resolution = 32});
  EXPECT_ERROR_HAS(e.Extract(MatX3d::Zero(5, 3), "smile.ply"), "smile.ply: 5 vertices");
}

TEST(MakeRigCompatible, RemovesMediumFrequenciesOfBlendshapesAndKeepsTheRest) {
  // A grid "rig" with two blendshapes: a smooth bend (kept) and a narrow fold
  // (removed: it is a medium-frequency expression detail).
  FaceRig rig;
  rig.neutral = MakeGrid(80, 80, 40.0, 40.0);
  const int n = rig.num_vertices();
  rig.expression_basis.setZero(3 * n, 2);
  rig.expression_names = {"bend", "fold"};
  for (int v = 0; v < n; ++v) {
    const double x = rig.neutral.V(v, 0), y = rig.neutral.V(v, 1);
    rig.expression_basis(3 * v + 2, 0) = static_cast<float>(0.01 * (x - 20) * (x - 20) + 0.01 * (y - 20) * (y - 20));
    rig.expression_basis(3 * v + 2, 1) = static_cast<float>(-0.5 * std::exp(-0.5 * std::pow((x - 20) / 0.7, 2)));
  }
  const FaceRig compatible = MakeRigCompatible(rig, {});
  ASSERT_EQ(compatible.num_expressions(), 2);
  // At the centre (away from the boundary) the bend survives, the fold mostly goes.
  const int centre = 40 * 81 + 40;
  const double bend_before = rig.expression_basis(3 * centre + 2, 0) - rig.expression_basis(3 * (centre + 20) + 2, 0);
  const double bend_after =
      compatible.expression_basis(3 * centre + 2, 0) - compatible.expression_basis(3 * (centre + 20) + 2, 0);
  EXPECT_NEAR(bend_after, bend_before, 0.1 * std::abs(bend_before));
  const double fold_before =
      rig.expression_basis(3 * centre + 2, 1) - rig.expression_basis(3 * (centre + 20) + 2, 1);
  const double fold_after =
      compatible.expression_basis(3 * centre + 2, 1) - compatible.expression_basis(3 * (centre + 20) + 2, 1);
  EXPECT_LT(std::abs(fold_after), 0.3 * std::abs(fold_before));
  // Without a lowpass the rig is unchanged.
  DetailExtractionOptions off;
  off.lowpass_bandwidth_mm = 0.0;
  EXPECT_EQ(MakeRigCompatible(rig, off).expression_basis, rig.expression_basis);
}

TEST(CompareMaps, RmseAndCorrelation) {
  cv::Mat a(4, 4, CV_32F), b(4, 4, CV_32F), m(4, 4, CV_8U, cv::Scalar(255));
  for (int k = 0; k < 16; ++k) {
    a.at<float>(k / 4, k % 4) = static_cast<float>(k);
    b.at<float>(k / 4, k % 4) = static_cast<float>(2 * k + 1);
  }
  const MapComparison c = CompareMaps(a, b, m);
  EXPECT_EQ(c.texels, 16);
  EXPECT_NEAR(c.correlation, 1.0, 1e-9);
  double se = 0;
  for (int k = 0; k < 16; ++k) se += (k + 1.0) * (k + 1.0);
  EXPECT_NEAR(c.rmse_mm, std::sqrt(se / 16), 1e-9);
  m.setTo(0);
  EXPECT_EQ(CompareMaps(a, b, m).texels, 0);
}

}  // namespace
}  // namespace crease
