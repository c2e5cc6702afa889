// The high-fidelity mesh H^t (paper Sec. 5.3); see hifi_mesh.h.
#include "pipeline/capture/hifi_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "core/uv_raster.h"
#include "pipeline/capture/frame_texture.h"

namespace crease {

void HifiMeshOptions::VisitFields(OptionVisitor& v) {
  v.Field("resolution", hifi_mesh_resolution);
  v.Field("phong_alpha", phong_alpha);
}

void HifiMeshOptions::Check() const {
  const char* o = "HifiMeshOptions";
  CheckGe(o, "hifi_mesh_resolution", hifi_mesh_resolution, 2);
  CheckLe(o, "hifi_mesh_resolution", hifi_mesh_resolution, 8192);
  CheckGe(o, "phong_alpha", phong_alpha, 0.0);
  CheckLe(o, "phong_alpha", phong_alpha, 1.0);
}

namespace {

// Difference 3: core/mesh_ops.h PhongTessellate with the fill loop's scalars (the
// loop keeps its shape, and its speed without the rounding). u0..u2: the corners'
// unit normals (RigVertexNormals gives unit normals, so the fill loop's own).
inline void PhongBase(double alpha, double b0, double b1, double b2, const double* v0, const double* v1,
                      const double* v2, const double* u0, const double* u1, const double* u2, double p[3]) {
  const double b[3] = {b0, b1, b2};
  const double* const v[3] = {v0, v1, v2};
  const double* const u[3] = {u0, u1, u2};
  PhongTessellate(alpha, b, v, u, p);
}

// Orientation of the chart in UV (u right, v down): true when counter-clockwise
// (outward) triangles have negative UV area, by majority.
bool ChartIsFlipped(const TriMesh& chart) {
  long positive = 0, negative = 0;
  for (int f = 0; f < chart.F.rows(); ++f) {
    const Eigen::Vector2d a = chart.UV.row(chart.F(f, 0)).transpose();
    const Eigen::Vector2d b = chart.UV.row(chart.F(f, 1)).transpose();
    const Eigen::Vector2d c = chart.UV.row(chart.F(f, 2)).transpose();
    const double area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
    if (area > 0) ++positive;
    if (area < 0) ++negative;
  }
  return negative > positive;
}

// The boundary edges of a chart (edges of one chart triangle only) on the N × N
// grid: the outer boundary where it is concave, and the slits of the eyelids and
// lips, which are opened slightly in UV. Two grid vertices may be joined when the
// segment between them crosses none of them. The edges are bucketed by grid cell
// (CSR).
class ChartBoundary {
 public:
  ChartBoundary(const TriMesh& chart, int N);
  // True when the segment between grid nodes p and q (grid coordinates) properly
  // crosses a boundary edge.
  bool Crosses(const Eigen::Vector2d& p, const Eigen::Vector2d& q) const;

 private:
  // The grid cell of coordinate c, clamped to the grid.
  int Cell(double c) const { return std::clamp(static_cast<int>(std::floor(c)), 0, N_ - 1); }
  // Calls f(b) for the cells b (row-major) of the bounding box of segment pq, row by
  // row, until f returns true; returns whether it did.
  template <class F>
  bool AnyCell(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const F& f) const {
    const int x0 = Cell(std::min(p.x(), q.x())), x1 = Cell(std::max(p.x(), q.x()));
    const int y0 = Cell(std::min(p.y(), q.y())), y1 = Cell(std::max(p.y(), q.y()));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        if (f(static_cast<size_t>(y) * N_ + x)) return true;
      }
    }
    return false;
  }

  int N_;
  std::vector<std::array<Eigen::Vector2d, 2>> boundary_;  // in grid coordinates X = u·N − 0.5
  std::vector<int> bucket_offset_, bucket_edges_;
};

ChartBoundary::ChartBoundary(const TriMesh& chart, int N) : N_(N) {
  std::vector<std::pair<int, int>> edges;  // (min vertex, max vertex) of every triangle edge
  edges.reserve(static_cast<size_t>(chart.F.rows()) * 3);
  for (int f = 0; f < chart.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = chart.F(f, k), b = chart.F(f, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) {
      auto grid = [&](int v) { return Eigen::Vector2d(chart.UV(v, 0) * N - 0.5, chart.UV(v, 1) * N - 0.5); };
      boundary_.push_back({grid(edges[i].first), grid(edges[i].second)});
    }
    i = j;
  }
  // Two passes: count the edges of every cell, then fill.
  bucket_offset_.assign(static_cast<size_t>(N) * N + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<int> cursor;
    if (pass == 1) {
      for (size_t b = 0; b + 1 < bucket_offset_.size(); ++b) bucket_offset_[b + 1] += bucket_offset_[b];
      bucket_edges_.resize(static_cast<size_t>(bucket_offset_.back()));
      cursor.assign(bucket_offset_.begin(), bucket_offset_.end() - 1);
    }
    for (size_t e = 0; e < boundary_.size(); ++e) {
      const auto& [p, q] = boundary_[e];
      AnyCell(p, q, [&](size_t b) {
        if (pass == 0) {
          ++bucket_offset_[b + 1];
        } else {
          bucket_edges_[static_cast<size_t>(cursor[b]++)] = static_cast<int>(e);
        }
        return false;
      });
    }
  }
}

bool ChartBoundary::Crosses(const Eigen::Vector2d& p, const Eigen::Vector2d& q) const {
  auto cross2 = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
  };
  return AnyCell(p, q, [&](size_t b) {
    for (int k = bucket_offset_[b]; k < bucket_offset_[b + 1]; ++k) {
      const auto& [a, c] = boundary_[static_cast<size_t>(bucket_edges_[static_cast<size_t>(k)])];
      // Proper crossing of segments pq and ac.
      if (cross2(p, q, a) * cross2(p, q, c) < 0 && cross2(a, c, p) * cross2(a, c, q) < 0) return true;
    }
    return false;
  });
}

// The dense triangles: two per grid cell with four vertices, one where a corner is
// missing, each kept when none of its edges crosses the chart's boundary; wound
// like the chart (`flip`).
std::vector<Eigen::Vector3i> GridTriangles(int N, const std::vector<int>& vertex_of_node, const std::vector<int>& node,
                                           const ChartBoundary& boundary, bool flip) {
  auto joinable = [&](int g, int h) {
    const int ng = node[static_cast<size_t>(g)], nh = node[static_cast<size_t>(h)];
    const Eigen::Vector2d p(ng % N, ng / N), q(nh % N, nh / N);
    return !boundary.Crosses(p, q);
  };
  std::vector<Eigen::Vector3i> faces;
  faces.reserve(node.size() * 2);
  const int cells = N - 1;
  auto add = [&](int p, int q, int r) {
    if (p < 0 || q < 0 || r < 0) return false;
    if (!joinable(p, q) || !joinable(q, r) || !joinable(p, r)) return false;
    faces.push_back(flip ? Eigen::Vector3i(p, r, q) : Eigen::Vector3i(p, q, r));
    return true;
  };
  for (int b = 0; b < cells; ++b) {
    for (int a = 0; a < cells; ++a) {
      // Corners: c00 = (a, b), c10 = (a+1, b), c01 = (a, b+1), c11 = (a+1, b+1);
      // each triangle below has positive UV area (u right, v down).
      const int c00 = vertex_of_node[static_cast<size_t>(b) * N + a];
      const int c10 = vertex_of_node[static_cast<size_t>(b) * N + a + 1];
      const int c01 = vertex_of_node[static_cast<size_t>(b + 1) * N + a];
      const int c11 = vertex_of_node[static_cast<size_t>(b + 1) * N + a + 1];
      const int present = (c00 >= 0) + (c10 >= 0) + (c01 >= 0) + (c11 >= 0);
      if (present == 4) {
        add(c00, c10, c11);
        add(c00, c11, c01);
      } else if (present == 3) {
        if (c11 < 0) add(c00, c10, c01);
        if (c00 < 0) add(c10, c11, c01);
        if (c10 < 0) add(c00, c11, c01);
        if (c01 < 0) add(c00, c10, c11);
      }
    }
  }
  return faces;
}

// Per vertex g of the nv, its triangles: vertex_faces[offset[g] .. offset[g + 1]) (CSR).
void IndexVertexFaces(const std::vector<Eigen::Vector3i>& faces, int nv, std::vector<int>* offset,
                      std::vector<int>* vertex_faces) {
  offset->assign(static_cast<size_t>(nv) + 1, 0);
  for (const Eigen::Vector3i& t : faces) {
    for (int k = 0; k < 3; ++k) ++(*offset)[static_cast<size_t>(t[k]) + 1];
  }
  for (int v = 0; v < nv; ++v) (*offset)[static_cast<size_t>(v) + 1] += (*offset)[static_cast<size_t>(v)];
  vertex_faces->resize(static_cast<size_t>(offset->back()));
  std::vector<int> cursor(offset->begin(), offset->end() - 1);
  for (size_t f = 0; f < faces.size(); ++f) {
    for (int k = 0; k < 3; ++k) (*vertex_faces)[static_cast<size_t>(cursor[static_cast<size_t>(faces[f][k])]++)] = static_cast<int>(f);
  }
}

}  // namespace

struct HifiMeshBuilder::Impl {
  int N = 0;             // grid vertices per side
  int num_rig_vertices = 0;
  std::unique_ptr<RigVertexNormals> normals;
  MatX3i coarse_F;       // face chart triangles of the rig
  // Per dense vertex: grid node, coarse triangle (row of coarse_F), barycentrics, UV.
  std::vector<int> node;
  std::vector<int> tri;
  std::vector<Eigen::Vector3f> w;
  MatX2d UV;
  MatX3i F;                     // dense triangles
  // Per dense vertex g, its triangles: vertex_faces[vertex_face_offset[g] ..
  // vertex_face_offset[g + 1]) (≤ 6 on the grid).
  std::vector<int> vertex_face_offset;
  std::vector<int> vertex_faces;
  std::vector<int> coarse_F_flat;  // coarse_F row-major, 3 per triangle
  double phong_alpha = 0.0;        // HifiMeshOptions::phong_alpha (Difference 3)

  void Fill(const MatX3d& V, const cv::Mat& D, TriMesh* mesh) const;
};

HifiMeshBuilder::HifiMeshBuilder(const FaceRig& rig, const HifiMeshOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  ValidateMesh(rig.neutral, "HifiMeshBuilder rig.neutral", {.uv = true});
  Impl& m = *impl_;
  m.N = options.hifi_mesh_resolution;
  m.phong_alpha = options.phong_alpha;
  m.num_rig_vertices = rig.num_vertices();
  m.normals = std::make_unique<RigVertexNormals>(rig.neutral);
  TriMesh chart;
  chart.V = rig.neutral.V;
  chart.UV = rig.neutral.UV;
  chart.F = FaceChartTriangles(rig);
  m.coarse_F = chart.F;
  const UvRaster raster = RasterizeUv(chart, m.N, m.N, "HifiMeshBuilder face chart");
  const bool flip = ChartIsFlipped(chart);

  // Grid vertices.
  const int N = m.N;
  std::vector<int> vertex_of_node(static_cast<size_t>(N) * N, -1);
  for (int b = 0; b < N; ++b) {
    for (int a = 0; a < N; ++a) {
      const size_t k = static_cast<size_t>(raster.index(a, b));
      if (raster.triangle[k] < 0) continue;
      vertex_of_node[k] = static_cast<int>(m.node.size());
      m.node.push_back(static_cast<int>(k));
      m.tri.push_back(raster.triangle[k]);
      m.w.push_back(raster.barycentric[k]);
    }
  }
  const int nv = static_cast<int>(m.node.size());
  Require(nv >= 3,
          fmt::format("HifiMeshBuilder: the face chart covers only {} grid vertices at resolution {}", nv, m.N));
  m.UV.resize(nv, 2);
  for (int v = 0; v < nv; ++v) {
    m.UV(v, 0) = (m.node[static_cast<size_t>(v)] % N + 0.5) / N;
    m.UV(v, 1) = (m.node[static_cast<size_t>(v)] / N + 0.5) / N;
  }

  const ChartBoundary boundary(chart, N);
  const std::vector<Eigen::Vector3i> faces = GridTriangles(N, vertex_of_node, m.node, boundary, flip);
  m.F.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) m.F.row(static_cast<int>(f)) = faces[f].transpose();
  IndexVertexFaces(faces, nv, &m.vertex_face_offset, &m.vertex_faces);
  m.coarse_F_flat.assign(m.coarse_F.data(), m.coarse_F.data() + m.coarse_F.size());
}

HifiMeshBuilder::~HifiMeshBuilder() = default;
HifiMeshBuilder::HifiMeshBuilder(HifiMeshBuilder&&) noexcept = default;
HifiMeshBuilder& HifiMeshBuilder::operator=(HifiMeshBuilder&&) noexcept = default;

int HifiMeshBuilder::num_vertices() const { return static_cast<int>(impl_->node.size()); }
int HifiMeshBuilder::num_triangles() const { return static_cast<int>(impl_->F.rows()); }
int HifiMeshBuilder::grid_resolution() const { return impl_->N; }
const std::vector<int>& HifiMeshBuilder::grid_node() const { return impl_->node; }

TriMesh HifiMeshBuilder::Build(const MatX3d& cam_vertices, const cv::Mat& displacement) const {
  TriMesh mesh;
  BuildInto(cam_vertices, displacement, &mesh);
  return mesh;
}

void HifiMeshBuilder::BuildInto(const MatX3d& cam_vertices, const cv::Mat& displacement, TriMesh* mesh) const {
  const Impl& m = *impl_;
  Require(cam_vertices.rows() == m.num_rig_vertices,
          fmt::format("HifiMeshBuilder::Build: cam_vertices has {} rows, the rig has {} vertices", cam_vertices.rows(),
                      m.num_rig_vertices));
  for (int i = 0; i < cam_vertices.rows(); ++i) {
    if (!cam_vertices.row(i).allFinite()) {
      throw Error(fmt::format("HifiMeshBuilder::Build: cam_vertices row {} is not finite ({}, {}, {})", i,
                              cam_vertices(i, 0), cam_vertices(i, 1), cam_vertices(i, 2)));
    }
  }
  Require(!displacement.empty() && displacement.type() == CV_32FC1,
          fmt::format("HifiMeshBuilder::Build: displacement must be a CV_32FC1 map in mm, got type {} with {} channels",
                      displacement.type(), displacement.channels()));
  Require(displacement.rows == displacement.cols,
          fmt::format("HifiMeshBuilder::Build: displacement is {}×{}, expected a square UV map", displacement.cols,
                      displacement.rows));
  m.Fill(cam_vertices, displacement, mesh);
}

void HifiMeshBuilder::Impl::Fill(const MatX3d& V, const cv::Mat& D, TriMesh* mesh) const {
  MatX3d coarse_normals;
  normals->Compute(V, &coarse_normals);
  const int nv = static_cast<int>(node.size());
  const int nf = static_cast<int>(F.rows());
  if (mesh->F.rows() != nf) mesh->F = F;
  if (mesh->UV.rows() != nv) mesh->UV = UV;
  mesh->V.resize(nv, 3);
  mesh->N.resize(nv, 3);
  const int R = D.rows;
  const size_t step = D.step1();
  const float* dbase = D.ptr<float>();
  constexpr int kChunk = 4096;
  const int num_chunks = (nv + kChunk - 1) / kChunk;
  std::vector<int> bad_chunks(static_cast<size_t>(num_chunks), 0);
  // Raw pointers: the stores below must not make the compiler reload everything.
  const double* const Vp = V.data();
  const double* const Np = coarse_normals.data();
  const double alpha = phong_alpha;  // Difference 3
  const int* const cF = coarse_F_flat.data();
  const int* const tri_p = tri.data();
  const Eigen::Vector3f* const w_p = w.data();
  const double* const uv_p = UV.data();  // row-major MatX2d
  double* const out_v = mesh->V.data();
  double* const out_n = mesh->N.data();
  const int x_max = std::max(0, R - 2);

  // H_g = p_g + D(u_g, v_g) · n_g (Sec. 5.3).
  tbb::parallel_for(tbb::blocked_range<int>(0, num_chunks, 1), [&](const tbb::blocked_range<int>& r) {
    for (int chunk = r.begin(); chunk != r.end(); ++chunk) {
      int bad = 0;
      const int end = std::min(nv, (chunk + 1) * kChunk);
      for (int g = chunk * kChunk; g < end; ++g) {
        const int* t = cF + 3 * static_cast<size_t>(tri_p[g]);
        const double b0 = w_p[g][0], b1 = w_p[g][1], b2 = w_p[g][2];
        const double* v0 = Vp + 3 * static_cast<size_t>(t[0]);
        const double* v1 = Vp + 3 * static_cast<size_t>(t[1]);
        const double* v2 = Vp + 3 * static_cast<size_t>(t[2]);
        const double* n0 = Np + 3 * static_cast<size_t>(t[0]);
        const double* n1 = Np + 3 * static_cast<size_t>(t[1]);
        const double* n2 = Np + 3 * static_cast<size_t>(t[2]);
        double p[3], n[3];
        for (int c = 0; c < 3; ++c) {
          p[c] = b0 * v0[c] + b1 * v1[c] + b2 * v2[c];
          n[c] = b0 * n0[c] + b1 * n1[c] + b2 * n2[c];
        }
        if (alpha > 0.0) PhongBase(alpha, b0, b1, b2, v0, v1, v2, n0, n1, n2, p);
        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        const double inv_len = len > 0.0 ? 1.0 / len : 0.0;
        // Bilinear sample at the grid vertex's UV (texel centres at (i + 0.5)/R).
        const double x = std::clamp(uv_p[2 * static_cast<size_t>(g)] * R - 0.5, 0.0, R - 1.0);
        const double y = std::clamp(uv_p[2 * static_cast<size_t>(g) + 1] * R - 0.5, 0.0, R - 1.0);
        const int x0 = std::min(static_cast<int>(x), x_max), y0 = std::min(static_cast<int>(y), x_max);
        const int x1 = std::min(x0 + 1, R - 1), y1 = std::min(y0 + 1, R - 1);
        const double ax = x - x0, ay = y - y0;
        const float* r0 = dbase + static_cast<size_t>(y0) * step;
        const float* r1 = dbase + static_cast<size_t>(y1) * step;
        const double top = r0[x0] + ax * (r0[x1] - r0[x0]);
        const double bottom = r1[x0] + ax * (r1[x1] - r1[x0]);
        const double d = top + ay * (bottom - top);
        bad += !std::isfinite(d);
        const double s = d * inv_len;
        double* o = out_v + 3 * static_cast<size_t>(g);
        for (int c = 0; c < 3; ++c) o[c] = p[c] + s * n[c];
      }
      bad_chunks[static_cast<size_t>(chunk)] = bad;
    }
  });
  long bad = 0;
  for (const int b : bad_chunks) bad += b;
  Require(bad == 0, fmt::format("HifiMeshBuilder::Build: the displacement map gives {} non-finite values at grid "
                                "vertices (NaN or inf texels in the {}×{} map)",
                                bad, R, R));

  // Area-weighted normals of the displaced mesh: unnormalised face normals, then
  // each vertex gathers its (≤ 6) triangles.
  std::vector<float> face_normals(3 * static_cast<size_t>(nf));
  float* const fn = face_normals.data();
  const int* const Fp = F.data();
  const double* const P = out_v;
  tbb::parallel_for(tbb::blocked_range<int>(0, nf, 8192), [&](const tbb::blocked_range<int>& r) {
    for (int f = r.begin(); f != r.end(); ++f) {
      const double* p0 = P + 3 * static_cast<size_t>(Fp[3 * f]);
      const double* p1 = P + 3 * static_cast<size_t>(Fp[3 * f + 1]);
      const double* p2 = P + 3 * static_cast<size_t>(Fp[3 * f + 2]);
      const double e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
      const double e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
      float* o = fn + 3 * static_cast<size_t>(f);
      o[0] = static_cast<float>(e1[1] * e2[2] - e1[2] * e2[1]);
      o[1] = static_cast<float>(e1[2] * e2[0] - e1[0] * e2[2]);
      o[2] = static_cast<float>(e1[0] * e2[1] - e1[1] * e2[0]);
    }
  });
  const int* const off = vertex_face_offset.data();
  const int* const vf = vertex_faces.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, nv, 4096), [&](const tbb::blocked_range<int>& r) {
    for (int g = r.begin(); g != r.end(); ++g) {
      float sx = 0.0f, sy = 0.0f, sz = 0.0f;
      for (int k = off[g]; k < off[g + 1]; ++k) {
        const float* n = fn + 3 * static_cast<size_t>(vf[k]);
        sx += n[0];
        sy += n[1];
        sz += n[2];
      }
      const float len = std::sqrt(sx * sx + sy * sy + sz * sz);
      const double inv = len > 0.0f ? 1.0 / len : 0.0;
      double* o = out_n + 3 * static_cast<size_t>(g);
      o[0] = sx * inv;
      o[1] = sy * inv;
      o[2] = sz * inv;
    }
  });
}

}  // namespace crease
