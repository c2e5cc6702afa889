// Per-frame texture T^t with visibility (paper Sec. 5.1) and the mesoscopic map
// D^HF (Sec. 5.3); see frame_texture.h for the definitions and the differences
// from the paper.
#include "pipeline/capture/frame_texture.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/image_filter.h"
#include "core/options.h"

namespace crease {

namespace {

// Vertices nearer than this to the camera plane are "behind" (mm).
constexpr double kNearMm = 1.0;
// tan θ is capped here in the depth tolerance (θ → 90° at silhouettes).
constexpr double kMaxTan = 10.0;

template <class F>
void ForRows(int rows, int grain, const F& f) {
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, grain), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) f(y);
  });
}

void RequireVertices(const MatX3d& V, int num_vertices, const char* what) {
  Require(V.rows() == num_vertices,
          fmt::format("{}: cam_vertices has {} rows, the rig has {} vertices", what, V.rows(), num_vertices));
  for (int i = 0; i < V.rows(); ++i) {
    if (!std::isfinite(V(i, 0)) || !std::isfinite(V(i, 1)) || !std::isfinite(V(i, 2))) {
      throw Error(fmt::format("{}: cam_vertices row {} is not finite ({}, {}, {})", what, i, V(i, 0), V(i, 1),
                              V(i, 2)));
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------
// Options.

void FrameTextureOptions::VisitFields(OptionVisitor& v) {
  v.Field("map_resolution", map_resolution);
  v.Field("max_view_angle_deg", max_view_angle_deg);
  v.Field("depth_tolerance_mm", depth_tolerance_mm);
  v.Field("erode_seen_texels", erode_seen_texels);
  v.Field("temporal_weight", temporal_weight);
}

void FrameTextureOptions::Check() const {
  const char* o = "FrameTextureOptions";
  CheckGe(o, "map_resolution", map_resolution, 2);
  CheckLe(o, "map_resolution", map_resolution, 8192);
  CheckGt(o, "max_view_angle_deg", max_view_angle_deg, 0.0);
  CheckLt(o, "max_view_angle_deg", max_view_angle_deg, 90.0);
  CheckGe(o, "depth_tolerance_mm", depth_tolerance_mm, 0.0);
  CheckLe(o, "depth_tolerance_mm", depth_tolerance_mm, 1000.0);
  CheckGe(o, "erode_seen_texels", erode_seen_texels, 0);
  CheckLe(o, "erode_seen_texels", erode_seen_texels, 64);
  CheckGe(o, "temporal_weight", temporal_weight, 0.0);
  CheckLe(o, "temporal_weight", temporal_weight, 0.95);
}

void BlendTextureHistory(double weight, FrameTexture* texture, FrameTexture* history) {
  cv::Mat& g = texture->gray;
  const cv::Mat& s = texture->seen;
  Require(g.type() == CV_32FC1 && s.type() == CV_8UC1 && g.size() == s.size(),
          "BlendTextureHistory: expected a CV_32F texture and a CV_8U seen mask of one size");
  if (history->gray.empty()) {
    history->gray = g.clone();
    history->seen = s.clone();
    history->num_seen = texture->num_seen;
    return;
  }
  Require(history->gray.size() == g.size() && history->gray.type() == CV_32FC1 && history->seen.size() == s.size() &&
              history->seen.type() == CV_8UC1,
          fmt::format("BlendTextureHistory: the history is {}x{}, the texture {}x{}", history->gray.cols,
                      history->gray.rows, g.cols, g.rows));
  // One pass, in place: blend where both saw the texel, then the result becomes the history.
  const float a = static_cast<float>(weight), b = 1.0f - a;
  tbb::parallel_for(tbb::blocked_range<int>(0, g.rows, 64), [&](const tbb::blocked_range<int>& rows) {
    for (int j = rows.begin(); j < rows.end(); ++j) {
      float* cur = g.ptr<float>(j);
      const uint8_t* seen = s.ptr<uint8_t>(j);
      float* hist = history->gray.ptr<float>(j);
      uint8_t* hist_seen = history->seen.ptr<uint8_t>(j);
      for (int i = 0; i < g.cols; ++i) {
        if (seen[i] && hist_seen[i]) cur[i] = b * cur[i] + a * hist[i];
        hist[i] = cur[i];
        hist_seen[i] = seen[i];
      }
    }
  });
  history->num_seen = texture->num_seen;
}

void MesoscopicOptions::VisitFields(OptionVisitor& v) {
  v.Field("small_kernel", meso_small_kernel);
  v.Field("large_kernel", meso_large_kernel);
  v.Field("scale", meso_scale);
  v.Field("reference_resolution", meso_reference_resolution);
}

void MesoscopicOptions::Check() const {
  const char* o = "MesoscopicOptions";
  CheckGe(o, "meso_small_kernel", meso_small_kernel, 1);
  Require(meso_small_kernel % 2 == 1,
          fmt::format("MesoscopicOptions.meso_small_kernel = {} must be odd (a window width)", meso_small_kernel));
  CheckGt(o, "meso_large_kernel", meso_large_kernel, meso_small_kernel);
  CheckLe(o, "meso_large_kernel", meso_large_kernel, 255);
  Require(meso_large_kernel % 2 == 1,
          fmt::format("MesoscopicOptions.meso_large_kernel = {} must be odd (a window width)", meso_large_kernel));
  Require(std::isfinite(meso_scale), "MesoscopicOptions.meso_scale must be finite");
  CheckGe(o, "meso_reference_resolution", meso_reference_resolution, 0);
}

// ---------------------------------------------------------------------------
// RigVertexNormals.

RigVertexNormals::RigVertexNormals(const TriMesh& neutral) : num_vertices_(neutral.num_vertices()), F_(neutral.F) {
  const std::vector<int> rep = CoincidentVertexRepresentatives(neutral);
  for (int v = 0; v < num_vertices_; ++v) {
    if (rep[static_cast<size_t>(v)] != v) seam_pairs_.emplace_back(v, rep[static_cast<size_t>(v)]);
  }
}

void RigVertexNormals::Compute(const MatX3d& V, MatX3d* N) const {
  Require(V.rows() == num_vertices_,
          fmt::format("RigVertexNormals: {} vertices given, the mesh has {}", V.rows(), num_vertices_));
  N->setZero(num_vertices_, 3);
  for (int f = 0; f < F_.rows(); ++f) {
    const int a = F_(f, 0), b = F_(f, 1), c = F_(f, 2);
    const Eigen::Vector3d p0 = V.row(a).transpose();
    const Eigen::Vector3d n = (V.row(b).transpose() - p0).cross(V.row(c).transpose() - p0);
    N->row(a) += n.transpose();
    N->row(b) += n.transpose();
    N->row(c) += n.transpose();
  }
  // Seam copies that still coincide share the sum over the group (as VertexNormals).
  for (const auto& [copy, r] : seam_pairs_) {
    if (V.row(copy) == V.row(r)) N->row(r) += N->row(copy);
  }
  for (const auto& [copy, r] : seam_pairs_) {
    if (V.row(copy) == V.row(r)) N->row(copy) = N->row(r);
  }
  for (int i = 0; i < num_vertices_; ++i) {
    const double len = N->row(i).norm();
    if (len > 0.0) {
      N->row(i) /= len;
    } else {
      N->row(i).setZero();
    }
  }
}

// ---------------------------------------------------------------------------
// FrameTextureExtractor.

struct FrameTextureExtractor::Impl {
  FrameTextureOptions options;
  CameraIntrinsics intrinsics;
  int num_vertices = 0;
  MatX3i rig_F;  // the whole rig mesh, for the depth buffer
  std::unique_ptr<RigVertexNormals> normals;
  TriMesh chart;  // neutral V, UV; F = face chart
  UvRaster raster;
  cv::Mat coverage;
  std::vector<int> chart_vertices;  // vertices used by the chart
  // Covered texels grouped by chart triangle (so a frame loads each triangle's
  // vertices once): texels of triangle t are [tri_offset[t], tri_offset[t+1]).
  std::vector<int> tri_offset;
  std::vector<int> texel_index;           // j·R + i
  std::vector<float> texel_w1, texel_w2;  // barycentrics of F(t,1), F(t,2); w0 = 1 − w1 − w2
  double cos_limit = 0.0;
  double pixel_f = 0.0;  // min(fx, fy): the larger pixel footprint

  // Screen positions of all vertices: (x, y, 1/z), valid = z > kNearMm.
  void Project(const MatX3d& V, std::vector<Eigen::Vector3f>* screen, std::vector<uint8_t>* valid) const;
  void Rasterize(const std::vector<Eigen::Vector3f>& screen, const std::vector<uint8_t>& valid,
                 int tri_begin, int tri_end, float* depth) const;
  cv::Mat Depth(const MatX3d& V) const;
  void Depth(const MatX3d& V, cv::Mat* depth, cv::Mat* second) const;
  void Visible(const MatX3d& V, const cv::Mat& depth, const MatX3d& N, std::vector<uint8_t>* visible) const;

  // Per-frame scratch reused across calls (allocating a few MB per frame costs
  // page faults); a concurrent call that finds it busy allocates its own.
  struct Scratch {
    cv::Mat gray, depth, second;
    MatX3d normals;
    std::vector<float> vertex_data;
  };
  mutable std::mutex scratch_mutex;
  mutable Scratch scratch;
};

void FrameTextureExtractor::Impl::Project(const MatX3d& V, std::vector<Eigen::Vector3f>* screen,
                                          std::vector<uint8_t>* valid) const {
  screen->resize(static_cast<size_t>(num_vertices));
  valid->resize(static_cast<size_t>(num_vertices));
  const double fx = intrinsics.fx, fy = intrinsics.fy, cx = intrinsics.cx, cy = intrinsics.cy;
  for (int v = 0; v < num_vertices; ++v) {
    const double z = V(v, 2);
    const bool ok = z > kNearMm;
    (*valid)[static_cast<size_t>(v)] = ok;
    if (ok) {
      const double iz = 1.0 / z;
      (*screen)[static_cast<size_t>(v)] = Eigen::Vector3f(static_cast<float>(fx * V(v, 0) * iz + cx),
                                                          static_cast<float>(fy * V(v, 1) * iz + cy),
                                                          static_cast<float>(iz));
    }
  }
}

// Z-buffer of triangles [tri_begin, tri_end) of rig_F into `depth` (W×H floats, min
// z): pixel centres inside a triangle (edges inclusive) get its perspective-correct
// depth (1/z interpolated linearly in screen space).
void FrameTextureExtractor::Impl::Rasterize(const std::vector<Eigen::Vector3f>& screen,
                                            const std::vector<uint8_t>& valid, int tri_begin, int tri_end,
                                            float* depth) const {
  const int W = intrinsics.width, H = intrinsics.height;
  for (int f = tri_begin; f < tri_end; ++f) {
    const int a = rig_F(f, 0), b = rig_F(f, 1), c = rig_F(f, 2);
    if (!valid[static_cast<size_t>(a)] || !valid[static_cast<size_t>(b)] || !valid[static_cast<size_t>(c)]) continue;
    const Eigen::Vector3f& p0 = screen[static_cast<size_t>(a)];
    const Eigen::Vector3f& p1 = screen[static_cast<size_t>(b)];
    const Eigen::Vector3f& p2 = screen[static_cast<size_t>(c)];
    // Twice the signed area in pixels (either sign: back faces are kept, since the
    // rig's inner parts — the mouth cavity seen through the lips — are seen from
    // inside).
    const double x0 = p0.x(), y0 = p0.y(), x1 = p1.x(), y1 = p1.y(), x2 = p2.x(), y2 = p2.y();
    const double area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0);
    if (!(std::abs(area) > 1e-12)) continue;
    const double minx = std::min({x0, x1, x2}), maxx = std::max({x0, x1, x2});
    const double miny = std::min({y0, y1, y2}), maxy = std::max({y0, y1, y2});
    if (!(maxx >= 0.0 && maxy >= 0.0 && minx <= W - 1.0 && miny <= H - 1.0)) continue;
    const int ix0 = std::max(0, static_cast<int>(std::ceil(minx)));
    const int ix1 = std::min(W - 1, static_cast<int>(std::floor(maxx)));
    const int iy0 = std::max(0, static_cast<int>(std::ceil(miny)));
    const int iy1 = std::min(H - 1, static_cast<int>(std::floor(maxy)));
    if (ix0 > ix1 || iy0 > iy1) continue;
    // Barycentrics as affine functions of the pixel centre (x, y), relative to the
    // box corner (small numbers, so floats are exact enough):
    //   w1 = ((x − x0)(y2 − y0) − (y − y0)(x2 − x0)) / area,
    //   w2 = ((x1 − x0)(y − y0) − (y1 − y0)(x − x0)) / area,  w0 = 1 − w1 − w2.
    const double inv = 1.0 / area;
    const double b1x = (y2 - y0) * inv, b1y = -(x2 - x0) * inv;
    const double b2x = -(y1 - y0) * inv, b2y = (x1 - x0) * inv;
    const double w1c = (ix0 - x0) * b1x + (iy0 - y0) * b1y;  // at the box corner (ix0, iy0)
    const double w2c = (ix0 - x0) * b2x + (iy0 - y0) * b2y;
    const float fb1x = static_cast<float>(b1x), fb1y = static_cast<float>(b1y);
    const float fb2x = static_cast<float>(b2x), fb2y = static_cast<float>(b2y);
    const float z0 = p0.z(), dz1 = p1.z() - z0, dz2 = p2.z() - z0;
    constexpr float kEps = -1e-5f;  // inclusive edges: shared edges leave no cracks
    for (int y = iy0; y <= iy1; ++y) {
      const float dy = static_cast<float>(y - iy0);
      float w1 = static_cast<float>(w1c) + dy * fb1y, w2 = static_cast<float>(w2c) + dy * fb2y;
      float* row = depth + static_cast<size_t>(y) * W;
      // Branch-free (tiny triangles make the inside test unpredictable).
      for (int x = ix0; x <= ix1; ++x, w1 += fb1x, w2 += fb2x) {
        const float iz = z0 + w1 * dz1 + w2 * dz2;
        const float z = 1.0f / iz;
        const bool inside = (w1 >= kEps) & (w2 >= kEps) & (1.0f - w1 - w2 >= kEps) & (iz > 0.0f) & (z < row[x]);
        row[x] = inside ? z : row[x];
      }
    }
  }
}

cv::Mat FrameTextureExtractor::Impl::Depth(const MatX3d& V) const {
  cv::Mat depth, second;
  Depth(V, &depth, &second);
  return depth;
}

void FrameTextureExtractor::Impl::Depth(const MatX3d& V, cv::Mat* depth_out, cv::Mat* second_out) const {
  std::vector<Eigen::Vector3f> screen;
  std::vector<uint8_t> valid;
  Project(V, &screen, &valid);
  const int W = intrinsics.width, H = intrinsics.height;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // Two halves of the triangles into two buffers, merged by min (deterministic:
  // min is order independent).
  depth_out->create(H, W, CV_32F);
  second_out->create(H, W, CV_32F);
  cv::Mat& depth = *depth_out;
  cv::Mat& second = *second_out;
  const int nf = static_cast<int>(rig_F.rows());
  tbb::parallel_for(0, 2, [&](int part) {
    float* buffer = part == 0 ? depth.ptr<float>() : second.ptr<float>();
    std::fill(buffer, buffer + static_cast<size_t>(W) * H, kInf);
    Rasterize(screen, valid, part == 0 ? 0 : nf / 2, part == 0 ? nf / 2 : nf, buffer);
  });
  cv::min(depth, second, depth);
}

FrameTextureExtractor::FrameTextureExtractor(const FaceRig& rig, const CameraIntrinsics& intrinsics,
                                             const FrameTextureOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  intrinsics.Validate("FrameTextureExtractor intrinsics");
  ValidateMesh(rig.neutral, "FrameTextureExtractor rig.neutral", {.uv = true});
  Impl& m = *impl_;
  m.options = options;
  m.intrinsics = intrinsics;
  m.num_vertices = rig.num_vertices();
  m.rig_F = rig.neutral.F;
  m.normals = std::make_unique<RigVertexNormals>(rig.neutral);
  m.chart.V = rig.neutral.V;
  m.chart.UV = rig.neutral.UV;
  m.chart.F = FaceChartTriangles(rig);
  const int R = options.map_resolution;
  m.raster = RasterizeUv(m.chart, R, R, "FrameTextureExtractor face chart");
  m.coverage = CoverageMask(m.raster);
  std::vector<uint8_t> used(static_cast<size_t>(m.num_vertices), 0);
  for (int f = 0; f < m.chart.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) used[static_cast<size_t>(m.chart.F(f, k))] = 1;
  }
  for (int v = 0; v < m.num_vertices; ++v) {
    if (used[static_cast<size_t>(v)]) m.chart_vertices.push_back(v);
  }
  const int num_chart = static_cast<int>(m.chart.F.rows());
  m.tri_offset.assign(static_cast<size_t>(num_chart) + 1, 0);
  for (const int t : m.raster.triangle) {
    if (t >= 0) ++m.tri_offset[static_cast<size_t>(t) + 1];
  }
  for (int t = 0; t < num_chart; ++t) m.tri_offset[static_cast<size_t>(t) + 1] += m.tri_offset[static_cast<size_t>(t)];
  const size_t num_covered = static_cast<size_t>(m.tri_offset.back());
  m.texel_index.resize(num_covered);
  m.texel_w1.resize(num_covered);
  m.texel_w2.resize(num_covered);
  {
    std::vector<int> cursor(m.tri_offset.begin(), m.tri_offset.end() - 1);
    for (int k = 0; k < R * R; ++k) {  // row-major: texels of a triangle stay in row order
      const int t = m.raster.triangle[static_cast<size_t>(k)];
      if (t < 0) continue;
      const size_t n = static_cast<size_t>(cursor[static_cast<size_t>(t)]++);
      m.texel_index[n] = k;
      m.texel_w1[n] = m.raster.barycentric[static_cast<size_t>(k)][1];
      m.texel_w2[n] = m.raster.barycentric[static_cast<size_t>(k)][2];
    }
  }
  m.cos_limit = std::cos(options.max_view_angle_deg * std::numbers::pi / 180.0);
  m.pixel_f = std::min(intrinsics.fx, intrinsics.fy);
}

FrameTextureExtractor::~FrameTextureExtractor() = default;
FrameTextureExtractor::FrameTextureExtractor(FrameTextureExtractor&&) noexcept = default;
FrameTextureExtractor& FrameTextureExtractor::operator=(FrameTextureExtractor&&) noexcept = default;

const cv::Mat& FrameTextureExtractor::coverage() const { return impl_->coverage; }
const UvRaster& FrameTextureExtractor::raster() const { return impl_->raster; }
const TriMesh& FrameTextureExtractor::chart_mesh() const { return impl_->chart; }
const FrameTextureOptions& FrameTextureExtractor::options() const { return impl_->options; }
const CameraIntrinsics& FrameTextureExtractor::intrinsics() const { return impl_->intrinsics; }
int FrameTextureExtractor::num_vertices() const { return impl_->num_vertices; }

cv::Mat FrameTextureExtractor::DepthBuffer(const MatX3d& cam_vertices) const {
  RequireVertices(cam_vertices, impl_->num_vertices, "FrameTextureExtractor::DepthBuffer");
  return impl_->Depth(cam_vertices);
}

// Per-vertex visibility from a depth buffer and vertex normals of the frame.
void FrameTextureExtractor::Impl::Visible(const MatX3d& V, const cv::Mat& depth, const MatX3d& N,
                                          std::vector<uint8_t>* visible) const {
  const int W = intrinsics.width, H = intrinsics.height;
  visible->assign(static_cast<size_t>(num_vertices), 0);
  const double tol0 = options.depth_tolerance_mm, slope = std::numbers::sqrt2 / pixel_f;
  for (int v = 0; v < num_vertices; ++v) {
    const double px = V(v, 0), py = V(v, 1), pz = V(v, 2);
    if (!(pz > kNearMm)) continue;
    const double iz = 1.0 / pz;
    const double x = intrinsics.fx * px * iz + intrinsics.cx, y = intrinsics.fy * py * iz + intrinsics.cy;
    if (!(x >= -0.5 && y >= -0.5 && x < W - 0.5 && y < H - 0.5)) continue;
    const double len = std::sqrt(px * px + py * py + pz * pz);
    const double c = -(N(v, 0) * px + N(v, 1) * py + N(v, 2) * pz) / len;  // cos of the view angle
    if (!(c > 0.0)) continue;                                             // back-facing (or no normal)
    const double tan_theta = std::min(kMaxTan, std::sqrt(std::max(0.0, 1.0 - c * c)) / c);
    const double tau = tol0 + slope * pz * tan_theta;
    const int ix = std::clamp(static_cast<int>(x + 0.5), 0, W - 1);
    const int iy = std::clamp(static_cast<int>(y + 0.5), 0, H - 1);
    if (depth.ptr<float>(iy)[ix] >= pz - tau) (*visible)[static_cast<size_t>(v)] = 255;
  }
}

std::vector<uint8_t> FrameTextureExtractor::VisibleVertices(const MatX3d& cam_vertices) const {
  const Impl& m = *impl_;
  RequireVertices(cam_vertices, m.num_vertices, "FrameTextureExtractor::VisibleVertices");
  const cv::Mat depth = m.Depth(cam_vertices);
  MatX3d N;
  m.normals->Compute(cam_vertices, &N);
  std::vector<uint8_t> visible;
  m.Visible(cam_vertices, depth, N, &visible);
  return visible;
}

FrameTexture FrameTextureExtractor::Extract(const MatX3d& cam_vertices, const cv::Mat& image) const {
  FrameTexture out;
  Extract(cam_vertices, image, &out);
  return out;
}

void FrameTextureExtractor::Extract(const MatX3d& cam_vertices, const cv::Mat& image, FrameTexture* out,
                                    std::vector<uint8_t>* visible_vertices) const {
  const auto start = std::chrono::steady_clock::now();
  const Impl& m = *impl_;
  const int W = m.intrinsics.width, H = m.intrinsics.height, R = m.options.map_resolution;
  Require(!image.empty() && (image.type() == CV_32FC3 || image.type() == CV_32FC1),
          fmt::format("FrameTextureExtractor::Extract: image must be linear float CV_32FC3 or CV_32FC1, got type {} "
                      "with {} channels",
                      image.type(), image.channels()));
  Require(image.cols == W && image.rows == H,
          fmt::format("FrameTextureExtractor::Extract: image size is {}×{} but the intrinsics say {}×{}", image.cols,
                      image.rows, W, H));
  RequireVertices(cam_vertices, m.num_vertices, "FrameTextureExtractor::Extract");

  std::unique_lock<std::mutex> lock(m.scratch_mutex, std::try_to_lock);
  Impl::Scratch local;
  Impl::Scratch& sc = lock.owns_lock() ? m.scratch : local;

  // Rec. 709 luminance (linear), as the training textures (Luminance of texture_extraction.h).
  cv::Mat gray;
  if (image.type() == CV_32FC1) {
    gray = image;
  } else {
    sc.gray.create(H, W, CV_32F);
    gray = sc.gray;
    ForRows(H, 16, [&](int j) {
      const cv::Vec3f* p = image.ptr<cv::Vec3f>(j);
      float* q = gray.ptr<float>(j);
      for (int i = 0; i < W; ++i) q[i] = 0.2126f * p[i][0] + 0.7152f * p[i][1] + 0.0722f * p[i][2];
    });
  }
  m.Depth(cam_vertices, &sc.depth, &sc.second);
  const cv::Mat& depth = sc.depth;
  m.normals->Compute(cam_vertices, &sc.normals);
  const MatX3d& N = sc.normals;
  if (visible_vertices) m.Visible(cam_vertices, depth, N, visible_vertices);
  // Per chart vertex (5 floats): position (camera frame), cos θ of the view angle
  // and the slope factor q = √2 · tan θ / f of the depth tolerance (header comment),
  // so that a texel needs no square root: τ = τ0 + p_z · q.
  constexpr int kVd = 5;
  sc.vertex_data.assign(static_cast<size_t>(m.num_vertices) * kVd, 0.0f);
  float* const vdata = sc.vertex_data.data();
  for (const int v : m.chart_vertices) {
    const Eigen::Vector3d p = cam_vertices.row(v).transpose();
    const double len = p.norm();
    const double c = len > 0.0 ? -N.row(v).dot(p.transpose()) / len : -1.0;
    const double tan_theta = c > 0.0 ? std::min(kMaxTan, std::sqrt(std::max(0.0, 1.0 - c * c)) / c) : kMaxTan;
    float* o = vdata + static_cast<size_t>(v) * kVd;
    o[0] = static_cast<float>(p.x());
    o[1] = static_cast<float>(p.y());
    o[2] = static_cast<float>(p.z());
    o[3] = static_cast<float>(c);
    o[4] = static_cast<float>(std::numbers::sqrt2 * tan_theta / m.pixel_f);
  }

  if (out->gray.rows != R || out->gray.cols != R || out->gray.type() != CV_32F) out->gray.create(R, R, CV_32F);
  if (out->seen.rows != R || out->seen.cols != R || out->seen.type() != CV_8U) out->seen.create(R, R, CV_8U);
  // Zero both maps, then scatter the seen texels triangle by triangle (each texel
  // belongs to one triangle: no two tasks write the same texel).
  ForRows(R, 16, [&](int j) {
    std::fill(out->gray.ptr<float>(j), out->gray.ptr<float>(j) + R, 0.0f);
    std::fill(out->seen.ptr<uint8_t>(j), out->seen.ptr<uint8_t>(j) + R, uint8_t{0});
  });
  std::atomic<int> seen_total{0};
  const int num_chart = static_cast<int>(m.chart.F.rows());
  tbb::parallel_for(tbb::blocked_range<int>(0, num_chart, 256), [&](const tbb::blocked_range<int>& range) {
    // Everything the loop reads, as locals: the stores (a uint8_t store may alias
    // anything) must not force reloads through the closure.
    const float fx = static_cast<float>(m.intrinsics.fx), fy = static_cast<float>(m.intrinsics.fy);
    const float cx = static_cast<float>(m.intrinsics.cx), cy = static_cast<float>(m.intrinsics.cy);
    const float cos_limit = static_cast<float>(m.cos_limit);
    const float tol0 = static_cast<float>(m.options.depth_tolerance_mm);
    const float near = static_cast<float>(kNearMm);
    const float xmax = static_cast<float>(W - 1), ymax = static_cast<float>(H - 1);
    const int wm2 = W - 2, hm2 = H - 2;
    const size_t gstep = gray.step1(), dstep = depth.step1();
    const float* const gbase = gray.ptr<float>();
    const float* const dbase = depth.ptr<float>();
    const int* const F = m.chart.F.data();
    const float* const vd = vdata;
    const int* const toff = m.tri_offset.data();
    const int* const idx_p = m.texel_index.data();
    const float* const w1_p = m.texel_w1.data();
    const float* const w2_p = m.texel_w2.data();
    float* const tex = out->gray.ptr<float>();
    uint8_t* const seen = out->seen.ptr<uint8_t>();
    int count = 0;
    for (int t = range.begin(); t != range.end(); ++t) {
      const float* a = vd + kVd * static_cast<size_t>(F[3 * t]);
      const float* b = vd + kVd * static_cast<size_t>(F[3 * t + 1]);
      const float* c = vd + kVd * static_cast<size_t>(F[3 * t + 2]);
      // cos θ and z are linear over the triangle: reject it whole when no corner passes.
      if (std::max({a[3], b[3], c[3]}) < cos_limit || std::max({a[2], b[2], c[2]}) <= near) continue;
      float base[kVd], e1[kVd], e2[kVd];
      for (int q = 0; q < kVd; ++q) {
        base[q] = a[q];
        e1[q] = b[q] - a[q];
        e2[q] = c[q] - a[q];
      }
      for (int k = toff[t]; k < toff[t + 1]; ++k) {
        const float w1 = w1_p[k], w2 = w2_p[k];
        const float cosv = base[3] + w1 * e1[3] + w2 * e2[3];
        const float pz = base[2] + w1 * e1[2] + w2 * e2[2];
        if (!(cosv >= cos_limit) || !(pz > near)) continue;
        const float px = base[0] + w1 * e1[0] + w2 * e2[0];
        const float py = base[1] + w1 * e1[1] + w2 * e2[1];
        const float iz = 1.0f / pz;
        const float x = fx * px * iz + cx, y = fy * py * iz + cy;
        if (!(x >= 0.0f && y >= 0.0f && x <= xmax && y <= ymax)) continue;
        const int x0 = std::min(static_cast<int>(x), wm2), y0 = std::min(static_cast<int>(y), hm2);
        // Depth test over the bilinear footprint (header comment).
        const float tau = tol0 + pz * (base[4] + w1 * e1[4] + w2 * e2[4]);
        const float* d0 = dbase + static_cast<size_t>(y0) * dstep + x0;
        const float* d1 = d0 + dstep;
        const float dmin = std::min(std::min(d0[0], d0[1]), std::min(d1[0], d1[1]));
        const float dmax = std::max(std::max(d0[0], d0[1]), std::max(d1[0], d1[1]));
        if (!(dmin >= pz - tau && dmax <= pz + tau)) continue;
        const float ax = x - static_cast<float>(x0), ay = y - static_cast<float>(y0);
        const float* g0 = gbase + static_cast<size_t>(y0) * gstep + x0;
        const float* g1 = g0 + gstep;
        const float top = g0[0] + ax * (g0[1] - g0[0]);
        const float bottom = g1[0] + ax * (g1[1] - g1[0]);
        const int i = idx_p[k];
        tex[i] = top + ay * (bottom - top);
        seen[i] = 255;
        ++count;
      }
    }
    seen_total += count;
  });
  int num_seen = seen_total.load();


  if (m.options.erode_seen_texels > 0) {
    // Erode towards covered-but-unseen texels only: uncovered texels (and the map's
    // outside) count as "seen" for the erosion.
    cv::Mat keep;
    cv::bitwise_or(out->seen, ~m.coverage, keep);
    const int k = 2 * m.options.erode_seen_texels + 1;
    cv::erode(keep, keep, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)), cv::Point(-1, -1), 1,
              cv::BORDER_CONSTANT, cv::Scalar(255));
    cv::bitwise_and(out->seen, keep, out->seen);
    out->gray.setTo(0.0f, out->seen == 0);
    num_seen = cv::countNonZero(out->seen);
  }
  out->num_seen = num_seen;
  out->ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// ---------------------------------------------------------------------------
// Mesoscopic map, Sec. 5.3.

namespace {

// Gaussian of window `k` (texels at the reference resolution) for a map of `size`
// (see MesoscopicOptions): OpenCV's σ(k), both scaled by size / reference.
void ScaledKernel(int k, int size, int reference, int* window, double* sigma) {
  const double scale = reference > 0 ? static_cast<double>(size) / reference : 1.0;
  *sigma = (0.3 * ((k - 1) * 0.5 - 1.0) + 0.8) * scale;
  *window = std::max(1, 2 * static_cast<int>(std::lround((k * scale - 1.0) / 2.0)) + 1);
}

cv::Mat GaussianConstant(const cv::Mat& src, int window, double sigma) {
  if (window <= 1) return src.clone();
  cv::Mat dst;
  cv::GaussianBlur(src, dst, cv::Size(window, window), sigma, sigma, cv::BORDER_CONSTANT);
  return dst;
}

}  // namespace

cv::Mat MesoscopicMap(const cv::Mat& gray_texture, const cv::Mat& seen, const MesoscopicOptions& options) {
  options.Check();
  Require(!gray_texture.empty() && gray_texture.type() == CV_32FC1,
          fmt::format("MesoscopicMap: texture must be a gray linear-float CV_32FC1 map, got type {} with {} channels",
                      gray_texture.type(), gray_texture.channels()));
  Require(gray_texture.rows == gray_texture.cols,
          fmt::format("MesoscopicMap: texture is {}×{}, expected a square UV map", gray_texture.cols,
                      gray_texture.rows));
  Require(seen.type() == CV_8UC1 && seen.size() == gray_texture.size(),
          fmt::format("MesoscopicMap: seen mask must be CV_8UC1 {}×{} like the texture, got {}×{} type {}",
                      gray_texture.cols, gray_texture.rows, seen.cols, seen.rows, seen.type()));
  const int R = gray_texture.rows;
  long num_bad = 0;
  cv::Mat mask;
  const cv::Mat tm = ZeroOutsideMask(gray_texture, seen, &num_bad, &mask);
  Require(num_bad == 0, fmt::format("MesoscopicMap: {} seen texels are not finite (NaN or inf)", num_bad));

  int ws = 1, wl = 1;
  double ss = 0.0, sl = 0.0;
  ScaledKernel(options.meso_small_kernel, R, options.meso_reference_resolution, &ws, &ss);
  ScaledKernel(options.meso_large_kernel, R, options.meso_reference_resolution, &wl, &sl);
  const cv::Mat ns = GaussianConstant(tm, ws, ss), ds = GaussianConstant(mask, ws, ss);
  const cv::Mat nl = GaussianConstant(tm, wl, sl), dl = GaussianConstant(mask, wl, sl);
  // D^HF = γ (G_small * T − G_large * T), normalised over `seen` (Sec. 5.3).
  return NormalisedDifference(ns, ds, nl, dl, seen, static_cast<float>(options.meso_scale));
}

}  // namespace crease
