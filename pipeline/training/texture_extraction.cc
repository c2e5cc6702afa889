#include "pipeline/training/texture_extraction.h"

#include <cmath>
#include <fmt/format.h>
#include <numbers>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"

namespace crease {

void TextureOptions::VisitFields(OptionVisitor& v) {
  v.Field("max_view_angle_deg", max_view_angle_deg);
  v.Field("view_weight_power", view_weight_power);
  v.Field("visibility_offset_mm", visibility_offset_mm);
}

void TextureOptions::Check() const {
  const char* o = "TextureOptions";
  CheckGt(o, "max_view_angle_deg", max_view_angle_deg, 0.0);
  CheckLe(o, "max_view_angle_deg", max_view_angle_deg, 90.0);
  CheckGe(o, "view_weight_power", view_weight_power, 0.0);
  CheckGe(o, "visibility_offset_mm", visibility_offset_mm, 0.0);
}

cv::Mat Luminance(const cv::Mat& linear_rgb) {
  if (linear_rgb.type() == CV_32F) return linear_rgb.clone();
  Require(linear_rgb.type() == CV_32FC3, "Luminance: expected a CV_32FC3 or CV_32F image");
  cv::Mat out(linear_rgb.size(), CV_32F);
  for (int j = 0; j < linear_rgb.rows; ++j) {
    const cv::Vec3f* p = linear_rgb.ptr<cv::Vec3f>(j);
    float* q = out.ptr<float>(j);
    for (int i = 0; i < linear_rgb.cols; ++i) q[i] = 0.2126f * p[i][0] + 0.7152f * p[i][1] + 0.0722f * p[i][2];
  }
  return out;
}

namespace {

// Bilinear sample of a CV_32FC3 image at pixel (x, y) (pixel centres at integers).
cv::Vec3f Bilinear(const cv::Mat& im, double x, double y) {
  const int x0 = std::clamp(static_cast<int>(std::floor(x)), 0, im.cols - 1);
  const int y0 = std::clamp(static_cast<int>(std::floor(y)), 0, im.rows - 1);
  const int x1 = std::min(x0 + 1, im.cols - 1), y1 = std::min(y0 + 1, im.rows - 1);
  const float fx = static_cast<float>(std::clamp(x - x0, 0.0, 1.0));
  const float fy = static_cast<float>(std::clamp(y - y0, 0.0, 1.0));
  const cv::Vec3f a = im.at<cv::Vec3f>(y0, x0), b = im.at<cv::Vec3f>(y0, x1);
  const cv::Vec3f c = im.at<cv::Vec3f>(y1, x0), d = im.at<cv::Vec3f>(y1, x1);
  return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
}

}  // namespace

ExtractedTexture ExtractTexture(const TriMesh& mesh, const UvRaster& raster, const RayCaster* caster,
                                const std::vector<Camera>& cameras, const std::vector<cv::Mat>& images,
                                const TextureOptions& options, const MatX3d* view_normals) {
  options.Check();
  Require(cameras.size() == images.size() && !cameras.empty(),
          fmt::format("ExtractTexture: {} cameras but {} images", cameras.size(), images.size()));
  Require(raster.num_triangles == mesh.num_faces(), "ExtractTexture: the UV raster was made for another mesh");
  std::vector<cv::Mat> rgb(images.size());
  for (size_t c = 0; c < images.size(); ++c) {
    const cv::Mat& im = images[c];
    Require(im.type() == CV_32FC3 || im.type() == CV_32F,
            fmt::format("ExtractTexture: image of camera {} must be linear float (CV_32FC3 or CV_32F)", c));
    Require(im.cols == cameras[c].intrinsics.width && im.rows == cameras[c].intrinsics.height,
            fmt::format("ExtractTexture: image of camera {} is {}×{} but its calibration says {}×{}", c, im.cols,
                        im.rows, cameras[c].intrinsics.width, cameras[c].intrinsics.height));
    if (im.type() == CV_32F) {
      cv::Mat planes[] = {im, im, im};
      cv::merge(planes, 3, rgb[c]);
    } else {
      rgb[c] = im;
    }
  }
  Require(!view_normals || view_normals->rows() == mesh.num_vertices(),
          fmt::format("ExtractTexture: {} view normals for a mesh of {} vertices",
                      view_normals ? view_normals->rows() : 0, mesh.num_vertices()));
  const MatX3d normals = view_normals ? *view_normals : VertexNormals(mesh);
  const int W = raster.width, H = raster.height;
  ExtractedTexture out;
  out.color = cv::Mat::zeros(H, W, CV_32FC3);
  out.weight = cv::Mat::zeros(H, W, CV_32F);
  out.seen = cv::Mat::zeros(H, W, CV_8U);
  const double cos_limit = std::cos(options.max_view_angle_deg * std::numbers::pi / 180.0);
  std::vector<Eigen::Vector3d> centres;
  for (const auto& cam : cameras) centres.push_back(cam.CentreInHead());
  tbb::parallel_for(tbb::blocked_range<int>(0, H, 8), [&](const tbb::blocked_range<int>& rows) {
    for (int j = rows.begin(); j < rows.end(); ++j) {
      cv::Vec3f* col = out.color.ptr<cv::Vec3f>(j);
      float* wt = out.weight.ptr<float>(j);
      uint8_t* seen = out.seen.ptr<uint8_t>(j);
      for (int i = 0; i < W; ++i) {
        const int k = raster.index(i, j);
        const int t = raster.triangle[k];
        if (t < 0) continue;
        const Eigen::Vector3f& b = raster.barycentric[k];
        Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
        for (int c = 0; c < 3; ++c) {
          p += b[c] * mesh.V.row(mesh.F(t, c)).transpose();
          n += b[c] * normals.row(mesh.F(t, c)).transpose();
        }
        if (!(n.norm() > 0.0)) continue;
        n.normalize();
        cv::Vec3f sum(0, 0, 0);
        double wsum = 0.0;
        for (size_t c = 0; c < cameras.size(); ++c) {
          Eigen::Vector3d to_cam = centres[c] - p;
          const double dist = to_cam.norm();
          to_cam /= dist;
          const double cosine = n.dot(to_cam);
          if (cosine < cos_limit) continue;
          const Eigen::Vector2d px = cameras[c].Project(p);
          if (!px.allFinite() || !cameras[c].InImage(px)) continue;
          if (caster) {
            Ray ray;
            ray.origin = (p + options.visibility_offset_mm * n).cast<float>();
            ray.direction = to_cam.cast<float>();
            ray.tfar = static_cast<float>(dist);
            if (caster->Occluded(ray)) continue;
          }
          const double w = std::pow(cosine, options.view_weight_power);
          sum += static_cast<float>(w) * Bilinear(rgb[c], px.x(), px.y());
          wsum += w;
        }
        if (wsum > 0.0) {
          col[i] = sum / static_cast<float>(wsum);
          wt[i] = static_cast<float>(wsum);
          seen[i] = 255;
        }
      }
    }
  });
  out.gray = Luminance(out.color);
  return out;
}

}  // namespace crease
