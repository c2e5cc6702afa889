#include "synth/hires_surface.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "core/uv_raster.h"
#include "synth/wrinkles.h"

namespace crease {

namespace {

// Per vertex, the vertex it is joined to for the subdivision's topology: the lowest id
// of its seam split (FaceRig::original_vertex; without it, equal neutral positions and
// expression deltas).
std::vector<int> SeamRepresentatives(const FaceRig& rig) {
  const int n = rig.num_vertices();
  std::vector<int> order(n), rep(n);
  for (int v = 0; v < n; ++v) order[v] = rep[v] = v;
  const bool by_id = static_cast<int>(rig.original_vertex.size()) == n;
  auto key = [&](int v) {
    return by_id ? std::array<double, 3>{static_cast<double>(rig.original_vertex[v]), 0.0, 0.0}
                 : std::array<double, 3>{rig.neutral.V(v, 0), rig.neutral.V(v, 1), rig.neutral.V(v, 2)};
  };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key(a) < key(b); });
  auto same_motion = [&](int a, int b) {
    return by_id || (rig.expression_basis.middleRows(3 * a, 3) == rig.expression_basis.middleRows(3 * b, 3));
  };
  for (size_t i = 1; i < order.size(); ++i) {
    const int a = order[i - 1], b = order[i];
    if (key(a) == key(b) && same_motion(rep[a], b)) rep[b] = rep[a];
  }
  return rep;
}

// The faces within two rings of the chart's (`chart`: rows of rig.neutral.F), over
// seam representatives, with a compact numbering of their vertices (`input`: the rig
// vertex of each). Chart faces come first, in `chart`'s order and corner order.
MatX3i SmoothRegion(const FaceRig& rig, const std::vector<int>& chart, std::vector<int>* input) {
  const std::vector<int> rep = SeamRepresentatives(rig);
  const MatX3i& F = rig.neutral.F;
  const int n = rig.num_vertices();
  std::vector<std::vector<int>> faces_of(n);
  for (int f = 0; f < F.rows(); ++f) {
    const int a = rep[F(f, 0)], b = rep[F(f, 1)], c = rep[F(f, 2)];
    if (a == b || b == c || c == a) continue;
    for (int v : {a, b, c}) faces_of[v].push_back(f);
  }
  std::vector<char> in_region(F.rows(), 0), seen(n, 0);
  std::vector<int> ring;
  for (int f : chart) {
    for (int k = 0; k < 3; ++k) {
      const int v = rep[F(f, k)];
      if (!seen[v]) ring.push_back(v);
      seen[v] = 1;
    }
  }
  for (int step = 0; step < 2; ++step) {
    std::vector<int> next;
    for (int v : ring) {
      for (int f : faces_of[v]) {
        in_region[f] = 1;
        for (int k = 0; k < 3; ++k) {
          const int u = rep[F(f, k)];
          if (!seen[u]) next.push_back(u);
          seen[u] = 1;
        }
      }
    }
    ring = std::move(next);
  }
  std::vector<int> faces = chart;
  for (int f : chart) in_region[f] = 0;
  for (int f = 0; f < F.rows(); ++f) {
    if (in_region[f]) faces.push_back(f);
  }
  std::vector<int> local(n, -1);
  input->clear();
  MatX3i R(static_cast<int>(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const int v = rep[F(faces[i], k)];
      if (local[v] < 0) {
        local[v] = static_cast<int>(input->size());
        input->push_back(v);
      }
      R(static_cast<int>(i), k) = local[v];
    }
  }
  return R;
}

// The smooth base of BuildHiResLayout (subdivision_levels > 0).
void AttachSmoothBase(const FaceRig& rig, int levels, HiResLayout* L) {
  std::vector<int> chart;  // the layout's coarse triangles, each once
  std::vector<int> chart_index(rig.neutral.num_faces(), -1);
  for (int t : L->triangle) {
    if (chart_index[t] < 0) {
      chart_index[t] = static_cast<int>(chart.size());
      chart.push_back(t);
    }
  }
  const MatX3i region = SmoothRegion(rig, chart, &L->smooth_input);
  for (size_t i = 0; i < chart.size(); ++i) {
    const Eigen::RowVector3i f = region.row(static_cast<int>(i));
    Require(f[0] != f[1] && f[1] != f[2] && f[2] != f[0],
            fmt::format("hi-res layout: chart triangle {} collapses when its seam vertices are joined", chart[i]));
  }
  L->smooth = std::make_shared<const LoopSubdivision>(
      BuildLoopSubdivision(region, static_cast<int>(L->smooth_input.size()), levels));
  const int nv = L->num_vertices();
  L->smooth_face.resize(nv);
  L->smooth_barycentric.resize(nv);
  for (int v = 0; v < nv; ++v) {
    int f = chart_index[L->triangle[v]];
    Eigen::Vector3d b = L->barycentric[v].cast<double>();
    for (int l = 0; l < levels; ++l) f = 4 * f + LocateLoopChild(&b);
    L->smooth_face[v] = f;
    L->smooth_barycentric[v] = b.cast<float>();
  }
}

}  // namespace

HiResLayout BuildHiResLayout(const FaceRig& rig, int resolution, int map_resolution, int subdivision_levels) {
  Require(subdivision_levels >= 0 && subdivision_levels <= 5,
          fmt::format("BuildHiResLayout: subdivision_levels {} must be in [0, 5]", subdivision_levels));
  Require(resolution >= 2 && resolution <= 8192,
          fmt::format("BuildHiResLayout: resolution {} must be in [2, 8192]", resolution));
  if (map_resolution <= 0) map_resolution = resolution;
  Require(map_resolution >= 2 && map_resolution <= 8192,
          fmt::format("BuildHiResLayout: map_resolution {} must be in [2, 8192]", map_resolution));
  const MatX3i Ff = FaceChartTriangles(rig);
  // Map chart triangles back to rows of rig.neutral.F.
  std::vector<int> rig_face;
  {
    const int face_part = rig.part_names.empty() ? -1 : rig.PartIndex("face");
    const TriMesh& m = rig.neutral;
    for (int f = 0; f < m.num_faces(); ++f) {
      bool ok = true;
      for (int k = 0; k < 3; ++k) {
        const int v = m.F(f, k);
        ok = ok && (face_part >= 0 ? rig.vertex_part[v] == face_part
                                   : (m.UV(v, 0) >= 0 && m.UV(v, 0) <= 1 && m.UV(v, 1) >= 0 && m.UV(v, 1) <= 1));
      }
      if (ok) rig_face.push_back(f);
    }
  }
  TriMesh chart;
  chart.V = rig.neutral.V;
  chart.UV = rig.neutral.UV;
  chart.F = Ff;
  const UvRaster raster = RasterizeUv(chart, resolution, resolution, "hi-res layout rig");
  const int R = resolution;
  HiResLayout L;
  L.resolution = R;
  L.map_resolution = map_resolution;
  L.vertex_of_texel.assign(static_cast<size_t>(R) * R, -1);
  for (int idx = 0; idx < R * R; ++idx) {
    const int t = raster.triangle[idx];
    if (t < 0) continue;
    L.vertex_of_texel[idx] = static_cast<int>(L.texel.size());
    L.texel.push_back(idx);
    L.triangle.push_back(rig_face[t]);
    L.barycentric.push_back(raster.barycentric[idx]);
  }
  const int nv = L.num_vertices();
  L.UV.resize(nv, 2);
  for (int v = 0; v < nv; ++v) {
    L.UV(v, 0) = (L.texel[v] % R + 0.5) / R;
    L.UV(v, 1) = (L.texel[v] / R + 0.5) / R;
  }
  // Bilinear stencils into the R_map × R_map maps.
  const int Rm = map_resolution;
  L.map_texel.resize(nv);
  L.map_weight.resize(nv);
  for (int v = 0; v < nv; ++v) {
    if (Rm == R) {
      L.map_texel[v] = L.texel[v];
      L.map_weight[v] = Eigen::Vector2f::Zero();
      continue;
    }
    const double x = std::clamp(L.UV(v, 0) * Rm - 0.5, 0.0, Rm - 1.0);
    const double y = std::clamp(L.UV(v, 1) * Rm - 0.5, 0.0, Rm - 1.0);
    const int x0 = std::min(static_cast<int>(x), Rm - 2), y0 = std::min(static_cast<int>(y), Rm - 2);
    L.map_texel[v] = y0 * Rm + x0;
    L.map_weight[v] = Eigen::Vector2f(static_cast<float>(x - x0), static_cast<float>(y - y0));
  }
  // Orientation: the majority sign of the chart's UV areas says whether
  // counter-clockwise in UV (u right, v down) is outward.
  double signed_sum = 0;
  for (int f = 0; f < Ff.rows(); ++f) {
    const Eigen::Vector2d a = chart.UV.row(Ff(f, 1)) - chart.UV.row(Ff(f, 0));
    const Eigen::Vector2d b = chart.UV.row(Ff(f, 2)) - chart.UV.row(Ff(f, 0));
    signed_sum += (a.x() * b.y() - a.y() * b.x()) > 0 ? 1 : -1;
  }
  const bool flip = signed_sum < 0;
  // Neutral positions to reject cells that span UV cuts.
  const double mm_per_texel = MmPerUv(rig) / R;
  const double max_edge = 6.0 * mm_per_texel;
  auto position = [&](int v) {
    const int t = L.triangle[v];
    const Eigen::Vector3f& b = L.barycentric[v];
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) p += b[k] * rig.neutral.V.row(rig.neutral.F(t, k)).transpose();
    return p;
  };
  // Coarse connectivity: two coarse triangles may be bridged by a grid cell only
  // when they share a vertex or have vertices joined by an edge; this keeps
  // cells from spanning slits (eyelids, lips: rims are distinct vertices at the
  // same UV) that open with the expression.
  std::vector<std::vector<int>> neighbours(rig.num_vertices());
  for (int f = 0; f < rig.neutral.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = rig.neutral.F(f, k), b = rig.neutral.F(f, (k + 1) % 3);
      neighbours[a].push_back(b);
      neighbours[b].push_back(a);
    }
  }
  for (auto& n : neighbours) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
  auto connected = [&](int t1, int t2) {
    if (t1 == t2) return true;
    for (int k = 0; k < 3; ++k) {
      const int a = rig.neutral.F(t1, k);
      for (int l = 0; l < 3; ++l) {
        const int b = rig.neutral.F(t2, l);
        if (a == b || std::binary_search(neighbours[a].begin(), neighbours[a].end(), b)) return true;
      }
    }
    return false;
  };
  int rejected_slit = 0;
  std::vector<Eigen::Vector3i> tris;
  tris.reserve(2 * static_cast<size_t>(nv));
  for (int j = 0; j + 1 < R; ++j) {
    for (int i = 0; i + 1 < R; ++i) {
      const int a = L.vertex_of_texel[j * R + i], b = L.vertex_of_texel[j * R + i + 1];
      const int c = L.vertex_of_texel[(j + 1) * R + i], d = L.vertex_of_texel[(j + 1) * R + i + 1];
      if (a < 0 || b < 0 || c < 0 || d < 0) continue;
      const Eigen::Vector3d pa = position(a), pb = position(b), pc = position(c), pd = position(d);
      if ((pa - pb).norm() > max_edge || (pa - pc).norm() > max_edge || (pb - pd).norm() > max_edge ||
          (pc - pd).norm() > max_edge || (pb - pc).norm() > 1.5 * max_edge) {
        continue;
      }
      const int ta = L.triangle[a], tb = L.triangle[b], tc = L.triangle[c], td = L.triangle[d];
      if (!(connected(ta, tb) && connected(ta, tc) && connected(tb, tc) && connected(tb, td) &&
            connected(tc, td))) {
        ++rejected_slit;
        continue;
      }
      // (a, b, c) has positive signed area in (u, v), like the chart unless flipped.
      if (!flip) {
        tris.emplace_back(a, b, c);
        tris.emplace_back(b, d, c);
      } else {
        tris.emplace_back(a, c, b);
        tris.emplace_back(b, c, d);
      }
    }
  }
  L.cells_across_slits = rejected_slit;
  L.F.resize(static_cast<int>(tris.size()), 3);
  for (size_t f = 0; f < tris.size(); ++f) L.F.row(static_cast<int>(f)) = tris[f].transpose();
  if (subdivision_levels > 0) AttachSmoothBase(rig, subdivision_levels, &L);
  return L;
}

namespace {

// The smooth base's subdivided positions for this frame (empty without one).
MatX3d SmoothPositions(const HiResLayout& layout, const TriMesh& coarse) {
  if (!layout.smooth) return {};
  MatX3d X(static_cast<int>(layout.smooth_input.size()), 3);
  for (int i = 0; i < X.rows(); ++i) X.row(i) = coarse.V.row(layout.smooth_input[i]);
  return layout.smooth->Apply(X);
}

// Base position (the smooth base's, from `smooth`, else the Phong-tessellated coarse
// triangle's) and interpolated unit normal at vertex v.
inline void CoarseAt(const HiResLayout& layout, const TriMesh& coarse, const MatX3d& smooth, int v,
                     double phong_alpha, Eigen::RowVector3d* P, Eigen::RowVector3d* N) {
  const int t = layout.triangle[v];
  const Eigen::Vector3f& b = layout.barycentric[v];
  const int i0 = coarse.F(t, 0), i1 = coarse.F(t, 1), i2 = coarse.F(t, 2);
  if (smooth.rows() > 0) {
    const int f = layout.smooth_face[v];
    const Eigen::Vector3f& c = layout.smooth_barycentric[v];
    const MatX3i& S = layout.smooth->faces;
    *P = c[0] * smooth.row(S(f, 0)) + c[1] * smooth.row(S(f, 1)) + c[2] * smooth.row(S(f, 2));
  } else {
    const Eigen::RowVector3d flat = b[0] * coarse.V.row(i0) + b[1] * coarse.V.row(i1) + b[2] * coarse.V.row(i2);
    const double w[3] = {b[0], b[1], b[2]};
    const double* const corners[3] = {coarse.V.row(i0).data(), coarse.V.row(i1).data(),
                                      coarse.V.row(i2).data()};
    const double* const normals[3] = {coarse.N.row(i0).data(), coarse.N.row(i1).data(),
                                      coarse.N.row(i2).data()};
    double p[3] = {flat[0], flat[1], flat[2]};
    PhongTessellate(phong_alpha, w, corners, normals, p);
    *P = Eigen::RowVector3d(p[0], p[1], p[2]);
  }
  const Eigen::RowVector3d n = b[0] * coarse.N.row(i0) + b[1] * coarse.N.row(i1) + b[2] * coarse.N.row(i2);
  const double len = n.norm();
  *N = len > 0 ? Eigen::RowVector3d(n / len) : Eigen::RowVector3d(0, 0, 0);
}

void CheckCoarse(const HiResLayout& layout, const TriMesh& coarse, double phong_alpha) {
  Require(phong_alpha >= 0 && phong_alpha <= 1,
          fmt::format("hi-res surface: phong_alpha = {} must be in [0, 1]", phong_alpha));
  Require(coarse.has_normals() && coarse.N.rows() == coarse.num_vertices(),
          "hi-res surface: the coarse mesh needs vertex normals");
  for (int t : {0, layout.num_vertices() - 1}) {
    if (t < 0) continue;
    Require(layout.triangle[t] < coarse.num_faces(), "hi-res surface: the coarse mesh is not the layout's rig");
  }
  Require(layout.smooth_input.empty() ||
              *std::max_element(layout.smooth_input.begin(), layout.smooth_input.end()) < coarse.num_vertices(),
          "hi-res surface: the coarse mesh is not the layout's rig");
}

}  // namespace

void InterpolateCoarse(const HiResLayout& layout, const TriMesh& coarse, MatX3d* P, MatX3d* N,
                       double phong_alpha) {
  CheckCoarse(layout, coarse, phong_alpha);
  const int nv = layout.num_vertices();
  P->resize(nv, 3);
  N->resize(nv, 3);
  const MatX3d smooth = SmoothPositions(layout, coarse);
  tbb::parallel_for(tbb::blocked_range<int>(0, nv, 8192), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) {
      Eigen::RowVector3d p, n;
      CoarseAt(layout, coarse, smooth, v, phong_alpha, &p, &n);
      P->row(v) = p;
      N->row(v) = n;
    }
  });
}

TriMesh BuildHiResSurface(const HiResLayout& layout, const TriMesh& coarse, const cv::Mat& displacement,
                          double phong_alpha) {
  const int R = layout.resolution;
  const int Rm = layout.map_resolution;
  Require(displacement.type() == CV_32F && displacement.rows == Rm && displacement.cols == Rm,
          fmt::format("BuildHiResSurface: displacement must be CV_32F {}×{}", Rm, Rm));
  Require(displacement.isContinuous(), "BuildHiResSurface: displacement must be continuous");
  TriMesh mesh;
  const int nv = layout.num_vertices();
  MatX3d N;  // the interpolated coarse normals
  InterpolateCoarse(layout, coarse, &mesh.V, &N, phong_alpha);
  tbb::parallel_for(tbb::blocked_range<int>(0, nv, 8192), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) mesh.V.row(v) += layout.SampleMap(displacement, v) * N.row(v);
  });
  mesh.F = layout.F;
  mesh.UV = layout.UV;
  // Normals by central differences on the grid, oriented like the coarse normal.
  mesh.N.resize(nv, 3);
  tbb::parallel_for(tbb::blocked_range<int>(0, nv, 8192), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) {
      const int i = layout.texel[v] % R, j = layout.texel[v] / R;
      auto at = [&](int ii, int jj) {
        return (ii < 0 || jj < 0 || ii >= R || jj >= R) ? -1 : layout.vertex_of_texel[jj * R + ii];
      };
      auto diff = [&](int a, int b) -> Eigen::RowVector3d {
        const int pa = a >= 0 ? a : v, pb = b >= 0 ? b : v;
        return mesh.V.row(pb) - mesh.V.row(pa);
      };
      const Eigen::RowVector3d du = diff(at(i - 1, j), at(i + 1, j));
      const Eigen::RowVector3d dv = diff(at(i, j - 1), at(i, j + 1));
      Eigen::RowVector3d n = du.cross(dv);
      const double len = n.norm();
      if (len <= 1e-20) {
        mesh.N.row(v) = N.row(v);
        continue;
      }
      n /= len;
      if (n.dot(N.row(v)) < 0) n = -n;
      mesh.N.row(v) = n;
    }
  });
  return mesh;
}

}  // namespace crease
