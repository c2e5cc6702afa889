#include "synth/renderer.h"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/ray_caster.h"

namespace crease {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;
constexpr int kPacketSide = 4;  // 4×4 pixels per 16-ray packet

using Vec3f = Eigen::Vector3f;
using Mat3f = Eigen::Matrix3f;

// Orthonormal basis (u, v) perpendicular to unit w (Duff et al. 2017, branchless).
void Basis(const Vec3f& w, Vec3f* u, Vec3f* v) {
  const float sign = std::copysign(1.0f, w.z());
  const float a = -1.0f / (sign + w.z());
  const float b = w.x() * w.y() * a;
  *u = Vec3f(1.0f + sign * w.x() * w.x() * a, sign * b, -sign * w.x());
  *v = Vec3f(b, sign + w.y() * w.y() * a, -w.y());
}

Vec3f ToVec3f(const std::vector<double>& c) {
  return {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
}

// Bilinear lookup of a float map at UV (texel centres at (i + 0.5)/W), clamped.
template <int C>
Eigen::Matrix<float, C, 1> SampleMap(const cv::Mat& map, float u, float v) {
  const int w = map.cols, h = map.rows;
  const float x = std::clamp(u * w - 0.5f, 0.0f, static_cast<float>(w - 1));
  const float y = std::clamp(v * h - 0.5f, 0.0f, static_cast<float>(h - 1));
  const int x0 = std::min(static_cast<int>(x), std::max(w - 2, 0)), y0 = std::min(static_cast<int>(y), std::max(h - 2, 0));
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const float fx = x - x0, fy = y - y0;
  const float* r0 = map.ptr<float>(y0);
  const float* r1 = map.ptr<float>(y1);
  Eigen::Matrix<float, C, 1> out;
  for (int k = 0; k < C; ++k) {
    out[k] = (1 - fy) * ((1 - fx) * r0[x0 * C + k] + fx * r0[x1 * C + k]) +
             fy * ((1 - fx) * r1[x0 * C + k] + fx * r1[x1 * C + k]);
  }
  return out;
}

void CheckMaterial(const Material& m, const std::string& where) {
  Require(m.albedo.allFinite() && m.albedo.minCoeff() >= 0.0f && m.albedo.maxCoeff() <= 1.0f,
          where + ": albedo must lie in [0, 1]");
  Require(std::isfinite(m.specular) && m.specular >= 0.0f && m.specular <= 1.0f,
          fmt::format("{}: specular = {} must lie in [0, 1]", where, m.specular));
  Require(std::isfinite(m.roughness) && m.roughness > 0.0f && m.roughness <= 1.0f,
          fmt::format("{}: roughness = {} must lie in (0, 1]", where, m.roughness));
  Require(std::isfinite(m.f0) && m.f0 >= 0.0f && m.f0 <= 1.0f, fmt::format("{}: f0 = {} must lie in [0, 1]", where, m.f0));
}

// Lights resolved into the head frame for one render.
enum class LightKind { kDirectional, kSphere, kEnvironment, kAmbient };
struct ResolvedLight {
  LightKind kind = LightKind::kDirectional;
  Vec3f direction = Vec3f::UnitZ();  // directional: towards the light, unit
  Vec3f color = Vec3f::Zero();       // directional: π·color; sphere: radiance; ambient: radiance
  Vec3f centre = Vec3f::Zero();      // sphere, head frame
  float radius = 0.0f;               // sphere
  float max_distance = 0.0f;         // ambient
  int samples = 1;
  const EnvironmentMap* map = nullptr;  // environment
  float scale = 1.0f;
  Mat3f head_from_env = Mat3f::Identity();
};

// One shading sample's surface point.
struct Surface {
  Vec3f p, n, ng;
  PreparedBrdf brdf;
};

// A shadow ray's pending contribution.
struct Pending {
  int pixel;
  Vec3f irradiance;  // diffuse, without albedo
  Vec3f specular;
};

// What one Render call resolves once: the camera, the lights in the head frame, the
// sampling and the tiling.
struct RenderContext {
  const RenderOptions* options = nullptr;
  uint64_t frame_seed = 0;  // per-pixel generators derive from it
  int width = 0, height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  Mat3f cam_from_head_r, head_from_cam;
  Vec3f eye;  // camera centre, head frame
  std::vector<ResolvedLight> lights;
  int background_env = -1;  // the light rays that miss see (environment_background), or −1
  int n_axis = 1, num_samples = 1;
  float inv_samples = 1.0f;
  bool sss = false;         // subsurface blur
  bool stochastic = false;  // per-pixel generators needed (jitter or sampled lights)
  Vec3f background;
  float eps = 0.0f;  // shadow-ray offset, mm
  int tile = 16, tiles_x = 0, tiles_y = 0;
};

// Subsurface: diffuse irradiance, albedo and the rest kept apart, blurred after.
struct SubsurfaceBuffers {
  cv::Mat irradiance, albedo, rest;  // CV_32FC3
  cv::Mat depth;                     // CV_32FC1 mean hit depth, mm; 0 where no hit
};

// One thread's buffers for a tile's pixels, in packet order; reused across tiles.
struct TileScratch {
  std::vector<int> px, py;
  std::vector<Rng> rngs;                               // per pixel, when stochastic
  std::vector<Ray> rays, coherent_rays, sampled_rays;  // primary; shadow rays (directional lights, the rest)
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
  std::vector<Pending> coherent_pending, sampled_pending;
  std::vector<Surface> surf;
  std::vector<uint8_t> has_hit;
  std::vector<Vec3f> color, irr, spec;               // sum over samples; this sample's diffuse and the rest
  std::vector<Vec3f> albedo_sum, irr_sum, rest_sum;  // subsurface sums
  std::vector<float> hit_count, depth_sum;
  int64_t primary_rays = 0, shadow_rays = 0;  // this tile's
};

}  // namespace

// ---- Options ------------------------------------------------------------------------

void RenderOptions::VisitFields(OptionVisitor& v) {
  v.Field("samples_per_axis", samples_per_axis);
  v.Field("shadows", shadows);
  v.Field("passes", passes);
  v.Field("background", background);
  v.Field("environment_background", environment_background);
  v.Field("subsurface_mm", subsurface_mm);
  v.Field("ray_epsilon_mm", ray_epsilon_mm);
  v.Field("tile_size", tile_size);
}

void RenderOptions::Check() const {
  const char* o = "RenderOptions";
  CheckGe(o, "samples_per_axis", samples_per_axis, 1);
  CheckLe(o, "samples_per_axis", samples_per_axis, 16);
  Require(background.size() == 3, fmt::format("RenderOptions.background needs 3 values, got {}", background.size()));
  for (double c : background) Require(std::isfinite(c) && c >= 0.0, "RenderOptions.background must be finite and >= 0");
  CheckGe(o, "subsurface_mm", subsurface_mm, 0.0);
  CheckLe(o, "subsurface_mm", subsurface_mm, 20.0);
  CheckGe(o, "ray_epsilon_mm", ray_epsilon_mm, 0.0);
  CheckGe(o, "tile_size", tile_size, kPacketSide);
  CheckLe(o, "tile_size", tile_size, 256);
  Require(tile_size % kPacketSide == 0, fmt::format("RenderOptions.tile_size = {} must be a multiple of 4", tile_size));
}

void RendererOptions::VisitFields(OptionVisitor& v) {
  v.Field("dynamic", dynamic);
  v.Field("build_quality", build_quality);
  v.Field("robust", robust);
}

void RendererOptions::Check() const {
  // Every value of every field is valid (build_quality is an enum).
}

// ---- Renderer -------------------------------------------------------------------------

struct Renderer::Impl {
  std::string what;
  RayCaster caster;
  MatX3i F;
  std::vector<Vec3f> V, N;
  std::vector<Eigen::Vector2f> UV;
  std::vector<int> rep;                    // seam representative of each vertex
  std::vector<int> vf_offset, vf_face;     // faces around each representative (CSR)
  std::vector<int> tri_part;               // part of each triangle (−1 without parts)
  SceneMaterials materials;

  Impl(const TriMesh& mesh, const RendererOptions& options, const std::string& w)
      : what(w), caster(mesh, BvhOptions(options), w), F(mesh.F) {}

  static RayCasterOptions BvhOptions(const RendererOptions& options) {
    options.Check();
    RayCasterOptions o;
    o.dynamic = options.dynamic;
    o.build_quality = options.build_quality;
    o.robust = options.robust;
    return o;
  }

  void SetMaterials(SceneMaterials m) {
    auto check_map = [&](const cv::Mat& map, int type, const char* name) {
      Require(map.empty() || (map.type() == type && map.cols >= 1 && map.rows >= 1),
              fmt::format("{}: materials.{} must be {} (got type {})", what, name,
                          type == CV_32FC3 ? "CV_32FC3" : "CV_32FC1", map.type()));
      if (map.empty()) return;
      double lo = 0, hi = 0;
      cv::minMaxIdx(map.reshape(1), &lo, &hi);
      Require(std::isfinite(lo) && std::isfinite(hi) && lo >= 0.0 && hi <= 1.0,
              fmt::format("{}: materials.{} values must lie in [0, 1] (found [{}, {}])", what, name, lo, hi));
    };
    check_map(m.albedo, CV_32FC3, "albedo");
    check_map(m.specular, CV_32FC1, "specular");
    check_map(m.roughness, CV_32FC1, "roughness");
    if (!m.roughness.empty()) {
      double lo = 0;
      cv::minMaxIdx(m.roughness, &lo, nullptr);
      Require(lo > 0.0, fmt::format("{}: materials.roughness must be > 0 (found {})", what, lo));
    }
    CheckMaterial(m.face, what + ": materials.face");
    CheckMaterial(m.other, what + ": materials.other");
    for (size_t i = 0; i < m.part_materials.size(); ++i) {
      CheckMaterial(m.part_materials[i], fmt::format("{}: materials.part_materials[{}]", what, i));
    }
    const int nv = static_cast<int>(V.size());
    Require(m.vertex_part.empty() || static_cast<int>(m.vertex_part.size()) == nv,
            fmt::format("{}: materials.vertex_part has {} entries for {} vertices", what, m.vertex_part.size(), nv));
    for (size_t i = 0; i < m.vertex_part.size(); ++i) {
      Require(m.vertex_part[i] >= 0 && m.vertex_part[i] < static_cast<int>(m.part_materials.size()),
              fmt::format("{}: materials.vertex_part[{}] = {} must lie in [0, {})", what, i, m.vertex_part[i],
                          m.part_materials.size()));
    }
    tri_part.assign(static_cast<size_t>(F.rows()), -1);
    if (!m.vertex_part.empty()) {
      for (int f = 0; f < F.rows(); ++f) tri_part[static_cast<size_t>(f)] = m.vertex_part[static_cast<size_t>(F(f, 0))];
    }
    materials = std::move(m);
  }

  // Area-weighted vertex normals, shared across UV-seam duplicates; parallel and
  // deterministic (each vertex sums its faces in a fixed order).
  void ComputeNormals() {
    const int nf = static_cast<int>(F.rows());
    std::vector<Vec3f> fn(static_cast<size_t>(nf));
    tbb::parallel_for(tbb::blocked_range<int>(0, nf, 8192), [&](const tbb::blocked_range<int>& r) {
      for (int f = r.begin(); f != r.end(); ++f) {
        const Vec3f& a = V[static_cast<size_t>(F(f, 0))];
        fn[static_cast<size_t>(f)] = (V[static_cast<size_t>(F(f, 1))] - a).cross(V[static_cast<size_t>(F(f, 2))] - a);
      }
    });
    tbb::parallel_for(tbb::blocked_range<size_t>(0, V.size(), 8192), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        const int g = rep[i];
        Vec3f s = Vec3f::Zero();
        for (int k = vf_offset[static_cast<size_t>(g)]; k < vf_offset[static_cast<size_t>(g) + 1]; ++k) {
          s += fn[static_cast<size_t>(vf_face[static_cast<size_t>(k)])];
        }
        const float len = s.norm();
        N[i] = len > 0.0f ? Vec3f(s / len) : Vec3f::Zero();
      }
    });
  }

  Material MaterialAt(int triangle, const Eigen::Vector2f& uv) const {
    const SceneMaterials& m = materials;
    const bool in_chart = uv.x() >= 0.0f && uv.x() <= 1.0f && uv.y() >= 0.0f && uv.y() <= 1.0f;
    const int part = tri_part[static_cast<size_t>(triangle)];
    Material mat = part >= 0 ? m.part_materials[static_cast<size_t>(part)] : (in_chart ? m.face : m.other);
    if (mat.textured && in_chart) {
      if (!m.albedo.empty()) mat.albedo = SampleMap<3>(m.albedo, uv.x(), uv.y());
      if (!m.specular.empty()) mat.specular = SampleMap<1>(m.specular, uv.x(), uv.y())[0];
      if (!m.roughness.empty()) mat.roughness = std::max(SampleMap<1>(m.roughness, uv.x(), uv.y())[0], 0.02f);
    }
    return mat;
  }

  RenderResult Render(const Camera& camera, const LightRig& rig, const RenderOptions& options, Rng& rng) const;

 private:
  // The steps of Render that need the mesh (the rest are free functions above Render).
  // One prepared tile: each sample's primary rays, shading, light samples and shadow
  // rays, then the passes and the pixel means.
  void RenderTile(const RenderContext& ctx, TileScratch* s, RenderResult* out, SubsurfaceBuffers* sss) const;
  // Barycentric interpolation of per-vertex `a` (or the UVs) at a hit.
  Vec3f Interpolate(const Hit& h, const std::vector<Vec3f>& a) const;
  Eigen::Vector2f InterpolateUv(const Hit& h) const;
  // Shading normal n facing the viewer side of the geometric normal ng (ray direction d).
  void Orient(const Hit& h, const Vec3f& d, Vec3f* n, Vec3f* ng) const;
  // Depth, normal, UV, triangle and part of the tile's hits.
  void WritePasses(const RenderContext& ctx, const TileScratch& s, RenderResult* out) const;
  // Surfaces and misses: each hit's point, normals and BRDF; a miss sees the background.
  void ShadeHits(const RenderContext& ctx, TileScratch* s) const;
  // Shadow rays of the pending light samples; the unoccluded ones add their light.
  void TraceShadows(const std::vector<Ray>& rays, const std::vector<Pending>& pending, RayCoherence coherence,
                    TileScratch* s) const;
};

Renderer::Renderer(const TriMesh& mesh, SceneMaterials materials, const RendererOptions& options,
                   const std::string& what) {
  ValidateMesh(mesh, what, MeshRequirements{.uv = true});
  impl_ = std::make_unique<Impl>(mesh, options, what);
  Impl& m = *impl_;
  const int nv = mesh.num_vertices();
  m.V.resize(static_cast<size_t>(nv));
  m.N.resize(static_cast<size_t>(nv));
  m.UV.resize(static_cast<size_t>(nv));
  for (int i = 0; i < nv; ++i) {
    m.V[static_cast<size_t>(i)] = mesh.V.row(i).transpose().cast<float>();
    m.UV[static_cast<size_t>(i)] = mesh.UV.row(i).transpose().cast<float>();
  }
  m.rep = CoincidentVertexRepresentatives(mesh);
  m.vf_offset.assign(static_cast<size_t>(nv) + 1, 0);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) ++m.vf_offset[static_cast<size_t>(m.rep[static_cast<size_t>(mesh.F(f, k))]) + 1];
  }
  for (int i = 0; i < nv; ++i) m.vf_offset[static_cast<size_t>(i) + 1] += m.vf_offset[static_cast<size_t>(i)];
  m.vf_face.resize(static_cast<size_t>(m.vf_offset.back()));
  std::vector<int> fill(m.vf_offset.begin(), m.vf_offset.end() - 1);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      m.vf_face[static_cast<size_t>(fill[static_cast<size_t>(m.rep[static_cast<size_t>(mesh.F(f, k))])]++)] = f;
    }
  }
  if (mesh.has_normals()) {
    for (int i = 0; i < nv; ++i) m.N[static_cast<size_t>(i)] = mesh.N.row(i).transpose().cast<float>().normalized();
  } else {
    m.ComputeNormals();
  }
  m.SetMaterials(std::move(materials));
}

Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

int Renderer::num_vertices() const { return static_cast<int>(impl_->V.size()); }
int Renderer::num_triangles() const { return static_cast<int>(impl_->F.rows()); }

void Renderer::UpdateGeometry(const MatX3d& V, const MatX3d& N) {
  Impl& m = *impl_;
  const auto nv = static_cast<Eigen::Index>(m.V.size());
  Require(N.rows() == 0 || N.rows() == nv,
          fmt::format("{}: UpdateGeometry got {} normals for {} vertices", m.what, N.rows(), nv));
  m.caster.UpdateVertices(V);  // checks the shape and finiteness, refits
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nv, 8192), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
      m.V[static_cast<size_t>(i)] = V.row(i).transpose().cast<float>();
      if (N.rows() > 0) m.N[static_cast<size_t>(i)] = N.row(i).transpose().cast<float>().normalized();
    }
  });
  if (N.rows() == 0) m.ComputeNormals();
}

void Renderer::SetMaterials(SceneMaterials materials) { impl_->SetMaterials(std::move(materials)); }

RenderResult Renderer::Render(const Camera& camera, const LightRig& rig, const RenderOptions& options, Rng& rng) const {
  return impl_->Render(camera, rig, options, rng);
}

// ---- Render ---------------------------------------------------------------------------

namespace {

// The lights of `rig` in the head frame. Camera-attached rigs: camera axes, origin at
// the head origin (synth/lights.h).
std::vector<ResolvedLight> ResolveLights(const LightRig& rig, const Mat3f& head_from_cam) {
  const Mat3f head_from_rig = rig.attached_to_camera ? head_from_cam : Mat3f::Identity();
  Mat3f rig_from_env = Mat3f::Identity();
  if (rig.attached_to_camera) rig_from_env.diagonal() << 1.0f, -1.0f, -1.0f;
  std::vector<ResolvedLight> lights;
  for (const Light& light : rig.lights) {
    ResolvedLight r;
    if (const auto* d = std::get_if<DirectionalLight>(&light)) {
      r.kind = LightKind::kDirectional;
      r.direction = (head_from_rig * d->direction.cast<float>()).normalized();
      r.color = kPi * d->color.cast<float>();
    } else if (const auto* s = std::get_if<SphereLight>(&light)) {
      r.kind = LightKind::kSphere;
      r.centre = head_from_rig * s->centre.cast<float>();
      r.radius = static_cast<float>(s->radius);
      r.color = (s->color * (s->centre.squaredNorm() / (s->radius * s->radius))).cast<float>();
      r.samples = s->samples;
    } else if (const auto* e = std::get_if<EnvironmentLight>(&light)) {
      r.kind = LightKind::kEnvironment;
      r.map = e->map.get();
      r.scale = static_cast<float>(e->scale);
      r.samples = e->samples;
      const float a = static_cast<float>(e->rotation_deg * std::numbers::pi / 180.0);
      Mat3f turn;
      turn << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
      r.head_from_env = head_from_rig * rig_from_env * turn;
    } else if (const auto* o = std::get_if<AmbientOcclusionLight>(&light)) {
      r.kind = LightKind::kAmbient;
      r.color = o->color.cast<float>();
      r.max_distance = static_cast<float>(o->max_distance_mm);
      r.samples = o->samples;
    }
    lights.push_back(r);
  }
  return lights;
}

RenderContext MakeContext(const Camera& camera, const LightRig& rig, const RenderOptions& options,
                          uint64_t frame_seed) {
  RenderContext c;
  c.options = &options;
  c.frame_seed = frame_seed;
  c.width = camera.intrinsics.width;
  c.height = camera.intrinsics.height;
  c.fx = static_cast<float>(camera.intrinsics.fx);
  c.fy = static_cast<float>(camera.intrinsics.fy);
  c.cx = static_cast<float>(camera.intrinsics.cx);
  c.cy = static_cast<float>(camera.intrinsics.cy);
  c.cam_from_head_r = camera.cam_from_head.rotation.toRotationMatrix().cast<float>();
  c.head_from_cam = c.cam_from_head_r.transpose();
  c.eye = camera.CentreInHead().cast<float>();
  c.lights = ResolveLights(rig, c.head_from_cam);
  for (size_t k = 0; k < c.lights.size() && options.environment_background; ++k) {
    if (c.lights[k].kind == LightKind::kEnvironment) {
      c.background_env = static_cast<int>(k);
      break;
    }
  }
  c.n_axis = options.samples_per_axis;
  c.num_samples = c.n_axis * c.n_axis;
  c.inv_samples = 1.0f / static_cast<float>(c.num_samples);
  c.sss = options.subsurface_mm > 0.0;
  c.stochastic = c.n_axis > 1;
  for (const ResolvedLight& l : c.lights) c.stochastic = c.stochastic || l.kind != LightKind::kDirectional;
  c.background = ToVec3f(options.background);
  c.eps = static_cast<float>(options.ray_epsilon_mm);
  c.tile = options.tile_size;
  c.tiles_x = (c.width + c.tile - 1) / c.tile;
  c.tiles_y = (c.height + c.tile - 1) / c.tile;
  return c;
}

RenderResult AllocateResult(int width, int height, bool passes) {
  RenderResult out;
  out.image = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(0));
  out.alpha = cv::Mat(height, width, CV_32FC1, cv::Scalar::all(0));
  if (passes) {
    out.depth = cv::Mat(height, width, CV_32FC1, cv::Scalar::all(0));
    out.normal = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(0));
    out.uv = cv::Mat(height, width, CV_32FC2, cv::Scalar::all(0));
    out.triangle_id = cv::Mat(height, width, CV_32SC1, cv::Scalar::all(-1));
    out.part_id = cv::Mat(height, width, CV_32SC1, cv::Scalar::all(-1));
  }
  return out;
}

SubsurfaceBuffers AllocateSubsurface(int width, int height) {
  SubsurfaceBuffers b;
  b.irradiance = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(0));
  b.albedo = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(0));
  b.rest = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(0));
  b.depth = cv::Mat(height, width, CV_32FC1, cv::Scalar::all(0));
  return b;
}

// Tile t's pixels and per-pixel generators, and the tile's sums cleared; false when
// the tile holds no pixel.
bool PrepareTile(const RenderContext& ctx, int t, TileScratch* s) {
  const int x0 = (t % ctx.tiles_x) * ctx.tile, y0 = (t / ctx.tiles_x) * ctx.tile;
  // Pixels in packet order: 4×4 blocks, row-major inside each block.
  s->px.clear();
  s->py.clear();
  for (int by = 0; by < ctx.tile; by += kPacketSide) {
    for (int bx = 0; bx < ctx.tile; bx += kPacketSide) {
      for (int iy = 0; iy < kPacketSide; ++iy) {
        for (int ix = 0; ix < kPacketSide; ++ix) {
          const int x = x0 + bx + ix, y = y0 + by + iy;
          if (x < ctx.width && y < ctx.height) {
            s->px.push_back(x);
            s->py.push_back(y);
          }
        }
      }
    }
  }
  const size_t np = s->px.size();
  if (np == 0) return false;
  s->rngs.clear();
  for (size_t i = 0; i < (ctx.stochastic ? np : 0); ++i) {
    const uint64_t pixel =
        static_cast<uint64_t>(s->py[i]) * static_cast<uint64_t>(ctx.width) + static_cast<uint64_t>(s->px[i]);
    s->rngs.emplace_back(ctx.frame_seed ^ (0x9E3779B97F4A7C15ULL * (pixel + 1)));
  }
  s->rays.resize(np);
  s->surf.resize(np);
  s->has_hit.assign(np, 0);
  s->color.assign(np, Vec3f::Zero());
  s->hit_count.assign(np, 0.0f);
  if (ctx.sss) {
    s->albedo_sum.assign(np, Vec3f::Zero());
    s->irr_sum.assign(np, Vec3f::Zero());
    s->rest_sum.assign(np, Vec3f::Zero());
    s->depth_sum.assign(np, 0.0f);
  }
  s->primary_rays = 0;
  s->shadow_rays = 0;
  return true;
}

// The primary ray through pixel i of the tile at offset (ox, oy) from its centre.
void PrimaryRay(const RenderContext& ctx, size_t i, float ox, float oy, TileScratch* s) {
  const Vec3f d_cam((static_cast<float>(s->px[i]) + ox - ctx.cx) / ctx.fx,
                    (static_cast<float>(s->py[i]) + oy - ctx.cy) / ctx.fy, 1.0f);
  Ray& r = s->rays[i];
  r.origin = ctx.eye;
  r.direction = ctx.head_from_cam * d_cam;  // unnormalised: t is the depth z in mm
  r.tnear = 0.0f;
  r.tfar = std::numeric_limits<float>::infinity();
}

// The primary rays of sample `sample` of every pixel (stratified and jittered when N > 1).
void PrimaryRays(const RenderContext& ctx, int sample, TileScratch* s) {
  const int sx = sample % ctx.n_axis, sy = sample / ctx.n_axis;
  for (size_t i = 0; i < s->px.size(); ++i) {
    float ox = 0.0f, oy = 0.0f;
    if (ctx.n_axis > 1) {
      ox = (static_cast<float>(sx) + static_cast<float>(s->rngs[i].Uniform())) / ctx.n_axis - 0.5f;
      oy = (static_cast<float>(sy) + static_cast<float>(s->rngs[i].Uniform())) / ctx.n_axis - 0.5f;
    }
    PrimaryRay(ctx, i, ox, oy, s);
  }
}

// A light sample at pixel i: radiance·cos from `dir`, weighted by the BRDF; added now
// without shadows, else pending on a shadow ray to `tfar` (coherent or sampled batch).
void Emit(const RenderContext& ctx, bool coherent, size_t i, const Vec3f& dir, float tfar, const Vec3f& radiance_cos,
          TileScratch* s) {
  const Surface& sf = s->surf[i];
  const Pending p{static_cast<int>(i), radiance_cos * sf.brdf.diffuse_weight(), radiance_cos * sf.brdf.Specular(dir)};
  if (!ctx.options->shadows) {
    s->irr[i] += p.irradiance;
    s->spec[i] += p.specular;
    return;
  }
  const Ray r{sf.p + ctx.eps * sf.ng, dir, 0.0f, tfar};
  (coherent ? s->coherent_rays : s->sampled_rays).push_back(r);
  (coherent ? s->coherent_pending : s->sampled_pending).push_back(p);
}

void SampleDirectional(const RenderContext& ctx, const ResolvedLight& light, TileScratch* s) {
  const float inf = std::numeric_limits<float>::infinity();
  for (size_t i = 0; i < s->px.size(); ++i) {
    if (!s->has_hit[i]) continue;
    const float c = s->surf[i].n.dot(light.direction);
    if (c <= 0.0f || s->surf[i].ng.dot(light.direction) <= 0.0f) continue;
    Emit(ctx, true, i, light.direction, inf, light.color * c, s);
  }
}

// Uniform sampling of the cone the sphere subtends, stratified in cos θ.
void SampleSphere(const RenderContext& ctx, const ResolvedLight& light, TileScratch* s) {
  for (int k = 0; k < light.samples; ++k) {
    for (size_t i = 0; i < s->px.size(); ++i) {
      if (!s->has_hit[i]) continue;
      const Surface& sf = s->surf[i];
      const Vec3f wc = light.centre - sf.p;
      const float dist = wc.norm();
      const float xi1 = (static_cast<float>(k) + static_cast<float>(s->rngs[i].Uniform())) / light.samples;
      const float xi2 = static_cast<float>(s->rngs[i].Uniform());
      if (dist <= light.radius * 1.0001f) continue;
      const float sin2 = light.radius * light.radius / (dist * dist);
      const float cos_max = std::sqrt(std::max(0.0f, 1.0f - sin2));
      const float one_minus = sin2 / (1.0f + cos_max);
      const float cos_t = 1.0f - xi1 * one_minus;
      const float sin_t = std::sqrt(std::max(0.0f, 1.0f - cos_t * cos_t));
      const float phi = 2.0f * kPi * xi2;
      const Vec3f w = wc / dist;
      Vec3f u, v;
      Basis(w, &u, &v);
      const Vec3f dir = (sin_t * std::cos(phi) * u + sin_t * std::sin(phi) * v + cos_t * w).normalized();
      const float c = sf.n.dot(dir);
      if (c <= 0.0f || sf.ng.dot(dir) <= 0.0f) continue;
      const float t_hit =
          dist * cos_t - std::sqrt(std::max(0.0f, light.radius * light.radius - dist * dist * sin_t * sin_t));
      const float inv_pdf = 2.0f * kPi * one_minus;
      Emit(ctx, false, i, dir, t_hit * (1.0f - 1e-4f), light.color * (c * inv_pdf / light.samples), s);
    }
  }
}

// Multiple importance sampling (balance heuristic, Veach 1997): n_l samples from the
// map's luminance distribution and n_b cosine-weighted samples; every sample is
// weighted by 1 / (n_l·pdf_l + n_b·pdf_b).
void SampleEnvironment(const RenderContext& ctx, const ResolvedLight& light, TileScratch* s) {
  const float inf = std::numeric_limits<float>::infinity();
  const int n_l = (light.samples + 1) / 2, n_b = light.samples - n_l;
  const Mat3f env_from_head = light.head_from_env.transpose();
  for (int k = 0; k < light.samples; ++k) {
    const bool from_map = k < n_l;
    const int stratum = from_map ? k : k - n_l, strata = from_map ? n_l : n_b;
    for (size_t i = 0; i < s->px.size(); ++i) {
      if (!s->has_hit[i]) continue;
      const Surface& sf = s->surf[i];
      const double u1 = (stratum + s->rngs[i].Uniform()) / strata;
      const double u2 = s->rngs[i].Uniform();
      Vec3f d_env, dir;
      float pdf_l = 0.0f;
      if (from_map) {
        d_env = light.map->Sample(u1, u2, &pdf_l);
        dir = light.head_from_env * d_env;
      } else {
        Vec3f u, v;
        Basis(sf.n, &u, &v);
        const float r = std::sqrt(static_cast<float>(u1)), phi = 2.0f * kPi * static_cast<float>(u2);
        dir = (r * std::cos(phi) * u + r * std::sin(phi) * v +
               std::sqrt(std::max(0.0f, 1.0f - static_cast<float>(u1))) * sf.n)
                  .normalized();
        d_env = env_from_head * dir;
        pdf_l = light.map->Pdf(d_env);
      }
      const float c = sf.n.dot(dir);
      if (c <= 0.0f || sf.ng.dot(dir) <= 0.0f) continue;
      const float denominator = static_cast<float>(n_l) * pdf_l + static_cast<float>(n_b) * c / kPi;
      if (!(denominator > 0.0f)) continue;
      Emit(ctx, false, i, dir, inf, light.map->Radiance(d_env) * (light.scale * c / denominator), s);
    }
  }
}

// Ambient occlusion: cosine-weighted rays up to max_distance; diffuse only.
void SampleAmbient(const RenderContext& ctx, const ResolvedLight& light, TileScratch* s) {
  for (int k = 0; k < light.samples; ++k) {
    for (size_t i = 0; i < s->px.size(); ++i) {
      if (!s->has_hit[i]) continue;
      const Surface& sf = s->surf[i];
      const float xi1 = (static_cast<float>(k) + static_cast<float>(s->rngs[i].Uniform())) / light.samples;
      const float xi2 = static_cast<float>(s->rngs[i].Uniform());
      Vec3f u, v;
      Basis(sf.n, &u, &v);
      const float r = std::sqrt(xi1), phi = 2.0f * kPi * xi2;
      const Vec3f dir =
          (r * std::cos(phi) * u + r * std::sin(phi) * v + std::sqrt(std::max(0.0f, 1.0f - xi1)) * sf.n).normalized();
      if (sf.ng.dot(dir) <= 0.0f) continue;
      // Cosine-weighted: radiance·cos/pdf = radiance·π; diffuse only.
      const Pending p{static_cast<int>(i), light.color * (kPi * sf.brdf.diffuse_weight() / light.samples),
                      Vec3f::Zero()};
      if (!ctx.options->shadows) {
        s->irr[i] += p.irradiance;
        continue;
      }
      s->sampled_rays.push_back(Ray{sf.p + ctx.eps * sf.ng, dir, 0.0f, light.max_distance});
      s->sampled_pending.push_back(p);
    }
  }
}

// Light samples of every light: contributions now, visibility by shadow rays after.
void SampleLights(const RenderContext& ctx, TileScratch* s) {
  s->coherent_rays.clear();
  s->sampled_rays.clear();
  s->coherent_pending.clear();
  s->sampled_pending.clear();
  for (const ResolvedLight& light : ctx.lights) {
    switch (light.kind) {
      case LightKind::kDirectional:
        SampleDirectional(ctx, light, s);
        break;
      case LightKind::kSphere:
        SampleSphere(ctx, light, s);
        break;
      case LightKind::kEnvironment:
        SampleEnvironment(ctx, light, s);
        break;
      case LightKind::kAmbient:
        SampleAmbient(ctx, light, s);
        break;
    }
  }
}

// Adds this sample's light to the pixels' sums (and the subsurface sums apart).
void AccumulateSample(const RenderContext& ctx, TileScratch* s) {
  for (size_t i = 0; i < s->px.size(); ++i) {
    const Vec3f albedo = s->has_hit[i] ? s->surf[i].brdf.albedo() : Vec3f::Zero();
    s->color[i] += albedo.cwiseProduct(s->irr[i]) + s->spec[i];
    if (ctx.sss) {
      s->irr_sum[i] += s->irr[i];
      s->rest_sum[i] += s->spec[i];
    }
  }
}

// The tile's pixel means: image and alpha (and the subsurface buffers).
void StoreTile(const RenderContext& ctx, const TileScratch& s, RenderResult* out, SubsurfaceBuffers* sss) {
  const float inv_samples = ctx.inv_samples;
  for (size_t i = 0; i < s.px.size(); ++i) {
    const int x = s.px[i], y = s.py[i];
    const Vec3f c = s.color[i] * inv_samples;
    out->image.at<cv::Vec3f>(y, x) = cv::Vec3f(c.x(), c.y(), c.z());
    out->alpha.at<float>(y, x) = s.hit_count[i] * inv_samples;
    if (ctx.sss) {
      const Vec3f ir = s.irr_sum[i] * inv_samples, re = s.rest_sum[i] * inv_samples;
      const Vec3f al = s.hit_count[i] > 0 ? Vec3f(s.albedo_sum[i] / s.hit_count[i]) : Vec3f::Zero();
      sss->irradiance.at<cv::Vec3f>(y, x) = cv::Vec3f(ir.x(), ir.y(), ir.z());
      sss->rest.at<cv::Vec3f>(y, x) = cv::Vec3f(re.x(), re.y(), re.z());
      sss->albedo.at<cv::Vec3f>(y, x) = cv::Vec3f(al.x(), al.y(), al.z());
      sss->depth.at<float>(y, x) = s.hit_count[i] > 0 ? s.depth_sum[i] / s.hit_count[i] : 0.0f;
    }
  }
}

// One pass of the separable, depth-aware Gaussian blur of the diffuse irradiance; σ
// per channel in mm (red 1, green 0.5, blue 0.25 × subsurface_mm), in pixels fx·σ/z.
cv::Mat BlurSubsurface(const RenderContext& ctx, const cv::Mat& depth, const cv::Mat& src, bool horizontal) {
  const float channel_scale[3] = {1.0f, 0.5f, 0.25f};
  const float subsurface_mm = static_cast<float>(ctx.options->subsurface_mm);
  const float sigma_z = static_cast<float>(2.0 * ctx.options->subsurface_mm + 0.5);  // mm
  constexpr int kMaxRadius = 48;
  const int width = ctx.width, height = ctx.height;
  cv::Mat dst(height, width, CV_32FC3, cv::Scalar::all(0));
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 4), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < width; ++x) {
        const float z = depth.at<float>(y, x);
        if (z <= 0.0f) {
          dst.at<cv::Vec3f>(y, x) = src.at<cv::Vec3f>(y, x);
          continue;
        }
        cv::Vec3f result;
        for (int c = 0; c < 3; ++c) {
          const float sigma_px = subsurface_mm * channel_scale[c] * ctx.fx / z;
          const int radius = std::min(kMaxRadius, static_cast<int>(std::ceil(2.5f * sigma_px)));
          if (radius < 1) {
            result[c] = src.at<cv::Vec3f>(y, x)[c];
            continue;
          }
          float sum = 0.0f, wsum = 0.0f;
          for (int k = -radius; k <= radius; ++k) {
            const int xx = horizontal ? x + k : x, yy = horizontal ? y : y + k;
            if (xx < 0 || yy < 0 || xx >= width || yy >= height) continue;
            const float zz = depth.at<float>(yy, xx);
            if (zz <= 0.0f) continue;
            const float dz = (zz - z) / sigma_z;
            const float w = std::exp(-0.5f * (static_cast<float>(k * k) / (sigma_px * sigma_px) + dz * dz));
            sum += w * src.at<cv::Vec3f>(yy, xx)[c];
            wsum += w;
          }
          result[c] = sum / wsum;
        }
        dst.at<cv::Vec3f>(y, x) = result;
      }
    }
  });
  return dst;
}

// The screen-space subsurface approximation: image = albedo · blurred irradiance + rest.
void ApplySubsurface(const RenderContext& ctx, const SubsurfaceBuffers& sss, cv::Mat* image) {
  const cv::Mat blurred = BlurSubsurface(ctx, sss.depth, BlurSubsurface(ctx, sss.depth, sss.irradiance, true), false);
  tbb::parallel_for(tbb::blocked_range<int>(0, ctx.height, 8), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < ctx.width; ++x) {
        const cv::Vec3f& a = sss.albedo.at<cv::Vec3f>(y, x);
        const cv::Vec3f& b = blurred.at<cv::Vec3f>(y, x);
        const cv::Vec3f& r = sss.rest.at<cv::Vec3f>(y, x);
        image->at<cv::Vec3f>(y, x) = cv::Vec3f(a[0] * b[0] + r[0], a[1] * b[1] + r[1], a[2] * b[2] + r[2]);
      }
    }
  });
}

}  // namespace

// The camera, lights and sampling resolved once (MakeContext); tiles in parallel
// (RenderTile); then the subsurface blur (ApplySubsurface).
RenderResult Renderer::Impl::Render(const Camera& camera, const LightRig& rig, const RenderOptions& options,
                                    Rng& rng) const {
  const auto start = std::chrono::steady_clock::now();
  options.Check();
  camera.intrinsics.Validate("Render camera");
  ValidateLightRig(rig);
  const RenderContext ctx = MakeContext(camera, rig, options, rng.NextU64());
  RenderResult out = AllocateResult(ctx.width, ctx.height, options.passes);
  SubsurfaceBuffers sss;
  if (ctx.sss) sss = AllocateSubsurface(ctx.width, ctx.height);

  std::atomic<int64_t> primary_rays{0}, shadow_rays{0};
  const int num_tiles = ctx.tiles_x * ctx.tiles_y;
  tbb::parallel_for(tbb::blocked_range<int>(0, num_tiles, 1), [&](const tbb::blocked_range<int>& range) {
    TileScratch s;  // reused across this range's tiles
    for (int t = range.begin(); t != range.end(); ++t) {
      if (!PrepareTile(ctx, t, &s)) continue;
      RenderTile(ctx, &s, &out, &sss);
      primary_rays += s.primary_rays;
      shadow_rays += s.shadow_rays;
    }
  });
  if (ctx.sss) ApplySubsurface(ctx, sss, &out.image);

  out.stats.primary_rays = primary_rays.load();
  out.stats.shadow_rays = shadow_rays.load();
  out.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

void Renderer::Impl::RenderTile(const RenderContext& ctx, TileScratch* s, RenderResult* out,
                                SubsurfaceBuffers* sss) const {
  const auto np = static_cast<int64_t>(s->px.size());
  for (int sample = 0; sample < ctx.num_samples; ++sample) {
    PrimaryRays(ctx, sample, s);
    caster.IntersectBatch(s->rays, &s->hits, RayCoherence::kCoherent);
    if (ctx.options->passes && ctx.n_axis == 1) WritePasses(ctx, *s, out);
    ShadeHits(ctx, s);
    SampleLights(ctx, s);
    TraceShadows(s->coherent_rays, s->coherent_pending, RayCoherence::kCoherent, s);
    TraceShadows(s->sampled_rays, s->sampled_pending, RayCoherence::kIncoherent, s);
    AccumulateSample(ctx, s);
  }
  if (ctx.options->passes && ctx.n_axis > 1) {  // passes from the pixel centres
    for (size_t i = 0; i < s->px.size(); ++i) PrimaryRay(ctx, i, 0.0f, 0.0f, s);
    caster.IntersectBatch(s->rays, &s->hits, RayCoherence::kCoherent);
    WritePasses(ctx, *s, out);
    s->primary_rays += np;
  }
  StoreTile(ctx, *s, out, sss);
  s->primary_rays += np * ctx.num_samples;
}

Vec3f Renderer::Impl::Interpolate(const Hit& h, const std::vector<Vec3f>& a) const {
  const float b1 = h.u, b2 = h.v, b0 = 1.0f - b1 - b2;
  return Vec3f(b0 * a[static_cast<size_t>(F(h.triangle, 0))] + b1 * a[static_cast<size_t>(F(h.triangle, 1))] +
               b2 * a[static_cast<size_t>(F(h.triangle, 2))]);
}

Eigen::Vector2f Renderer::Impl::InterpolateUv(const Hit& h) const {
  const float b1 = h.u, b2 = h.v, b0 = 1.0f - b1 - b2;
  return Eigen::Vector2f(b0 * UV[static_cast<size_t>(F(h.triangle, 0))] +
                         b1 * UV[static_cast<size_t>(F(h.triangle, 1))] +
                         b2 * UV[static_cast<size_t>(F(h.triangle, 2))]);
}

void Renderer::Impl::Orient(const Hit& h, const Vec3f& d, Vec3f* n, Vec3f* ng) const {
  *ng = h.geometric_normal;
  if (ng->dot(d) > 0.0f) *ng = -*ng;
  Vec3f s = Interpolate(h, N);
  const float len = s.norm();
  s = len > 1e-12f ? Vec3f(s / len) : *ng;
  if (s.dot(*ng) < 0.0f) s = -s;
  *n = s;
}

void Renderer::Impl::WritePasses(const RenderContext& ctx, const TileScratch& s, RenderResult* out) const {
  for (size_t i = 0; i < s.px.size(); ++i) {
    const Hit& h = s.hits[i];
    if (!h.valid()) continue;
    const int x = s.px[i], y = s.py[i];
    Vec3f n, ng;
    Orient(h, s.rays[i].direction, &n, &ng);
    const Vec3f n_cam = ctx.cam_from_head_r * n;
    const Eigen::Vector2f uv = InterpolateUv(h);
    out->depth.at<float>(y, x) = h.t;
    out->normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n_cam.x(), n_cam.y(), n_cam.z());
    out->uv.at<cv::Vec2f>(y, x) = cv::Vec2f(uv.x(), uv.y());
    out->triangle_id.at<int>(y, x) = h.triangle;
    out->part_id.at<int>(y, x) = tri_part[static_cast<size_t>(h.triangle)];
  }
}

void Renderer::Impl::ShadeHits(const RenderContext& ctx, TileScratch* s) const {
  const size_t np = s->px.size();
  s->irr.assign(np, Vec3f::Zero());
  s->spec.assign(np, Vec3f::Zero());
  for (size_t i = 0; i < np; ++i) {
    const Hit& h = s->hits[i];
    s->has_hit[i] = h.valid() ? 1 : 0;
    if (!h.valid()) {
      Vec3f bg = ctx.background;
      if (ctx.background_env >= 0) {
        const ResolvedLight& env = ctx.lights[static_cast<size_t>(ctx.background_env)];
        const Vec3f d_env = env.head_from_env.transpose() * s->rays[i].direction.normalized();
        bg = env.scale * env.map->Radiance(d_env);
      }
      s->spec[i] = bg;  // passes through unchanged
      continue;
    }
    Surface& sf = s->surf[i];
    const Vec3f d = s->rays[i].direction;
    Orient(h, d, &sf.n, &sf.ng);
    const float b1 = h.u, b2 = h.v, b0 = 1.0f - b1 - b2;
    sf.p = b0 * V[static_cast<size_t>(F(h.triangle, 0))] + b1 * V[static_cast<size_t>(F(h.triangle, 1))] +
           b2 * V[static_cast<size_t>(F(h.triangle, 2))];
    const Material mat = MaterialAt(h.triangle, InterpolateUv(h));
    sf.brdf = PreparedBrdf(mat, sf.n, -d.normalized());
    s->hit_count[i] += 1.0f;
    if (ctx.sss) {
      s->albedo_sum[i] += mat.albedo;
      s->depth_sum[i] += h.t;
    }
  }
}

void Renderer::Impl::TraceShadows(const std::vector<Ray>& rays, const std::vector<Pending>& pending,
                                  RayCoherence coherence, TileScratch* s) const {
  if (rays.empty()) return;
  caster.OccludedBatch(rays, &s->occluded, coherence);
  for (size_t k = 0; k < rays.size(); ++k) {
    if (s->occluded[k]) continue;
    s->irr[static_cast<size_t>(pending[k].pixel)] += pending[k].irradiance;
    s->spec[static_cast<size_t>(pending[k].pixel)] += pending[k].specular;
  }
  s->shadow_rays += static_cast<int64_t>(rays.size());
}

// ---- Motion blur ------------------------------------------------------------------------

RenderResult RenderMotionBlurred(Renderer& renderer, const std::function<MotionBlurFrame(double)>& frame_at,
                                 int subframes, const LightRig& rig, const RenderOptions& options, Rng& rng) {
  Require(subframes >= 1, fmt::format("RenderMotionBlurred: subframes = {} must be >= 1", subframes));
  const auto start = std::chrono::steady_clock::now();
  RenderResult out;
  const int middle = subframes / 2;  // nearest to s = 0.5 (the lower one for even counts)
  for (int k = 0; k < subframes; ++k) {
    const MotionBlurFrame f = frame_at((k + 0.5) / subframes);
    renderer.UpdateGeometry(f.V);
    RenderResult r = renderer.Render(f.camera, rig, options, rng);
    if (k == 0) {
      out.image = r.image / subframes;
      out.alpha = r.alpha / subframes;
    } else {
      out.image += r.image / subframes;
      out.alpha += r.alpha / subframes;
    }
    if (k == middle) {
      out.depth = r.depth;
      out.normal = r.normal;
      out.uv = r.uv;
      out.triangle_id = r.triangle_id;
      out.part_id = r.part_id;
    }
    out.stats.primary_rays += r.stats.primary_rays;
    out.stats.shadow_rays += r.stats.shadow_rays;
  }
  out.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

RenderResult RenderMotionBlurred(Renderer& renderer, const MotionBlurFrame& open, const MotionBlurFrame& close,
                                 int subframes, const LightRig& rig, const RenderOptions& options, Rng& rng) {
  Require(open.V.rows() == close.V.rows(),
          fmt::format("RenderMotionBlurred: {} vertices at shutter open but {} at close", open.V.rows(), close.V.rows()));
  return RenderMotionBlurred(
      renderer,
      [&](double s) {
        MotionBlurFrame f;
        f.V = (1.0 - s) * open.V + s * close.V;
        f.camera.intrinsics = open.camera.intrinsics;
        f.camera.cam_from_head = Rigid3d(open.camera.cam_from_head.rotation.slerp(s, close.camera.cam_from_head.rotation),
                                         (1.0 - s) * open.camera.cam_from_head.translation +
                                             s * close.camera.cam_from_head.translation);
        return f;
      },
      subframes, rig, options, rng);
}

}  // namespace crease
