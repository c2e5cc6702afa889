// Poisson fill of uncovered texels (paper Sec. 5.2); see poisson_fill.h.
#include "pipeline/capture/poisson_fill.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <vector>

#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/options.h"

namespace crease {

void PoissonFillOptions::VisitFields(OptionVisitor& v) {
  v.Field("resolution", fill_resolution);
  v.Field("boundary", fill_boundary);
  v.Field("smoothing_sweeps", fill_smoothing_sweeps);
  v.Field("band_texels", fill_band_texels);
}

void PoissonFillOptions::Check() const {
  const char* o = "PoissonFillOptions";
  CheckGe(o, "fill_resolution", fill_resolution, 2);
  CheckGe(o, "fill_smoothing_sweeps", fill_smoothing_sweeps, 0);
  CheckLe(o, "fill_smoothing_sweeps", fill_smoothing_sweeps, 1000);
  CheckGe(o, "fill_band_texels", fill_band_texels, 0);
  CheckLe(o, "fill_band_texels", fill_band_texels, 256);
}

namespace {

enum : uint8_t { kOutside = 0, kKnown = 1, kUnknown = 2 };
// Coarse node types.
enum : uint8_t { kCoarseOutside = 0, kCoarseKnown = 1, kCoarseVar = 2, kCoarseDropped = 3 };

struct Run {  // texels [x0, x0 + length) of row y
  int32_t y, x0, length;
};

void RequireMask(const cv::Mat& m, const char* name) {
  Require(!m.empty(), fmt::format("PoissonFill: the {} mask is empty", name));
  Require(m.type() == CV_8UC1,
          fmt::format("PoissonFill: the {} mask must be CV_8UC1, got type {} with {} channels", name, m.type(),
                      m.channels()));
  Require(m.rows == m.cols, fmt::format("PoissonFill: the {} mask is {}x{}, expected a square map", name, m.cols, m.rows));
}

// Runs of texels of `label` equal to `value`.
std::vector<Run> RunsOf(const cv::Mat& label, uint8_t value) {
  std::vector<Run> runs;
  for (int y = 0; y < label.rows; ++y) {
    const uint8_t* l = label.ptr<uint8_t>(y);
    int x = 0;
    while (x < label.cols) {
      if (l[x] != value) {
        ++x;
        continue;
      }
      const int x0 = x;
      while (x < label.cols && l[x] == value) ++x;
      runs.push_back({y, x0, x - x0});
    }
  }
  return runs;
}

// Splits `runs` into chunks of roughly `texels` texels for parallel loops (the
// split depends only on the runs, not on the thread count).
std::vector<int> Chunks(const std::vector<Run>& runs, int texels) {
  std::vector<int> begin = {0};
  int acc = 0;
  for (int i = 0; i < static_cast<int>(runs.size()); ++i) {
    acc += runs[i].length;
    if (acc >= texels) {
      begin.push_back(i + 1);
      acc = 0;
    }
  }
  if (begin.back() != static_cast<int>(runs.size())) begin.push_back(static_cast<int>(runs.size()));
  return begin;
}

// The fine labels: kOutside / kKnown / kUnknown per texel (known counts only in the domain).
cv::Mat LabelTexels(const cv::Mat& domain, const cv::Mat& known) {
  const int R = domain.rows;
  cv::Mat label(R, R, CV_8U);
  for (int y = 0; y < R; ++y) {
    const uint8_t* d = domain.ptr<uint8_t>(y);
    const uint8_t* k = known.ptr<uint8_t>(y);
    uint8_t* l = label.ptr<uint8_t>(y);
    for (int x = 0; x < R; ++x) l[x] = !d[x] ? kOutside : (k[x] ? kKnown : kUnknown);
  }
  return label;
}

// Weights w_i with Σ_i w_i f_i = the least-squares affine fit of the values f_i at
// `texels`, evaluated at (cx, cy) (exact for linear fields). A full block of s² texels,
// and degenerate configurations (collinear texels), take the plain mean.
std::vector<double> AffineFitWeights(const std::vector<std::pair<int, int>>& texels, double cx, double cy, int s) {
  const int k = static_cast<int>(texels.size());
  std::vector<double> w(k, 1.0 / k);
  if (k < s * s) {
    Eigen::Matrix3d AtA = Eigen::Matrix3d::Zero();
    for (const auto& [x, y] : texels) {
      const Eigen::Vector3d a(1.0, x - cx, y - cy);
      AtA += a * a.transpose();
    }
    Eigen::Matrix3d inv;
    bool invertible = false;
    double det = 0.0;
    AtA.computeInverseAndDetWithCheck(inv, det, invertible, 1e-9 * std::pow(AtA.trace(), 3));
    if (invertible) {
      const Eigen::Vector3d g = inv.col(0);  // (AᵀA)⁻¹ e1
      for (int i = 0; i < k; ++i) w[i] = g[0] + g[1] * (texels[i].first - cx) + g[2] * (texels[i].second - cy);
    }
  }
  return w;
}

// The 4-neighbours of a coarse node, (dI, dJ).
constexpr int kDi[4] = {1, -1, 0, 0}, kDj[4] = {0, 0, 1, -1};

}  // namespace

struct PoissonFill::Impl {
  int R = 0, s = 1, Rc = 0;
  bool zero_boundary = true;
  int sweeps = 0;
  int num_unknown = 0;
  std::vector<Run> outside_runs, unknown_runs;
  std::vector<int> outside_chunks, unknown_chunks;
  // Coarse grid.
  std::vector<uint8_t> node_type;     // Rc², kCoarse*
  std::vector<int32_t> var_node;      // coarse node of each var
  std::vector<int32_t> known_nodes;   // known nodes whose value is needed (near a var)
  std::vector<int32_t> known_begin;   // entries [known_begin[i], known_begin[i+1]) of known node i
  std::vector<uint16_t> known_x, known_y;
  std::vector<float> known_w;
  std::vector<int32_t> rhs_var, rhs_node;  // pairs (var, known neighbour node): rhs[var] += value(node)
  std::vector<int32_t> dropped_nodes;      // vars of components with no Dirichlet neighbour (value 0)
  // Neumann: outside nodes near vars take the mean of their in-domain neighbours.
  std::vector<int32_t> ext_node, ext_begin, ext_source;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
  int num_vars = 0;
  // Bilinear interpolation from the coarse nodes: per fine coordinate.
  std::vector<int32_t> i0;
  std::vector<float> f;
  // Smoothing band, by colour (x + y even / odd).
  struct BandTexel {
    uint16_t x, y;
    float inv_den;
  };
  std::vector<BandTexel> band[2];

  // The constructor's steps, in order (see poisson_fill.h, "Solver").
  // Map size R, block size s, coarse size Rc and the options that hold per frame.
  void SetSizes(int map_size, const PoissonFillOptions& options);
  // The runs of outside and unknown texels (and their parallel chunks).
  void SetRuns(const cv::Mat& label);
  // Step 1: the type of each coarse node (block) from its share of known / domain texels.
  void ClassifyBlocks(const cv::Mat& label);
  uint8_t TypeAt(int I, int J) const {
    if (I < 0 || J < 0 || I >= Rc || J >= Rc) return kCoarseOutside;
    return node_type[static_cast<size_t>(J) * Rc + I];
  }
  // Step 1, "neumann": components of vars without a known neighbour are singular → dropped (0).
  void DropUnanchoredComponents();
  // Step 2: the bilinear weights of each fine coordinate.
  void SetBilinearWeights();
  // Step 1: the coarse 5-point Laplace system, its factorisation and its right-hand
  // side's (var, known node) pairs. Marks in `needed` the nodes around the vars.
  void FactoriseCoarseSystem(std::vector<uint8_t>* needed);
  // Step 2: marks in `needed` the nodes the interpolation of any unknown texel reads.
  void MarkInterpolatedNodes(std::vector<uint8_t>* needed) const;
  // The needed known nodes and ("neumann") the needed outside nodes' sources.
  void CollectNeededNodes(std::vector<uint8_t>* needed);
  // Step 1: each needed known node's value as weights of its block's known texels.
  void FitKnownBlocks(const cv::Mat& label);
  // Step 3: the unknown texels within `band_texels` of a known texel (or, "zero", of
  // the domain's edge), by colour, with their 5-point denominators.
  void BuildBand(const cv::Mat& label, int band_texels);
};

void PoissonFill::Impl::SetSizes(int map_size, const PoissonFillOptions& options) {
  R = map_size;
  Require(R >= 2 && R <= 65535, fmt::format("PoissonFill: map size {} must be in [2, 65535]", R));
  s = std::max(1, R / options.fill_resolution);
  Require(R % s == 0, fmt::format("PoissonFill: map size {} is not a multiple of the block size {} "
                                  "(R / fill_resolution = {} / {}); choose fill_resolution so that it is",
                                  R, s, R, options.fill_resolution));
  Rc = R / s;
  Require(Rc >= 2, fmt::format("PoissonFill: coarse grid {}x{} is too small", Rc, Rc));
  zero_boundary = options.fill_boundary == FillBoundary::kZero;
  sweeps = s > 1 ? options.fill_smoothing_sweeps : 0;
}

void PoissonFill::Impl::SetRuns(const cv::Mat& label) {
  outside_runs = RunsOf(label, kOutside);
  unknown_runs = RunsOf(label, kUnknown);
  outside_chunks = Chunks(outside_runs, 16384);
  unknown_chunks = Chunks(unknown_runs, 16384);
  for (const Run& r : unknown_runs) num_unknown += r.length;
}

void PoissonFill::Impl::ClassifyBlocks(const cv::Mat& label) {
  node_type.assign(static_cast<size_t>(Rc) * Rc, kCoarseOutside);
  for (int J = 0; J < Rc; ++J) {
    for (int I = 0; I < Rc; ++I) {
      int in_domain = 0, in_known = 0;
      for (int y = J * s; y < (J + 1) * s; ++y) {
        const uint8_t* l = label.ptr<uint8_t>(y);
        for (int x = I * s; x < (I + 1) * s; ++x) {
          in_domain += l[x] != kOutside;
          in_known += l[x] == kKnown;
        }
      }
      // Known when at least half the block is known (its value: the affine fit of
      // the known texels at the block centre); unknown when (zero) at least half of
      // it, (neumann) any of it lies in the domain; else outside. Half-block
      // thresholds keep the coarse boundaries unbiased (within ±s/2 of the fine ones).
      uint8_t t = kCoarseOutside;
      if (2 * in_known >= s * s) {
        t = kCoarseKnown;
      } else if (zero_boundary ? 2 * in_domain >= s * s : in_domain > 0) {
        t = kCoarseVar;
      }
      node_type[static_cast<size_t>(J) * Rc + I] = t;
    }
  }
}

void PoissonFill::Impl::DropUnanchoredComponents() {
  std::vector<uint8_t> seen(node_type.size(), 0);
  for (int start = 0; start < Rc * Rc; ++start) {
    if (node_type[start] != kCoarseVar || seen[start]) continue;
    std::vector<int> component;
    std::deque<int> queue = {start};
    seen[start] = 1;
    bool anchored = false;
    while (!queue.empty()) {
      const int n = queue.front();
      queue.pop_front();
      component.push_back(n);
      const int I = n % Rc, J = n / Rc;
      for (int e = 0; e < 4; ++e) {
        const uint8_t t = TypeAt(I + kDi[e], J + kDj[e]);
        if (t == kCoarseKnown) anchored = true;
        if (t == kCoarseVar) {
          const int q = (J + kDj[e]) * Rc + I + kDi[e];
          if (!seen[q]) {
            seen[q] = 1;
            queue.push_back(q);
          }
        }
      }
    }
    if (!anchored) {
      for (int n : component) {
        node_type[n] = kCoarseDropped;
        dropped_nodes.push_back(n);
      }
    }
  }
  std::sort(dropped_nodes.begin(), dropped_nodes.end());
}

void PoissonFill::Impl::SetBilinearWeights() {
  // Fine coordinate x lies at coarse X = (x + 0.5)/s − 0.5.
  i0.resize(R);
  f.resize(R);
  for (int x = 0; x < R; ++x) {
    const double X = (x + 0.5) / s - 0.5;
    int I = static_cast<int>(std::floor(X));
    double fr = X - I;
    if (I < 0) {
      I = 0;
      fr = 0.0;
    }
    if (I > Rc - 2) {
      fr = X - (Rc - 2) > 1.0 ? 1.0 : X - (Rc - 2);
      I = Rc - 2;
    }
    i0[x] = I;
    f[x] = static_cast<float>(fr);
  }
}

void PoissonFill::Impl::FactoriseCoarseSystem(std::vector<uint8_t>* needed) {
  std::vector<int32_t> var_of(node_type.size(), -1);
  for (int n = 0; n < Rc * Rc; ++n) {
    if (node_type[n] == kCoarseVar) {
      var_of[n] = static_cast<int32_t>(var_node.size());
      var_node.push_back(n);
    }
  }
  num_vars = static_cast<int>(var_node.size());
  if (num_vars == 0) return;
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(num_vars) * 5);
  for (int v = 0; v < num_vars; ++v) {
    const int n = var_node[v];
    const int I = n % Rc, J = n / Rc;
    double diag = 0.0;
    for (int e = 0; e < 4; ++e) {
      const int In = I + kDi[e], Jn = J + kDj[e];
      const uint8_t t = TypeAt(In, Jn);
      if (t == kCoarseOutside || t == kCoarseDropped) {
        if (zero_boundary) diag += 1.0;  // Dirichlet 0 (Neumann: left out of the mean)
        continue;
      }
      diag += 1.0;
      const int q = Jn * Rc + In;
      if (t == kCoarseKnown) {
        rhs_var.push_back(v);
        rhs_node.push_back(q);
      } else {
        triplets.emplace_back(v, var_of[q], -1.0);
      }
    }
    triplets.emplace_back(v, v, diag);
    for (int dJ = -1; dJ <= 1; ++dJ) {
      for (int dI = -1; dI <= 1; ++dI) {
        const int In = I + dI, Jn = J + dJ;
        if (In >= 0 && Jn >= 0 && In < Rc && Jn < Rc) (*needed)[static_cast<size_t>(Jn) * Rc + In] = 1;
      }
    }
  }
  Eigen::SparseMatrix<double> A(num_vars, num_vars);
  A.setFromTriplets(triplets.begin(), triplets.end());
  solver.compute(A);
  Require(solver.info() == Eigen::Success,
          fmt::format("PoissonFill: factorising the {}-unknown coarse Laplace system failed", num_vars));
}

void PoissonFill::Impl::MarkInterpolatedNodes(std::vector<uint8_t>* needed) const {
  for (const Run& run : unknown_runs) {
    for (int x = run.x0; x < run.x0 + run.length; ++x) {
      for (int dJ = 0; dJ <= 1; ++dJ)
        for (int dI = 0; dI <= 1; ++dI) (*needed)[static_cast<size_t>(i0[run.y] + dJ) * Rc + i0[x] + dI] = 1;
    }
  }
}

void PoissonFill::Impl::CollectNeededNodes(std::vector<uint8_t>* needed) {
  std::vector<uint8_t>& need = *needed;
  for (int n = 0; n < Rc * Rc; ++n) {
    if (!need[n]) continue;
    if (node_type[n] == kCoarseKnown) known_nodes.push_back(n);
    if (node_type[n] == kCoarseOutside && !zero_boundary) {
      // Neumann extension: mean of the 4-neighbours in the domain, else of the 8-neighbours.
      const int I = n % Rc, J = n / Rc;
      std::vector<int32_t> src;
      for (int e = 0; e < 4; ++e) {
        const uint8_t t = TypeAt(I + kDi[e], J + kDj[e]);
        if (t == kCoarseKnown || t == kCoarseVar) src.push_back((J + kDj[e]) * Rc + I + kDi[e]);
      }
      if (src.empty()) {
        for (int dJ = -1; dJ <= 1; ++dJ)
          for (int dI = -1; dI <= 1; ++dI) {
            const uint8_t t = TypeAt(I + dI, J + dJ);
            if (t == kCoarseKnown || t == kCoarseVar) src.push_back((J + dJ) * Rc + I + dI);
          }
      }
      if (src.empty()) continue;
      ext_node.push_back(n);
      ext_begin.push_back(static_cast<int32_t>(ext_source.size()));
      ext_source.insert(ext_source.end(), src.begin(), src.end());
      // Known sources must have their values computed too.
      for (int32_t q : src) {
        if (node_type[q] == kCoarseKnown && !need[q]) {
          need[q] = 2;  // added below
        }
      }
    }
  }
  ext_begin.push_back(static_cast<int32_t>(ext_source.size()));
  for (int n = 0; n < Rc * Rc; ++n) {
    if (need[n] == 2 && node_type[n] == kCoarseKnown) known_nodes.push_back(n);
  }
  std::sort(known_nodes.begin(), known_nodes.end());
}

void PoissonFill::Impl::FitKnownBlocks(const cv::Mat& label) {
  // Value of a known node: Σ_i w_i f_i over the known texels of its block, with the
  // affine fit's weights evaluated at the block centre (the plain mean for a full block).
  known_begin.push_back(0);
  for (int n : known_nodes) {
    const int I = n % Rc, J = n / Rc;
    const double cx = I * s + 0.5 * (s - 1), cy = J * s + 0.5 * (s - 1);
    std::vector<std::pair<int, int>> texels;
    for (int y = J * s; y < (J + 1) * s; ++y)
      for (int x = I * s; x < (I + 1) * s; ++x)
        if (label.ptr<uint8_t>(y)[x] == kKnown) texels.emplace_back(x, y);
    const std::vector<double> w = AffineFitWeights(texels, cx, cy, s);
    for (size_t i = 0; i < texels.size(); ++i) {
      known_y.push_back(static_cast<uint16_t>(texels[i].second));
      known_x.push_back(static_cast<uint16_t>(texels[i].first));
      known_w.push_back(static_cast<float>(w[i]));
    }
    known_begin.push_back(static_cast<int32_t>(known_w.size()));
  }
}

void PoissonFill::Impl::BuildBand(const cv::Mat& label, int band_texels) {
  // (zero: also near the chart border, where the coarse Dirichlet boundary is off by up to s/2)
  cv::Mat seeds = zero_boundary ? (label != kUnknown) : (label == kKnown);
  cv::Mat near;
  const int b = band_texels;
  cv::dilate(seeds, near, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * b + 1, 2 * b + 1)), cv::Point(-1, -1),
             1, cv::BORDER_CONSTANT, cv::Scalar(255));
  for (int y = 1; y < R - 1; ++y) {
    const uint8_t* l = label.ptr<uint8_t>(y);
    const uint8_t* nr = near.ptr<uint8_t>(y);
    for (int x = 1; x < R - 1; ++x) {
      if (l[x] != kUnknown || !nr[x]) continue;
      float den = 4.0f;
      if (!zero_boundary) {
        den = static_cast<float>((l[x - 1] != kOutside) + (l[x + 1] != kOutside) +
                                 (label.ptr<uint8_t>(y - 1)[x] != kOutside) +
                                 (label.ptr<uint8_t>(y + 1)[x] != kOutside));
        if (den == 0.0f) continue;
      }
      band[(x + y) & 1].push_back({static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1.0f / den});
    }
  }
}

// Builds what does not change from frame to frame (poisson_fill.h, "Solver"; the
// paper's pre-factorised Poisson matrix, Sec. 5.2).
PoissonFill::PoissonFill(const cv::Mat& domain, const cv::Mat& known, const PoissonFillOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  RequireMask(domain, "domain");
  RequireMask(known, "known");
  Require(known.size() == domain.size(), fmt::format("PoissonFill: the known mask is {}x{}, the domain mask {}x{}",
                                                     known.cols, known.rows, domain.cols, domain.rows));
  Impl& m = *impl_;
  m.SetSizes(domain.rows, options);
  const cv::Mat label = LabelTexels(domain, known);
  m.SetRuns(label);
  // Step 1: the coarse Dirichlet nodes (block fits), unknowns and the factorised system.
  m.ClassifyBlocks(label);
  if (!m.zero_boundary) m.DropUnanchoredComponents();
  m.SetBilinearWeights();
  std::vector<uint8_t> needed(m.node_type.size(), 0);  // known / outside nodes near a var
  m.FactoriseCoarseSystem(&needed);
  m.MarkInterpolatedNodes(&needed);  // step 2 reads them
  m.CollectNeededNodes(&needed);
  m.FitKnownBlocks(label);
  // Step 3: the smoothing band.
  if (m.sweeps > 0 && options.fill_band_texels > 0) m.BuildBand(label, options.fill_band_texels);
}

PoissonFill::~PoissonFill() = default;
PoissonFill::PoissonFill(PoissonFill&&) noexcept = default;
PoissonFill& PoissonFill::operator=(PoissonFill&&) noexcept = default;

int PoissonFill::map_size() const { return impl_->R; }
int PoissonFill::block_size() const { return impl_->s; }
int PoissonFill::num_unknown() const { return impl_->num_unknown; }
int PoissonFill::num_coarse_unknown() const { return impl_->num_vars; }
int PoissonFill::num_band() const { return static_cast<int>(impl_->band[0].size() + impl_->band[1].size()); }

void PoissonFill::Apply(cv::Mat* map) const {
  const Impl& m = *impl_;
  Require(map != nullptr && !map->empty(), "PoissonFill::Apply: empty map");
  Require(map->type() == CV_32FC1, fmt::format("PoissonFill::Apply: expected a CV_32FC1 map, got type {} with {} "
                                               "channels",
                                               map->type(), map->channels()));
  Require(map->rows == m.R && map->cols == m.R,
          fmt::format("PoissonFill::Apply: map is {}x{}, expected {}x{} (the domain mask's size)", map->cols,
                      map->rows, m.R, m.R));
  float* base = map->ptr<float>(0);
  const size_t step = map->step1();
  const int Rc = m.Rc;

  // 1. Outside the domain: 0.
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m.outside_chunks.size() - 1),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t c = r.begin(); c != r.end(); ++c) {
                        for (int i = m.outside_chunks[c]; i < m.outside_chunks[c + 1]; ++i) {
                          const Run& run = m.outside_runs[i];
                          std::fill_n(base + run.y * step + run.x0, run.length, 0.0f);
                        }
                      }
                    });
  if (m.num_unknown == 0) return;

  // 2. Coarse values: block means of the known nodes near the unknowns.
  std::vector<float> coarse(static_cast<size_t>(Rc) * Rc, 0.0f);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m.known_nodes.size(), 512), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      float sum = 0.0f;
      for (int32_t e = m.known_begin[i]; e < m.known_begin[i + 1]; ++e)
        sum += m.known_w[e] * base[m.known_y[e] * step + m.known_x[e]];
      coarse[m.known_nodes[i]] = sum;
    }
  });
  // 3. The coarse solve (back-substitution of the factorisation).
  if (m.num_vars > 0) {
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(m.num_vars);
    for (size_t i = 0; i < m.rhs_var.size(); ++i) rhs[m.rhs_var[i]] += coarse[m.rhs_node[i]];
    const Eigen::VectorXd u = m.solver.solve(rhs);
    for (int v = 0; v < m.num_vars; ++v) {
      const double value = u[v];
      coarse[m.var_node[v]] = std::isfinite(value) ? static_cast<float>(value) : 0.0f;
    }
  }
  for (size_t i = 0; i + 1 < m.ext_begin.size(); ++i) {
    float sum = 0.0f;
    for (int32_t e = m.ext_begin[i]; e < m.ext_begin[i + 1]; ++e) sum += coarse[m.ext_source[e]];
    coarse[m.ext_node[i]] = sum / static_cast<float>(m.ext_begin[i + 1] - m.ext_begin[i]);
  }

  // 4. Fine unknown texels: bilinear interpolation of the coarse field.
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m.unknown_chunks.size() - 1),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t c = r.begin(); c != r.end(); ++c) {
                        for (int i = m.unknown_chunks[c]; i < m.unknown_chunks[c + 1]; ++i) {
                          const Run& run = m.unknown_runs[i];
                          const int J = m.i0[run.y];
                          const float fy = m.f[run.y];
                          const float* c0 = coarse.data() + static_cast<size_t>(J) * Rc;
                          const float* c1 = c0 + Rc;
                          float* out = base + run.y * step;
                          for (int x = run.x0; x < run.x0 + run.length; ++x) {
                            const int I = m.i0[x];
                            const float fx = m.f[x];
                            const float top = (1.0f - fx) * c0[I] + fx * c0[I + 1];
                            const float bottom = (1.0f - fx) * c1[I] + fx * c1[I + 1];
                            out[x] = (1.0f - fy) * top + fy * bottom;
                          }
                        }
                      }
                    });

  // 5. Red-black Gauss–Seidel sweeps on the band (outside texels are 0 in the map,
  //    so "zero" sums all four neighbours and "neumann" divides by the in-domain count).
  for (int sweep = 0; sweep < m.sweeps; ++sweep) {
    for (int colour = 0; colour < 2; ++colour) {
      const std::vector<Impl::BandTexel>& band = m.band[colour];
      tbb::parallel_for(tbb::blocked_range<size_t>(0, band.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const Impl::BandTexel& t = band[i];
          float* p = base + t.y * step + t.x;
          p[0] = (p[-1] + p[1] + p[-static_cast<ptrdiff_t>(step)] + p[step]) * t.inv_den;
        }
      });
    }
  }
}

}  // namespace crease
