// Studio renderer (synth/renderer.h, lights.h, brdf.h, sensor.h): analytic and
// golden images, shadow geometry, BRDF energy, sensor statistics, determinism,
// environment sampling, relighting without rebuilding.
#include "synth/renderer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <opencv2/core.hpp>

#include "core/image_io.h"
#include "core/mesh_primitives.h"
#include "synth/brdf.h"
#include "synth/lights.h"
#include "synth/sensor.h"
#include "tests/test_util.h"

namespace crease {
namespace {

constexpr double kPi = std::numbers::pi;

SceneMaterials Uniform(const std::string& preset) {
  SceneMaterials m;
  m.face = MaterialPreset(preset);
  m.other = MaterialPreset(preset);
  return m;
}

// Appends mesh b to mesh a (UVs kept).
TriMesh Append(const TriMesh& a, const TriMesh& b) {
  TriMesh m;
  m.V.resize(a.V.rows() + b.V.rows(), 3);
  m.V << a.V, b.V;
  m.UV.resize(a.UV.rows() + b.UV.rows(), 2);
  m.UV << a.UV, b.UV;
  m.F.resize(a.F.rows() + b.F.rows(), 3);
  m.F << a.F, (b.F.array() + a.num_vertices()).matrix();
  return m;
}

LightRig HeadFrameRig(const Eigen::Vector3d& towards_light, double intensity) {
  LightRig rig;
  rig.name = "test";
  rig.attached_to_camera = false;
  DirectionalLight d;
  d.direction = towards_light;
  d.color = Eigen::Vector3d::Constant(intensity);
  rig.lights = {d};
  return rig;
}

Camera FrontCamera(int width, int height, double distance, double fov = 30.0) {
  return LookAtCamera(CameraIntrinsics::FromFov(fov, width, height), Eigen::Vector3d(0, 0, distance),
                      Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
}

// Analytic image of an ideal grey (ρ = 0.5) Lambertian sphere of radius R at the
// origin under a head-frame directional light; NaN where the ray misses or grazes
// (within `margin_px` pixels of the silhouette).
cv::Mat AnalyticLambert(const Camera& cam, double radius, const Eigen::Vector3d& l, double margin_px) {
  const int w = cam.intrinsics.width, h = cam.intrinsics.height;
  cv::Mat img(h, w, CV_32FC1);
  const Eigen::Vector3d eye = cam.CentreInHead();
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d d = cam.PixelRayInHead(x, y);
      const double b = eye.dot(d), c = eye.squaredNorm() - radius * radius;
      const double disc = b * b - c;
      // Distance of the ray from the centre vs the radius, in pixels at the sphere.
      const double miss = std::sqrt(std::max(0.0, eye.squaredNorm() - b * b)) - radius;
      const double px_size = eye.norm() / cam.intrinsics.fx;
      if (disc <= 0 || std::abs(miss) < margin_px * px_size) {
        img.at<float>(y, x) = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      const Eigen::Vector3d p = eye + (-b - std::sqrt(disc)) * d;
      img.at<float>(y, x) = static_cast<float>(0.5 * std::max(0.0, p.normalized().dot(l.normalized())));
    }
  }
  return img;
}

TEST(Renderer, LambertSphereMatchesAnalyticImage) {
  const double radius = 50.0;
  Renderer renderer(MakeUVSphere(radius, 96, 192), Uniform("grey"));
  const Camera cam = FrontCamera(160, 120, 300.0);
  const Eigen::Vector3d l = Eigen::Vector3d(1.0, 1.0, 2.0).normalized();
  Rng rng(1);
  const RenderResult r = renderer.Render(cam, HeadFrameRig(l, 1.0), RenderOptions{}, rng);
  const cv::Mat expected = AnalyticLambert(cam, radius, l, 1.5);
  double sum = 0.0;
  int n = 0, far = 0;
  for (int y = 0; y < 120; ++y) {
    for (int x = 0; x < 160; ++x) {
      const float e = expected.at<float>(y, x);
      if (std::isnan(e)) continue;
      const float got = r.image.at<cv::Vec3f>(y, x)[1];
      if (e == 0.0f || e > 0.02f) {  // skip the terminator band (faceted shadow line)
        sum += std::abs(got - e);
        ++n;
        if (std::abs(got - e) > 0.01) ++far;
      }
    }
  }
  ASSERT_GT(n, 5000);
  EXPECT_LT(sum / n, 2e-3);
  EXPECT_LT(static_cast<double>(far) / n, 0.01);
  // Background stays black; grey is grey.
  EXPECT_EQ(r.image.at<cv::Vec3f>(2, 2), cv::Vec3f(0, 0, 0));
  const cv::Vec3f c = r.image.at<cv::Vec3f>(60, 80);
  EXPECT_FLOAT_EQ(c[0], c[1]);
  EXPECT_FLOAT_EQ(c[1], c[2]);
}

// Regression against a committed golden PNG (8-bit sRGB) of a shaded, shadowed
// scene with specular skin, soft and hard lights; regenerate with
// CREASE_UPDATE_GOLDEN=1 after an intended change, and look at it.
TEST(Renderer, StudioGoldenImage) {
  TriMesh sphere = MakeUVSphere(30.0, 48, 96);
  TriMesh plane = MakeGrid(8, 8, 160.0, 160.0);
  for (int i = 0; i < plane.num_vertices(); ++i) {
    plane.V.row(i) = Eigen::RowVector3d(plane.V(i, 0) - 80.0, -31.0, plane.V(i, 1) - 80.0);
    plane.UV.row(i) = Eigen::RowVector2d(2.0, 2.0);  // outside the chart: `other`
  }
  SceneMaterials mats;
  mats.face = MaterialPreset("skin");
  mats.other = MaterialPreset("grey");
  Renderer renderer(Append(sphere, plane), mats);
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(40.0, 96, 72), Eigen::Vector3d(0, 60, 200),
                                  Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  RenderOptions options;
  options.samples_per_axis = 2;
  Rng rng(7);
  const RenderResult r = renderer.Render(cam, MakeLightRig("studio"), options, rng);
  const cv::Mat got = EncodeSrgb8(r.image);
  const std::filesystem::path golden = std::filesystem::path(CREASE_TEST_DIR) / "data/golden/studio_sphere.png";
  if (std::getenv("CREASE_UPDATE_GOLDEN") != nullptr) {
    std::filesystem::create_directories(golden.parent_path());
    WriteImage(golden, got, ImageWriteOptions{.srgb = false});
  }
  ASSERT_TRUE(std::filesystem::exists(golden)) << golden;
  cv::Mat expected_f = ReadImage(golden, /*srgb=*/false);  // value·255 as float
  ASSERT_EQ(expected_f.rows, got.rows);
  ASSERT_EQ(expected_f.cols, got.cols);
  ASSERT_EQ(expected_f.channels(), 3);
  cv::Mat got_f;
  got.convertTo(got_f, CV_32F, 1.0 / 255.0);
  const cv::Mat diff = cv::abs(got_f - expected_f) * 255.0;
  const double mean_diff = cv::mean(diff.reshape(1))[0];
  const double big = cv::countNonZero(diff.reshape(1) > 6.0) / static_cast<double>(diff.total() * 3);
  EXPECT_LT(mean_diff, 1.0) << "mean |difference| in 8-bit levels";
  EXPECT_LT(big, 0.01) << "fraction of values more than 6 levels off";
}

// A sphere of radius R at height H above the plane z = 0 under a directional light
// casts an elliptical shadow: centre c − (H / l_z)·l_xy, semi-axes R / l_z (along
// l_xy) and R, area π R² / l_z.
void CheckShadow(const Eigen::Vector3d& towards_light) {
  const double R = 20.0, H = 80.0;
  TriMesh sphere = MakeUVSphere(R, 64, 128);
  for (int i = 0; i < sphere.num_vertices(); ++i) sphere.V(i, 2) += H;
  TriMesh plane = MakeGrid(64, 64, 240.0, 240.0);
  plane.V.col(0).array() -= 120.0;
  plane.V.col(1).array() -= 120.0;
  const int sphere_triangles = sphere.num_faces();
  Renderer renderer(Append(sphere, plane), Uniform("grey"));
  // Seen obliquely from the side, so that the view under the sphere is free.
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(50.0, 200, 200), Eigen::Vector3d(0, -300, 150),
                                  Eigen::Vector3d(0, -20, 0), Eigen::Vector3d::UnitZ());
  RenderOptions options;
  options.passes = true;
  Rng rng(3);
  const Eigen::Vector3d l = towards_light.normalized();
  const RenderResult r = renderer.Render(cam, HeadFrameRig(l, 1.0), options, rng);
  const Eigen::Vector2d centre(-H / l.z() * l.x(), -H / l.z() * l.y());
  const Eigen::Vector2d axis = Eigen::Vector2d(l.x(), l.y()).norm() > 0 ? Eigen::Vector2d(l.x(), l.y()).normalized()
                                                                       : Eigen::Vector2d::UnitX();
  const double a = R / l.z(), b = R;
  const Eigen::Vector3d eye = cam.CentreInHead();
  double shadow_area = 0.0, pixel_plane_area = 0.0;
  Eigen::Vector2d shadow_sum = Eigen::Vector2d::Zero();
  int wrong = 0, tested = 0;
  for (int y = 0; y < 200; ++y) {
    for (int x = 0; x < 200; ++x) {
      const int tri = r.triangle_id.at<int>(y, x);
      if (tri < sphere_triangles) continue;  // background or sphere
      const Eigen::Vector3d d = cam.PixelRayInHead(x, y);
      const Eigen::Vector3d p = eye + (-eye.z() / d.z()) * d;  // on z = 0
      const Eigen::Vector2d q = p.head<2>() - centre;
      const double u = q.dot(axis) / a, v = (q.x() * -axis.y() + q.y() * axis.x()) / b;
      const double rho = std::sqrt(u * u + v * v);  // 1 on the predicted shadow boundary
      // Area of this pixel on the plane: depth² cos(off-axis angle) / (fx fy cos(incidence)).
      const double depth = r.depth.at<float>(y, x);
      const double cos_axis = (cam.cam_from_head.rotation * d).z();
      const double area = depth * depth * cos_axis / (cam.intrinsics.fx * cam.intrinsics.fy * std::abs(d.z()));
      pixel_plane_area = area;
      const bool dark = r.image.at<cv::Vec3f>(y, x)[0] < 0.25f * static_cast<float>(0.5 * l.z());
      if (dark) {
        shadow_area += area;
        shadow_sum += area * p.head<2>();
      }
      if (rho < 0.93 || rho > 1.07) {
        ++tested;
        if (dark != (rho < 1.0)) ++wrong;
      }
    }
  }
  EXPECT_GT(tested, 10000);
  EXPECT_EQ(wrong, 0);
  const double predicted = kPi * a * b;
  EXPECT_NEAR(shadow_area / predicted, 1.0, 0.03) << "area " << shadow_area << " vs " << predicted;
  EXPECT_NEAR((shadow_sum / shadow_area - centre).norm(), 0.0, 0.5) << "pixel ≈ " << std::sqrt(pixel_plane_area) << " mm";
}

TEST(Renderer, HardShadowFromAbove) { CheckShadow(Eigen::Vector3d(0, 0, 1)); }
TEST(Renderer, HardShadowOblique) { CheckShadow(Eigen::Vector3d(1, 0.3, 1.5)); }

// ∫ f(l, v) cos θ_l dω_l over the hemisphere by the midpoint rule in (cos θ_l, φ).
double IntegrateUniform(const PreparedBrdf& brdf, int n, bool specular_only) {
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double mu = (i + 0.5) / n, s = std::sqrt(1.0 - mu * mu);
    for (int j = 0; j < 2 * n; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / (2 * n);
      const Eigen::Vector3f l(static_cast<float>(s * std::cos(phi)), static_cast<float>(s * std::sin(phi)),
                              static_cast<float>(mu));
      const double f = specular_only ? brdf.Specular(l) : brdf.Eval(l)[1];
      sum += f * mu;
    }
  }
  return sum * (1.0 / n) * (2.0 * kPi / (2 * n));
}

// ∫ f_s cos θ_l dω_l by the midpoint rule in the GGX-distributed half-vector
// coordinates (exact change of variables dω_l = 4 (v·h) dω_h, density D cos θ_h).
double IntegrateSpecular(const PreparedBrdf& brdf, const Eigen::Vector3f& v, float alpha, int n) {
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double xi1 = (i + 0.5) / n;
    const double a2 = static_cast<double>(alpha) * alpha;
    const double cos2 = (1.0 - xi1) / (1.0 + (a2 - 1.0) * xi1);
    const double ch = std::sqrt(cos2), sh = std::sqrt(std::max(0.0, 1.0 - cos2));
    for (int j = 0; j < n; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / n;
      const Eigen::Vector3f h(static_cast<float>(sh * std::cos(phi)), static_cast<float>(sh * std::sin(phi)),
                              static_cast<float>(ch));
      const float vh = v.dot(h);
      if (vh <= 0.0f) continue;
      const Eigen::Vector3f l = 2.0f * vh * h - v;
      if (l.z() <= 0.0f) continue;
      const double pdf_h = GgxD(static_cast<float>(ch), alpha) * ch;
      sum += brdf.Specular(l.normalized()) * l.z() * 4.0 * vh / pdf_h;
    }
  }
  return sum / (static_cast<double>(n) * n);
}

TEST(Brdf, WhiteFurnaceLambertIsOne) {
  const Material white = MaterialPreset("white-lambert");
  for (double theta_deg : {0.0, 30.0, 60.0, 85.0}) {
    const double t = theta_deg * kPi / 180.0;
    const Eigen::Vector3f v(static_cast<float>(std::sin(t)), 0.0f, static_cast<float>(std::cos(t)));
    const PreparedBrdf brdf(white, Eigen::Vector3f::UnitZ(), v);
    EXPECT_NEAR(IntegrateUniform(brdf, 200, false), 1.0, 1e-3) << theta_deg;
  }
}

TEST(Brdf, WhiteFurnaceSpecularAndSkinAtMostOne) {
  for (float roughness : {0.1f, 0.25f, 0.45f, 0.7f, 1.0f}) {
    for (double theta_deg : {0.0, 40.0, 70.0, 85.0}) {
      const double t = theta_deg * kPi / 180.0;
      const Eigen::Vector3f v(static_cast<float>(std::sin(t)), 0.0f, static_cast<float>(std::cos(t)));
      const float alpha = roughness * roughness;
      // Specular lobe alone, worst case F0 = 1 (a perfect mirror's Fresnel).
      Material mirror = MaterialPreset("white-lambert");
      mirror.albedo.setZero();
      mirror.specular = 1.0f;
      mirror.roughness = roughness;
      mirror.f0 = 1.0f;
      const double es = IntegrateSpecular(PreparedBrdf(mirror, Eigen::Vector3f::UnitZ(), v), v, alpha, 256);
      EXPECT_LE(es, 1.0 + 1e-3) << "roughness " << roughness << " view " << theta_deg;
      EXPECT_NEAR(es, SpecularAlbedo(v.z(), roughness, 1.0f), 0.02);  // table interpolation
      // White skin (ρ_d = 1, ρ_s = 1): diffuse + specular = 1 (energy-conserving
      // coupling), within the table's interpolation error.
      Material skin = MaterialPreset("skin");
      skin.albedo.setOnes();
      skin.specular = 1.0f;
      skin.roughness = roughness;
      const PreparedBrdf b(skin, Eigen::Vector3f::UnitZ(), v);
      const double total = b.albedo()[1] * b.diffuse_weight() * kPi + IntegrateSpecular(b, v, alpha, 256);
      EXPECT_LE(total, 1.0 + 5e-3) << "roughness " << roughness << " view " << theta_deg;
      EXPECT_GE(total, 0.98) << "roughness " << roughness << " view " << theta_deg;
      // Independent check with the plain hemisphere rule where the lobe is wide.
      if (roughness >= 0.45f) {
        EXPECT_NEAR(IntegrateUniform(b, 200, false), total, 5e-3) << "roughness " << roughness << " view " << theta_deg;
      }
    }
  }
}

TEST(Sensor, PoissonGaussianNoiseHasStatedMeanAndVariance) {
  SensorOptions options;
  options.full_well_electrons = 1000.0;
  options.read_noise_electrons = 5.0;
  options.exposure = 0.5;
  const float x = 0.5f;  // exposed value 0.25
  const cv::Mat img(200, 200, CV_32FC3, cv::Scalar::all(x));
  Rng rng(11);
  const SensorImage out = ApplySensor(img, options, rng);
  cv::Scalar mean, stddev;
  cv::meanStdDev(out.linear.reshape(1), mean, stddev);
  const double m = 0.25, var = m / 1000.0 + std::pow(5.0 / 1000.0, 2);
  const double n = 200.0 * 200.0 * 3.0;
  EXPECT_NEAR(mean[0], m, 4.0 * std::sqrt(var / n));
  EXPECT_NEAR(stddev[0] * stddev[0] / var, 1.0, 0.03);
  // 8-bit sRGB of the noisy image decodes close to it (quantisation only).
  EXPECT_LT(cv::norm(out.decoded, out.linear, cv::NORM_INF), 0.01);
  // Without noise: exposure and clipping only.
  options.noise = false;
  options.exposure = 3.0;
  const SensorImage clean = ApplySensor(img, options, rng);
  EXPECT_FLOAT_EQ(clean.linear.at<cv::Vec3f>(5, 5)[0], 1.0f);
}

TEST(Sensor, PoissonSampler) {
  for (double lambda : {0.7, 4.0, 30.0, 2500.0}) {
    Rng rng(5);
    const int n = 40000;
    double s = 0.0, s2 = 0.0;
    for (int i = 0; i < n; ++i) {
      const double k = static_cast<double>(SamplePoisson(lambda, rng));
      s += k;
      s2 += k * k;
    }
    const double mean = s / n, var = s2 / n - mean * mean;
    EXPECT_NEAR(mean, lambda, 4.0 * std::sqrt(lambda / n)) << lambda;
    EXPECT_NEAR(var / lambda, 1.0, 0.05) << lambda;
  }
}

TEST(Sensor, SrgbQuantisationAndJpeg) {
  cv::Mat img(8, 8, CV_32FC3, cv::Scalar(0.0, 0.5, 1.0));
  const cv::Mat s = EncodeSrgb8(img);
  EXPECT_EQ(s.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 188, 255));
  const cv::Mat d = DecodeSrgb8(s);
  EXPECT_NEAR(d.at<cv::Vec3f>(3, 3)[1], 0.5f, 0.003f);
  cv::Mat ramp(64, 64, CV_8UC3);
  for (int y = 0; y < 64; ++y) {
    for (int x = 0; x < 64; ++x) ramp.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uint8_t>(4 * x), static_cast<uint8_t>(4 * y), 90);
  }
  const cv::Mat j = JpegRoundTrip(ramp, 80);
  ASSERT_EQ(j.type(), CV_8UC3);
  EXPECT_LT(cv::norm(j, ramp, cv::NORM_L1) / (64.0 * 64.0 * 3.0), 3.0);  // close, and channels not swapped
  EXPECT_ERROR_HAS(JpegRoundTrip(ramp, 0), "quality");
}

RenderResult RenderStudio(Rng& rng) {
  TriMesh sphere = MakeIcosphere(40.0, 3);
  Renderer renderer(sphere, Uniform("skin"));
  LightRig rig = MakeLightRig("studio");
  EnvironmentLight env;
  env.map = ProceduralEnvironment("window", 64);
  env.samples = 4;
  env.scale = 0.3;
  rig.lights.push_back(env);
  RenderOptions options;
  options.samples_per_axis = 2;
  options.subsurface_mm = 1.0;
  options.environment_background = true;
  return renderer.Render(FrontCamera(64, 48, 250.0), rig, options, rng);
}

bool SameBytes(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() &&
         std::equal(a.datastart, a.dataend, b.datastart, b.dataend);
}

TEST(Renderer, DeterministicForSeedAndThreadCount) {
  Rng a(99), b(99), c(100);
  const RenderResult ra = RenderStudio(a);
  RenderResult rb;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    rb = RenderStudio(b);
  }
  EXPECT_TRUE(SameBytes(ra.image, rb.image));
  EXPECT_TRUE(SameBytes(ra.alpha, rb.alpha));
  const RenderResult rc = RenderStudio(c);
  EXPECT_FALSE(SameBytes(ra.image, rc.image));  // noise differs with the seed
  EXPECT_GT(ra.stats.shadow_rays, ra.stats.primary_rays);
  // The sensor too.
  SensorOptions so;
  so.jpeg_quality = 90;
  Rng s1(5), s2(5);
  const SensorImage i1 = ApplySensor(ra.image, so, s1);
  SensorImage i2;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    i2 = ApplySensor(ra.image, so, s2);
  }
  EXPECT_TRUE(SameBytes(i1.srgb8, i2.srgb8));
}

TEST(Renderer, EnvironmentSamplingConvergesForConstantEnvironment) {
  // Constant radiance L: an unoccluded white Lambertian surface renders at L.
  const float L = 0.7f;
  auto map = std::make_shared<const EnvironmentMap>(cv::Mat(16, 32, CV_32FC3, cv::Scalar::all(L)), "constant");
  // The sampling density integrates to one: E[1/pdf] = 4π.
  Rng rng(2);
  double inv = 0.0;
  for (int i = 0; i < 20000; ++i) {
    float pdf = 0.0f;
    const double v = rng.Uniform();  // one draw per statement
    const Eigen::Vector3f d = map->Sample(rng.Uniform(), v, &pdf);
    ASSERT_NEAR(d.norm(), 1.0f, 1e-5f);
    ASSERT_NEAR(pdf, map->Pdf(d), 1e-2f * pdf);
    inv += 1.0 / pdf;
  }
  EXPECT_NEAR(inv / 20000.0 / (4.0 * kPi), 1.0, 0.02);
  EXPECT_NEAR(map->LambertValue(Eigen::Vector3d::UnitX()).y(), L, 1e-3);

  Renderer renderer(MakeUVSphere(40.0, 48, 96), Uniform("white-lambert"));
  LightRig rig;
  rig.name = "constant";
  EnvironmentLight env;
  env.map = map;
  // With a constant map, luminance sampling alone is uniform on the sphere: one
  // sample estimates 4 L cos θ on the upper hemisphere (0 below), σ = L·sqrt(16/6 − 1);
  // MIS with cosine-weighted samples may only do better.
  const double sigma = L * std::sqrt(16.0 / 6.0 - 1.0);
  for (int samples : {4, 64, 256}) {
    env.samples = samples;
    rig.lights = {env};
    Rng r(8);
    const RenderResult img = renderer.Render(FrontCamera(64, 48, 250.0), rig, RenderOptions{}, r);
    double sum = 0.0, sq = 0.0;
    int n = 0;
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        if (img.alpha.at<float>(y, x) < 1.0f) continue;
        const double v = img.image.at<cv::Vec3f>(y, x)[1];
        sum += v;
        sq += (v - L) * (v - L);
        ++n;
      }
    }
    ASSERT_GT(n, 500);
    const double predicted_rms = sigma / std::sqrt(samples);
    EXPECT_NEAR(sum / n, L, 3.0 * predicted_rms / std::sqrt(n) + 0.005) << samples << " samples";
    EXPECT_LT(std::sqrt(sq / n), 1.1 * predicted_rms) << samples << " samples";
  }
}

TEST(Renderer, EnvironmentMapFromExr) {
  // A dim map with one bright pixel, through an EXR file (core/image_io).
  cv::Mat img(32, 64, CV_32FC3, cv::Scalar::all(0.01f));
  img.at<cv::Vec3f>(10, 40) = cv::Vec3f(500.0f, 400.0f, 300.0f);
  const std::filesystem::path path = testing::TestDir() / "env.exr";
  WriteImage(path, img);
  const EnvironmentMap map(ReadImage(path), path.string());
  ASSERT_EQ(map.width(), 64);
  Rng rng(3);
  int bright = 0;
  for (int i = 0; i < 1000; ++i) {
    float pdf = 0.0f;
    const double v = rng.Uniform();  // one draw per statement
    const Eigen::Vector3f d = map.Sample(rng.Uniform(), v, &pdf);
    const Eigen::Vector3f r = map.Radiance(d);
    if (r.x() > 100.0f) ++bright;
  }
  EXPECT_GT(bright, 900);
  EXPECT_ERROR_HAS(EnvironmentMap(cv::Mat(8, 16, CV_32FC3, cv::Scalar::all(0.0f)), "black.exr"), "black.exr");
}

// A plane z = 0 seen from above under one head-frame light (grey, ρ = 0.5);
// its triangles come first.
constexpr int kPlaneTriangles = 32 * 32 * 2;
RenderResult RenderPlane(const LightRig& rig, const TriMesh& extra = TriMesh()) {
  TriMesh plane = MakeGrid(32, 32, 400.0, 400.0);
  plane.V.col(0).array() -= 200.0;
  plane.V.col(1).array() -= 200.0;
  const TriMesh mesh = extra.num_faces() > 0 ? Append(plane, extra) : plane;
  Renderer renderer(mesh, Uniform("grey"));
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(60.0, 64, 64), Eigen::Vector3d(0, 0, 300),
                                  Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  Rng rng(12);
  RenderOptions options;
  options.passes = true;
  return renderer.Render(cam, rig, options, rng);
}

TEST(Renderer, SphereLightIrradianceAndSoftShadow) {
  LightRig rig;
  rig.name = "sphere";
  rig.attached_to_camera = false;
  SphereLight s;
  s.centre = Eigen::Vector3d(0, 0, 800);
  s.radius = 150.0;
  s.color = Eigen::Vector3d::Ones();
  s.samples = 64;
  rig.lights = {s};
  // Unoccluded: the centre of the plane (the rig origin) renders at ρ·color.
  const RenderResult open = RenderPlane(rig);
  EXPECT_NEAR(open.image.at<cv::Vec3f>(32, 32)[1], 0.5f, 0.01f);
  // A small occluder 100 mm above the plane: umbra in the middle, penumbra around.
  TriMesh ball = MakeUVSphere(20.0, 24, 48);
  ball.V.col(2).array() += 100.0;
  ball.UV.setConstant(0.5);
  const RenderResult shadowed = RenderPlane(rig, ball);
  // Seen from above, the ball hides the umbra; around it lies a penumbra ring:
  // plane pixels that are neither dark nor fully lit.
  int penumbra = 0;
  double lit_min = 1.0, lit_max = 0.0;
  for (int y = 0; y < 64; ++y) {
    for (int x = 0; x < 64; ++x) {
      if (shadowed.triangle_id.at<int>(y, x) >= kPlaneTriangles || shadowed.triangle_id.at<int>(y, x) < 0) continue;
      const float v = shadowed.image.at<cv::Vec3f>(y, x)[1];
      if (v > 0.05f && v < 0.45f) ++penumbra;
      lit_min = std::min(lit_min, static_cast<double>(v));
      lit_max = std::max(lit_max, static_cast<double>(v));
    }
  }
  EXPECT_GT(penumbra, 20);
  EXPECT_LT(lit_min, 0.45);  // something is shadowed
  EXPECT_NEAR(lit_max, 0.5, 0.02);
}

TEST(Renderer, AmbientOcclusionDarkensContact) {
  LightRig rig;
  rig.name = "ao";
  rig.attached_to_camera = false;
  AmbientOcclusionLight ao;
  ao.color = Eigen::Vector3d::Ones();
  ao.samples = 16;
  ao.max_distance_mm = 100.0;
  rig.lights = {ao};
  // An open plane is unoccluded: exactly ρ·color.
  const RenderResult open = RenderPlane(rig);
  EXPECT_NEAR(open.image.at<cv::Vec3f>(5, 5)[1], 0.5f, 1e-4f);
  // A wall standing on the plane occludes half the hemisphere at its foot.
  TriMesh wall = MakeGrid(4, 4, 400.0, 200.0);
  for (int i = 0; i < wall.num_vertices(); ++i) {
    wall.V.row(i) = Eigen::RowVector3d(wall.V(i, 0) - 200.0, 40.0, wall.V(i, 1));
  }
  const RenderResult near_wall = RenderPlane(rig, wall);
  // Plane pixels just in front of the wall (y slightly below 40 mm) are darker.
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(60.0, 64, 64), Eigen::Vector3d(0, 0, 300),
                                  Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  const Eigen::Vector2d foot = cam.Project(Eigen::Vector3d(0, 30, 0));
  const Eigen::Vector2d far = cam.Project(Eigen::Vector3d(0, -150, 0));
  const float v_foot = near_wall.image.at<cv::Vec3f>(static_cast<int>(std::lround(foot.y())),
                                                     static_cast<int>(std::lround(foot.x())))[1];
  const float v_far = near_wall.image.at<cv::Vec3f>(static_cast<int>(std::lround(far.y())),
                                                    static_cast<int>(std::lround(far.x())))[1];
  EXPECT_LT(v_foot, 0.38f);
  EXPECT_GT(v_far, 0.45f);
}

TEST(Renderer, SubsurfaceBlurSoftensShadowEdgesRedMost) {
  // A hard shadow edge on a plane: a half-plane occluder 50 mm above z = 0.
  TriMesh plane = MakeGrid(16, 16, 400.0, 400.0);
  plane.V.col(0).array() -= 200.0;
  plane.V.col(1).array() -= 200.0;
  TriMesh blocker = MakeGrid(4, 4, 200.0, 400.0);
  blocker.V.col(0).array() -= 200.0;  // x in [−200, 0]
  blocker.V.col(1).array() -= 200.0;
  blocker.V.col(2).array() += 50.0;
  // The camera sits below the blocker, on the lit side, looking down at the shadow's
  // edge (x = 0 on the plane); image rows cross the edge.
  Renderer renderer(Append(plane, blocker), Uniform("white-lambert"));
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(20.0, 96, 64), Eigen::Vector3d(60, 0, 40),
                                  Eigen::Vector3d(10, 0, 0), Eigen::Vector3d::UnitY());
  const LightRig rig = HeadFrameRig(Eigen::Vector3d(0, 0, 1), 1.0);
  RenderOptions sharp;
  RenderOptions soft;
  soft.subsurface_mm = 2.0;
  Rng r1(1), r2(1);
  const RenderResult a = renderer.Render(cam, rig, sharp, r1);
  const RenderResult b = renderer.Render(cam, rig, soft, r2);
  // Count pixels of the middle row in transition (neither lit 1 nor dark 0), per channel.
  auto transition = [](const cv::Mat& img, int c) {
    int n = 0;
    for (int x = 0; x < img.cols; ++x) {
      const float v = img.at<cv::Vec3f>(img.rows / 2, x)[c];
      if (v > 0.05f && v < 0.95f) ++n;
    }
    return n;
  };
  EXPECT_LE(transition(a.image, 0), 2);
  EXPECT_GT(transition(b.image, 0), transition(b.image, 2));  // red scatters furthest
  EXPECT_GE(transition(b.image, 2), transition(a.image, 2));
  // Far from the edge the blur changes nothing (flat, uniformly lit skin).
  const int lit_x = 90;
  ASSERT_GT(a.image.at<cv::Vec3f>(32, lit_x)[0], 0.9f);
  EXPECT_NEAR(b.image.at<cv::Vec3f>(32, lit_x)[0], a.image.at<cv::Vec3f>(32, lit_x)[0], 1e-3f);
}

TEST(Renderer, RelightsAndRefitsWithoutRebuilding) {
  const TriMesh sphere = MakeUVSphere(40.0, 48, 96);
  Renderer renderer(sphere, Uniform("skin"));
  const Camera cam = FrontCamera(80, 60, 250.0);
  RenderOptions options;
  options.passes = true;
  Rng r1(4), r2(4), r3(4);
  const RenderResult front = renderer.Render(cam, MakeLightRig("front"), options, r1);
  const RenderResult raking = renderer.Render(cam, MakeLightRig("raking-above"), options, r2);
  EXPECT_GT(cv::norm(front.image, raking.image, cv::NORM_L1) / (80.0 * 60.0), 0.05);
  EXPECT_TRUE(SameBytes(front.depth, raking.depth));  // same geometry
  // Raking light from above: the top of the sphere is brighter than the bottom.
  EXPECT_GT(raking.image.at<cv::Vec3f>(18, 40)[0], 2.0f * raking.image.at<cv::Vec3f>(42, 40)[0]);
  // New geometry (refit), then the first geometry again: the same image as before.
  MatX3d bigger = 1.25 * sphere.V;
  renderer.UpdateGeometry(bigger);
  Rng r4(4);
  const RenderResult big = renderer.Render(cam, MakeLightRig("front"), options, r4);
  EXPECT_GT(cv::sum(big.alpha)[0], 1.4 * cv::sum(front.alpha)[0]);
  renderer.UpdateGeometry(sphere.V, sphere.N);
  const RenderResult again = renderer.Render(cam, MakeLightRig("front"), options, r3);
  EXPECT_TRUE(SameBytes(front.image, again.image));
  // Passes: depth at the centre is the distance to the front of the sphere, the
  // normal faces the camera.
  EXPECT_NEAR(front.depth.at<float>(30, 40), 250.0 - 40.0, 0.2);
  const cv::Vec3f n = front.normal.at<cv::Vec3f>(30, 40);
  EXPECT_NEAR(n[2], -1.0f, 0.01f);
  EXPECT_GE(front.triangle_id.at<int>(30, 40), 0);
  EXPECT_EQ(front.triangle_id.at<int>(0, 0), -1);
}

TEST(Renderer, PartMaterialsAndMaps) {
  TriMesh sphere = MakeUVSphere(40.0, 32, 64);
  SceneMaterials m;
  m.part_materials = {MaterialPreset("skin"), MaterialPreset("hair")};
  m.vertex_part.assign(static_cast<size_t>(sphere.num_vertices()), 0);
  for (int i = 0; i < sphere.num_vertices(); ++i) {
    if (sphere.V(i, 0) > 0) m.vertex_part[static_cast<size_t>(i)] = 1;  // +x half is "hair"
  }
  m.albedo = cv::Mat(16, 16, CV_32FC3, cv::Scalar(0.1f, 0.9f, 0.1f));  // green skin map
  Renderer renderer(sphere, m);
  const Camera cam = FrontCamera(80, 60, 250.0);
  RenderOptions options;
  options.passes = true;
  Rng rng(1);
  const RenderResult r = renderer.Render(cam, HeadFrameRig(Eigen::Vector3d::UnitZ(), 1.0), options, rng);
  // The camera looks along −z with y up, so head +x appears on the right... or left:
  // find it from the part pass.
  int skin_green = 0, hair_dark = 0, checked = 0;
  for (int y = 20; y < 40; ++y) {
    for (int x = 20; x < 60; ++x) {
      const int part = r.part_id.at<int>(y, x);
      if (part < 0) continue;
      const cv::Vec3f c = r.image.at<cv::Vec3f>(y, x);
      ++checked;
      if (part == 0 && c[1] > 3.0f * c[0]) ++skin_green;
      if (part == 1 && c[1] < 0.1f) ++hair_dark;
    }
  }
  EXPECT_GT(checked, 400);
  EXPECT_EQ(skin_green + hair_dark, checked);
  // Bad materials are rejected by name.
  m.vertex_part.pop_back();
  EXPECT_ERROR_HAS(Renderer(sphere, m), "vertex_part");
  SceneMaterials bad;
  bad.albedo = cv::Mat(4, 4, CV_32FC1, cv::Scalar(0.5));
  EXPECT_ERROR_HAS(Renderer(sphere, bad), "albedo");
}

TEST(Renderer, OptionsAndRigsAreChecked) {
  RenderOptions o;
  o.samples_per_axis = 0;
  EXPECT_ERROR_HAS(o.Check(), "samples_per_axis");
  o = RenderOptions{};
  o.tile_size = 18;
  EXPECT_ERROR_HAS(o.Check(), "tile_size");
  EXPECT_ERROR_HAS(MakeLightRig("disco"), "raking-above");
  EXPECT_ERROR_HAS(ProceduralEnvironment("beach"), "overcast");
  LightRig rig = MakeLightRig("front");
  std::get<DirectionalLight>(rig.lights[0]).direction.setZero();
  EXPECT_ERROR_HAS(ValidateLightRig(rig), "direction");
  SensorOptions s;
  s.full_well_electrons = 0.0;
  EXPECT_ERROR_HAS(s.Check(), "full_well_electrons");
  for (const auto& name : LightRigNames()) EXPECT_NO_THROW(ValidateLightRig(MakeLightRig(name))) << name;
  // Azimuth/elevation convention: (0, 0) faces the camera, elevation goes up.
  EXPECT_TRUE(RigDirection(0, 0).isApprox(Eigen::Vector3d(0, 0, -1)));
  EXPECT_TRUE(RigDirection(0, 90).isApprox(Eigen::Vector3d(0, -1, 0)));
  EXPECT_TRUE(RigDirection(90, 0).isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_TRUE(RigDirection(0, 90, false).isApprox(Eigen::Vector3d(0, 1, 0)));
  const LightRig moving = DirectionalRig(0.0, 45.0, 0.8);
  EXPECT_TRUE(std::get<DirectionalLight>(moving.lights[0]).direction.isApprox(RigDirection(0.0, 45.0)));
  EXPECT_NO_THROW(ValidateLightRig(moving));
}

TEST(Renderer, MotionBlurAveragesSubframes) {
  const TriMesh sphere = MakeUVSphere(20.0, 32, 64);
  Renderer renderer(sphere, Uniform("grey"));
  MotionBlurFrame open{sphere.V, FrontCamera(80, 60, 250.0)};
  MotionBlurFrame close = open;
  close.V.col(0).array() += 30.0;  // moves 30 mm along x during the shutter
  Rng rng(6);
  const LightRig rig = HeadFrameRig(Eigen::Vector3d::UnitZ(), 1.0);
  const RenderResult blurred = RenderMotionBlurred(renderer, open, close, 8, rig, RenderOptions{}, rng);
  // Partial coverage along the motion, total coverage ≈ a still sphere's.
  int partial = 0;
  for (int x = 0; x < 80; ++x) {
    const float a = blurred.alpha.at<float>(30, x);
    if (a > 0.05f && a < 0.95f) ++partial;
  }
  EXPECT_GT(partial, 8);
  Rng still_rng(6);
  renderer.UpdateGeometry(sphere.V);
  const RenderResult still = renderer.Render(open.camera, rig, RenderOptions{}, still_rng);
  EXPECT_NEAR(cv::sum(blurred.alpha)[0] / cv::sum(still.alpha)[0], 1.0, 0.03);
  EXPECT_ERROR_HAS(RenderMotionBlurred(renderer, open, close, 0, rig, RenderOptions{}, rng), "subframes");
}

}  // namespace
}  // namespace crease
