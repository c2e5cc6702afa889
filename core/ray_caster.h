// RayCaster — ray queries against one triangle mesh, backed by an Embree 3 BVH.
//
// Used by detail extraction (signed displacement between two surfaces along the
// normals, IntersectSigned), by the synthetic renderer (primary and shadow rays)
// and by anything that needs "which triangle is behind this pixel".
//
// Conventions: positions in mm (single precision inside Embree). A ray is the set
// origin + t·direction for t in [tnear, tfar]; t is in units of |direction|, so
// t is in mm when direction is a unit vector. Barycentrics (u, v) weigh the
// triangle's 2nd and 3rd vertex: hit point = (1−u−v)·V[F(t,0)] + u·V[F(t,1)] + v·V[F(t,2)].
//
// Threads: all const queries may run concurrently from any number of threads.
// UpdateVertices must not run concurrently with queries. The batched queries run
// in parallel with TBB; every ray is independent, so their results do not depend
// on the number of threads. One Embree device is shared by the whole process.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/options.h"
#include "core/tri_mesh.h"
#include "core/types.h"

namespace crease {

struct Ray {
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();     // mm
  Eigen::Vector3f direction = Eigen::Vector3f::UnitZ();  // need not be unit; t scales with it
  float tnear = 0.0f;                                    // start of the segment
  float tfar = std::numeric_limits<float>::infinity();   // end of the segment
};

// First intersection along a ray.
struct Hit {
  float t = std::numeric_limits<float>::infinity();  // ray parameter of the hit
  int triangle = -1;                                 // row of TriMesh::F; -1 = no hit
  float u = 0.0f, v = 0.0f;  // barycentrics of the triangle's 2nd and 3rd vertex
  Eigen::Vector3f geometric_normal = Eigen::Vector3f::Zero();  // unit, (V1−V0)×(V2−V0): outward
                                                               // for counter-clockwise triangles
  bool valid() const { return triangle >= 0; }
};

// Nearest intersection along a line through `origin`, searched both ways. t is
// signed: positive along +direction, negative along −direction.
struct SignedHit {
  float t = std::numeric_limits<float>::infinity();  // signed ray parameter; inf when invalid
  int triangle = -1;                                 // -1 = no hit within max_distance
  float u = 0.0f, v = 0.0f;                          // as in Hit
  Eigen::Vector3f geometric_normal = Eigen::Vector3f::Zero();  // as in Hit
  bool valid() const { return triangle >= 0; }
};

// RayCasterOptions::build_quality (see there).
enum class BvhBuildQuality { kLow, kMedium, kHigh };
constexpr std::array<const char*, 3> OptionEnumNames(BvhBuildQuality) { return {"low", "medium", "high"}; }

struct RayCasterOptions {
  // Embree's robust traversal (RTC_SCENE_FLAG_ROBUST): no misses on shared edges
  // and vertices at some cost in speed. Not a paper parameter.
  bool robust = false;
  // BVH build quality when dynamic = false: "low" (fast build, two-level),
  // "medium" (Embree's default) or "high" (spatial splits, slowest build).
  // Ignored when dynamic = true, where Embree's refit builder is used.
  BvhBuildQuality build_quality = BvhBuildQuality::kMedium;
  // For meshes whose vertices move every frame: the scene is built with
  // RTC_SCENE_FLAG_DYNAMIC, scene quality low and geometry quality refit, so that
  // UpdateVertices refits the BVH (keeps its topology) instead of rebuilding it.
  // Faster updates, slower rays once the vertices have moved far.
  bool dynamic = false;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// How the rays of one batch relate. kCoherent (neighbouring rays in the batch are
// neighbouring rays in space, e.g. the pixels of an image in scanline order)
// traces packets of 16 rays with rtcIntersect16/rtcOccluded16; kIncoherent traces
// each ray alone. Both give the same hits up to floating-point rounding.
enum class RayCoherence { kIncoherent, kCoherent };

class RayCaster {
 public:
  // Builds the BVH of `mesh` (validated with ValidateMesh; errors start with `what`).
  // Throws Error on an invalid mesh, invalid options or an Embree error.
  explicit RayCaster(const TriMesh& mesh, const RayCasterOptions& options = {},
                     const std::string& what = "RayCaster mesh");
  ~RayCaster();
  // A moved-from RayCaster may only be destroyed or assigned to.
  RayCaster(RayCaster&&) noexcept;
  RayCaster& operator=(RayCaster&&) noexcept;
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  int num_vertices() const;
  int num_triangles() const;
  const RayCasterOptions& options() const;

  // Moves the vertices (same topology): V is #V×3, mm, finite. Updates the Embree
  // vertex buffer and recommits the scene (a refit when options.dynamic, else a
  // rebuild). Throws Error on a wrong shape, a non-finite value or an Embree error.
  void UpdateVertices(const MatX3d& V);

  // First hit in [ray.tnear, ray.tfar]; invalid Hit when none.
  Hit Intersect(const Ray& ray) const;
  // True when anything is hit in [ray.tnear, ray.tfar].
  bool Occluded(const Ray& ray) const;
  // Casts origin + t·direction for t in [0, max_distance] and origin − t·direction
  // for t in [0, max_distance]; returns the nearer of the two hits with t signed
  // (negative for the hit behind), preferring the + side on a tie; invalid when
  // neither ray hits. With a unit direction, t is the signed distance in mm.
  SignedHit IntersectSigned(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                            float max_distance) const;

  // Batched, parallel versions: output i is the result for input i; outputs are
  // resized to the number of rays. occluded[i] is 1 when ray i is occluded, else 0.
  void IntersectBatch(const std::vector<Ray>& rays, std::vector<Hit>* hits,
                      RayCoherence coherence = RayCoherence::kIncoherent) const;
  void OccludedBatch(const std::vector<Ray>& rays, std::vector<uint8_t>* occluded,
                     RayCoherence coherence = RayCoherence::kIncoherent) const;
  // origins and directions have equal sizes.
  void IntersectSignedBatch(const std::vector<Eigen::Vector3f>& origins,
                            const std::vector<Eigen::Vector3f>& directions, float max_distance,
                            std::vector<SignedHit>* hits) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

namespace internal {
// Makes an invalid call on the shared Embree device and runs the same error check
// the RayCaster uses after each Embree call; throws Error("Embree: ...").
// Exists so that tests can exercise the Embree error path, which valid meshes and
// options never reach.
void ProvokeEmbreeErrorForTesting();
}  // namespace internal

}  // namespace crease
