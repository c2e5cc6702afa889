#include "core/ray_caster.h"

#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/error.h"

namespace crease {
namespace {

// ---- The one Embree error handler --------------------------------------------
//
// Embree keeps one error code per thread and device and calls the device's error
// function on the thread whose API call failed. The callback records the first
// error of the calling thread; ThrowIfEmbreeError, run after each API call that
// can fail (device creation, buffer setup, commits), turns it into crease::Error.

struct PendingEmbreeError {
  RTCError code = RTC_ERROR_NONE;
  std::string message;
};
thread_local PendingEmbreeError t_pending_error;

void OnEmbreeError(void* /*user*/, RTCError code, const char* message) {
  if (t_pending_error.code != RTC_ERROR_NONE) return;  // keep the first error, like Embree
  t_pending_error.code = code;
  t_pending_error.message = message != nullptr ? message : "";
}

const char* EmbreeErrorName(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "RTC_ERROR_NONE";
    case RTC_ERROR_UNKNOWN: return "RTC_ERROR_UNKNOWN";
    case RTC_ERROR_INVALID_ARGUMENT: return "RTC_ERROR_INVALID_ARGUMENT";
    case RTC_ERROR_INVALID_OPERATION: return "RTC_ERROR_INVALID_OPERATION";
    case RTC_ERROR_OUT_OF_MEMORY: return "RTC_ERROR_OUT_OF_MEMORY";
    case RTC_ERROR_UNSUPPORTED_CPU: return "RTC_ERROR_UNSUPPORTED_CPU";
    case RTC_ERROR_CANCELLED: return "RTC_ERROR_CANCELLED";
  }
  return "RTC_ERROR_?";
}

// Throws Error("Embree: <code>: <message> (in <call>)") when an Embree call of
// this thread has failed since the last check.
void ThrowIfEmbreeError(RTCDevice device, const char* call) {
  PendingEmbreeError pending = std::exchange(t_pending_error, PendingEmbreeError{});
  const RTCError code = rtcGetDeviceError(device);  // also clears Embree's own record
  if (pending.code == RTC_ERROR_NONE) pending.code = code;
  if (pending.code == RTC_ERROR_NONE) return;
  throw Error(fmt::format("Embree: {}: {} (in {})", EmbreeErrorName(pending.code),
                          pending.message.empty() ? "no message" : pending.message, call));
}

// One device per process, created on first use (thread-safe static initialisation),
// released at exit. Scenes keep their own reference to the device.
class SharedDevice {
 public:
  static RTCDevice Get() {
    static SharedDevice instance;
    return instance.device_;
  }

 private:
  SharedDevice() {
    device_ = rtcNewDevice(nullptr);
    if (device_ == nullptr) {
      throw Error(fmt::format("Embree: {}: could not create the Embree device (in rtcNewDevice)",
                              EmbreeErrorName(rtcGetDeviceError(nullptr))));
    }
    rtcSetDeviceErrorFunction(device_, &OnEmbreeError, nullptr);
    ThrowIfEmbreeError(device_, "rtcSetDeviceErrorFunction");
  }
  ~SharedDevice() { rtcReleaseDevice(device_); }

  RTCDevice device_ = nullptr;
};

RTCBuildQuality EmbreeBuildQuality(BvhBuildQuality quality) {
  switch (quality) {
    case BvhBuildQuality::kLow: return RTC_BUILD_QUALITY_LOW;
    case BvhBuildQuality::kMedium: return RTC_BUILD_QUALITY_MEDIUM;
    case BvhBuildQuality::kHigh: return RTC_BUILD_QUALITY_HIGH;
  }
  return RTC_BUILD_QUALITY_MEDIUM;
}

constexpr int kPacketSize = 16;          // rtcIntersect16 / rtcOccluded16
constexpr size_t kRaysPerTask = 256;     // TBB grain size of the single-ray batches
constexpr size_t kPacketsPerTask = 16;   // TBB grain size of the packet batches

void FillRay(const Ray& ray, RTCRay* r) {
  r->org_x = ray.origin.x();
  r->org_y = ray.origin.y();
  r->org_z = ray.origin.z();
  r->tnear = ray.tnear;
  r->dir_x = ray.direction.x();
  r->dir_y = ray.direction.y();
  r->dir_z = ray.direction.z();
  r->time = 0.0f;
  r->tfar = ray.tfar;
  r->mask = 0xFFFFFFFFu;
  r->id = 0;
  r->flags = 0;
}

}  // namespace

// ---- Options ------------------------------------------------------------------

void RayCasterOptions::VisitFields(OptionVisitor& v) {
  v.Field("robust", robust);
  v.Field("build_quality", build_quality);
  v.Field("dynamic", dynamic);
}

void RayCasterOptions::Check() const {
  // Every value of every field is valid (build_quality is an enum).
}

// ---- RayCaster ----------------------------------------------------------------

struct RayCaster::Impl {
  RayCasterOptions options;
  std::string what;
  int num_vertices = 0;
  int num_triangles = 0;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  RTCGeometry geometry = nullptr;
  float* vertices = nullptr;         // Embree-owned vertex buffer, #V×3 floats
  const unsigned* indices = nullptr;  // Embree-owned index buffer, #F×3

  Impl() = default;
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (geometry != nullptr) rtcReleaseGeometry(geometry);
  }

  void Commit(const char* call) {
    rtcCommitGeometry(geometry);
    ThrowIfEmbreeError(device, "rtcCommitGeometry");
    rtcCommitScene(scene);
    ThrowIfEmbreeError(device, call);
  }

  // Unit normal (V1−V0)×(V2−V0) of triangle f, from Embree's copy of the mesh.
  Eigen::Vector3f TriangleNormal(unsigned f) const {
    const unsigned* idx = indices + 3 * static_cast<size_t>(f);
    const Eigen::Map<const Eigen::Vector3f> a(vertices + 3 * static_cast<size_t>(idx[0]));
    const Eigen::Map<const Eigen::Vector3f> b(vertices + 3 * static_cast<size_t>(idx[1]));
    const Eigen::Map<const Eigen::Vector3f> c(vertices + 3 * static_cast<size_t>(idx[2]));
    return (b - a).cross(c - a).normalized();
  }

  Hit ToHit(const RTCRayHit& rh) const {
    Hit h;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return h;
    h.t = rh.ray.tfar;
    h.triangle = static_cast<int>(rh.hit.primID);
    h.u = rh.hit.u;
    h.v = rh.hit.v;
    h.geometric_normal = TriangleNormal(rh.hit.primID);
    return h;
  }

  Hit Intersect(const Ray& ray, RTCIntersectContext* context) const {
    RTCRayHit rh;
    FillRay(ray, &rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, context, &rh);
    return ToHit(rh);
  }

  bool Occluded(const Ray& ray, RTCIntersectContext* context) const {
    RTCRay r;
    FillRay(ray, &r);
    rtcOccluded1(scene, context, &r);
    return r.tfar < 0.0f;  // Embree sets tfar = -inf for occluded rays
  }

  SignedHit IntersectSigned(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                            float max_distance, RTCIntersectContext* context) const {
    const Hit forward = Intersect({origin, direction, 0.0f, max_distance}, context);
    // The hit behind only wins when strictly nearer than the one ahead.
    const float back_limit = forward.valid() ? std::min(forward.t, max_distance) : max_distance;
    const Hit backward = Intersect({origin, -direction, 0.0f, back_limit}, context);
    SignedHit s;
    const Hit* best = nullptr;
    float sign = 1.0f;
    if (forward.valid() && (!backward.valid() || forward.t <= backward.t)) {
      best = &forward;
    } else if (backward.valid()) {
      best = &backward;
      sign = -1.0f;
    }
    if (best == nullptr) return s;
    s.t = sign * best->t;
    s.triangle = best->triangle;
    s.u = best->u;
    s.v = best->v;
    s.geometric_normal = best->geometric_normal;
    return s;
  }

  // The rays rays[begin, end) as a packet of 16: lanes past `end` repeat the first
  // ray and are marked invalid in `valid`.
  static void FillPacket(const std::vector<Ray>& rays, size_t begin, size_t end, int* valid, RTCRay16* r) {
    for (int k = 0; k < kPacketSize; ++k) {
      const size_t i = begin + static_cast<size_t>(k);
      const Ray& ray = i < end ? rays[i] : rays[begin];
      valid[k] = i < end ? -1 : 0;
      r->org_x[k] = ray.origin.x();
      r->org_y[k] = ray.origin.y();
      r->org_z[k] = ray.origin.z();
      r->tnear[k] = ray.tnear;
      r->dir_x[k] = ray.direction.x();
      r->dir_y[k] = ray.direction.y();
      r->dir_z[k] = ray.direction.z();
      r->time[k] = 0.0f;
      r->tfar[k] = ray.tfar;
      r->mask[k] = 0xFFFFFFFFu;
      r->id[k] = static_cast<unsigned>(k);
      r->flags[k] = 0;
    }
  }

  // Packet of up to 16 rays rays[begin, end).
  void IntersectPacket(const std::vector<Ray>& rays, size_t begin, size_t end,
                       RTCIntersectContext* context, Hit* out) const {
    alignas(64) int valid[kPacketSize];
    RTCRayHit16 rh;
    FillPacket(rays, begin, end, valid, &rh.ray);
    for (int k = 0; k < kPacketSize; ++k) {
      rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect16(valid, scene, context, &rh);
    for (size_t i = begin; i < end; ++i) {
      const int k = static_cast<int>(i - begin);
      Hit& h = out[i];
      h = Hit{};
      if (rh.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID) continue;
      h.t = rh.ray.tfar[k];
      h.triangle = static_cast<int>(rh.hit.primID[k]);
      h.u = rh.hit.u[k];
      h.v = rh.hit.v[k];
      h.geometric_normal = TriangleNormal(rh.hit.primID[k]);
    }
  }

  void OccludedPacket(const std::vector<Ray>& rays, size_t begin, size_t end,
                      RTCIntersectContext* context, uint8_t* out) const {
    alignas(64) int valid[kPacketSize];
    RTCRay16 r;
    FillPacket(rays, begin, end, valid, &r);
    rtcOccluded16(valid, scene, context, &r);
    for (size_t i = begin; i < end; ++i) out[i] = r.tfar[i - begin] < 0.0f ? 1 : 0;
  }
};

RayCaster::RayCaster(const TriMesh& mesh, const RayCasterOptions& options, const std::string& what)
    : impl_(std::make_unique<Impl>()) {
  ValidateMesh(mesh, what);
  options.Check();
  Impl& m = *impl_;
  m.options = options;
  m.what = what;
  m.num_vertices = mesh.num_vertices();
  m.num_triangles = mesh.num_faces();
  m.device = SharedDevice::Get();

  m.scene = rtcNewScene(m.device);
  ThrowIfEmbreeError(m.device, "rtcNewScene");
  int flags = RTC_SCENE_FLAG_NONE;
  if (options.robust) flags |= RTC_SCENE_FLAG_ROBUST;
  if (options.dynamic) flags |= RTC_SCENE_FLAG_DYNAMIC;
  rtcSetSceneFlags(m.scene, static_cast<RTCSceneFlags>(flags));
  // Embree honours a per-geometry quality (here: refit) only in its two-level
  // mode, i.e. with scene build quality low (rtcSetGeometryBuildQuality(3)).
  rtcSetSceneBuildQuality(m.scene, options.dynamic ? RTC_BUILD_QUALITY_LOW
                                                   : EmbreeBuildQuality(options.build_quality));
  ThrowIfEmbreeError(m.device, "rtcSetSceneBuildQuality");

  m.geometry = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  ThrowIfEmbreeError(m.device, "rtcNewGeometry");
  if (options.dynamic) rtcSetGeometryBuildQuality(m.geometry, RTC_BUILD_QUALITY_REFIT);
  m.vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      m.geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
      static_cast<size_t>(m.num_vertices)));
  ThrowIfEmbreeError(m.device, "rtcSetNewGeometryBuffer(vertex)");
  unsigned* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      m.geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
      static_cast<size_t>(m.num_triangles)));
  ThrowIfEmbreeError(m.device, "rtcSetNewGeometryBuffer(index)");
  Require(m.vertices != nullptr && indices != nullptr,
          fmt::format("Embree: {}: no buffer returned for {}", EmbreeErrorName(RTC_ERROR_UNKNOWN), what));
  m.indices = indices;

  tbb::parallel_for(tbb::blocked_range<int>(0, m.num_vertices, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) {
      for (int k = 0; k < 3; ++k) m.vertices[3 * static_cast<size_t>(i) + k] = static_cast<float>(mesh.V(i, k));
    }
  });
  tbb::parallel_for(tbb::blocked_range<int>(0, m.num_triangles, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int f = r.begin(); f != r.end(); ++f) {
      for (int k = 0; k < 3; ++k) indices[3 * static_cast<size_t>(f) + k] = static_cast<unsigned>(mesh.F(f, k));
    }
  });

  rtcAttachGeometry(m.scene, m.geometry);
  ThrowIfEmbreeError(m.device, "rtcAttachGeometry");
  m.Commit("rtcCommitScene");
}

RayCaster::~RayCaster() = default;
RayCaster::RayCaster(RayCaster&&) noexcept = default;
RayCaster& RayCaster::operator=(RayCaster&&) noexcept = default;

int RayCaster::num_vertices() const { return impl_->num_vertices; }
int RayCaster::num_triangles() const { return impl_->num_triangles; }
const RayCasterOptions& RayCaster::options() const { return impl_->options; }

void RayCaster::UpdateVertices(const MatX3d& V) {
  Impl& m = *impl_;
  Require(V.rows() == m.num_vertices,
          fmt::format("{}: UpdateVertices got {} vertices, but the mesh has {} (same topology expected)",
                      m.what, V.rows(), m.num_vertices));
  // Validate everything before touching the buffer, so a bad input leaves the
  // caster unchanged. First non-finite vertex, deterministically (minimum index).
  const int bad = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, m.num_vertices, 4096), m.num_vertices,
      [&](const tbb::blocked_range<int>& r, int first) {
        for (int i = r.begin(); i != r.end() && i < first; ++i) {
          if (!V.row(i).allFinite()) return i;
        }
        return first;
      },
      [](int a, int b) { return std::min(a, b); });
  if (bad < m.num_vertices) {
    throw Error(fmt::format("{}: UpdateVertices: vertex {} has a non-finite coordinate ({}, {}, {})",
                            m.what, bad, V(bad, 0), V(bad, 1), V(bad, 2)));
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, m.num_vertices, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) {
      for (int k = 0; k < 3; ++k) m.vertices[3 * static_cast<size_t>(i) + k] = static_cast<float>(V(i, k));
    }
  });
  rtcUpdateGeometryBuffer(m.geometry, RTC_BUFFER_TYPE_VERTEX, 0);
  ThrowIfEmbreeError(m.device, "rtcUpdateGeometryBuffer");
  m.Commit("rtcCommitScene after UpdateVertices");
}

Hit RayCaster::Intersect(const Ray& ray) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  return impl_->Intersect(ray, &context);
}

bool RayCaster::Occluded(const Ray& ray) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  return impl_->Occluded(ray, &context);
}

SignedHit RayCaster::IntersectSigned(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                                     float max_distance) const {
  Require(max_distance >= 0.0f,
          fmt::format("RayCaster::IntersectSigned: max_distance = {} must be >= 0", max_distance));
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  return impl_->IntersectSigned(origin, direction, max_distance, &context);
}

namespace {

// Runs a batch in parallel: 16-ray packets with a coherent context, or single rays.
// Each ray's result depends on that ray alone, so the thread count does not matter.
template <class PacketFn, class SingleFn>
void ForEachRayBatch(size_t num_rays, RayCoherence coherence, const PacketFn& packet, const SingleFn& single) {
  if (coherence == RayCoherence::kCoherent) {
    const size_t num_packets = (num_rays + kPacketSize - 1) / kPacketSize;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, num_packets, kPacketsPerTask),
                      [&](const tbb::blocked_range<size_t>& r) {
                        RTCIntersectContext context;
                        rtcInitIntersectContext(&context);
                        context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
                        for (size_t p = r.begin(); p != r.end(); ++p) {
                          const size_t begin = p * kPacketSize;
                          packet(begin, std::min(num_rays, begin + kPacketSize), &context);
                        }
                      });
    return;
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, num_rays, kRaysPerTask), [&](const tbb::blocked_range<size_t>& r) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    for (size_t i = r.begin(); i != r.end(); ++i) single(i, &context);
  });
}

}  // namespace

void RayCaster::IntersectBatch(const std::vector<Ray>& rays, std::vector<Hit>* hits,
                               RayCoherence coherence) const {
  hits->resize(rays.size());
  const Impl& m = *impl_;
  Hit* out = hits->data();
  ForEachRayBatch(
      rays.size(), coherence,
      [&](size_t begin, size_t end, RTCIntersectContext* ctx) { m.IntersectPacket(rays, begin, end, ctx, out); },
      [&](size_t i, RTCIntersectContext* ctx) { out[i] = m.Intersect(rays[i], ctx); });
}

void RayCaster::OccludedBatch(const std::vector<Ray>& rays, std::vector<uint8_t>* occluded,
                              RayCoherence coherence) const {
  occluded->resize(rays.size());
  const Impl& m = *impl_;
  uint8_t* out = occluded->data();
  ForEachRayBatch(
      rays.size(), coherence,
      [&](size_t begin, size_t end, RTCIntersectContext* ctx) { m.OccludedPacket(rays, begin, end, ctx, out); },
      [&](size_t i, RTCIntersectContext* ctx) { out[i] = m.Occluded(rays[i], ctx) ? 1 : 0; });
}

void RayCaster::IntersectSignedBatch(const std::vector<Eigen::Vector3f>& origins,
                                     const std::vector<Eigen::Vector3f>& directions, float max_distance,
                                     std::vector<SignedHit>* hits) const {
  Require(origins.size() == directions.size(),
          fmt::format("RayCaster::IntersectSignedBatch: {} origins but {} directions", origins.size(),
                      directions.size()));
  Require(max_distance >= 0.0f,
          fmt::format("RayCaster::IntersectSignedBatch: max_distance = {} must be >= 0", max_distance));
  hits->resize(origins.size());
  const Impl& m = *impl_;
  SignedHit* out = hits->data();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, origins.size(), kRaysPerTask / 2),
                    [&](const tbb::blocked_range<size_t>& r) {
                      RTCIntersectContext context;
                      rtcInitIntersectContext(&context);
                      for (size_t i = r.begin(); i != r.end(); ++i) {
                        out[i] = m.IntersectSigned(origins[i], directions[i], max_distance, &context);
                      }
                    });
}

namespace internal {

void ProvokeEmbreeErrorForTesting() {
  const RTCDevice device = SharedDevice::Get();
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  ThrowIfEmbreeError(device, "rtcNewGeometry");
  // A triangle mesh's index buffer must be RTC_FORMAT_UINT3: Embree rejects FLOAT3.
  rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 1);
  rtcReleaseGeometry(geometry);
  ThrowIfEmbreeError(device, "rtcSetNewGeometryBuffer(index, RTC_FORMAT_FLOAT3)");
}

}  // namespace internal
}  // namespace crease
