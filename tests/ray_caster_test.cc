#include "core/ray_caster.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"
#include <tbb/global_control.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/mesh_primitives.h"
#include "core/options.h"
#include "core/rng.h"

namespace crease {
namespace {

using testing::ErrorOf;
using testing::TestDir;
using testing::WriteText;

constexpr double kRadius = 10.0;  // mm

Eigen::Vector3f RandomUnit(Rng& rng) {
  Eigen::Vector3f d;
  do {
    d = Eigen::Vector3f(static_cast<float>(rng.Normal()), static_cast<float>(rng.Normal()),
                        static_cast<float>(rng.Normal()));
  } while (d.norm() < 1e-3f);
  return d.normalized();
}

// Chordal error of a tessellated sphere: every surface point lies at a distance
// in [R − tol, R] from the centre, where R − tol is the smallest distance of a
// triangle's plane from the centre (exact for a mesh inscribed in the sphere).
double ChordalTolerance(const TriMesh& m, double radius) {
  double min_plane = radius;
  for (int f = 0; f < m.num_faces(); ++f) {
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    min_plane = std::min(min_plane, std::abs(n.dot(a)));
  }
  return radius - min_plane;
}

class SphereTest : public ::testing::Test {
 protected:
  SphereTest() : sphere_(MakeIcosphere(kRadius, 5)), caster_(sphere_) {
    // Chordal error plus single-precision rounding of coordinates of ~10–30 mm.
    tol_ = static_cast<float>(ChordalTolerance(sphere_, kRadius)) + 1e-4f;
  }

  // Hit point from the barycentrics of the hit triangle.
  Eigen::Vector3f PointFromBarycentrics(int f, float u, float v) const {
    const Eigen::Vector3f a = sphere_.V.row(sphere_.F(f, 0)).cast<float>();
    const Eigen::Vector3f b = sphere_.V.row(sphere_.F(f, 1)).cast<float>();
    const Eigen::Vector3f c = sphere_.V.row(sphere_.F(f, 2)).cast<float>();
    return (1.0f - u - v) * a + u * b + v * c;
  }

  TriMesh sphere_;
  RayCaster caster_;
  float tol_ = 0.0f;
};

TEST_F(SphereTest, ToleranceIsTheTessellationsChordalError) {
  EXPECT_EQ(caster_.num_triangles(), 20480);
  EXPECT_GT(tol_, 1e-4f);
  EXPECT_LT(tol_, 0.01f);  // level 5 of a 10 mm sphere: a few µm
}

TEST_F(SphereTest, HitsFromOutsideAtTheRightDistance) {
  Rng rng(1);
  const float distance = 30.0f;
  for (int k = 0; k < 500; ++k) {
    const Eigen::Vector3f d = RandomUnit(rng);
    const Ray ray{distance * d, -d};
    const Hit h = caster_.Intersect(ray);
    ASSERT_TRUE(h.valid());
    EXPECT_GE(h.t, distance - kRadius - 1e-4f);
    EXPECT_LE(h.t, distance - kRadius + tol_);
    EXPECT_GT(h.geometric_normal.dot(d), 0.99f);  // outward, facing the ray's origin
    EXPECT_NEAR(h.geometric_normal.norm(), 1.0f, 1e-5f);
    const Eigen::Vector3f p = PointFromBarycentrics(h.triangle, h.u, h.v);
    EXPECT_LT((p - (ray.origin + h.t * ray.direction)).norm(), 1e-4f);
  }
}

TEST_F(SphereTest, HitsFromInsideAtTheRightDistance) {
  Rng rng(2);
  for (int k = 0; k < 500; ++k) {
    const Eigen::Vector3f d = RandomUnit(rng);
    const Hit h = caster_.Intersect(Ray{Eigen::Vector3f::Zero(), d});
    ASSERT_TRUE(h.valid());
    EXPECT_GE(h.t, kRadius - tol_);
    EXPECT_LE(h.t, kRadius + 1e-4f);
    EXPECT_GT(h.geometric_normal.dot(d), 0.99f);  // outward even when hit from inside
  }
}

TEST_F(SphereTest, RaySegmentLimitsAreHonoured) {
  const Eigen::Vector3f d(0.0f, 0.6f, 0.8f);
  EXPECT_FALSE(caster_.Intersect(Ray{30.0f * d, -d, 0.0f, 19.0f}).valid());   // stops short
  EXPECT_TRUE(caster_.Intersect(Ray{30.0f * d, -d, 0.0f, 21.0f}).valid());
  // tnear past the near side: the far side of the sphere is hit.
  const Hit far = caster_.Intersect(Ray{30.0f * d, -d, 25.0f});
  ASSERT_TRUE(far.valid());
  EXPECT_NEAR(far.t, 40.0f, tol_);
  EXPECT_FALSE(caster_.Intersect(Ray{30.0f * d, d}).valid());  // pointing away
}

TEST_F(SphereTest, SignedHitBothWays) {
  Rng rng(3);
  const float offset = 0.05f;  // mm, >> tol_
  for (int k = 0; k < 300; ++k) {
    const Eigen::Vector3f n = RandomUnit(rng);
    const Eigen::Vector3f on_sphere = static_cast<float>(kRadius) * n;

    // Origin just outside, direction = outward normal: the surface is behind.
    const SignedHit out = caster_.IntersectSigned(on_sphere + offset * n, n, 1.0f);
    ASSERT_TRUE(out.valid());
    EXPECT_LE(out.t, -offset + 1e-4f);
    EXPECT_GE(out.t, -offset - tol_);
    // Same origin, direction flipped: same hit, t negated.
    const SignedHit out_flipped = caster_.IntersectSigned(on_sphere + offset * n, -n, 1.0f);
    ASSERT_TRUE(out_flipped.valid());
    EXPECT_EQ(out_flipped.triangle, out.triangle);
    EXPECT_FLOAT_EQ(out_flipped.t, -out.t);

    // Origin just inside: the surface is ahead.
    const SignedHit in = caster_.IntersectSigned(on_sphere - offset * n, n, 1.0f);
    ASSERT_TRUE(in.valid());
    EXPECT_GE(in.t, offset - tol_);
    EXPECT_LE(in.t, offset + 1e-4f);
    EXPECT_GT(in.geometric_normal.dot(n), 0.99f);

    // Beyond max_distance on both sides: invalid.
    EXPECT_FALSE(caster_.IntersectSigned(on_sphere + offset * n, n, 0.5f * offset).valid());
  }
  // From the centre the near side in both directions is at ~R; + wins only on a tie.
  const SignedHit centre = caster_.IntersectSigned(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), 20.0f);
  ASSERT_TRUE(centre.valid());
  EXPECT_NEAR(std::abs(centre.t), kRadius, tol_);
  EXPECT_THROW(caster_.IntersectSigned(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), -1.0f), Error);
}

TEST_F(SphereTest, Occlusion) {
  const Eigen::Vector3f d = Eigen::Vector3f(1.0f, 2.0f, -2.0f).normalized();
  EXPECT_TRUE(caster_.Occluded(Ray{30.0f * d, -d}));
  EXPECT_FALSE(caster_.Occluded(Ray{30.0f * d, -d, 0.0f, 19.0f}));
  EXPECT_TRUE(caster_.Occluded(Ray{30.0f * d, -d, 0.0f, 20.5f}));
  EXPECT_FALSE(caster_.Occluded(Ray{30.0f * d, d}));
  EXPECT_TRUE(caster_.Occluded(Ray{Eigen::Vector3f::Zero(), d}));  // from inside
}

// Random rays: origins in a box around the sphere, random directions.
std::vector<Ray> RandomRays(int n, uint64_t seed) {
  Rng rng(seed);
  std::vector<Ray> rays(static_cast<size_t>(n));
  for (Ray& r : rays) {
    r.origin = Eigen::Vector3f(static_cast<float>(rng.Uniform(-15, 15)), static_cast<float>(rng.Uniform(-15, 15)),
                               static_cast<float>(rng.Uniform(-15, 15)));
    r.direction = RandomUnit(rng);
  }
  return rays;
}

// Primary rays of a small pinhole camera looking at the sphere (coherent).
std::vector<Ray> CameraRays(int width, int height) {
  std::vector<Ray> rays;
  const Eigen::Vector3f eye(0.0f, 0.0f, -40.0f);
  const float f = 1.2f * static_cast<float>(width);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector3f d((x - 0.5f * (width - 1)) / f, (y - 0.5f * (height - 1)) / f, 1.0f);
      rays.push_back(Ray{eye, d.normalized()});
    }
  }
  return rays;
}

bool SameHit(const Hit& a, const Hit& b) {
  return a.triangle == b.triangle && (a.t == b.t || (std::isinf(a.t) && std::isinf(b.t))) && a.u == b.u &&
         a.v == b.v && a.geometric_normal == b.geometric_normal;
}
bool SameHit(const SignedHit& a, const SignedHit& b) {
  return a.triangle == b.triangle && (a.t == b.t || (std::isinf(a.t) && std::isinf(b.t))) && a.u == b.u &&
         a.v == b.v && a.geometric_normal == b.geometric_normal;
}

TEST_F(SphereTest, BatchedEqualsSingle) {
  const std::vector<Ray> rays = RandomRays(5000, 4);
  std::vector<Hit> hits;
  caster_.IntersectBatch(rays, &hits);
  ASSERT_EQ(hits.size(), rays.size());
  std::vector<uint8_t> occluded;
  caster_.OccludedBatch(rays, &occluded);
  ASSERT_EQ(occluded.size(), rays.size());
  int num_hits = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit single = caster_.Intersect(rays[i]);
    EXPECT_TRUE(SameHit(hits[i], single)) << "ray " << i;
    EXPECT_EQ(occluded[i] != 0, caster_.Occluded(rays[i])) << "ray " << i;
    EXPECT_EQ(occluded[i] != 0, single.valid()) << "ray " << i;
    num_hits += single.valid();
  }
  EXPECT_GT(num_hits, 1000);
  EXPECT_LT(num_hits, 5000);

  std::vector<Eigen::Vector3f> origins, directions;
  for (const Ray& r : rays) {
    origins.push_back(r.origin);
    directions.push_back(r.direction);
  }
  std::vector<SignedHit> signed_hits;
  caster_.IntersectSignedBatch(origins, directions, 8.0f, &signed_hits);
  ASSERT_EQ(signed_hits.size(), rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    EXPECT_TRUE(SameHit(signed_hits[i], caster_.IntersectSigned(origins[i], directions[i], 8.0f))) << i;
  }
  directions.pop_back();
  EXPECT_THROW(caster_.IntersectSignedBatch(origins, directions, 8.0f, &signed_hits), Error);
}

TEST_F(SphereTest, PacketsAgreeWithSingleRays) {
  const std::vector<Ray> rays = CameraRays(97, 61);  // not a multiple of 16: a partial packet
  std::vector<Hit> packet_hits, single_hits;
  caster_.IntersectBatch(rays, &packet_hits, RayCoherence::kCoherent);
  caster_.IntersectBatch(rays, &single_hits, RayCoherence::kIncoherent);
  std::vector<uint8_t> packet_occluded;
  caster_.OccludedBatch(rays, &packet_occluded, RayCoherence::kCoherent);
  int same_triangle = 0, num_hits = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(packet_hits[i].valid(), single_hits[i].valid()) << "ray " << i;
    EXPECT_EQ(packet_occluded[i] != 0, single_hits[i].valid()) << "ray " << i;
    if (!single_hits[i].valid()) continue;
    ++num_hits;
    EXPECT_NEAR(packet_hits[i].t, single_hits[i].t, 1e-4f);
    same_triangle += packet_hits[i].triangle == single_hits[i].triangle;
  }
  EXPECT_GT(num_hits, 1000);
  // Rays exactly on a shared edge may pick either neighbour.
  EXPECT_GE(same_triangle, num_hits - num_hits / 100);
}

TEST_F(SphereTest, ResultsDoNotDependOnTheThreadCount) {
  const std::vector<Ray> rays = RandomRays(20000, 5);
  const std::vector<Ray> camera = CameraRays(160, 120);
  std::vector<Eigen::Vector3f> origins, directions;
  for (const Ray& r : rays) {
    origins.push_back(r.origin);
    directions.push_back(r.direction);
  }
  struct Results {
    std::vector<Hit> hits, packet_hits;
    std::vector<uint8_t> occluded;
    std::vector<SignedHit> signed_hits;
  };
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    Results r;
    caster_.IntersectBatch(rays, &r.hits);
    caster_.IntersectBatch(camera, &r.packet_hits, RayCoherence::kCoherent);
    caster_.OccludedBatch(rays, &r.occluded);
    caster_.IntersectSignedBatch(origins, directions, 5.0f, &r.signed_hits);
    return r;
  };
  const Results one = run(1), two = run(2), four = run(4);
  for (const Results* other : {&two, &four}) {
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_TRUE(SameHit(one.hits[i], other->hits[i])) << i;
      ASSERT_TRUE(SameHit(one.signed_hits[i], other->signed_hits[i])) << i;
    }
    for (size_t i = 0; i < camera.size(); ++i) ASSERT_TRUE(SameHit(one.packet_hits[i], other->packet_hits[i])) << i;
    EXPECT_EQ(one.occluded, other->occluded);
  }
}

TEST(RayCaster, BvhBuiltWithAnyThreadCountGivesTheSameHits) {
  const TriMesh sphere = MakeIcosphere(kRadius, 6);
  const std::vector<Ray> rays = RandomRays(20000, 7);
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    const RayCaster caster(sphere);
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    std::vector<Hit> hits;
    caster.IntersectBatch(rays, &hits);
    return hits;
  };
  // Embree does not document its builders as thread-count independent (this build
  // was bit-identical in every run here); what must hold is the same surface: the
  // same hits, with at most a different neighbour picked exactly on a shared edge.
  const std::vector<Hit> one = run(1), two = run(2), four = run(4);
  for (const std::vector<Hit>* other : {&two, &four}) {
    int same = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(one[i].valid(), (*other)[i].valid()) << i;
      if (one[i].valid()) {
        ASSERT_NEAR(one[i].t, (*other)[i].t, 1e-5f) << i;
      }
      same += SameHit(one[i], (*other)[i]);
    }
    EXPECT_GE(same, static_cast<int>(rays.size()) - 5);
  }
}

TEST(RayCaster, PlaneHitNormalAndBarycentrics) {
  const TriMesh grid = MakeGrid(4, 4, 40.0, 40.0);
  const RayCaster caster(grid);
  const Hit h = caster.Intersect(Ray{Eigen::Vector3f(13.0f, 27.0f, 5.0f), -Eigen::Vector3f::UnitZ()});
  ASSERT_TRUE(h.valid());
  EXPECT_FLOAT_EQ(h.t, 5.0f);
  EXPECT_TRUE(h.geometric_normal.isApprox(Eigen::Vector3f::UnitZ()));
  const Eigen::Vector3d p = (1.0 - h.u - h.v) * grid.V.row(grid.F(h.triangle, 0)) +
                            h.u * grid.V.row(grid.F(h.triangle, 1)) + h.v * grid.V.row(grid.F(h.triangle, 2));
  EXPECT_NEAR(p.x(), 13.0, 1e-5);
  EXPECT_NEAR(p.y(), 27.0, 1e-5);
  // Below the plane, looking up: the same triangle, the normal still +z.
  const Hit below = caster.Intersect(Ray{Eigen::Vector3f(13.0f, 27.0f, -5.0f), Eigen::Vector3f::UnitZ()});
  EXPECT_EQ(below.triangle, h.triangle);
  EXPECT_TRUE(below.geometric_normal.isApprox(Eigen::Vector3f::UnitZ()));
}

TEST(RayCaster, UpdateVerticesMovesTheHits) {
  for (const bool dynamic : {false, true}) {
    TriMesh sphere = MakeIcosphere(kRadius, 4);
    RayCasterOptions options;
    options.dynamic = dynamic;
    RayCaster caster(sphere, options);
    const float tol = static_cast<float>(ChordalTolerance(sphere, kRadius)) + 1e-4f;
    const Ray ray{Eigen::Vector3f::Zero(), Eigen::Vector3f(0.3f, -0.4f, 0.5f).normalized()};
    EXPECT_NEAR(caster.Intersect(ray).t, kRadius, tol);

    const MatX3d scaled = 1.5 * sphere.V;  // 15 mm sphere
    caster.UpdateVertices(scaled);
    EXPECT_NEAR(caster.Intersect(ray).t, 1.5 * kRadius, 1.5f * tol) << "dynamic " << dynamic;
    // Rays that missed the small sphere now hit.
    EXPECT_TRUE(caster.Occluded(Ray{Eigen::Vector3f(12.0f, 0.0f, -30.0f), Eigen::Vector3f::UnitZ()}));

    const MatX3d shifted = scaled.rowwise() + Eigen::RowVector3d(100.0, 0.0, 0.0);
    caster.UpdateVertices(shifted);
    EXPECT_FALSE(caster.Intersect(ray).valid());
    const Hit moved = caster.Intersect(Ray{Eigen::Vector3f(100.0f, 0.0f, 0.0f), ray.direction});
    EXPECT_NEAR(moved.t, 1.5 * kRadius, 1.5f * tol);

    // Bad input is rejected and leaves the caster as it was.
    EXPECT_THROW(caster.UpdateVertices(scaled.topRows(10)), Error);
    MatX3d bad = scaled;
    bad(7, 1) = std::numeric_limits<double>::quiet_NaN();
    try {
      caster.UpdateVertices(bad);
      ADD_FAILURE() << "expected an Error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("vertex 7 has a non-finite coordinate"), std::string::npos) << e.what();
    }
    EXPECT_NEAR(caster.Intersect(Ray{Eigen::Vector3f(100.0f, 0.0f, 0.0f), ray.direction}).t, 1.5 * kRadius,
                1.5f * tol);
  }
}

TEST(RayCaster, BuildQualitiesAndRobustModeGiveTheSameHits) {
  const TriMesh sphere = MakeIcosphere(kRadius, 3);
  const RayCaster reference(sphere);
  const std::vector<Ray> rays = RandomRays(2000, 6);
  std::vector<Hit> expected;
  reference.IntersectBatch(rays, &expected);
  for (const char* quality : {"low", "medium", "high"}) {
    for (const bool robust : {false, true}) {
      RayCasterOptions options;
      options.build_quality = FromString<BvhBuildQuality>(quality, "build_quality");
      options.robust = robust;
      const RayCaster caster(sphere, options);
      std::vector<Hit> hits;
      caster.IntersectBatch(rays, &hits);
      int agree = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(hits[i].valid(), expected[i].valid()) << quality << " robust " << robust << " ray " << i;
        if (hits[i].valid()) {
          EXPECT_NEAR(hits[i].t, expected[i].t, 1e-4f);
        }
        agree += hits[i].triangle == expected[i].triangle;
      }
      EXPECT_GE(agree, 1990) << quality << " robust " << robust;
    }
  }
}

TEST(RayCaster, IsMovable) {
  RayCaster a(MakeIcosphere(kRadius, 2));
  RayCaster b(std::move(a));
  EXPECT_TRUE(b.Intersect(Ray{Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX()}).valid());
  RayCaster c(MakeGrid(1, 1, 1.0, 1.0));
  c = std::move(b);
  EXPECT_EQ(c.num_triangles(), 320);
  EXPECT_TRUE(c.Intersect(Ray{Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX()}).valid());
}


TEST(RayCaster, OptionsAreCheckedAndSettableByName) {
  RayCasterOptions options;
  const std::string message = ErrorOf([&] { SetOptionsFromJson(R"({"build_quality": "ultra"})", "test.json", &options); });
  EXPECT_NE(message.find("build_quality"), std::string::npos) << message;
  EXPECT_NE(message.find("ultra"), std::string::npos) << message;
  EXPECT_NE(message.find("low, medium, high"), std::string::npos) << message;

  RayCasterOptions from_json;
  SetOptionsFromJson(R"({"build_quality": "high", "robust": true, "dynamic": true})", "test.json", &from_json);
  EXPECT_EQ(from_json.build_quality, BvhBuildQuality::kHigh);
  EXPECT_TRUE(from_json.robust);
  EXPECT_TRUE(from_json.dynamic);
  EXPECT_THROW(SetOptionsFromJson(R"({"build_quality": "best"})", "test.json", &from_json), Error);
}

TEST(RayCaster, InvalidMeshNamesTheMesh) {
  TriMesh m = MakeGrid(2, 2, 1.0, 1.0);
  m.F(1, 2) = 42;
  const std::string message = ErrorOf([&] { RayCaster caster(m, {}, "scan_03.ply"); });
  EXPECT_NE(message.find("scan_03.ply: triangle 1 references vertex 42"), std::string::npos) << message;
  EXPECT_NE(ErrorOf([] { RayCaster caster(TriMesh{}); }).find("no triangles"), std::string::npos);
}

TEST(RayCaster, EmbreeErrorsBecomeCreaseErrors) {
  const std::string message = ErrorOf([] { internal::ProvokeEmbreeErrorForTesting(); });
  EXPECT_EQ(message.rfind("Embree: RTC_ERROR_INVALID_OPERATION: ", 0), 0u) << message;
  EXPECT_NE(message.find("index buffer"), std::string::npos) << message;
  // The error was consumed: the device keeps working.
  const RayCaster caster(MakeIcosphere(kRadius, 1));
  EXPECT_TRUE(caster.Intersect(Ray{Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitY()}).valid());
  EXPECT_EQ(ErrorOf([] { internal::ProvokeEmbreeErrorForTesting(); }), message);
}

}  // namespace
}  // namespace crease
