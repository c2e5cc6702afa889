// Texture extraction (Sec. 4.1's T^j): which texels a camera sees, and the
// view normals that judge the view angle (texture_extraction.h, Difference 2).
#include "pipeline/training/texture_extraction.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "core/camera.h"
#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/mesh_primitives.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"

namespace crease {
namespace {

constexpr double kSizeMm = 40.0;

// A 40 mm plate with Gaussian grooves along x (σ = 0.15 period), like a wrinkle's
// valley.
TriMesh GroovedPlate(double depth_mm, double period_mm) {
  TriMesh m = MakeGrid(160, 160, kSizeMm, kSizeMm);
  for (int v = 0; v < m.num_vertices(); ++v) {
    const double f = m.V(v, 1) / period_mm - std::floor(m.V(v, 1) / period_mm);
    m.V(v, 2) = -depth_mm * std::exp(-std::pow((f - 0.5) / 0.15, 2));
  }
  return m;
}

// A camera 300 mm away, looking at the plate's centre from 65° off its normal
// (an oblique forehead), tilted across the grooves so one wall of each faces away.
Camera ObliqueCamera() {
  const double a = 65.0 * std::numbers::pi / 180.0;
  const Eigen::Vector3d target(kSizeMm / 2, kSizeMm / 2, 0.0);
  const Eigen::Vector3d eye = target + 300.0 * Eigen::Vector3d(0.0, -std::sin(a), std::cos(a));
  return LookAtCamera(CameraIntrinsics::FromFov(20.0, 160, 120), eye, target, Eigen::Vector3d::UnitY());
}

struct Extraction {
  int covered = 0;
  int seen = 0;
  double max_gray_error = 0.0;
};

Extraction Extract(const TriMesh& mesh, const MatX3d* view_normals) {
  const UvRaster raster = RasterizeUv(mesh, 64, 64);
  const RayCaster caster(mesh);
  const Camera cam = ObliqueCamera();
  const cv::Mat image(cam.intrinsics.height, cam.intrinsics.width, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  const ExtractedTexture tex = ExtractTexture(mesh, raster, &caster, {cam}, {image}, TextureOptions{}, view_normals);
  Extraction e;
  e.covered = raster.num_covered();
  e.seen = cv::countNonZero(tex.seen);
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 64; ++i)
      if (tex.seen.at<uint8_t>(j, i)) e.max_gray_error = std::max(e.max_gray_error, std::abs(tex.gray.at<float>(j, i) - 0.5));
  return e;
}

TEST(TextureExtraction, FlatPlateSeenWholeAtAnObliqueView) {
  const Extraction e = Extract(MakeGrid(160, 160, kSizeMm, kSizeMm), nullptr);
  EXPECT_EQ(e.seen, e.covered);
  EXPECT_LT(e.max_gray_error, 1e-5);
}

TEST(TextureExtraction, GrooveWallsVanishWithTheirOwnNormalsButNotWithSmoothOnes) {
  // Grooves 0.3 mm deep every 4 mm: walls tilted up to ~23° (a studio forehead line).
  const TriMesh grooved = GroovedPlate(0.3, 4.0);
  const Extraction own = Extract(grooved, nullptr);
  // 65° + the wall's tilt exceeds max_view_angle_deg = 75° on the walls facing away.
  EXPECT_LT(own.seen, own.covered * 9 / 10) << own.seen << " of " << own.covered;
  // Judged by the plate's smooth normal (M_0^j's in training), the camera sees them:
  // nothing occludes a wall this shallow from 65°.
  const MatX3d smooth = VertexNormals(MakeGrid(160, 160, kSizeMm, kSizeMm));
  const Extraction judged = Extract(grooved, &smooth);
  EXPECT_EQ(judged.seen, judged.covered);
  EXPECT_LT(judged.max_gray_error, 1e-5);
}

TEST(TextureExtraction, ViewNormalsOfAnotherMeshAreRefused) {
  const TriMesh plate = MakeGrid(8, 8, kSizeMm, kSizeMm);
  const MatX3d wrong = MatX3d::Zero(5, 3);
  EXPECT_THROW(Extract(plate, &wrong), Error);
}

}  // namespace
}  // namespace crease
