#include "core/uv_raster.h"

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/error.h"

namespace crease {
namespace {

constexpr int64_t kStep = kUvSubpixelSteps;   // fixed-point units per texel
constexpr int64_t kHalfStep = kStep / 2;      // texel centre offset
constexpr int kBandRows = 16;                 // rows per parallel task

// Per-triangle setup: snapped fixed-point vertices in canonical (positive-area)
// order with their top-left biases, the covered texel box, and the affine map from
// UV to barycentrics of the original (unsnapped) triangle.
struct TriangleSetup {
  bool active = false;
  int64_t x[3] = {0, 0, 0}, y[3] = {0, 0, 0};  // fixed point, canonical order
  int64_t bias[3] = {0, 0, 0};                 // 0 = edge owns its zero set, -1 = not
  int i0 = 0, i1 = -1, j0 = 0, j1 = -1;        // inclusive texel box
  double au = 0, av = 0;                       // UV of F(t,0)
  double m00 = 0, m01 = 0, m10 = 0, m11 = 0;   // (w1, w2) = M · (uv − a)
};

int64_t Snap(double texels) { return std::llround(texels * static_cast<double>(kStep)); }

// Smallest texel index whose centre c = i·S + S/2 satisfies c >= lo.
int64_t FirstCentreAtOrAbove(int64_t lo) {
  const int64_t n = lo - kHalfStep;
  return n >= 0 ? (n + kStep - 1) / kStep : -((-n) / kStep);
}
// Largest texel index whose centre satisfies c <= hi.
int64_t LastCentreAtOrBelow(int64_t hi) {
  const int64_t n = hi - kHalfStep;
  return n >= 0 ? n / kStep : -((-n + kStep - 1) / kStep);
}

// Edge A→B owns the centres exactly on it when nudging the centre by
// (ε, ε·η), 0 < η << 1, moves it inside: the top-left rule as a perturbation,
// which also decides centres on vertices consistently.
int64_t TopLeftBias(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
  const int64_t dx = bx - ax, dy = by - ay;
  const bool owns = dy < 0 || (dy == 0 && dx > 0);
  return owns ? 0 : -1;
}

// `sx`, `sy`: the snapped UVs of all vertices (texel units × kStep).
TriangleSetup SetUp(const TriMesh& mesh, const std::vector<int64_t>& sx, const std::vector<int64_t>& sy, int f,
                    int width, int height) {
  TriangleSetup s;
  const int v0 = mesh.F(f, 0), v1 = mesh.F(f, 1), v2 = mesh.F(f, 2);
  int64_t x[3] = {sx[static_cast<size_t>(v0)], sx[static_cast<size_t>(v1)], sx[static_cast<size_t>(v2)]};
  int64_t y[3] = {sy[static_cast<size_t>(v0)], sy[static_cast<size_t>(v1)], sy[static_cast<size_t>(v2)]};
  // Twice the signed area in fixed point; edge function E_ab(p) = (b−a)×(p−a).
  const int64_t area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
  if (area == 0) return s;
  if (area < 0) {  // mirrored in UV: swap to positive orientation for the edge tests
    std::swap(x[1], x[2]);
    std::swap(y[1], y[2]);
  }
  const double au = mesh.UV(v0, 0), av = mesh.UV(v0, 1);
  const double e1u = mesh.UV(v1, 0) - au, e1v = mesh.UV(v1, 1) - av;
  const double e2u = mesh.UV(v2, 0) - au, e2v = mesh.UV(v2, 1) - av;
  const double det = e1u * e2v - e1v * e2u;
  if (det == 0.0) return s;

  const int64_t i0 = std::max<int64_t>(0, FirstCentreAtOrAbove(std::min({x[0], x[1], x[2]})));
  const int64_t i1 = std::min<int64_t>(width - 1, LastCentreAtOrBelow(std::max({x[0], x[1], x[2]})));
  const int64_t j0 = std::max<int64_t>(0, FirstCentreAtOrAbove(std::min({y[0], y[1], y[2]})));
  const int64_t j1 = std::min<int64_t>(height - 1, LastCentreAtOrBelow(std::max({y[0], y[1], y[2]})));
  if (i0 > i1 || j0 > j1) return s;

  s.active = true;
  for (int k = 0; k < 3; ++k) {
    s.x[k] = x[k];
    s.y[k] = y[k];
    const int n = (k + 1) % 3;
    s.bias[k] = TopLeftBias(x[k], y[k], x[n], y[n]);
  }
  s.i0 = static_cast<int>(i0);
  s.i1 = static_cast<int>(i1);
  s.j0 = static_cast<int>(j0);
  s.j1 = static_cast<int>(j1);
  s.au = au;
  s.av = av;
  const double inv_det = 1.0 / det;
  s.m00 = e2v * inv_det;
  s.m01 = -e2u * inv_det;
  s.m10 = -e1v * inv_det;
  s.m11 = e1u * inv_det;
  return s;
}

}  // namespace

int UvRaster::num_covered() const {
  return static_cast<int>(std::count_if(triangle.begin(), triangle.end(), [](int t) { return t >= 0; }));
}

UvRaster RasterizeUv(const TriMesh& mesh, int width, int height, const std::string& what) {
  ValidateMesh(mesh, what, {.uv = true});
  Require(width >= 1 && width <= kMaxUvRasterSize && height >= 1 && height <= kMaxUvRasterSize,
          fmt::format("{}: UV raster size {}×{} must be in [1, {}] in both directions", what, width,
                      height, kMaxUvRasterSize));
  for (int i = 0; i < mesh.num_vertices(); ++i) {
    if (std::abs(mesh.UV(i, 0)) > kMaxAbsUv || std::abs(mesh.UV(i, 1)) > kMaxAbsUv) {
      throw Error(fmt::format("{}: vertex {} has UV ({}, {}) outside [-{}, {}]", what, i, mesh.UV(i, 0),
                              mesh.UV(i, 1), kMaxAbsUv, kMaxAbsUv));
    }
  }

  // Snap every vertex once.
  const int num_vertices = mesh.num_vertices(), num_faces = mesh.num_faces();
  std::vector<int64_t> sx(static_cast<size_t>(num_vertices)), sy(static_cast<size_t>(num_vertices));
  tbb::parallel_for(tbb::blocked_range<int>(0, num_vertices, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v != r.end(); ++v) {
      sx[static_cast<size_t>(v)] = Snap(mesh.UV(v, 0) * width);
      sy[static_cast<size_t>(v)] = Snap(mesh.UV(v, 1) * height);
    }
  });

  // Bin triangles into bands of rows by the rows their centres can touch, in index
  // order (so each band's list is sorted): counts, offsets, then the lists (CSR).
  const int num_bands = (height + kBandRows - 1) / kBandRows;
  std::vector<int> band_lo(static_cast<size_t>(num_faces)), band_hi(static_cast<size_t>(num_faces));
  tbb::parallel_for(tbb::blocked_range<int>(0, num_faces, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int f = r.begin(); f != r.end(); ++f) {
      const int64_t y0 = sy[static_cast<size_t>(mesh.F(f, 0))], y1 = sy[static_cast<size_t>(mesh.F(f, 1))],
                    y2 = sy[static_cast<size_t>(mesh.F(f, 2))];
      const int64_t j0 = std::max<int64_t>(0, FirstCentreAtOrAbove(std::min({y0, y1, y2})));
      const int64_t j1 = std::min<int64_t>(height - 1, LastCentreAtOrBelow(std::max({y0, y1, y2})));
      band_lo[static_cast<size_t>(f)] = j0 <= j1 ? static_cast<int>(j0 / kBandRows) : 0;
      band_hi[static_cast<size_t>(f)] = j0 <= j1 ? static_cast<int>(j1 / kBandRows) : -1;
    }
  });
  std::vector<size_t> band_offset(static_cast<size_t>(num_bands) + 1, 0);
  for (int f = 0; f < num_faces; ++f) {
    for (int b = band_lo[static_cast<size_t>(f)]; b <= band_hi[static_cast<size_t>(f)]; ++b) {
      ++band_offset[static_cast<size_t>(b) + 1];
    }
  }
  for (int b = 0; b < num_bands; ++b) band_offset[static_cast<size_t>(b) + 1] += band_offset[static_cast<size_t>(b)];
  std::vector<int> band_triangles(band_offset.back());
  {
    std::vector<size_t> cursor(band_offset.begin(), band_offset.end() - 1);
    for (int f = 0; f < num_faces; ++f) {
      for (int b = band_lo[static_cast<size_t>(f)]; b <= band_hi[static_cast<size_t>(f)]; ++b) {
        band_triangles[cursor[static_cast<size_t>(b)]++] = f;
      }
    }
  }

  UvRaster raster;
  raster.width = width;
  raster.height = height;
  raster.num_triangles = num_faces;
  const size_t num_texels = static_cast<size_t>(width) * static_cast<size_t>(height);
  // Filled band by band below (in parallel, while the rows are in cache).
  raster.triangle.resize(num_texels);
  raster.barycentric.resize(num_texels);
  std::vector<int> band_overlaps(static_cast<size_t>(num_bands), 0);

  tbb::parallel_for(tbb::blocked_range<int>(0, num_bands, 1), [&](const tbb::blocked_range<int>& r) {
    for (int b = r.begin(); b != r.end(); ++b) {
      const int row_begin = b * kBandRows, row_end = std::min(height, row_begin + kBandRows) - 1;
      const size_t first_texel = static_cast<size_t>(row_begin) * static_cast<size_t>(width);
      const size_t end_texel = static_cast<size_t>(row_end + 1) * static_cast<size_t>(width);
      std::fill(raster.triangle.begin() + first_texel, raster.triangle.begin() + end_texel, -1);
      std::fill(raster.barycentric.begin() + first_texel, raster.barycentric.begin() + end_texel,
                Eigen::Vector3f::Zero());
      int overlaps = 0;
      for (size_t n = band_offset[static_cast<size_t>(b)]; n < band_offset[static_cast<size_t>(b) + 1]; ++n) {
        const int f = band_triangles[n];
        // Set up again in every band the triangle touches: cheaper than storing it.
        const TriangleSetup s = SetUp(mesh, sx, sy, f, width, height);
        if (!s.active) continue;
        const int j_first = std::max(s.j0, row_begin), j_last = std::min(s.j1, row_end);
        // Edge k runs from vertex k to vertex k+1; E_k(p) = dx_k·(py − y_k) − dy_k·(px − x_k).
        int64_t dx[3], dy[3];
        for (int k = 0; k < 3; ++k) {
          const int n = (k + 1) % 3;
          dx[k] = s.x[n] - s.x[k];
          dy[k] = s.y[n] - s.y[k];
        }
        const int64_t px0 = static_cast<int64_t>(s.i0) * kStep + kHalfStep;
        for (int j = j_first; j <= j_last; ++j) {
          const int64_t py = static_cast<int64_t>(j) * kStep + kHalfStep;
          int64_t e[3];
          for (int k = 0; k < 3; ++k) e[k] = dx[k] * (py - s.y[k]) - dy[k] * (px0 - s.x[k]) + s.bias[k];
          // Each E_k is linear along the row, E_k(i) = E_k(i0) − dy_k·S·(i − i0): the
          // texels with E_k ≥ 0 for all k form one span, found by exact integer division.
          int64_t lo = s.i0, hi = s.i1;
          for (int k = 0; k < 3; ++k) {
            const int64_t step = dy[k] * kStep;
            if (step == 0) {
              if (e[k] < 0) hi = lo - 1;
            } else if (step > 0) {  // decreasing along the row
              hi = e[k] < 0 ? lo - 1 : std::min(hi, s.i0 + e[k] / step);
            } else if (e[k] < 0) {  // increasing along the row
              lo = std::max(lo, s.i0 + (-e[k] - step - 1) / (-step));
            }
          }
          const double v = (j + 0.5) / height;
          for (int64_t i = lo; i <= hi; ++i) {
            const size_t idx = static_cast<size_t>(j) * static_cast<size_t>(width) + static_cast<size_t>(i);
            if (raster.triangle[idx] >= 0) {
              ++overlaps;
              continue;
            }
            const double du = (static_cast<double>(i) + 0.5) / width - s.au, dv = v - s.av;
            const double w1 = s.m00 * du + s.m01 * dv, w2 = s.m10 * du + s.m11 * dv;
            raster.triangle[idx] = f;
            raster.barycentric[idx] =
                Eigen::Vector3f(static_cast<float>(1.0 - w1 - w2), static_cast<float>(w1), static_cast<float>(w2));
          }
        }
      }
      band_overlaps[static_cast<size_t>(b)] = overlaps;
    }
  });
  for (const int o : band_overlaps) raster.num_overlaps += o;
  return raster;
}

cv::Mat InterpolateToUv(const UvRaster& raster, const TriMesh& mesh, const Eigen::MatrixXd& per_vertex) {
  const int channels = static_cast<int>(per_vertex.cols());
  Require(channels >= 1 && channels <= 4,
          fmt::format("InterpolateToUv: per-vertex data has {} columns, expected 1 to 4", channels));
  Require(per_vertex.rows() == mesh.num_vertices(),
          fmt::format("InterpolateToUv: per-vertex data has {} rows, but the mesh has {} vertices",
                      per_vertex.rows(), mesh.num_vertices()));
  Require(raster.num_triangles == mesh.num_faces(),
          fmt::format("InterpolateToUv: the UV raster was built for a mesh with {} triangles, this mesh has {}",
                      raster.num_triangles, mesh.num_faces()));
  const size_t num_texels = static_cast<size_t>(raster.width) * static_cast<size_t>(raster.height);
  Require(raster.width >= 1 && raster.height >= 1 && raster.triangle.size() == num_texels &&
              raster.barycentric.size() == num_texels,
          fmt::format("InterpolateToUv: malformed UV raster ({}×{} with {} triangle and {} barycentric entries)",
                      raster.width, raster.height, raster.triangle.size(), raster.barycentric.size()));

  // Vertex data as contiguous rows (one cache line per vertex, not C columns apart).
  const int num_vertices = mesh.num_vertices();
  std::vector<double> data(static_cast<size_t>(num_vertices) * static_cast<size_t>(channels));
  tbb::parallel_for(tbb::blocked_range<int>(0, num_vertices, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v != r.end(); ++v) {
      for (int ch = 0; ch < channels; ++ch) {
        data[static_cast<size_t>(v) * channels + ch] = per_vertex(v, ch);
      }
    }
  });

  cv::Mat out(raster.height, raster.width, CV_32FC(channels));  // every texel is written below
  tbb::parallel_for(tbb::blocked_range<int>(0, raster.height, 8), [&](const tbb::blocked_range<int>& r) {
    for (int j = r.begin(); j != r.end(); ++j) {
      float* row = out.ptr<float>(j);
      for (int i = 0; i < raster.width; ++i) {
        const size_t idx = static_cast<size_t>(j) * static_cast<size_t>(raster.width) + static_cast<size_t>(i);
        float* px = row + static_cast<size_t>(i) * channels;
        const int f = raster.triangle[idx];
        if (f < 0) {
          for (int ch = 0; ch < channels; ++ch) px[ch] = 0.0f;
          continue;
        }
        const Eigen::Vector3d w = raster.barycentric[idx].cast<double>();
        const double* a = data.data() + static_cast<size_t>(mesh.F(f, 0)) * channels;
        const double* b = data.data() + static_cast<size_t>(mesh.F(f, 1)) * channels;
        const double* c = data.data() + static_cast<size_t>(mesh.F(f, 2)) * channels;
        for (int ch = 0; ch < channels; ++ch) {
          px[ch] = static_cast<float>(w[0] * a[ch] + w[1] * b[ch] + w[2] * c[ch]);
        }
      }
    }
  });
  return out;
}

cv::Mat CoverageMask(const UvRaster& raster) {
  cv::Mat mask(raster.height, raster.width, CV_8U, cv::Scalar::all(0));
  for (int j = 0; j < raster.height; ++j) {
    uint8_t* row = mask.ptr<uint8_t>(j);
    for (int i = 0; i < raster.width; ++i) {
      if (raster.triangle[static_cast<size_t>(raster.index(i, j))] >= 0) row[i] = 255;
    }
  }
  return mask;
}

cv::Mat ResampleSquareMap(const cv::Mat& map, int R) {
  if (map.rows != map.cols || map.rows == R || map.rows == 0) return map;
  cv::Mat r;
  cv::resize(map, r, cv::Size(R, R), 0, 0, map.rows > R ? cv::INTER_AREA : cv::INTER_LINEAR);
  return r;
}

}  // namespace crease
