#include "core/preview_render.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <fmt/format.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/ray_caster.h"

namespace crease {

void PreviewRenderOptions::VisitFields(OptionVisitor& v) {
  v.Field("width", width);
  v.Field("height", height);
  v.Field("fov_deg", fov_deg);
  v.Field("azimuth_deg", azimuth_deg);
  v.Field("elevation_deg", elevation_deg);
  v.Field("margin", margin);
  v.Field("base_color", base_color);
  v.Field("background", background);
  v.Field("key_light_dir", key_light_dir);
  v.Field("key_intensity", key_intensity);
  v.Field("fill_intensity", fill_intensity);
  v.Field("ambient", ambient);
  v.Field("shadows", shadows);
}

void PreviewRenderOptions::Check() const {
  const char* o = "PreviewRenderOptions";
  CheckGe(o, "width", width, 8);
  CheckGe(o, "height", height, 8);
  CheckLe(o, "width", width, 16384);
  CheckLe(o, "height", height, 16384);
  CheckGt(o, "fov_deg", fov_deg, 1.0);
  CheckLt(o, "fov_deg", fov_deg, 170.0);
  CheckGt(o, "margin", margin, 0.0);
  CheckGe(o, "key_intensity", key_intensity, 0.0);
  CheckGe(o, "fill_intensity", fill_intensity, 0.0);
  CheckGe(o, "ambient", ambient, 0.0);
  for (const auto* f : {&base_color, &background, &key_light_dir}) {
    Require(f->size() == 3, fmt::format("{}: colours and directions need 3 values", o));
  }
  Require(Eigen::Vector3d(key_light_dir[0], key_light_dir[1], key_light_dir[2]).norm() > 0,
          "PreviewRenderOptions.key_light_dir must not be zero");
}

PreviewRender RenderPreview(const TriMesh& mesh, const PreviewRenderOptions& options,
                            const MatX3d& vertex_colors) {
  options.Check();
  ValidateMesh(mesh, "RenderPreview mesh");
  Require(vertex_colors.rows() == 0 || vertex_colors.rows() == mesh.num_vertices(),
          fmt::format("RenderPreview: {} vertex colours for {} vertices", vertex_colors.rows(),
                      mesh.num_vertices()));
  const RayCaster caster(mesh, {}, "RenderPreview mesh");
  const MatX3d N = mesh.has_normals() ? mesh.N : VertexNormals(mesh);

  // Frame the bounding sphere of the referenced vertices.
  const auto [lo, hi] = BoundingBox(mesh);
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double radius = std::max(0.5 * (hi - lo).norm(), 1e-6);
  const double deg = std::numbers::pi / 180.0;
  const double az = options.azimuth_deg * deg, el = options.elevation_deg * deg;
  const Eigen::Vector3d view_dir(std::sin(az) * std::cos(el), std::sin(el), std::cos(az) * std::cos(el));
  const CameraIntrinsics K = CameraIntrinsics::FromFov(options.fov_deg, options.width, options.height);
  const double half_fov = 0.5 * std::min(options.fov_deg * deg,
                                         2.0 * std::atan(0.5 * options.height / K.fy));
  const double distance = radius * options.margin / std::sin(half_fov);
  PreviewRender out;
  out.camera = LookAtCamera(K, centre + distance * view_dir, centre, Eigen::Vector3d::UnitY());
  const Eigen::Vector3d eye = out.camera.CentreInHead();

  const int w = options.width, h = options.height;
  std::vector<Ray> rays(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      Ray& r = rays[static_cast<size_t>(y) * w + x];
      r.origin = eye.cast<float>();
      r.direction = out.camera.PixelRayInHead(x, y).cast<float>();
    }
  }
  std::vector<Hit> hits;
  caster.IntersectBatch(rays, &hits, RayCoherence::kCoherent);

  const Eigen::Vector3d key = Eigen::Vector3d(options.key_light_dir[0], options.key_light_dir[1],
                                              options.key_light_dir[2]).normalized();
  // Shading normals and shadow rays for the pixels that hit.
  std::vector<Eigen::Vector3d> normal(hits.size()), albedo(hits.size());
  std::vector<Ray> shadow_rays(hits.size());
  const double eps = 1e-4 * radius;
  for (size_t i = 0; i < hits.size(); ++i) {
    const Hit& hit = hits[i];
    if (!hit.valid()) {
      shadow_rays[i].tfar = -1.0f;  // empty segment: never occluded, skipped below
      continue;
    }
    const double b1 = hit.u, b2 = hit.v, b0 = 1.0 - b1 - b2;
    const int i0 = mesh.F(hit.triangle, 0), i1 = mesh.F(hit.triangle, 1), i2 = mesh.F(hit.triangle, 2);
    Eigen::Vector3d n = b0 * N.row(i0) + b1 * N.row(i1) + b2 * N.row(i2);
    const Eigen::Vector3d ng = hit.geometric_normal.cast<double>();
    if (n.squaredNorm() < 1e-20) n = ng;
    n.normalize();
    const Eigen::Vector3d d = rays[i].direction.cast<double>();
    if (n.dot(d) > 0) n = -n;  // two-sided
    normal[i] = n;
    albedo[i] = vertex_colors.rows() > 0
                    ? Eigen::Vector3d(b0 * vertex_colors.row(i0) + b1 * vertex_colors.row(i1) +
                                      b2 * vertex_colors.row(i2))
                    : Eigen::Vector3d(options.base_color[0], options.base_color[1], options.base_color[2]);
    const Eigen::Vector3d p = eye + static_cast<double>(hit.t) * d;
    const Eigen::Vector3d offset = (ng.dot(d) > 0 ? -ng : ng) * eps;
    shadow_rays[i].origin = (p + offset).cast<float>();
    shadow_rays[i].direction = key.cast<float>();
    shadow_rays[i].tnear = 0.0f;
    shadow_rays[i].tfar = options.shadows && n.dot(key) > 0 ? std::numeric_limits<float>::infinity() : -1.0f;
  }
  std::vector<uint8_t> occluded;
  caster.OccludedBatch(shadow_rays, &occluded);

  out.image.create(h, w, CV_32FC3);
  out.triangle_id.create(h, w, CV_32SC1);
  const Eigen::Vector3d bg(options.background[0], options.background[1], options.background[2]);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      Eigen::Vector3d c = bg;
      out.triangle_id.at<int>(y, x) = hits[i].triangle;
      if (hits[i].valid()) {
        ++out.covered_pixels;
        const Eigen::Vector3d d = rays[i].direction.cast<double>();
        const double key_term = (options.shadows && occluded[i]) ? 0.0 : std::max(0.0, normal[i].dot(key));
        const double fill_term = std::max(0.0, -normal[i].dot(d));
        c = albedo[i] * (options.ambient + options.key_intensity * key_term + options.fill_intensity * fill_term);
      }
      out.image.at<cv::Vec3f>(y, x) = cv::Vec3f(static_cast<float>(c.x()), static_cast<float>(c.y()),
                                                static_cast<float>(c.z()));
    }
  }
  return out;
}

MatX3d ScalarToColors(const Eigen::VectorXd& values, double lo, double hi, bool diverging) {
  MatX3d colors(values.size(), 3);
  const double span = hi > lo ? hi - lo : 1.0;
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    const double s = std::clamp((values[i] - lo) / span, 0.0, 1.0);
    Eigen::Vector3d c;
    if (diverging) {  // blue → white → red
      const Eigen::Vector3d blue(0.02, 0.15, 0.6), white(0.85, 0.85, 0.85), red(0.6, 0.03, 0.03);
      c = s < 0.5 ? Eigen::Vector3d(blue + (white - blue) * (2 * s)) : Eigen::Vector3d(white + (red - white) * (2 * s - 1));
    } else {  // dark blue → teal → yellow (viridis-like, linear RGB)
      const Eigen::Vector3d a(0.05, 0.0, 0.1), b(0.02, 0.3, 0.3), d(0.95, 0.85, 0.02);
      c = s < 0.5 ? Eigen::Vector3d(a + (b - a) * (2 * s)) : Eigen::Vector3d(b + (d - b) * (2 * s - 1));
    }
    colors.row(i) = c.transpose();
  }
  return colors;
}

}  // namespace crease
