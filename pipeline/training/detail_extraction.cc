#include "pipeline/training/detail_extraction.h"

#include <cmath>
#include <fmt/format.h>
#include <array>
#include <chrono>
#include <limits>
#include <optional>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/stats.h"
#include "core/mesh_ops.h"
#include "core/options.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"
#include "pipeline/training/deformation_transfer.h"

namespace crease {

void DetailExtractionOptions::VisitFields(OptionVisitor& v) {
  v.Field("lowpass_bandwidth_mm", lowpass_bandwidth_mm);
  v.Field("high_frequency_bandwidth_mm", high_frequency_bandwidth_mm);
  v.Field("lowpass_steps", lowpass_steps);
  v.Field("high_frequency_steps", high_frequency_steps);
  v.Field("map_resolution", map_resolution);
  v.Field("max_displacement_mm", max_displacement_mm);
  v.Field("operator_resolution", operator_resolution);
}

void DetailExtractionOptions::Check() const {
  const char* o = "DetailExtractionOptions";
  CheckGe(o, "lowpass_bandwidth_mm", lowpass_bandwidth_mm, 0.0);
  CheckLe(o, "lowpass_bandwidth_mm", lowpass_bandwidth_mm, 100.0);
  CheckGe(o, "high_frequency_bandwidth_mm", high_frequency_bandwidth_mm, 0.0);
  CheckLe(o, "high_frequency_bandwidth_mm", high_frequency_bandwidth_mm, 100.0);
  CheckGe(o, "lowpass_steps", lowpass_steps, 1);
  CheckLe(o, "lowpass_steps", lowpass_steps, 256);
  CheckGe(o, "high_frequency_steps", high_frequency_steps, 1);
  CheckLe(o, "high_frequency_steps", high_frequency_steps, 256);
  CheckGe(o, "map_resolution", map_resolution, 16);
  CheckLe(o, "map_resolution", map_resolution, 8192);
  CheckGt(o, "max_displacement_mm", max_displacement_mm, 0.0);
  CheckGe(o, "operator_resolution", operator_resolution, 0);
  CheckLe(o, "operator_resolution", operator_resolution, 4096);
  Require(operator_resolution == 0 || operator_resolution >= 16,
          fmt::format("DetailExtractionOptions.operator_resolution = {} must be 0 or >= 16", operator_resolution));
}

namespace {

std::optional<MeshLowpass> MakeLowpass(const TriMesh& mesh, double bandwidth_mm, int steps,
                                       LowpassSolver solver = LowpassSolver::kDirect, double tolerance = 1e-8) {
  if (bandwidth_mm <= 0.0) return std::nullopt;
  LowpassOptions lo;
  lo.bandwidth_mm = bandwidth_mm;
  lo.steps = steps;
  lo.solver = solver;
  lo.iterative_tolerance = tolerance;
  return MeshLowpass(mesh, lo);
}

}  // namespace

struct DetailExtractor::Impl {
  // Up to 4 weighted vertices of another mesh.
  struct Stencil {
    int count = 0;
    std::array<int, 4> id{};
    std::array<double, 4> w{};
  };
  DetailExtractionOptions options;
  std::string what;
  TriMesh neutral;                     // M^0 after G^HF (full resolution)
  std::optional<MeshLowpass> hf;       // G^HF, on the input neutral
  std::optional<MeshLowpass> hf_delta;  // the same filter, looser CG tolerance, for scan − neutral
  MatX3d input_neutral;                // M^0 before G^HF
  // The operator grid O (Difference 4): O = samples of the full mesh.
  TriMesh grid;                        // O^0 (positions of the smoothed neutral)
  std::vector<Stencil> grid_from_full;  // per grid vertex: 3 full vertices (barycentric)
  std::vector<Stencil> full_from_grid;  // per full vertex: ≤ 4 grid vertices (bilinear)
  MatX3d detail_offset;                // o_v = M^0(v) − Σ w_k O^0(k)
  MatX3d grid_normals;                 // of O^0
  std::optional<MeshLowpass> lowpass;  // G, on O^0
  std::optional<DeformationTransfer> transfer;  // G(O^0) → · onto O^0
  UvRaster raster;                     // of M^0 at the map resolution
  cv::Mat coverage;
  bool use_grid = false;               // false: G and the transfer run on the full mesh

  MatX3d GridFromFull(const MatX3d& V) const {
    MatX3d out = MatX3d::Zero(static_cast<int>(grid_from_full.size()), 3);
    for (size_t k = 0; k < grid_from_full.size(); ++k) {
      const Stencil& s = grid_from_full[k];
      for (int i = 0; i < s.count; ++i) out.row(static_cast<int>(k)) += s.w[i] * V.row(s.id[i]);
    }
    return out;
  }
};

namespace {

// The operator grid of Difference 4: one vertex per covered texel centre of an
// S×S raster of the neutral's UV chart, two triangles per cell whose four corners
// are covered, cells stretched by any scan cut.
using Stencil = DetailExtractor::Impl::Stencil;
// Returns false (and builds nothing) when the grid would not be smaller than the mesh.
bool BuildOperatorGrid(DetailExtractor::Impl& m, int S, const std::vector<MatX3d>& other_scans) {
  const TriMesh& full = m.neutral;
  const UvRaster r = RasterizeUv(full, S, S, m.what);
  if (r.num_covered() >= full.num_vertices()) return false;
  std::vector<int> vertex_of_texel(static_cast<size_t>(S) * S, -1);
  for (int j = 0; j < S; ++j) {
    for (int i = 0; i < S; ++i) {
      const int k = r.index(i, j);
      if (r.triangle[k] < 0) continue;
      vertex_of_texel[k] = static_cast<int>(m.grid_from_full.size());
      Stencil st;
      st.count = 3;
      for (int c = 0; c < 3; ++c) {
        st.id[c] = full.F(r.triangle[k], c);
        st.w[c] = r.barycentric[k][c];
      }
      m.grid_from_full.push_back(st);
    }
  }
  Require(m.grid_from_full.size() >= 16,
          fmt::format("{}: the UV chart covers only {} texels of the {}² operator grid", m.what,
                      m.grid_from_full.size(), S));
  m.grid.V = m.GridFromFull(full.V);
  // UV orientation of the chart (v grows downwards): the sign of the UV area of
  // counter-clockwise triangles, so grid triangles face the same way.
  double uv_area = 0.0;
  for (int f = 0; f < full.num_faces(); ++f) {
    const Eigen::Vector2d a = full.UV.row(full.F(f, 0)), b = full.UV.row(full.F(f, 1)), c = full.UV.row(full.F(f, 2));
    uv_area += (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
  }
  const bool flip = uv_area < 0.0;  // (i,j),(i+1,j),(i,j+1) has positive UV area
  std::vector<MatX3d> scans_on_grid;
  for (const auto& V : other_scans) scans_on_grid.push_back(m.GridFromFull(V));
  std::vector<Eigen::Vector3i> tris;
  auto stretched = [&](int a, int b) {
    const double l0 = (m.grid.V.row(a) - m.grid.V.row(b)).norm();
    for (const auto& X : scans_on_grid) {
      if ((X.row(a) - X.row(b)).norm() > 2.5 * l0 + 1e-9) return true;
    }
    return false;
  };
  for (int j = 0; j + 1 < S; ++j) {
    for (int i = 0; i + 1 < S; ++i) {
      const int a = vertex_of_texel[r.index(i, j)], b = vertex_of_texel[r.index(i + 1, j)];
      const int c = vertex_of_texel[r.index(i, j + 1)], d = vertex_of_texel[r.index(i + 1, j + 1)];
      if (a < 0 || b < 0 || c < 0 || d < 0) continue;
      if (stretched(a, b) || stretched(a, c) || stretched(b, d) || stretched(c, d) || stretched(b, c)) continue;
      if (flip) {
        tris.emplace_back(a, c, b);
        tris.emplace_back(b, c, d);
      } else {
        tris.emplace_back(a, b, c);
        tris.emplace_back(b, d, c);
      }
    }
  }
  // Cells across a slit that never opens in the scans keep both sides together;
  // 3D edges much longer than the grid's typical edge are cut as well.
  std::vector<double> lengths;
  for (const auto& t : tris) lengths.push_back((m.grid.V.row(t[0]) - m.grid.V.row(t[1])).norm());
  Require(!lengths.empty(), fmt::format("{}: the operator grid has no cells", m.what));
  const double typical = Median(lengths);
  std::vector<Eigen::Vector3i> kept;
  for (const auto& t : tris) {
    bool ok = true;
    for (int e = 0; e < 3; ++e) ok = ok && (m.grid.V.row(t[e]) - m.grid.V.row(t[(e + 1) % 3])).norm() < 4.0 * typical;
    if (ok) kept.push_back(t);
  }
  m.grid.F.resize(static_cast<int>(kept.size()), 3);
  for (size_t f = 0; f < kept.size(); ++f) m.grid.F.row(static_cast<int>(f)) = kept[f];
  // Full vertices from the grid: bilinear in UV over the four surrounding texel
  // centres that are grid vertices (renormalised), else the nearest within 2 texels.
  m.full_from_grid.assign(full.num_vertices(), Stencil{});
  for (int v = 0; v < full.num_vertices(); ++v) {
    const double x = full.UV(v, 0) * S - 0.5, y = full.UV(v, 1) * S - 0.5;
    const int i0 = static_cast<int>(std::floor(x)), j0 = static_cast<int>(std::floor(y));
    const double fx = x - i0, fy = y - j0;
    Stencil st;
    double sum = 0.0;
    for (int dy = 0; dy <= 1; ++dy) {
      for (int dx = 0; dx <= 1; ++dx) {
        const int i = i0 + dx, j = j0 + dy;
        if (i < 0 || j < 0 || i >= S || j >= S) continue;
        const int g = vertex_of_texel[r.index(i, j)];
        if (g < 0) continue;
        const double w = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
        if (w <= 0.0) continue;
        st.id[st.count] = g;
        st.w[st.count] = w;
        sum += w;
        ++st.count;
      }
    }
    if (st.count == 0) {
      double best = 1e30;
      for (int dj = -2; dj <= 3; ++dj) {
        for (int di = -2; di <= 3; ++di) {
          const int i = i0 + di, j = j0 + dj;
          if (i < 0 || j < 0 || i >= S || j >= S || vertex_of_texel[r.index(i, j)] < 0) continue;
          const double d = (i - x) * (i - x) + (j - y) * (j - y);
          if (d < best) {
            best = d;
            st.count = 1;
            st.id[0] = vertex_of_texel[r.index(i, j)];
            st.w[0] = 1.0;
          }
        }
      }
      sum = st.count ? 1.0 : 0.0;
    }
    for (int k = 0; k < st.count; ++k) st.w[k] /= sum;
    m.full_from_grid[v] = st;
  }
  m.detail_offset.resize(full.num_vertices(), 3);
  for (int v = 0; v < full.num_vertices(); ++v) {
    const Stencil& st = m.full_from_grid[v];
    Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
    for (int k = 0; k < st.count; ++k) p += st.w[k] * m.grid.V.row(st.id[k]);
    m.detail_offset.row(v) = st.count ? Eigen::RowVector3d(full.V.row(v) - p) : Eigen::RowVector3d::Zero();
  }
  return true;
}

}  // namespace

DetailExtractor::DetailExtractor(const TriMesh& neutral, const DetailExtractionOptions& options,
                                 const std::string& what, const std::vector<MatX3d>& other_scans)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  Impl& m = *impl_;
  m.options = options;
  m.what = what;
  ValidateMesh(neutral, what, {.uv = true});
  for (const auto& V : other_scans) {
    Require(V.rows() == neutral.num_vertices(), fmt::format("{}: another scan has {} vertices, expected {}", what,
                                                            V.rows(), neutral.num_vertices()));
  }
  m.neutral = neutral;
  m.neutral.N.resize(0, 3);
  m.hf = MakeLowpass(neutral, options.high_frequency_bandwidth_mm, options.high_frequency_steps, LowpassSolver::kIterative);
  if (m.hf) {
    m.neutral.V = m.hf->Apply(neutral.V);
    // G^HF is linear: G^HF(M^j) = G^HF(M^0) + G^HF(M^j − M^0). The difference is
    // millimetres rather than ~100 mm, so a 1e-5 relative residual is ~1e-5 mm.
    m.hf_delta = MakeLowpass(neutral, options.high_frequency_bandwidth_mm, options.high_frequency_steps,
                             LowpassSolver::kIterative, 1e-5);
    m.input_neutral = neutral.V;
  }
  if (options.lowpass_bandwidth_mm > 0.0) {
    m.use_grid = options.operator_resolution > 0 && BuildOperatorGrid(m, options.operator_resolution, other_scans);
    if (!m.use_grid) m.grid = m.neutral;  // the full mesh is its own operator mesh
    m.lowpass = MakeLowpass(m.grid, options.lowpass_bandwidth_mm, options.lowpass_steps);
    TriMesh source = m.grid;
    source.V = m.lowpass->Apply(m.grid.V);
    m.transfer.emplace(source, m.grid, DeformationTransferOptions{}, what + " (deformation transfer)");
    m.grid_normals = VertexNormals(m.grid);
  }
  m.raster = RasterizeUv(m.neutral, options.map_resolution, options.map_resolution, what);
  m.coverage = CoverageMask(m.raster);
}

DetailExtractor::~DetailExtractor() = default;
DetailExtractor::DetailExtractor(DetailExtractor&&) noexcept = default;
DetailExtractor& DetailExtractor::operator=(DetailExtractor&&) noexcept = default;

const TriMesh& DetailExtractor::smoothed_neutral() const { return impl_->neutral; }
const cv::Mat& DetailExtractor::coverage() const { return impl_->coverage; }
const DetailExtractionOptions& DetailExtractor::options() const { return impl_->options; }
int DetailExtractor::operator_grid_vertices() const {
  return impl_->use_grid ? impl_->grid.num_vertices() : 0;
}

MatX3d DetailExtractor::HighFrequencyFilter(const MatX3d& V) const {
  const Impl& m = *impl_;
  if (!m.hf) return V;
  Require(V.rows() == m.input_neutral.rows(), "HighFrequencyFilter: wrong vertex count");
  const MatX3d delta = V - m.input_neutral;
  return m.neutral.V + m.hf_delta->Apply(delta);
}

ExtractedDetail DetailExtractor::Extract(const MatX3d& expression, const std::string& what) const {
  const Impl& m = *impl_;
  Require(expression.rows() == m.neutral.num_vertices(),
          fmt::format("{}: {} vertices, but the neutral scan has {} (the scans of an actor must share "
                      "one topology)",
                      what, expression.rows(), m.neutral.num_vertices()));
  for (int i = 0; i < expression.rows(); ++i) {
    Require(expression.row(i).allFinite(), fmt::format("{}: vertex {} is not finite", what, i));
  }
  ExtractedDetail out;
  using Clock = std::chrono::steady_clock;
  auto since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
  auto t0 = Clock::now();
  // 1. M^j ← G^HF(M^j).
  TriMesh scan = m.neutral;
  scan.V = HighFrequencyFilter(expression);
  out.seconds_hf = since(t0);
  t0 = Clock::now();
  // 2–3. M_0^j: the deformation G(M^0) → G(M^j) transferred to M^0 (on the
  // operator grid, carried to the full mesh with the rotated detail offsets).
  if (!m.transfer) {
    out.aligned = m.neutral.V;
  } else if (!m.use_grid) {
    out.aligned = m.transfer->Transfer(m.lowpass->Apply(scan.V));
  } else {
    const MatX3d grid_j = m.GridFromFull(scan.V);
    const MatX3d grid_0j = m.transfer->Transfer(m.lowpass->Apply(grid_j));
    out.seconds_transfer = since(t0);
    t0 = Clock::now();
    TriMesh g = m.grid;
    g.V = grid_0j;
    const MatX3d n1 = VertexNormals(g);
    std::vector<Eigen::Matrix3d> rot(g.num_vertices());
    for (int k = 0; k < g.num_vertices(); ++k) {
      const Eigen::Vector3d a = m.grid_normals.row(k), b = n1.row(k);
      rot[k] = (a.norm() > 0 && b.norm() > 0) ? Eigen::Quaterniond::FromTwoVectors(a, b).toRotationMatrix()
                                              : Eigen::Matrix3d::Identity();
    }
    out.aligned = m.neutral.V;
    for (int v = 0; v < m.neutral.num_vertices(); ++v) {
      const Impl::Stencil& st = m.full_from_grid[v];
      if (st.count == 0) continue;
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      const Eigen::Vector3d o = m.detail_offset.row(v);
      for (int k = 0; k < st.count; ++k) p += st.w[k] * (grid_0j.row(st.id[k]).transpose() + rot[st.id[k]] * o);
      out.aligned.row(v) = p;
    }
  }
  TriMesh aligned = m.neutral;
  aligned.V = out.aligned;
  out.aligned_normals = VertexNormals(aligned);
  const MatX3d& normals = out.aligned_normals;
  out.seconds_aligned = since(t0);
  t0 = Clock::now();
  // 4. D^j: per texel, the signed distance along M_0^j's normal to M^j. The ray
  // starts ε above the surface so that a surface through the texel itself (D = 0)
  // is a clean hit at distance ε rather than a grazing one at t = 0.
  constexpr float kEps = 1e-3f;
  const int R = m.options.map_resolution;
  std::vector<Eigen::Vector3f> origins, directions;
  std::vector<int> texel_of_ray;
  origins.reserve(m.raster.triangle.size());
  for (int k = 0; k < R * R; ++k) {
    const int t = m.raster.triangle[k];
    if (t < 0) continue;
    const Eigen::Vector3f& b = m.raster.barycentric[k];
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) {
      p += b[c] * aligned.V.row(aligned.F(t, c)).transpose();
      n += b[c] * normals.row(aligned.F(t, c)).transpose();
    }
    const double len = n.norm();
    if (!(len > 0.0)) continue;
    n /= len;
    origins.push_back((p + kEps * n).cast<float>());
    directions.push_back(n.cast<float>());
    texel_of_ray.push_back(k);
  }
  // Robust traversal: texel centres may pass exactly through scan vertices and
  // edges (a scan sampled on the map grid), where the fast traversal can miss.
  RayCasterOptions robust;
  robust.robust = true;
  const RayCaster caster(scan, robust, what);
  std::vector<SignedHit> hits;
  caster.IntersectSignedBatch(origins, directions, static_cast<float>(m.options.max_displacement_mm) + kEps, &hits);
  out.displacement = cv::Mat::zeros(R, R, CV_32F);
  out.valid = cv::Mat::zeros(R, R, CV_8U);
  float* d = out.displacement.ptr<float>();
  uint8_t* ok = out.valid.ptr<uint8_t>();
  for (size_t r = 0; r < hits.size(); ++r) {
    const float dist = hits[r].t + kEps;
    // A hit on a surface facing the other way (the opposite lip or eyelid across
    // a slit, the inside of a fold) is not this texel's skin.
    if (!hits[r].valid() || std::abs(dist) > m.options.max_displacement_mm ||
        hits[r].geometric_normal.dot(directions[r]) < 0.3f) {
      ++out.rays_missed;
      continue;
    }
    d[texel_of_ray[r]] = dist;
    ok[texel_of_ray[r]] = 255;
  }
  out.seconds_rays = since(t0);
  return out;
}

FaceRig MakeRigCompatible(const FaceRig& rig, const DetailExtractionOptions& options) {
  options.Check();
  if (options.lowpass_bandwidth_mm <= 0.0 || rig.num_expressions() == 0) return rig;
  // G on L^0 (the rig's mean-identity neutral), one factorisation for all blendshapes.
  const std::optional<MeshLowpass> g =
      MakeLowpass(rig.neutral, options.lowpass_bandwidth_mm, options.lowpass_steps);
  TriMesh source = rig.neutral;
  source.V = g->Apply(rig.neutral.V);
  const DeformationTransfer transfer(source, rig.neutral, DeformationTransferOptions{},
                                     "rig compatibility (deformation transfer)");
  FaceRig out = rig;
  const int nv = rig.num_vertices();
  for (int b = 0; b < rig.num_expressions(); ++b) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.num_expressions());
    w[b] = 1.0;
    const MatX3d Lb = rig.EvaluatePositions({}, w);
    // L_0^b = DT(G(L^0) → G(L^b)) onto L^0; the new blendshape is L_0^b − L^0.
    const MatX3d L0b = transfer.Transfer(g->Apply(Lb));
    for (int v = 0; v < nv; ++v) {
      for (int c = 0; c < 3; ++c) {
        out.expression_basis(3 * v + c, b) = static_cast<float>(L0b(v, c) - rig.neutral.V(v, c));
      }
    }
  }
  out.source = rig.source.empty() ? "made compatible for detail regression (Sec. 4.1)"
                                  : rig.source + "; made compatible for detail regression (Sec. 4.1)";
  return out;
}

void MapMoments::Add(const cv::Mat& extracted, const cv::Mat& reference, const cv::Mat& mask) {
  Require(extracted.type() == CV_32F && reference.type() == CV_32F && mask.type() == CV_8U,
          "CompareMaps: expected CV_32F maps and a CV_8U mask");
  Require(extracted.size() == reference.size() && extracted.size() == mask.size(),
          fmt::format("CompareMaps: sizes differ ({}×{}, {}×{}, mask {}×{})", extracted.cols, extracted.rows,
                      reference.cols, reference.rows, mask.cols, mask.rows));
  for (int j = 0; j < extracted.rows; ++j) {
    const float* x = extracted.ptr<float>(j);
    const float* y = reference.ptr<float>(j);
    const uint8_t* k = mask.ptr<uint8_t>(j);
    for (int i = 0; i < extracted.cols; ++i) {
      if (k[i]) AddValue(x[i], y[i]);
    }
  }
}

nlohmann::json MapComparisonJson(const MapComparison& c) {
  return {{"texels", c.texels},
          {"rmse_mm", c.rmse_mm},
          {"correlation", c.correlation},
          {"reference_rms_mm", c.reference_rms_mm},
          {"extracted_rms_mm", c.extracted_rms_mm}};
}

void MapMoments::AddValue(double x, double y) {
  if (!std::isfinite(x) || !std::isfinite(y)) return;
  sx += x;
  sy += y;
  sxx += x * x;
  syy += y * y;
  sxy += x * y;
  se += (x - y) * (x - y);
  ++n;
}

MapComparison MapMoments::Result() const {
  MapComparison c;
  c.texels = static_cast<int>(std::min<int64_t>(n, std::numeric_limits<int>::max()));
  if (n == 0) return c;
  const double m = static_cast<double>(n);
  c.rmse_mm = std::sqrt(se / m);
  c.reference_rms_mm = std::sqrt(syy / m);
  c.extracted_rms_mm = std::sqrt(sxx / m);
  const double vx = sxx / m - (sx / m) * (sx / m), vy = syy / m - (sy / m) * (sy / m);
  const double cov = sxy / m - (sx / m) * (sy / m);
  c.correlation = (vx > 0 && vy > 0) ? cov / std::sqrt(vx * vy) : 0.0;
  return c;
}

MapComparison CompareMaps(const cv::Mat& extracted, const cv::Mat& reference, const cv::Mat& mask) {
  MapMoments m;
  m.Add(extracted, reference, mask);
  return m.Result();
}

double MmPerTexel(const TriMesh& mesh, int R) {
  double a3 = 0, auv = 0;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p0 = mesh.V.row(mesh.F(f, 0)), p1 = mesh.V.row(mesh.F(f, 1)), p2 = mesh.V.row(mesh.F(f, 2));
    const Eigen::Vector2d u0 = mesh.UV.row(mesh.F(f, 0)), u1 = mesh.UV.row(mesh.F(f, 1)), u2 = mesh.UV.row(mesh.F(f, 2));
    a3 += 0.5 * (p1 - p0).cross(p2 - p0).norm();
    auv += 0.5 * std::abs((u1 - u0).x() * (u2 - u0).y() - (u1 - u0).y() * (u2 - u0).x());
  }
  return auv > 0 ? std::sqrt(a3 / auv) / R : 0.0;
}

WrinkleBandMask MakeWrinkleBandMask(const cv::Mat& mask, double sigma_texels) {
  WrinkleBandMask m;
  m.sigma_texels = sigma_texels;
  mask.convertTo(m.mask, CV_32F, 1.0 / 255.0);
  cv::GaussianBlur(m.mask, m.blurred, cv::Size(0, 0), sigma_texels);
  return m;
}

cv::Mat WrinkleBand(const cv::Mat& d, const WrinkleBandMask& mask) {
  cv::Mat dm, bd;
  cv::multiply(d, mask.mask, dm);
  cv::GaussianBlur(dm, bd, cv::Size(0, 0), mask.sigma_texels);
  cv::Mat out(d.size(), CV_32F);
  for (int j = 0; j < d.rows; ++j) {
    const float* dj = d.ptr<float>(j);
    const float* bdj = bd.ptr<float>(j);
    const float* w = mask.blurred.ptr<float>(j);
    float* o = out.ptr<float>(j);
    for (int i = 0; i < d.cols; ++i) o[i] = w[i] > 1e-6f ? dj[i] - bdj[i] / w[i] : 0.0f;
  }
  return out;
}

cv::Mat WrinkleBand(const cv::Mat& d, const cv::Mat& mask, double sigma_texels) {
  return WrinkleBand(d, MakeWrinkleBandMask(mask, sigma_texels));
}

}  // namespace crease
