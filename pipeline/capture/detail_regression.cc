// Online detail regression, paper Sec. 5.2; see detail_regression.h.
#include "pipeline/capture/detail_regression.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <optional>

#include <Eigen/Core>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/options.h"

namespace crease {

void DetailRegressionOptions::VisitFields(OptionVisitor& v) {
  v.Field("wrinkle_frames", wrinkle_frames);
  v.Field("wrinkle_min_seen_fraction", wrinkle_min_seen_fraction);
  v.Field("wrinkle_extension_sigma", wrinkle_extension_sigma);
  v.Field("wrinkle_seen_margin_sigmas", wrinkle_seen_margin_sigmas);
  v.Field("patch_max_unseen_fraction", patch_max_unseen_fraction);
  v.Field("gate_by_response", gate_by_response);
  v.Field("gate_softness", gate_softness);
  v.Field("recentre_radius", recentre_radius);
  v.Field("recentre_step", recentre_step);
  v.Section("fill", fill);
  v.Section("reference_alignment", reference_alignment);
}

void DetailRegressionOptions::Check() const {
  const char* o = "DetailRegressionOptions";
  CheckGe(o, "wrinkle_frames", wrinkle_frames, 1);
  CheckGe(o, "wrinkle_min_seen_fraction", wrinkle_min_seen_fraction, 0.0);
  CheckLe(o, "wrinkle_min_seen_fraction", wrinkle_min_seen_fraction, 1.0);
  CheckGt(o, "wrinkle_extension_sigma", wrinkle_extension_sigma, 0.0);
  CheckGe(o, "wrinkle_seen_margin_sigmas", wrinkle_seen_margin_sigmas, 0.0);
  CheckLe(o, "wrinkle_seen_margin_sigmas", wrinkle_seen_margin_sigmas, 16.0);
  CheckGe(o, "patch_max_unseen_fraction", patch_max_unseen_fraction, 0.0);
  CheckLe(o, "patch_max_unseen_fraction", patch_max_unseen_fraction, 1.0);
  CheckGe(o, "gate_softness", gate_softness, 0.0);
  CheckLe(o, "gate_softness", gate_softness, 1.0);
  CheckGe(o, "recentre_radius", recentre_radius, 0.0);
  CheckLe(o, "recentre_radius", recentre_radius, 64.0);
  CheckGt(o, "recentre_step", recentre_step, 0.0);
  CheckLe(o, "recentre_step", recentre_step, 64.0);
  fill.Check();
  reference_alignment.Check();
}

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// Footprint grid of a patch for the seen check: samples a, b ∈ {0, g, 2g, …, w−1}.
constexpr int kFootprintGrid = 9;

// The soft gate (gate_softness s > 0): a patch's weight w rises linearly from 0 at a
// DoG response r = (1 − s)α to 1 at (1 + s)α, so that a response near α, which sensor
// noise moves from frame to frame, moves the patch's share of D^t a little instead of
// switching it on and off (s = 0: the hard gate, dropped at r ≤ α).
float GateWeight(float response, float alpha, float softness) {
  if (!std::isfinite(response)) return 0.0f;
  const float w = (response - (1.0f - softness) * alpha) / (2.0f * softness * alpha);
  return std::clamp(w, 0.0f, 1.0f);
}

// Under the soft gate a texel's merge is divided by its kept share no smaller than
// this, so that it fades to 0 as the weights of all the patches covering it do,
// instead of jumping to 0 when the last one reaches w = 0. One of 4 patches at the
// layout's spacing of about half a patch (PlacePatches) keeps its full value.
constexpr float kSoftGateShareFloor = 0.25f;

// A texel's merge `merged` (Σ_kept w d / Σ_all w) divided by its kept share `kept` (Σ_kept w
// / Σ_all w): under the soft gate by at least kSoftGateShareFloor; with the hard gate 0
// where (almost) nothing was kept. Shared by RenormaliseDropped and MergeMoved.
float DivideByKeptShare(float merged, float kept, bool soft) {
  if (soft) return merged / std::max(kept, kSoftGateShareFloor);
  return kept > 1e-4f ? merged / kept : 0.0f;
}

// 1D Gaussian of σ truncated at 3σ (it is normalised per texel anyway: the gate
// evaluates normalised convolutions like DogResponse, whose OpenCV kernels reach 4σ;
// the difference is < 0.3 % of the kernel mass), normalised.
std::vector<float> GaussianTaps(double sigma) {
  const int radius = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  const cv::Mat k = cv::getGaussianKernel(2 * radius + 1, sigma, CV_32F);
  return std::vector<float>(k.begin<float>(), k.end<float>());
}

}  // namespace

struct DetailRegressor::Impl {
  DetailModel model;
  DetailRegressionOptions options;
  int R = 0;
  cv::Mat coverage;  // CV_8U 255 / 0
  std::optional<WrinkleMapBuilder> builder;
  cv::Mat seen_count;  // CV_32S: J_p
  int frames = 0;
  // After FixLayout.
  bool fixed = false;
  WrinkleMap wmap;
  PatchLayout layout;
  PatchLayoutReport layout_report;
  std::optional<PatchSampler> sampler;
  std::optional<PoissonFill> fill;
  std::vector<int32_t> footprint;  // N × kFootprintGrid² texel indices (y·R + x), -1 beyond the map
  // Share of every patch in the merge: for patch k, entries [share_begin[k],
  // share_begin[k+1]) give texels t and w_k(t) / Σ_j w_j(t) (its bilinear splat
  // weight over the total), to renormalise the average when patches drop out.
  std::vector<int64_t> share_begin;
  std::vector<int32_t> share_texel;
  std::vector<float> share_value;
  std::vector<float> taps_small, taps_large;  // DoG gate kernels (1D)
  // Re-centring (Difference 7): the candidate offsets along e1, texels of the map; empty = off.
  std::vector<float> recentre_offsets;
  // Difference 6 (model.wrinkle.texture_reference ratio or difference): the wrinkle frames are
  // held until FixLayout, whose per-texel median of them is the reference every
  // texture is flattened by (FlattenByReference) before the map and the patches.
  std::vector<cv::Mat> held_gray, held_seen, held_map;
  std::vector<double> held_expression;
  cv::Mat reference;
  double reference_mean = 0.0;
  std::optional<ReferenceAligner> aligner;  // the reference prepared once (reference_alignment.enabled)

  bool flattens() const { return model.wrinkle.texture_reference != TextureReference::kNone; }
  // Difference 6's alignment (reference_alignment.h): T^t onto the reference, or the
  // reference onto T^t (only where it flattens).
  bool warps_texture() const { return options.reference_alignment.enabled && options.reference_alignment.warp_texture; }
  bool warps_reference() const {
    return flattens() && options.reference_alignment.enabled && !options.reference_alignment.warp_texture;
  }
  // Frames wait for the reference (FixLayout) when it flattens or warps T^t.
  bool holds() const { return flattens() || warps_texture(); }
  // A frame as the map and the patches read it, and its seen mask.
  struct Frame {
    cv::Mat gray, seen;
  };
  // `gray` after FixLayout: warped onto the reference (warps_texture), then flattened
  // by the reference (aligned to it when warps_reference) in mode ratio or difference;
  // itself otherwise. `report`: the alignment's.
  Frame Input(const cv::Mat& gray, const cv::Mat& seen, ReferenceAlignmentReport* report = nullptr) const {
    if (!holds()) return {gray.isContinuous() ? gray : gray.clone(), seen};
    Frame f{gray, SeenChart(seen)};
    if (warps_texture()) {
      aligner->AlignTexture(gray, f.seen, &f.gray, &f.seen, report);
      cv::bitwise_and(f.seen, coverage, f.seen);
    }
    if (flattens()) {
      const cv::Mat ref = warps_reference() ? aligner->AlignReference(f.gray, f.seen, report) : reference;
      f.gray = FlattenByReference(f.gray, ref, f.seen, model.wrinkle.texture_reference, reference_mean);
    }
    if (!warps_texture()) f.seen = seen;  // the frame's own mask, as without a reference
    return f;
  }
  // One frame as the patches read it, and which patches drop out of it.
  struct Prepared {
    Frame input;
    std::vector<uint8_t> drop;
    std::vector<float> weight;  // the soft gate's w_k (gate_softness > 0; else empty: all 1)
    std::vector<PatchFrame> frames;  // this frame's re-centred patches (Difference 7; else empty: the layout)
  };
  // Step 1: the patches of `map`, one per row, on the layout or on p.frames.
  RowMatrixXf SampleRows(const cv::Mat& map, const Prepared& p) const;
  // Step 4 with re-centred patches (Difference 7): the merge of the rows of `d`.
  cv::Mat MergeMoved(const Eigen::MatrixXf& d, const Prepared& p) const;
  Prepared Prepare(const cv::Mat& gray, const cv::Mat& seen, DetailTiming* t) const;
  cv::Mat Assemble(const RowMatrixXf& c, const Prepared& p, DetailTiming* t) const;
  void RenormaliseDropped(const Prepared& p, cv::Mat* D) const;
  // The chart texels seen in a frame (coverage ∧ seen; empty seen = all).
  cv::Mat SeenChart(const cv::Mat& seen) const {
    cv::Mat seen_chart = coverage.clone();
    if (!seen.empty()) cv::bitwise_and(seen_chart, seen != 0, seen_chart);
    return seen_chart;
  }
  // The texels of `seen_chart` at least the seen margin inside it (header
  // "Unseen texels"): the ones that count for the wrinkle map. The chart's own border
  // is not a seam (the DoG is normalised over the chart).
  cv::Mat MapSeen(const cv::Mat& seen_chart) const {
    const double margin =
        options.wrinkle_seen_margin_sigmas * model.wrinkle.dog_large_sigma * SigmaScale(model.wrinkle, R);
    if (margin <= 0.0) return seen_chart;
    cv::Mat unseen;  // chart texels not seen
    cv::bitwise_xor(coverage, seen_chart, unseen);
    if (cv::countNonZero(unseen) == 0) return seen_chart;
    cv::Mat distance;  // to the nearest unseen chart texel
    cv::distanceTransform(unseen == 0, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    cv::Mat inside = distance >= static_cast<float>(margin);
    cv::bitwise_and(inside, seen_chart, inside);
    return inside;
  }
  // J_p += 1 where a frame's `seen_chart` counts (MapSeen); returns those texels.
  cv::Mat CountSeen(const cv::Mat& seen_chart) {
    cv::Mat counted = MapSeen(seen_chart);
    cv::add(seen_count, cv::Scalar(1), seen_count, counted);
    return counted;
  }
  // `counted`: MapSeen(seen_chart) when already made (empty: made here).
  void AddToMap(const cv::Mat& gray, const cv::Mat& seen_chart, cv::Mat counted = {});

  // Difference 6's capture reference: the per-texel median of the held frames whose
  // expression is within the smallest quarter (at least one frame).
  void FixReference() {
    std::vector<double> sorted = held_expression;
    std::sort(sorted.begin(), sorted.end());
    const double limit = sorted[std::max<size_t>(1, sorted.size() / 4) - 1];
    std::vector<cv::Mat> gray, seen;
    for (size_t k = 0; k < held_gray.size(); ++k) {
      if (held_expression[k] > limit) continue;
      gray.push_back(held_gray[k]);
      seen.push_back(held_seen[k]);
    }
    reference = MedianTexture(gray, seen);
    reference_mean = FlatteningLevel(model.wrinkle, reference, coverage);
    if (options.reference_alignment.enabled) aligner.emplace(reference, options.reference_alignment);
  }

  void RequireFrame(const cv::Mat& gray, const cv::Mat& seen, const char* what) const {
    Require(!gray.empty(), fmt::format("{}: empty texture", what));
    Require(gray.type() == CV_32FC1, fmt::format("{}: expected a gray linear-float texture (CV_32FC1), got type {} "
                                                 "with {} channels",
                                                 what, gray.type(), gray.channels()));
    Require(gray.rows == R && gray.cols == R, fmt::format("{}: texture is {}x{}, expected {}x{} (the model's map "
                                                          "resolution)",
                                                          what, gray.cols, gray.rows, R, R));
    if (!seen.empty()) {
      Require(seen.type() == CV_8UC1,
              fmt::format("{}: the seen mask must be CV_8UC1, got type {}", what, seen.type()));
      Require(seen.rows == R && seen.cols == R,
              fmt::format("{}: the seen mask is {}x{}, expected {}x{}", what, seen.cols, seen.rows, R, R));
    }
  }

  // Which patches drop out of this frame (header "Unseen texels"): p->drop 1 =
  // dropped; with gate_softness > 0 also the gate's weights p->weight, with re-centring
  // (Difference 7) this frame's moved patches p->frames.
  void Drops(const cv::Mat& src, const cv::Mat& seen, Prepared* p) const {
    const Impl& m = *this;
    const int N = layout.num_patches();
    std::vector<uint8_t>& drop = p->drop;
    drop.assign(N, 0);
    cv::Mat mask;  // coverage ∧ seen (CV_8U), for the gate and the re-centring
    if (!seen.empty()) {
      const cv::Mat s = seen.isContinuous() ? seen : seen.clone();
      const uint8_t* sp = s.ptr<uint8_t>(0);
      const int grid = kFootprintGrid * kFootprintGrid;
      const int allowed = static_cast<int>(std::floor(m.options.patch_max_unseen_fraction * grid + 1e-9));
      for (int k = 0; k < N; ++k) {
        int unseen = 0;
        for (int g = 0; g < grid; ++g) {
          const int32_t i = m.footprint[static_cast<size_t>(k) * grid + g];
          unseen += (i < 0 || !sp[i]);
        }
        drop[k] = unseen > allowed;
      }
    }
    const bool recentres = !m.recentre_offsets.empty();
    if (recentres) p->frames = m.layout.patches;
    if (m.options.gate_by_response || recentres) {
      if (seen.empty()) {
        mask = m.coverage;
      } else {
        cv::Mat s;
        cv::compare(seen, 0, s, cv::CMP_NE);
        cv::bitwise_and(m.coverage, s, mask);
      }
      const float alpha = static_cast<float>(m.model.wrinkle.wrinkle_threshold);
      const float s = static_cast<float>(m.options.gate_softness);
      if (s > 0.0f && m.options.gate_by_response) p->weight.assign(N, 1.0f);
      tbb::parallel_for(tbb::blocked_range<int>(0, N, 16), [&](const tbb::blocked_range<int>& r) {
        for (int k = r.begin(); k != r.end(); ++k) {
          if (drop[k]) continue;
          const float response = recentres ? m.Recentre(src, mask, &p->frames[k]) : m.LayoutResponse(src, mask, k);
          if (!m.options.gate_by_response) continue;
          if (s > 0.0f) {
            p->weight[k] = GateWeight(response, alpha, s);
            drop[k] = !(p->weight[k] > 0.0f);
          } else if (!(response > alpha)) {
            drop[k] = 1;
          }
        }
      });
    }
  }

  // The DoG response at patch k's centre in the layout (its nearest texel).
  float LayoutResponse(const cv::Mat& gray, const cv::Mat& mask, int k) const {
    const PatchFrame& f = layout.patches[k];
    const int x = std::clamp(static_cast<int>(std::lround(f.center_texel.x())), 0, R - 1);
    const int y = std::clamp(static_cast<int>(std::lround(f.center_texel.y())), 0, R - 1);
    return CentreResponse(gray, mask, x, y);
  }

  // Difference 7: moves `f` along e1 to the candidate centre of largest DoG response
  // (each candidate at its nearest texel), refined by the parabola through it and its
  // two neighbours when it is not the last either side; returns that largest response.
  float Recentre(const cv::Mat& gray, const cv::Mat& mask, PatchFrame* f) const {
    const Eigen::Vector2f e1(std::cos(f->angle), std::sin(f->angle));
    const int n = static_cast<int>(recentre_offsets.size());
    std::vector<float> r(n);
    int best = 0;
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector2f c = f->center_texel + recentre_offsets[j] * e1;
      const int x = std::clamp(static_cast<int>(std::lround(c.x())), 0, R - 1);
      const int y = std::clamp(static_cast<int>(std::lround(c.y())), 0, R - 1);
      r[j] = CentreResponse(gray, mask, x, y);
      if (r[j] > r[best]) best = j;
    }
    float offset = recentre_offsets[best];
    if (best > 0 && best + 1 < n) {
      const float curvature = r[best - 1] - 2.0f * r[best] + r[best + 1];
      const float step = recentre_offsets[1] - recentre_offsets[0];
      if (curvature < 0.0f) offset += std::clamp(0.5f * (r[best - 1] - r[best + 1]) / curvature, -0.5f, 0.5f) * step;
    }
    const Eigen::Vector2f c = f->center_texel + offset * e1;
    f->center_texel = c.cwiseMax(0.0f).cwiseMin(static_cast<float>(R - 1));
    return r[best];
  }

  // The optional gate: the DoG response r = G_large * T − G_small * T at texel
  // (x, y), normalised convolutions over `m` = coverage ∧ seen, as DogResponse.
  float CentreResponse(const cv::Mat& gray, const cv::Mat& mask, int x, int y) const {
    const int rl = static_cast<int>(taps_large.size()) / 2, rs = static_cast<int>(taps_small.size()) / 2;
    double nl = 0, dl = 0, ns = 0, ds = 0;
    for (int dy = -rl; dy <= rl; ++dy) {
      const int yy = y + dy;
      if (yy < 0 || yy >= R) continue;
      const float* t = gray.ptr<float>(yy);
      const uint8_t* m = mask.ptr<uint8_t>(yy);
      float row_nl = 0, row_dl = 0, row_ns = 0, row_ds = 0;
      const int xa = std::max(-rl, -x), xb = std::min(rl, R - 1 - x);
      for (int dx = xa; dx <= xb; ++dx) {  // masked texels weigh 0
        const bool in = m[x + dx] != 0;
        const float gl = in ? taps_large[dx + rl] : 0.0f, tv = in ? t[x + dx] : 0.0f;  // unseen may hold NaN
        row_nl += gl * tv;
        row_dl += gl;
      }
      if (dy >= -rs && dy <= rs) {
        const int sa = std::max(-rs, -x), sb = std::min(rs, R - 1 - x);
        for (int dx = sa; dx <= sb; ++dx) {
          const bool in = m[x + dx] != 0;
          const float gs = in ? taps_small[dx + rs] : 0.0f, tv = in ? t[x + dx] : 0.0f;
          row_ns += gs * tv;
          row_ds += gs;
        }
      }
      nl += taps_large[dy + rl] * row_nl;
      dl += taps_large[dy + rl] * row_dl;
      if (dy >= -rs && dy <= rs) {
        ns += taps_small[dy + rs] * row_ns;
        ds += taps_small[dy + rs] * row_ds;
      }
    }
    if (!(dl > 1e-6 && ds > 1e-6)) return 0.0f;
    return static_cast<float>(nl / dl - ns / ds);
  }
};

DetailRegressor::DetailRegressor(const DetailModel& model, const std::vector<RegionMask>& regions,
                                 const cv::Mat& coverage, const DetailRegressionOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  model.Validate("DetailRegressor: model");
  Impl& m = *impl_;
  m.model = model;
  m.options = options;
  m.R = model.map_resolution;
  Require(!coverage.empty() && coverage.type() == CV_8UC1,
          fmt::format("DetailRegressor: the face-chart coverage must be a non-empty CV_8UC1 mask, got type {}",
                      coverage.type()));
  Require(coverage.rows == m.R && coverage.cols == m.R,
          fmt::format("DetailRegressor: the coverage is {}x{}, expected {}x{} (the model's map resolution)",
                      coverage.cols, coverage.rows, m.R, m.R));
  cv::compare(coverage, 0, m.coverage, cv::CMP_NE);
  m.builder.emplace(m.R, m.coverage, regions, model.wrinkle);
  m.seen_count = cv::Mat(m.R, m.R, CV_32S, cv::Scalar(0));
  const double scale = SigmaScale(model.wrinkle, m.R);
  m.taps_small = GaussianTaps(model.wrinkle.dog_small_sigma * scale);
  m.taps_large = GaussianTaps(model.wrinkle.dog_large_sigma * scale);
  const int steps = static_cast<int>(std::floor(options.recentre_radius / options.recentre_step + 1e-9));
  for (int j = -steps; steps > 0 && j <= steps; ++j)
    m.recentre_offsets.push_back(static_cast<float>(j * options.recentre_step * scale));
}

DetailRegressor::~DetailRegressor() = default;
DetailRegressor::DetailRegressor(DetailRegressor&&) noexcept = default;
DetailRegressor& DetailRegressor::operator=(DetailRegressor&&) noexcept = default;

void DetailRegressor::AddWrinkleFrame(const cv::Mat& gray, const cv::Mat& seen, double expression,
                                      const cv::Mat& map_texture) {
  Impl& m = *impl_;
  Require(!m.fixed, "DetailRegressor::AddWrinkleFrame: the layout is already fixed (FixLayout was called)");
  m.RequireFrame(gray, seen, "DetailRegressor::AddWrinkleFrame");
  const cv::Mat seen_chart = m.SeenChart(seen);
  if (!map_texture.empty()) m.RequireFrame(map_texture, cv::Mat(), "DetailRegressor::AddWrinkleFrame map texture");
  ++m.frames;
  if (m.holds()) {  // the map and J_p wait for the reference (FixLayout)
    m.held_gray.push_back(gray.clone());
    m.held_seen.push_back(seen_chart);
    m.held_map.push_back(map_texture.empty() ? cv::Mat() : map_texture.clone());
    m.held_expression.push_back(std::isfinite(expression) ? expression : 0.0);
    return;
  }
  m.AddToMap(map_texture.empty() ? gray : map_texture, seen_chart, m.CountSeen(seen_chart));
}

// The wrinkle map's share of one frame (Sec. 5.2), unseen chart texels extended
// smoothly from the seen ones.
void DetailRegressor::Impl::AddToMap(const cv::Mat& gray, const cv::Mat& seen_chart, cv::Mat counted) {
  Impl& m = *this;
  cv::Mat texture = gray;
  const int unseen = cv::countNonZero(m.coverage) - cv::countNonZero(seen_chart);
  if (unseen > 0) {
    // Smooth extension of the seen texels into the unseen chart texels (header):
    // normalised Gaussian on a 4× coarser grid, bilinear back up.
    const int f = R >= 64 ? 4 : 1;
    cv::Mat m01, tm;
    seen_chart.convertTo(m01, CV_32F, 1.0 / 255.0);
    cv::Mat clean = gray.clone();
    clean.setTo(0.0f, seen_chart == 0);  // unseen may hold anything
    cv::multiply(clean, m01, tm);
    cv::Mat tm_s, m_s;
    cv::resize(tm, tm_s, cv::Size(R / f, R / f), 0, 0, cv::INTER_AREA);
    cv::resize(m01, m_s, cv::Size(R / f, R / f), 0, 0, cv::INTER_AREA);
    const double sigma = m.options.wrinkle_extension_sigma * SigmaScale(m.model.wrinkle, R) / f;
    cv::GaussianBlur(tm_s, tm_s, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
    cv::GaussianBlur(m_s, m_s, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
    const double mean_seen = cv::countNonZero(seen_chart) > 0 ? cv::mean(clean, seen_chart)[0] : 0.5;
    cv::Mat ext_s(tm_s.size(), CV_32F);
    for (int y = 0; y < ext_s.rows; ++y) {
      const float* n = tm_s.ptr<float>(y);
      const float* d = m_s.ptr<float>(y);
      float* o = ext_s.ptr<float>(y);
      for (int x = 0; x < ext_s.cols; ++x) o[x] = d[x] > 1e-4f ? n[x] / d[x] : static_cast<float>(mean_seen);
    }
    cv::Mat ext;
    cv::resize(ext_s, ext, cv::Size(R, R), 0, 0, cv::INTER_LINEAR);
    ext.copyTo(clean, seen_chart == 0);
    texture = clean;
  }
  if (counted.empty()) counted = m.MapSeen(seen_chart);
  m.builder->Add(texture, fmt::format("DetailRegressor::AddWrinkleFrame: frame {}", m.frames), counted);
}

bool DetailRegressor::NeedsWrinkleFrames() const {
  return !impl_->fixed && impl_->frames < impl_->options.wrinkle_frames;
}

void DetailRegressor::FixLayout() {
  Impl& m = *impl_;
  Require(!m.fixed, "DetailRegressor::FixLayout: the layout is already fixed");
  Require(m.frames > 0, "DetailRegressor::FixLayout: no wrinkle frames were added (call AddWrinkleFrame with the "
                        "first N frames' textures first, Sec. 5.2)");
  const int R = m.R;
  if (m.holds()) {
    m.FixReference();
    for (size_t k = 0; k < m.held_gray.size(); ++k) {
      const cv::Mat counted = m.CountSeen(m.held_seen[k]);  // J_p from the frame's own mask
      if (!m.held_map[k].empty()) {
        m.AddToMap(m.held_map[k], m.held_seen[k], counted);
        continue;
      }
      const Impl::Frame f = m.Input(m.held_gray[k], m.held_seen[k]);
      // A warped texture brings its own seen mask (Input); otherwise f.seen is the frame's.
      m.AddToMap(f.gray, f.seen, m.warps_texture() ? cv::Mat() : counted);
    }
    m.held_gray.clear();
    m.held_seen.clear();
    m.held_map.clear();
  }
  m.wmap = m.builder->Finish();
  // W(p) = Σ_j [r_j > α] r_j / J_p, 0 where J_p < min fraction · J (header).
  const double min_seen = std::max(1.0, m.options.wrinkle_min_seen_fraction * m.frames);
  const float J = static_cast<float>(m.frames);
  for (int y = 0; y < R; ++y) {
    float* w = m.wmap.probability.ptr<float>(y);
    const int* c = m.seen_count.ptr<int>(y);
    for (int x = 0; x < R; ++x) w[x] = c[x] >= min_seen - 1e-9 ? w[x] * J / static_cast<float>(c[x]) : 0.0f;
  }
  m.layout = PlacePatches(m.wmap, m.model.patch, &m.layout_report);
  m.builder.reset();
  const int N = m.layout.num_patches(), w = m.layout.patch_size;
  cv::Mat known(R, R, CV_8U, cv::Scalar(0));
  if (N > 0) {
    m.sampler.emplace(m.layout);
    cv::compare(m.sampler->splat_weight(), 0.0f, known, cv::CMP_GT);
    // Footprint grid of every patch (sample positions as patches.h defines them).
    m.footprint.resize(static_cast<size_t>(N) * kFootprintGrid * kFootprintGrid);
    for (int k = 0; k < N; ++k) {
      const PatchFrame& f = m.layout.patches[k];
      const double c = std::cos(static_cast<double>(f.angle)), s = std::sin(static_cast<double>(f.angle));
      const double half = 0.5 * (w - 1);
      for (int gb = 0; gb < kFootprintGrid; ++gb) {
        for (int ga = 0; ga < kFootprintGrid; ++ga) {
          const double a = std::round(ga * (w - 1) / double(kFootprintGrid - 1)) - half;
          const double b = std::round(gb * (w - 1) / double(kFootprintGrid - 1)) - half;
          const int x = static_cast<int>(std::lround(f.center_texel.x() + a * c - b * s));
          const int y = static_cast<int>(std::lround(f.center_texel.y() + a * s + b * c));
          m.footprint[(static_cast<size_t>(k) * kFootprintGrid + gb) * kFootprintGrid + ga] =
              (x < 0 || y < 0 || x >= R || y >= R) ? -1 : y * R + x;
        }
      }
    }
  }
  if (N > 0) {
    // Per-patch shares (Impl::share_*): patches coloured so that the discs of radius
    // r around the centres (which hold their bilinear footprints) of one colour are
    // disjoint; one Splat of a colour's indicator then gives each of its patches' shares.
    const float r = 0.5f * static_cast<float>(w - 1) * std::numbers::sqrt2_v<float> + 2.0f;
    std::vector<int> colour(N, -1);
    std::vector<std::vector<int>> members;
    for (int k = 0; k < N; ++k) {
      for (int c = 0;; ++c) {
        if (c == static_cast<int>(members.size())) members.emplace_back();
        bool free = true;
        for (int j : members[c]) {
          if ((m.layout.patches[j].center_texel - m.layout.patches[k].center_texel).norm() <= 2.0f * r) {
            free = false;
            break;
          }
        }
        if (free) {
          colour[k] = c;
          members[c].push_back(k);
          break;
        }
      }
    }
    std::vector<std::vector<std::pair<int32_t, float>>> lists(N);
    for (const std::vector<int>& group : members) {
      Eigen::MatrixXf indicator = Eigen::MatrixXf::Zero(N, w * w);
      for (int k : group) indicator.row(k).setOnes();
      const cv::Mat share = m.sampler->Splat(indicator);
      for (int k : group) {
        const Eigen::Vector2f& c = m.layout.patches[k].center_texel;
        const int x0 = std::max(0, static_cast<int>(std::floor(c.x() - r))), x1 = std::min(R - 1, static_cast<int>(std::ceil(c.x() + r)));
        const int y0 = std::max(0, static_cast<int>(std::floor(c.y() - r))), y1 = std::min(R - 1, static_cast<int>(std::ceil(c.y() + r)));
        for (int y = y0; y <= y1; ++y) {
          const float* sp = share.ptr<float>(y);
          for (int x = x0; x <= x1; ++x) {
            const float dx = x - c.x(), dy = y - c.y();
            if (sp[x] > 0.0f && dx * dx + dy * dy <= r * r) lists[k].emplace_back(y * R + x, sp[x]);
          }
        }
      }
    }
    m.share_begin.assign(1, 0);
    for (int k = 0; k < N; ++k) {
      for (const auto& [t, v] : lists[k]) {
        m.share_texel.push_back(t);
        m.share_value.push_back(v);
      }
      m.share_begin.push_back(static_cast<int64_t>(m.share_texel.size()));
    }
  }
  m.fill.emplace(m.coverage, known, m.options.fill);
  m.fixed = true;
}

bool DetailRegressor::layout_fixed() const { return impl_->fixed; }

// Step 0 of Regress and AssembleFromTruth (and DroppedPatches): the input T^t
// (flattened by the aligned reference) and the patches that drop out this frame.
// `t` (optional) receives the alignment's time and shift, the drops' time and count.
DetailRegressor::Impl::Prepared DetailRegressor::Impl::Prepare(const cv::Mat& gray, const cv::Mat& seen,
                                                               DetailTiming* t) const {
  auto t0 = Clock::now();
  ReferenceAlignmentReport alignment;
  Prepared p{Input(gray, seen, &alignment), {}, {}, {}};
  if (t && (warps_texture() || warps_reference())) t->reference_shift = alignment.mean_shift;
  if (t) t->align_ms = MsSince(t0);
  t0 = Clock::now();
  Drops(p.input.gray, p.input.seen, &p);
  if (t) {
    for (uint8_t d : p.drop) t->dropped += d;
    t->sample_ms += MsSince(t0);
  }
  return p;
}

// Steps 3–5: d_i = mean + basis · c_i (dropped patches: 0; under the soft gate
// w_k d_k), merged by averaging over the kept patches covering each texel, the
// uncovered chart texels Poisson-filled.
cv::Mat DetailRegressor::Impl::Assemble(const RowMatrixXf& c, const Prepared& p, DetailTiming* t) const {
  const int N = layout.num_patches(), n = layout.patch_size * layout.patch_size;
  const std::vector<uint8_t>& drop = p.drop;
  const bool any_dropped = std::any_of(drop.begin(), drop.end(), [](uint8_t x) { return x != 0; });
  const bool any_weak = std::any_of(p.weight.begin(), p.weight.end(), [](float w) { return w < 1.0f; });
  auto t0 = Clock::now();
  Eigen::MatrixXf d(N, n);  // column-major, as Splat takes it
  const Eigen::MatrixXf& basis = model.pca.basis;  // n × D
  const Eigen::VectorXf& mean = model.pca.mean;
  constexpr int kBlock = 128;
  tbb::parallel_for(tbb::blocked_range<int>(0, (n + kBlock - 1) / kBlock), [&](const tbb::blocked_range<int>& r) {
    for (int b = r.begin(); b != r.end(); ++b) {
      const int j0 = b * kBlock, cols = std::min(kBlock, n - j0);
      d.middleCols(j0, cols).noalias() = c * basis.middleRows(j0, cols).transpose();
      d.middleCols(j0, cols).rowwise() += mean.segment(j0, cols).transpose();
      for (int k = 0; (any_dropped || any_weak) && k < N; ++k) {
        if (drop[k]) d.block(k, j0, 1, cols).setZero();
        else if (any_weak) d.block(k, j0, 1, cols) *= p.weight[k];
      }
    }
  });
  t->reconstruct_ms = MsSince(t0);

  t0 = Clock::now();
  cv::Mat D;
  if (!p.frames.empty()) {
    D = MergeMoved(d, p);
  } else {
    D = sampler->Splat(d);  // Σ_kept w d / Σ_all w (dropped rows are 0)
    if (any_dropped || any_weak) RenormaliseDropped(p, &D);
  }
  t->merge_ms = MsSince(t0);

  t0 = Clock::now();
  fill->Apply(&D);  // 0 outside the chart
  t->fill_ms = MsSince(t0);
  return D;
}

// Where dropped patches had weight, divides the merge by the kept share
// 1 − Σ_dropped w_k / Σ w, only on the dropped patches' footprints (sequential,
// fixed order). Under the soft gate a patch of gate weight g_k counts 1 − g_k
// dropped, and the kept share is floored at kSoftGateShareFloor. calloc: only the
// touched pages of the scratch map are zeroed.
void DetailRegressor::Impl::RenormaliseDropped(const Prepared& p, cv::Mat* D) const {
  const int N = layout.num_patches();
  std::unique_ptr<float, decltype(&std::free)> acc(static_cast<float*>(std::calloc(static_cast<size_t>(R) * R, sizeof(float))),
                                                   &std::free);
  Require(acc != nullptr, "DetailRegressor: out of memory (renormalising the merge)");
  const bool soft = !p.weight.empty();
  std::vector<int32_t> touched;
  for (int k = 0; k < N; ++k) {
    const float dropped = p.drop[k] ? 1.0f : soft ? 1.0f - p.weight[k] : 0.0f;
    if (dropped == 0.0f) continue;
    for (int64_t e = share_begin[k]; e < share_begin[k + 1]; ++e) {
      float& a = acc.get()[share_texel[e]];
      if (a == 0.0f) touched.push_back(share_texel[e]);
      a += dropped * share_value[e];
    }
  }
  float* o = D->ptr<float>(0);
  for (int32_t i : touched) o[i] = DivideByKeptShare(o[i], 1.0f - acc.get()[i], soft);
}

RowMatrixXf DetailRegressor::Impl::SampleRows(const cv::Mat& map, const Prepared& p) const {
  RowMatrixXf rows;
  if (p.frames.empty()) {
    Eigen::MatrixXf sampled;  // N × n, column-major (PatchSampler's layout)
    sampler->Sample(map, &sampled);
    rows = sampled;
  } else {
    rows.resize(layout.num_patches(), layout.samples_per_patch());
    SamplePatches(map, p.frames, layout.patch_size, rows.data());
  }
  return rows;
}

// The average of step 4 on this frame's moved patches: the rows of `d` (already scaled
// by the gate's weights g_k, dropped rows 0) splatted and divided by the kept share
// Σ g_k w_k(t) / Σ w_k(t) (DivideByKeptShare, as RenormaliseDropped).
cv::Mat DetailRegressor::Impl::MergeMoved(const Eigen::MatrixXf& d, const Prepared& p) const {
  const int N = layout.num_patches();
  std::vector<float> gain(N);
  for (int k = 0; k < N; ++k) gain[k] = p.drop[k] ? 0.0f : p.weight.empty() ? 1.0f : p.weight[k];
  const RowMatrixXf rows = d;
  const SplatSums sums = SplatPatches(p.frames, layout.patch_size, R, rows.data(), gain);
  cv::Mat D(R, R, CV_32F, cv::Scalar(0));
  const bool soft = !p.weight.empty();
  for (int y = 0; y < R; ++y) {
    const float *v = sums.value.ptr<float>(y), *g = sums.gain.ptr<float>(y), *w = sums.weight.ptr<float>(y);
    float* o = D.ptr<float>(y);
    for (int x = 0; x < R; ++x)
      if (w[x] > 0.0f) o[x] = DivideByKeptShare(v[x] / w[x], g[x] / w[x], soft);
  }
  return D;
}

cv::Mat DetailRegressor::Regress(const cv::Mat& gray, const cv::Mat& seen, DetailTiming* timing) const {
  const Impl& m = *impl_;
  Require(m.fixed, "DetailRegressor::Regress: the layout is not fixed yet (add the first N frames with "
                   "AddWrinkleFrame, then call FixLayout)");
  m.RequireFrame(gray, seen, "DetailRegressor::Regress");
  DetailTiming t;
  const int R = m.R, N = m.layout.num_patches();
  t.patches = N;
  cv::Mat D;
  if (N == 0) {
    D = cv::Mat(R, R, CV_32F, cv::Scalar(0));
    if (timing) *timing = t;
    return D;
  }
  // 0. T^t (flattened) and the drops; 1. its patches t_i on the fixed layout.
  const Impl::Prepared p = m.Prepare(gray, seen, &t);
  auto t0 = Clock::now();
  RowMatrixXf patches = m.SampleRows(p.input.gray, p);  // one patch per row, for RegressBatch (normalised in place)
  t.sample_ms += MsSince(t0);

  // 2. Eq. 6: c_i = c̄ + Σ_k R^k(t_i).
  t0 = Clock::now();
  RowMatrixXf c(N, m.model.pca.dimensions());
  m.model.RegressBatch(patches.data(), N, c.data());
  t.regress_ms = MsSince(t0);

  // 3–5. Reconstruct, merge, fill.
  D = m.Assemble(c, p, &t);
  if (timing) *timing = t;
  return D;
}

cv::Mat DetailRegressor::AssembleFromTruth(const cv::Mat& gray, const cv::Mat& seen, const cv::Mat& truth,
                                           DetailTiming* timing) const {
  const Impl& m = *impl_;
  Require(m.fixed, "DetailRegressor::AssembleFromTruth: the layout is not fixed yet");
  m.RequireFrame(gray, seen, "DetailRegressor::AssembleFromTruth");
  m.RequireFrame(truth, cv::Mat(), "DetailRegressor::AssembleFromTruth truth");
  Require(cv::checkRange(truth), "DetailRegressor::AssembleFromTruth: the truth map has non-finite values");
  DetailTiming t;
  const int R = m.R, N = m.layout.num_patches();
  t.patches = N;
  if (N == 0) {
    if (timing) *timing = t;
    return cv::Mat(R, R, CV_32F, cv::Scalar(0));
  }
  const Impl::Prepared p = m.Prepare(gray, seen, &t);
  // 2'. The truth's own patches projected onto the model's basis: c_i = basisᵀ (d_i − mean).
  const auto t0 = Clock::now();
  const RowMatrixXf c = m.model.pca.ProjectPatches(Eigen::MatrixXf(m.SampleRows(truth, p)));
  t.regress_ms = MsSince(t0);
  const cv::Mat D = m.Assemble(c, p, &t);
  if (timing) *timing = t;
  return D;
}

void DetailRegressor::CutPairs(const cv::Mat& gray, const cv::Mat& seen, const cv::Mat& truth,
                               Eigen::MatrixXf* texture, Eigen::MatrixXf* displacement,
                               std::vector<int>* patches) const {
  const Impl& m = *impl_;
  Require(m.fixed, "DetailRegressor::CutPairs: the layout is not fixed yet");
  m.RequireFrame(gray, seen, "DetailRegressor::CutPairs");
  m.RequireFrame(truth, cv::Mat(), "DetailRegressor::CutPairs truth");
  Require(cv::checkRange(truth), "DetailRegressor::CutPairs: the truth map has non-finite values");
  const int N = m.layout.num_patches(), n = m.layout.patch_size * m.layout.patch_size;
  std::vector<int> kept;
  RowMatrixXf t_all, d_all;
  if (N > 0) {
    const Impl::Prepared p = m.Prepare(gray, seen, nullptr);
    for (int k = 0; k < N; ++k)
      if (!p.drop[k]) kept.push_back(k);
    t_all = m.SampleRows(p.input.gray, p);
    d_all = m.SampleRows(truth, p);
  }
  const auto rows = static_cast<Eigen::Index>(kept.size());
  texture->resize(rows, n);
  displacement->resize(rows, n);
  for (Eigen::Index i = 0; i < rows; ++i) {
    texture->row(i) = t_all.row(kept[i]);
    displacement->row(i) = d_all.row(kept[i]);
  }
  if (patches) *patches = std::move(kept);
}

std::vector<uint8_t> DetailRegressor::DroppedPatches(const cv::Mat& gray, const cv::Mat& seen) const {
  const Impl& m = *impl_;
  Require(m.fixed, "DetailRegressor::DroppedPatches: the layout is not fixed yet");
  m.RequireFrame(gray, seen, "DetailRegressor::DroppedPatches");
  if (m.layout.num_patches() == 0) return {};
  return m.Prepare(gray, seen, nullptr).drop;
}

const WrinkleMap& DetailRegressor::wrinkle_map() const {
  Require(impl_->fixed, "DetailRegressor::wrinkle_map: call FixLayout first");
  return impl_->wmap;
}
const PatchLayout& DetailRegressor::layout() const {
  Require(impl_->fixed, "DetailRegressor::layout: call FixLayout first");
  return impl_->layout;
}
const PatchLayoutReport& DetailRegressor::layout_report() const {
  Require(impl_->fixed, "DetailRegressor::layout_report: call FixLayout first");
  return impl_->layout_report;
}
const PoissonFill& DetailRegressor::fill() const {
  Require(impl_->fixed, "DetailRegressor::fill: call FixLayout first");
  return *impl_->fill;
}
int DetailRegressor::frames_added() const { return impl_->frames; }
int DetailRegressor::map_size() const { return impl_->R; }

}  // namespace crease
