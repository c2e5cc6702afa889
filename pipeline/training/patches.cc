// Local wrinkle patches, paper Sec. 4.2 (placement, sampling, training pairs)
// and the merge of Sec. 5.2; see patches.h for conventions and differences.
#include "pipeline/training/patches.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/picture.h"
#include "core/options.h"

namespace crease {

void PatchLayoutOptions::VisitFields(OptionVisitor& v) {
  v.Field("size", patch_size);
  v.Field("density", patch_density);
  v.Field("max_outside_fraction", patch_max_outside_fraction);
}

void PatchLayoutOptions::Check() const {
  const char* o = "PatchLayoutOptions";
  CheckGe(o, "patch_size", patch_size, 1);
  CheckLe(o, "patch_size", patch_size, 1024);
  CheckGt(o, "patch_density", patch_density, 0.0);
  CheckLe(o, "patch_density", patch_density, 4.0);
  CheckGe(o, "patch_max_outside_fraction", patch_max_outside_fraction, 0.0);
  CheckLe(o, "patch_max_outside_fraction", patch_max_outside_fraction, 1.0);
}

void PatchLayout::Validate(const std::string& what) const {
  Require(map_size >= 2, fmt::format("{}: map size {} must be >= 2", what, map_size));
  Require(patch_size >= 1, fmt::format("{}: patch size {} must be >= 1", what, patch_size));
  // (Conditions first, messages only on failure: this runs per patch.)
  const float lo = -0.5f, hi = static_cast<float>(map_size) - 0.5f;
  for (size_t k = 0; k < patches.size(); ++k) {
    const PatchFrame& f = patches[k];
    if (!(std::isfinite(f.center_texel.x()) && std::isfinite(f.center_texel.y()) && std::isfinite(f.angle))) {
      throw Error(fmt::format("{}: patch {} has a non-finite centre or angle", what, k));
    }
    if (!(f.center_texel.x() >= lo && f.center_texel.x() <= hi && f.center_texel.y() >= lo &&
          f.center_texel.y() <= hi)) {
      throw Error(fmt::format("{}: patch {} centre ({}, {}) lies outside the {}x{} map", what, k,
                              f.center_texel.x(), f.center_texel.y(), map_size, map_size));
    }
  }
}

namespace {

// ---------------------------------------------------------------------------
// Bilinear stencils, shared by SamplePatch, PatchSampler and the placement test
// so that all agree to the bit.

struct Stencil {
  int x0 = 0, y0 = 0;  // top-left tap
  float fx = 0.0f, fy = 0.0f;  // weights of the right / lower taps
  bool clamped = false;        // the position lay beyond the map
};

// Patch axes of angle θ: e1 = (cos θ, sin θ), e2 = (−sin θ, cos θ).
struct Axes {
  float c, s;
  explicit Axes(float angle)
      : c(static_cast<float>(std::cos(static_cast<double>(angle)))),
        s(static_cast<float>(std::sin(static_cast<double>(angle)))) {}
};

// Position of sample (a, b) of a w × w patch (patches.h).
inline void SamplePosition(const PatchFrame& f, const Axes& e, int w, int a, int b, float* x, float* y) {
  const float half = 0.5f * static_cast<float>(w - 1);
  const float sa = static_cast<float>(a) - half;
  const float sb = static_cast<float>(b) - half;
  *x = f.center_texel.x() + sa * e.c - sb * e.s;
  *y = f.center_texel.y() + sa * e.s + sb * e.c;
}

// Bilinear stencil at texel coordinates (x, y) of a cols × rows map (≥ 2 each);
// positions beyond the map clamp to its border.
inline Stencil MakeStencil(float x, float y, int cols, int rows) {
  Stencil st;
  const float xmax = static_cast<float>(cols - 1), ymax = static_cast<float>(rows - 1);
  st.clamped = !(x >= 0.0f && x <= xmax && y >= 0.0f && y <= ymax);
  x = std::clamp(x, 0.0f, xmax);
  y = std::clamp(y, 0.0f, ymax);
  st.x0 = std::min(static_cast<int>(std::floor(x)), cols - 2);
  st.y0 = std::min(static_cast<int>(std::floor(y)), rows - 2);
  st.fx = x - static_cast<float>(st.x0);
  st.fy = y - static_cast<float>(st.y0);
  return st;
}

// The four bilinear taps of sample (a, b) of patch `f`, as f(texel, weight), weights > 0
// only; the adjoint of SamplePatch (PatchSampler's splat and SplatPatches).
template <typename F>
inline void ForEachTap(const PatchFrame& f, const Axes& e, int w, int S, int a, int b, const F& fn) {
  float x, y;
  SamplePosition(f, e, w, a, b, &x, &y);
  const Stencil st = MakeStencil(x, y, S, S);
  const int32_t o = st.y0 * S + st.x0;
  const float w00 = (1.0f - st.fx) * (1.0f - st.fy), w01 = st.fx * (1.0f - st.fy);
  const float w10 = (1.0f - st.fx) * st.fy, w11 = st.fx * st.fy;
  if (w00 > 0.0f) fn(o, w00);
  if (w01 > 0.0f) fn(o + 1, w01);
  if (w10 > 0.0f) fn(o + S, w10);
  if (w11 > 0.0f) fn(o + S + 1, w11);
}

// The bilinear value; `p` points at the top-left tap, `step` is the row stride in floats.
inline float Apply(const float* p, size_t step, float fx, float fy) {
  const float top = (1.0f - fx) * p[0] + fx * p[1];
  const float bottom = (1.0f - fx) * p[step] + fx * p[step + 1];
  return (1.0f - fy) * top + fy * bottom;
}

void RequireMap(const cv::Mat& map, const std::string& what) {
  Require(!map.empty(), fmt::format("{}: empty map", what));
  Require(map.type() == CV_32FC1,
          fmt::format("{}: expected a CV_32FC1 map, got type {} with {} channels", what, map.type(), map.channels()));
  Require(map.rows >= 2 && map.cols >= 2,
          fmt::format("{}: map is {}x{}, expected at least 2x2", what, map.cols, map.rows));
}

void RequireSquare(const cv::Mat& m, int size, int type, const char* type_name, const std::string& what) {
  Require(m.type() == type, fmt::format("{}: expected {}, got type {}", what, type_name, m.type()));
  Require(m.rows == size && m.cols == size,
          fmt::format("{}: is {}x{}, expected {}x{}", what, m.cols, m.rows, size, size));
}

}  // namespace

void SamplePatch(const cv::Mat& map, const PatchFrame& frame, int w, float* out) {
  RequireMap(map, "SamplePatch");
  Require(w >= 1, fmt::format("SamplePatch: patch size {} must be >= 1", w));
  const Axes e(frame.angle);
  const size_t step = map.step1();
  const float* data = map.ptr<float>(0);
  for (int b = 0; b < w; ++b) {
    for (int a = 0; a < w; ++a) {
      float x, y;
      SamplePosition(frame, e, w, a, b, &x, &y);
      const Stencil st = MakeStencil(x, y, map.cols, map.rows);
      out[b * w + a] = Apply(data + static_cast<size_t>(st.y0) * step + st.x0, step, st.fx, st.fy);
    }
  }
}

// ---------------------------------------------------------------------------
// Placement (Sec. 4.2).

PatchLayout PlacePatches(const cv::Mat& probability, const cv::Mat& angle, const cv::Mat& valid,
                         const cv::Mat& coverage, const PatchLayoutOptions& options, PatchLayoutReport* report) {
  options.Check();
  Require(!probability.empty(), "PlacePatches: empty wrinkle map");
  const int S = probability.rows;
  Require(S >= 2, fmt::format("PlacePatches: wrinkle map is {}x{}, expected at least 2x2", probability.cols, S));
  RequireSquare(probability, S, CV_32FC1, "CV_32FC1", "PlacePatches: wrinkle map");
  RequireSquare(angle, S, CV_32FC1, "CV_32FC1", "PlacePatches: angle map (same size as the wrinkle map)");
  if (!valid.empty()) RequireSquare(valid, S, CV_8UC1, "CV_8UC1", "PlacePatches: valid mask");
  if (!coverage.empty()) RequireSquare(coverage, S, CV_8UC1, "CV_8UC1", "PlacePatches: coverage mask");
  const int w = options.patch_size;

  // ℓ: valid texels with W > 0, by decreasing W, ties by texel index.
  struct Candidate {
    float value;
    int index;
  };
  std::vector<Candidate> list;
  for (int y = 0; y < S; ++y) {
    const float* p = probability.ptr<float>(y);
    const uint8_t* v = valid.empty() ? nullptr : valid.ptr<uint8_t>(y);
    for (int x = 0; x < S; ++x) {
      if (!std::isfinite(p[x])) {
        throw Error(fmt::format("PlacePatches: wrinkle map texel ({}, {}) is not finite", x, y));
      }
      if (p[x] > 0.0f && (!v || v[x])) list.push_back({p[x], y * S + x});
    }
  }
  std::sort(list.begin(), list.end(), [](const Candidate& a, const Candidate& b) {
    return a.value != b.value ? a.value > b.value : a.index < b.index;
  });

  // Uncovered texels and their integral image (fast accept of patches whose
  // bounding box is fully covered).
  cv::Mat uncovered(S, S, CV_8U, cv::Scalar(0));
  if (!coverage.empty()) cv::compare(coverage, 0, uncovered, cv::CMP_EQ);
  cv::Mat uncovered01, integral;
  cv::compare(uncovered, 0, uncovered01, cv::CMP_NE);
  uncovered01 /= 255;  // CV_8U 0 / 1
  cv::integral(uncovered01, integral, CV_32S);
  auto uncovered_in = [&](int x0, int y0, int x1, int y1) {  // inclusive box, inside the map
    return integral.at<int>(y1 + 1, x1 + 1) - integral.at<int>(y0, x1 + 1) - integral.at<int>(y1 + 1, x0) +
           integral.at<int>(y0, x0);
  };
  const int max_outside = static_cast<int>(std::floor(options.patch_max_outside_fraction * w * w + 1e-9));

  // Does the patch at `f` read at most max_outside samples off the coverage?
  auto footprint_ok = [&](const PatchFrame& f) {
    const Axes e(f.angle);
    const float extent = 0.5f * static_cast<float>(w - 1) * (std::abs(e.c) + std::abs(e.s));
    const int bx0 = static_cast<int>(std::floor(f.center_texel.x() - extent));
    const int by0 = static_cast<int>(std::floor(f.center_texel.y() - extent));
    const int bx1 = static_cast<int>(std::ceil(f.center_texel.x() + extent));
    const int by1 = static_cast<int>(std::ceil(f.center_texel.y() + extent));
    if (bx0 >= 0 && by0 >= 0 && bx1 < S && by1 < S && uncovered_in(bx0, by0, bx1, by1) == 0) return true;
    int outside = 0;
    for (int b = 0; b < w; ++b) {
      for (int a = 0; a < w; ++a) {
        float x, y;
        SamplePosition(f, e, w, a, b, &x, &y);
        const Stencil st = MakeStencil(x, y, S, S);
        bool out = st.clamped;
        if (!out) {
          const uint8_t* r0 = uncovered.ptr<uint8_t>(st.y0);
          const uint8_t* r1 = uncovered.ptr<uint8_t>(st.y0 + 1);
          const float w00 = (1.0f - st.fx) * (1.0f - st.fy), w01 = st.fx * (1.0f - st.fy);
          const float w10 = (1.0f - st.fx) * st.fy, w11 = st.fx * st.fy;
          out = (w00 > 0.0f && r0[st.x0]) || (w01 > 0.0f && r0[st.x0 + 1]) || (w10 > 0.0f && r1[st.x0]) ||
                (w11 > 0.0f && r1[st.x0 + 1]);
        }
        if (out && ++outside > max_outside) return false;
      }
    }
    return true;
  };

  PatchLayout layout;
  layout.map_size = S;
  layout.patch_size = w;
  PatchLayoutReport rep;
  rep.candidates = static_cast<int>(list.size());
  std::vector<uint8_t> removed(static_cast<size_t>(S) * S, 0);
  const float h = 0.5f * static_cast<float>(options.patch_density * w);  // half side of the ρw sub-rectangle
  for (const Candidate& c : list) {
    if (removed[c.index]) continue;
    const int px = c.index % S, py = c.index / S;
    PatchFrame frame;
    frame.center_texel = Eigen::Vector2f(static_cast<float>(px), static_cast<float>(py));
    frame.angle = angle.at<float>(py, px);
    if (!std::isfinite(frame.angle)) {
      throw Error(fmt::format("PlacePatches: angle at texel ({}, {}) is not finite", px, py));
    }
    removed[c.index] = 1;
    if (!footprint_ok(frame)) {  // Difference 2: only p leaves ℓ
      ++rep.skipped_outside;
      continue;
    }
    layout.patches.push_back(frame);
    // Remove the texels strictly inside the oriented ρw × ρw sub-rectangle (Difference 1).
    const Axes e(frame.angle);
    const float extent = h * (std::abs(e.c) + std::abs(e.s));
    const int x0 = std::max(0, static_cast<int>(std::floor(px - extent)));
    const int x1 = std::min(S - 1, static_cast<int>(std::ceil(px + extent)));
    const int y0 = std::max(0, static_cast<int>(std::floor(py - extent)));
    const int y1 = std::min(S - 1, static_cast<int>(std::ceil(py + extent)));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const float dx = static_cast<float>(x - px), dy = static_cast<float>(y - py);
        const float along1 = dx * e.c + dy * e.s, along2 = -dx * e.s + dy * e.c;
        if (std::abs(along1) < h && std::abs(along2) < h) removed[static_cast<size_t>(y) * S + x] = 1;
      }
    }
  }
  rep.placed = layout.num_patches();
  if (report) *report = rep;
  return layout;
}

PatchLayout PlacePatches(const WrinkleMap& map, const PatchLayoutOptions& options, PatchLayoutReport* report) {
  return PlacePatches(map.probability, map.angle, map.valid, map.coverage, options, report);
}

// ---------------------------------------------------------------------------
// PatchSampler: stencils once, then per-frame sampling and merging (Sec. 5.2).

struct PatchSampler::Impl {
  int N = 0, w = 0, S = 0;
  // Stencil of sample s of patch k at s·N + k (the column-major order of the
  // N×w² matrix, so Sample writes one contiguous column per sample index).
  std::vector<int32_t> offset;  // y0·S + x0
  std::vector<float> fx, fy;
  // Splat as a gather: for covered texel t = texels[q], the entries
  // [begin[q], begin[q+1]) name matrix elements (data index) and their bilinear
  // weights, by patch then sample (a fixed summation order: deterministic).
  std::vector<int32_t> texels;
  std::vector<int32_t> begin;
  std::vector<int32_t> entry_index;
  std::vector<float> entry_weight;
  cv::Mat weight;  // CV_32F S×S
};

PatchSampler::PatchSampler(const PatchLayout& layout) : impl_(std::make_unique<Impl>()) {
  layout.Validate("PatchSampler");
  Impl& m = *impl_;
  m.N = layout.num_patches();
  m.w = layout.patch_size;
  m.S = layout.map_size;
  const int64_t total = static_cast<int64_t>(m.N) * m.w * m.w;
  Require(total * 4 < std::numeric_limits<int32_t>::max(),
          fmt::format("PatchSampler: {} patches of {}x{} samples are too many", m.N, m.w, m.w));
  m.offset.resize(total);
  m.fx.resize(total);
  m.fy.resize(total);
  // Sample-major, like the stencil arrays (contiguous writes).
  std::vector<Axes> axes;
  axes.reserve(m.N);
  for (const PatchFrame& f : layout.patches) axes.emplace_back(f.angle);
  const int ww = m.w * m.w;
  tbb::parallel_for(tbb::blocked_range<int>(0, ww, 8), [&](const tbb::blocked_range<int>& r) {
    for (int s = r.begin(); s != r.end(); ++s) {
      const int a = s % m.w, b = s / m.w;
      for (int k = 0; k < m.N; ++k) {
        float x, y;
        SamplePosition(layout.patches[k], axes[k], m.w, a, b, &x, &y);
        const Stencil st = MakeStencil(x, y, m.S, m.S);
        const int64_t i = static_cast<int64_t>(s) * m.N + k;
        m.offset[i] = st.y0 * m.S + st.x0;
        m.fx[i] = st.fx;
        m.fy[i] = st.fy;
      }
    }
  });

  // Gather lists for Splat: counting sort of the (texel, data index, weight)
  // entries by texel, filled in a fixed order (patch, then sample).
  const int64_t texel_count = static_cast<int64_t>(m.S) * m.S;
  std::vector<int32_t> count(texel_count + 1, 0);
  // The stencils are recomputed patch by patch here (the same arithmetic as
  // above, so the same values): neighbouring samples then hit neighbouring
  // texels, where reading the sample-major arrays would stride by N.
  auto for_each_tap = [&](const auto& f) {
    for (int k = 0; k < m.N; ++k) {
      for (int s = 0; s < ww; ++s) {
        const int32_t i = static_cast<int32_t>(static_cast<int64_t>(s) * m.N + k);
        ForEachTap(layout.patches[k], axes[k], m.w, m.S, s % m.w, s / m.w, [&](int32_t t, float wt) { f(t, i, wt); });
      }
    }
  };
  for_each_tap([&](int32_t t, int32_t, float) { ++count[t]; });
  std::vector<int32_t> start(texel_count + 1, 0);  // entries < 4·total < 2³¹ (checked above)
  for (int64_t t = 0; t < texel_count; ++t) start[t + 1] = start[t] + count[t];
  m.entry_index.resize(start[texel_count]);
  m.entry_weight.resize(start[texel_count]);
  {
    std::vector<int32_t> cursor(start.begin(), start.end() - 1);
    for_each_tap([&](int32_t t, int32_t i, float wt) {
      const int32_t e = cursor[t]++;
      m.entry_index[e] = i;
      m.entry_weight[e] = wt;
    });
  }
  m.weight = cv::Mat(m.S, m.S, CV_32F, cv::Scalar(0));
  float* weight = m.weight.ptr<float>(0);
  for (int64_t t = 0; t < texel_count; ++t) {
    if (count[t] == 0) continue;
    m.texels.push_back(static_cast<int32_t>(t));
    m.begin.push_back(start[t]);
    float sum = 0.0f;
    for (int32_t e = start[t]; e < start[t + 1]; ++e) sum += m.entry_weight[e];
    weight[t] = sum;
  }
  m.begin.push_back(start[texel_count]);
}

PatchSampler::~PatchSampler() = default;
PatchSampler::PatchSampler(PatchSampler&&) noexcept = default;
PatchSampler& PatchSampler::operator=(PatchSampler&&) noexcept = default;

int PatchSampler::num_patches() const { return impl_->N; }
int PatchSampler::patch_size() const { return impl_->w; }
int PatchSampler::map_size() const { return impl_->S; }
const cv::Mat& PatchSampler::splat_weight() const { return impl_->weight; }

Eigen::MatrixXf PatchSampler::Sample(const cv::Mat& map) const {
  Eigen::MatrixXf patches;
  Sample(map, &patches);
  return patches;
}

void PatchSampler::Sample(const cv::Mat& map, Eigen::MatrixXf* patches) const {
  const Impl& m = *impl_;
  RequireMap(map, "PatchSampler::Sample");
  RequireSquare(map, m.S, CV_32FC1, "CV_32FC1", "PatchSampler::Sample: map (the layout's map size)");
  const cv::Mat src = map.isContinuous() ? map : map.clone();
  const float* data = src.ptr<float>(0);
  const size_t step = static_cast<size_t>(m.S);
  const int ww = m.w * m.w;
  patches->resize(m.N, ww);
  float* out = patches->data();
  tbb::parallel_for(tbb::blocked_range<int>(0, ww, 8), [&](const tbb::blocked_range<int>& r) {
    for (int s = r.begin(); s != r.end(); ++s) {
      const int64_t base = static_cast<int64_t>(s) * m.N;
      for (int k = 0; k < m.N; ++k) {
        const int64_t i = base + k;
        out[i] = Apply(data + m.offset[i], step, m.fx[i], m.fy[i]);
      }
    }
  });
}

cv::Mat PatchSampler::Splat(const Eigen::MatrixXf& patches) const {
  const Impl& m = *impl_;
  Require(patches.rows() == m.N && patches.cols() == m.w * m.w,
          fmt::format("PatchSampler::Splat: patches are {}x{}, expected {}x{} (patches x w*w)", patches.rows(),
                      patches.cols(), m.N, m.w * m.w));
  cv::Mat out(m.S, m.S, CV_32F, cv::Scalar(0));
  float* o = out.ptr<float>(0);
  const float* weight = m.weight.ptr<float>(0);
  const float* data = patches.data();
  const int n = static_cast<int>(m.texels.size());
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 256), [&](const tbb::blocked_range<int>& r) {
    for (int q = r.begin(); q != r.end(); ++q) {
      float sum = 0.0f;
      for (int32_t e = m.begin[q]; e < m.begin[q + 1]; ++e) sum += m.entry_weight[e] * data[m.entry_index[e]];
      const int32_t t = m.texels[q];
      o[t] = sum / weight[t];
    }
  });
  return out;
}

void SamplePatches(const cv::Mat& map, const std::vector<PatchFrame>& frames, int w, float* rows) {
  RequireMap(map, "SamplePatches");
  const cv::Mat src = map.isContinuous() ? map : map.clone();
  const int N = static_cast<int>(frames.size());
  const size_t n = static_cast<size_t>(w) * w;
  tbb::parallel_for(tbb::blocked_range<int>(0, N, 8), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k != r.end(); ++k) SamplePatch(src, frames[k], w, rows + k * n);
  });
}

SplatSums SplatPatches(const std::vector<PatchFrame>& frames, int w, int S, const float* rows,
                       const std::vector<float>& gain) {
  Require(S >= 2 && w >= 1, fmt::format("SplatPatches: map size {} must be >= 2 and patch size {} >= 1", S, w));
  Require(gain.size() == frames.size(),
          fmt::format("SplatPatches: {} gains for {} patches", gain.size(), frames.size()));
  SplatSums out{cv::Mat(S, S, CV_32F, cv::Scalar(0)), cv::Mat(S, S, CV_32F, cv::Scalar(0)),
                cv::Mat(S, S, CV_32F, cv::Scalar(0))};
  float* value = out.value.ptr<float>(0);
  float* g = out.gain.ptr<float>(0);
  float* weight = out.weight.ptr<float>(0);
  const size_t n = static_cast<size_t>(w) * w;
  for (size_t k = 0; k < frames.size(); ++k) {  // sequential, in patch order: deterministic
    const Axes e(frames[k].angle);
    const float* d = rows + k * n;
    const float gk = gain[k];
    for (int b = 0; b < w; ++b) {
      for (int a = 0; a < w; ++a) {
        const float dv = d[b * w + a];
        ForEachTap(frames[k], e, w, S, a, b, [&](int32_t t, float wt) {
          value[t] += wt * dv;
          g[t] += wt * gk;
          weight[t] += wt;
        });
      }
    }
  }
  return out;
}

// ---------------------------------------------------------------------------
// Training pairs (Sec. 4.2).

PatchLayout ShiftedLayout(const PatchLayout& layout, double shift_texels, int steps) {
  Require(steps >= 0, fmt::format("ShiftedLayout: steps = {} must be >= 0", steps));
  if (steps == 0) return layout;
  Require(std::isfinite(shift_texels) && shift_texels > 0,
          fmt::format("ShiftedLayout: shift = {} texels must be finite and > 0", shift_texels));
  PatchLayout out = layout;
  const float S = static_cast<float>(layout.map_size);
  for (int k = -steps; k <= steps; ++k) {
    if (k == 0) continue;
    for (const PatchFrame& f : layout.patches) {
      const Eigen::Vector2f e1(std::cos(f.angle), std::sin(f.angle));
      PatchFrame g = f;
      g.center_texel += static_cast<float>(k * shift_texels) * e1;
      if (g.center_texel.x() < 0 || g.center_texel.y() < 0 || g.center_texel.x() > S - 1 ||
          g.center_texel.y() > S - 1)
        continue;
      out.patches.push_back(g);
    }
  }
  return out;
}

TrainingPatches ExtractTrainingPatches(const PatchLayout& layout, const std::vector<cv::Mat>& textures,
                                       const std::vector<cv::Mat>& responses,
                                       const std::vector<cv::Mat>& displacements,
                                       const WrinkleMapOptions& options) {
  options.Check();
  layout.Validate("ExtractTrainingPatches: layout");
  const int J = static_cast<int>(textures.size());
  Require(J > 0, "ExtractTrainingPatches: no textures (need at least one expression)");
  Require(static_cast<int>(responses.size()) == J,
          fmt::format("ExtractTrainingPatches: {} responses for {} textures", responses.size(), J));
  Require(static_cast<int>(displacements.size()) == J,
          fmt::format("ExtractTrainingPatches: {} displacement maps for {} textures", displacements.size(), J));
  const int S = layout.map_size;
  for (int j = 0; j < J; ++j) {
    RequireSquare(textures[j], S, CV_32FC1, "CV_32FC1",
                  fmt::format("ExtractTrainingPatches: texture {} (layout map size)", j));
    RequireSquare(responses[j], S, CV_32FC1, "CV_32FC1",
                  fmt::format("ExtractTrainingPatches: response {} (layout map size)", j));
    RequireSquare(displacements[j], S, CV_32FC1, "CV_32FC1",
                  fmt::format("ExtractTrainingPatches: displacement map {} (layout map size)", j));
  }
  // One pair per patch k and expression j with r_j(centre) > α (Sec. 4.2).
  TrainingPatches out;
  const float alpha = static_cast<float>(options.wrinkle_threshold);
  for (int k = 0; k < layout.num_patches(); ++k) {
    const Eigen::Vector2f& c = layout.patches[k].center_texel;
    const int x = std::clamp(static_cast<int>(std::lround(c.x())), 0, S - 1);
    const int y = std::clamp(static_cast<int>(std::lround(c.y())), 0, S - 1);
    for (int j = 0; j < J; ++j) {
      if (responses[j].at<float>(y, x) > alpha) {
        out.patch_index.push_back(k);
        out.expression_index.push_back(j);
      }
    }
  }
  const int N = out.size(), w = layout.patch_size, ww = w * w;
  out.texture.resize(N, ww);
  out.displacement.resize(N, ww);
  tbb::parallel_for(tbb::blocked_range<int>(0, N, 8), [&](const tbb::blocked_range<int>& r) {
    std::vector<float> buffer(ww);
    for (int i = r.begin(); i != r.end(); ++i) {
      const PatchFrame& f = layout.patches[out.patch_index[i]];
      const int j = out.expression_index[i];
      SamplePatch(textures[j], f, w, buffer.data());
      for (int s = 0; s < ww; ++s) out.texture(i, s) = buffer[s];
      SamplePatch(displacements[j], f, w, buffer.data());
      for (int s = 0; s < ww; ++s) out.displacement(i, s) = buffer[s];
    }
  });
  return out;
}

// ---------------------------------------------------------------------------
// Picture (Fig. 6).

cv::Mat DrawPatchLayout(const cv::Mat& wrinkle_map, const PatchLayout& layout, const cv::Mat& valid) {
  RequireMap(wrinkle_map, "DrawPatchLayout: wrinkle map");
  const int S = wrinkle_map.rows;
  RequireSquare(wrinkle_map, S, CV_32FC1, "CV_32FC1", "DrawPatchLayout: wrinkle map");
  if (!valid.empty()) RequireSquare(valid, S, CV_8UC1, "CV_8UC1", "DrawPatchLayout: valid mask");
  Require(layout.num_patches() == 0 || layout.map_size == S,
          fmt::format("DrawPatchLayout: layout is for {}x{} maps, wrinkle map is {}x{}", layout.map_size,
                      layout.map_size, S, S));
  // Heat map scaled to the 99.5th percentile of the positive values.
  std::vector<float> positive;
  for (int y = 0; y < S; ++y) {
    const float* p = wrinkle_map.ptr<float>(y);
    for (int x = 0; x < S; ++x) {
      if (p[x] > 0.0f && std::isfinite(p[x])) positive.push_back(p[x]);
    }
  }
  float top = 1.0f;
  if (!positive.empty()) {
    const size_t q = std::min(positive.size() - 1, static_cast<size_t>(0.995 * positive.size()));
    std::nth_element(positive.begin(), positive.begin() + q, positive.end());
    top = positive[q] > 0.0f ? positive[q] : 1.0f;
  }
  cv::Mat gray8;
  wrinkle_map.convertTo(gray8, CV_8U, 255.0 / top);
  cv::Mat heat;
  cv::applyColorMap(gray8, heat, cv::COLORMAP_INFERNO);
  if (!valid.empty()) heat.setTo(cv::Scalar(56, 56, 56), valid == 0);
  // Small maps are enlarged so the rectangles stay legible.
  const int k = std::max(1, (512 + S - 1) / S);
  if (k > 1) cv::resize(heat, heat, cv::Size(S * k, S * k), 0, 0, cv::INTER_NEAREST);
  constexpr int kShift = 4;  // sub-pixel drawing, 1/16 pixel
  auto to_px = [&](float tx, float ty) {
    // texel coordinate → enlarged pixel centre, in 1/16 pixels
    const float px = (tx + 0.5f) * k - 0.5f, py = (ty + 0.5f) * k - 0.5f;
    return cv::Point(static_cast<int>(std::lround(px * (1 << kShift))),
                     static_cast<int>(std::lround(py * (1 << kShift))));
  };
  const float half = 0.5f * static_cast<float>(layout.patch_size);
  for (const PatchFrame& f : layout.patches) {
    const Axes e(f.angle);
    const float cx = f.center_texel.x(), cy = f.center_texel.y();
    const float sa[4] = {-half, half, half, -half}, sb[4] = {-half, -half, half, half};
    cv::Point corner[4];
    for (int i = 0; i < 4; ++i) corner[i] = to_px(cx + sa[i] * e.c - sb[i] * e.s, cy + sa[i] * e.s + sb[i] * e.c);
    for (int i = 0; i < 4; ++i) cv::line(heat, corner[i], corner[(i + 1) % 4], cv::Scalar(255, 255, 0), 1, cv::LINE_AA, kShift);
    cv::line(heat, to_px(cx, cy), to_px(cx + half * e.c, cy + half * e.s), cv::Scalar(80, 255, 80), 1, cv::LINE_AA,
             kShift);
  }
  cv::cvtColor(heat, heat, cv::COLOR_BGR2RGB);  // OpenCV draws BGR; WriteImage writes R, G, B
  return heat;
}

cv::Mat PairMosaic(const Eigen::MatrixXf& texture, const Eigen::MatrixXf& displacement, int patch_size, int count,
                   int scale) {
  const int w = patch_size, n = w * w;
  Require(w > 0 && count > 0 && scale > 0 && texture.cols() == n && displacement.cols() == n &&
              texture.rows() == displacement.rows() && texture.rows() > 0,
          fmt::format("PairMosaic: {}×{} texture and {}×{} displacement patches, patch size {}", texture.rows(),
                      texture.cols(), displacement.rows(), displacement.cols(), w));
  const int N = static_cast<int>(texture.rows()), shown = std::min(count, N), per_row = 8, gap = 2;
  const int cell_w = 2 * w + gap, rows = (shown + per_row - 1) / per_row;
  cv::Mat out(rows * (w + gap), per_row * cell_w, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int k = 0; k < shown; ++k) {
    const int i = static_cast<int>(static_cast<int64_t>(k) * N / shown);
    cv::Mat t(w, w, CV_32F), d(w, w, CV_32F);
    for (int p = 0; p < n; ++p) {
      t.at<float>(p / w, p % w) = texture(i, p);
      d.at<float>(p / w, p % w) = displacement(i, p);
    }
    double lo = 0, hi = 0;
    cv::minMaxLoc(t, &lo, &hi);
    cv::Mat t8, t3;
    t.convertTo(t8, CV_8U, hi > lo ? 255.0 / (hi - lo) : 0.0, hi > lo ? -255.0 * lo / (hi - lo) : 128.0);
    cv::cvtColor(t8, t3, cv::COLOR_GRAY2RGB);
    const double range = std::max(cv::norm(d, cv::NORM_INF), 1e-9);
    const int x = (k % per_row) * cell_w, y = (k / per_row) * (w + gap);
    t3.copyTo(out(cv::Rect(x, y, w, w)));
    DisplacementPicture(d, range).copyTo(out(cv::Rect(x + w, y, w, w)));
  }
  cv::Mat big;
  cv::resize(out, big, cv::Size(), scale, scale, cv::INTER_NEAREST);
  return big;
}

}  // namespace crease
