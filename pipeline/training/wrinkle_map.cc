// The actor's wrinkle map, paper Sec. 4.2 (see wrinkle_map.h for the
// definitions and the differences from the paper).
#include "pipeline/training/wrinkle_map.h"

#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/image_filter.h"
#include "core/options.h"

namespace crease {

void WrinkleMapOptions::VisitFields(OptionVisitor& v) {
  v.Field("dog_small_sigma", dog_small_sigma);
  v.Field("dog_large_sigma", dog_large_sigma);
  v.Field("dog_reference_resolution", dog_reference_resolution);
  v.Field("wrinkle_threshold", wrinkle_threshold);
  v.Field("patch_regions", patch_regions);
  v.Field("patch_exclude_regions", patch_exclude_regions);
  v.Field("patch_exclude_margin", patch_exclude_margin);
  v.Field("orientation_gradient_sigma", orientation_gradient_sigma);
  v.Field("orientation_smoothing_sigma", orientation_smoothing_sigma);
  v.Field("orientation_reference_deg", orientation_reference_deg);
  v.Field("orient_patches", orient_patches);
  v.Field("texture_reference", texture_reference);
  v.Field("texture_reference_level", texture_reference_level);
}

void WrinkleMapOptions::Check() const {
  const char* o = "WrinkleMapOptions";
  CheckGt(o, "dog_small_sigma", dog_small_sigma, 0.0);
  CheckGt(o, "dog_large_sigma", dog_large_sigma, dog_small_sigma);
  CheckLe(o, "dog_large_sigma", dog_large_sigma, 1000.0);
  CheckGe(o, "dog_reference_resolution", dog_reference_resolution, 0);
  CheckGe(o, "wrinkle_threshold", wrinkle_threshold, 0.0);
  CheckGe(o, "orientation_gradient_sigma", orientation_gradient_sigma, 0.0);
  CheckLe(o, "orientation_gradient_sigma", orientation_gradient_sigma, 1000.0);
  CheckGe(o, "orientation_smoothing_sigma", orientation_smoothing_sigma, 0.0);
  CheckGe(o, "patch_exclude_margin", patch_exclude_margin, 0.0);
  CheckLe(o, "patch_exclude_margin", patch_exclude_margin, 1000.0);
  CheckLe(o, "orientation_smoothing_sigma", orientation_smoothing_sigma, 1000.0);
  CheckGe(o, "orientation_reference_deg", orientation_reference_deg, -360.0);
  CheckLe(o, "orientation_reference_deg", orientation_reference_deg, 360.0);
  CheckGe(o, "texture_reference_level", texture_reference_level, 0.0);
  Require(texture_reference_level == 0.0 || texture_reference != TextureReference::kNone,
          fmt::format("{}: texture_reference_level = {} needs texture_reference ratio or difference (it sets the "
                      "flattening's gray level)",
                      o, texture_reference_level));
  for (size_t k = 0; k < patch_regions.size(); ++k) {
    Require(!patch_regions[k].empty(),
            fmt::format("WrinkleMapOptions.patch_regions[{}] is empty; expected a region name", k));
  }
}

double SigmaScale(const WrinkleMapOptions& options, int map_size) {
  if (options.dog_reference_resolution <= 0) return 1.0;
  return static_cast<double>(map_size) / options.dog_reference_resolution;
}

namespace {

// Denominators below this (a fraction of the kernel's mass) count as "no data":
// a covered texel always carries at least the weight of its own kernel tap.
constexpr float kMinWeight = kMinNormalisedWeight;

template <class F>
void ForRows(int rows, const F& f) {
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) f(y);
  });
}

// Gaussian of standard deviation `sigma` (texels) with zeros outside the image
// (the normalised convolutions below divide the zeros out again).
cv::Mat Blur(const cv::Mat& src, double sigma) {
  if (sigma <= 0.0) return src.clone();
  cv::Mat dst;
  cv::GaussianBlur(src, dst, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
  return dst;
}

// CV_8U 255/0 coverage of a size×size map from an optional mask.
cv::Mat PrepareCoverage(const cv::Mat& coverage, int size, const std::string& what) {
  if (coverage.empty()) return cv::Mat(size, size, CV_8U, cv::Scalar(255));
  Require(coverage.type() == CV_8UC1,
          fmt::format("{}: coverage mask must be CV_8UC1, got type {}", what, coverage.type()));
  Require(coverage.rows == size && coverage.cols == size,
          fmt::format("{}: coverage mask is {}x{}, expected {}x{} like the maps", what, coverage.cols,
                      coverage.rows, size, size));
  cv::Mat out;
  cv::compare(coverage, 0, out, cv::CMP_NE);  // 255 / 0
  return out;
}

void RequireGray(const cv::Mat& image, const std::string& what) {
  Require(!image.empty(), fmt::format("{}: empty image", what));
  Require(image.type() == CV_32FC1,
          fmt::format("{}: expected a gray linear-float texture (CV_32FC1), got type {} with {} channels",
                      what, image.type(), image.channels()));
  Require(image.rows == image.cols,
          fmt::format("{}: texture is {}x{}, expected a square UV map", what, image.cols, image.rows));
}

// An angle as a float in [0, 2π).
float WrapAngle(double a) {
  a = std::fmod(a, 2.0 * std::numbers::pi);
  return static_cast<float>(a < 0.0 ? a + 2.0 * std::numbers::pi : a);
}

// θ of a patch from the averaged doubled-angle vector o: ½ atan2(o_y, o_x) in
// [0, π), plus or minus π where needed so that θ ∈ [φ_0 − π/2, φ_0 + π/2)
// (Difference 7), wrapped into [0, 2π). With φ_0 = π/2 nothing is added.
float PatchAngle(const cv::Vec2f& o, double phi0) {
  constexpr double kPi = std::numbers::pi;
  double t = 0.5 * std::atan2(static_cast<double>(o[1]), static_cast<double>(o[0]));
  if (t < 0.0) t += kPi;
  float tf = static_cast<float>(t);
  if (tf >= static_cast<float>(kPi)) tf = 0.0f;
  double a = tf;
  while (a < phi0 - 0.5 * kPi) a += kPi;
  while (a >= phi0 + 0.5 * kPi) a -= kPi;
  return WrapAngle(a);
}

}  // namespace

namespace internal {

// The DoG of Sec. 4.2 as normalised convolutions against one fixed coverage:
// the blurred coverage (the denominators) is computed once and reused for every
// texture (all textures of an actor or a capture share the coverage).
class DogFilter {
 public:
  DogFilter(const cv::Mat& coverage8u, const WrinkleMapOptions& options)
      : coverage_(coverage8u), options_(options) {
    const double scale = SigmaScale(options, coverage8u.cols);
    sigma_small_ = options.dog_small_sigma * scale;
    sigma_large_ = options.dog_large_sigma * scale;
    sigma_gradient_ = options.orientation_gradient_sigma * scale;
    coverage8u.convertTo(m_, CV_32F, 1.0 / 255.0);
    den_small_ = Blur(m_, sigma_small_);
    den_large_ = Blur(m_, sigma_large_);
    if (sigma_gradient_ > 0.0) den_gradient_ = Blur(m_, sigma_gradient_);
  }

  // T·m with the texels outside coverage set to 0 (whatever they held, NaN
  // included); throws on non-finite texels inside coverage.
  cv::Mat Masked(const cv::Mat& texture, const std::string& what) const {
    RequireGray(texture, what);
    Require(texture.rows == coverage_.rows,
            fmt::format("{}: texture is {}x{}, expected {}x{} (the coverage / map size)", what, texture.cols,
                        texture.rows, coverage_.cols, coverage_.rows));
    long bad = 0;
    cv::Mat tm = ZeroOutsideMask(texture, coverage_, &bad);
    Require(bad == 0, fmt::format("{}: {} covered texels are not finite (NaN or inf)", what, bad));
    return tm;
  }

  // r = G_large * T − G_small * T on covered texels, 0 elsewhere (Sec. 4.2).
  cv::Mat Response(const cv::Mat& tm) const {
    const cv::Mat num_small = Blur(tm, sigma_small_);
    const cv::Mat num_large = Blur(tm, sigma_large_);
    return NormalisedDifference(num_large, den_large_, num_small, den_small_, coverage_, 1.0f);
  }

  // The texture gradient for the orientation (Difference 4): central differences
  // of G_d * T (normalised, so it extends a little beyond the coverage and the
  // boundary gives no step), one-sided where a neighbour is undefined.
  void Gradient(const cv::Mat& tm, cv::Mat* gx, cv::Mat* gy) const {
    cv::Mat s;
    cv::Mat defined;  // CV_8U
    if (sigma_gradient_ > 0.0) {
      const cv::Mat num = Blur(tm, sigma_gradient_);
      s = cv::Mat(tm.size(), CV_32F);
      defined = cv::Mat(tm.size(), CV_8U);
      // The normalised blur is trusted where it averages at least this much mass.
      constexpr float kDefined = 0.05f;
      ForRows(tm.rows, [&](int y) {
        const float* n = num.ptr<float>(y);
        const float* d = den_gradient_.ptr<float>(y);
        float* o = s.ptr<float>(y);
        uint8_t* def = defined.ptr<uint8_t>(y);
        for (int x = 0; x < tm.cols; ++x) {
          def[x] = d[x] > kDefined ? 1 : 0;
          o[x] = def[x] ? n[x] / d[x] : 0.0f;
        }
      });
    } else {
      s = tm;
      defined = coverage_;
    }
    const int rows = tm.rows, cols = tm.cols;
    gx->create(tm.size(), CV_32F);
    gy->create(tm.size(), CV_32F);
    // d/dt along one axis from values a (at −1), b (0), c (+1) and their flags.
    auto diff = [](float a, float b, float c, bool da, bool db, bool dc) -> float {
      if (!db) return 0.0f;
      if (da && dc) return 0.5f * (c - a);
      if (dc) return c - b;
      if (da) return b - a;
      return 0.0f;
    };
    ForRows(rows, [&](int y) {
      const float* sp = s.ptr<float>(y);
      const uint8_t* dp = defined.ptr<uint8_t>(y);
      const float* su = y > 0 ? s.ptr<float>(y - 1) : nullptr;
      const uint8_t* du = y > 0 ? defined.ptr<uint8_t>(y - 1) : nullptr;
      const float* sd = y + 1 < rows ? s.ptr<float>(y + 1) : nullptr;
      const uint8_t* dd = y + 1 < rows ? defined.ptr<uint8_t>(y + 1) : nullptr;
      float* ox = gx->ptr<float>(y);
      float* oy = gy->ptr<float>(y);
      for (int x = 0; x < cols; ++x) {
        const bool l = x > 0 && dp[x - 1], r = x + 1 < cols && dp[x + 1];
        ox[x] = diff(x > 0 ? sp[x - 1] : 0.0f, sp[x], x + 1 < cols ? sp[x + 1] : 0.0f, l, dp[x] != 0, r);
        const bool u = su && du[x], d = sd && dd[x];
        oy[x] = diff(su ? su[x] : 0.0f, sp[x], sd ? sd[x] : 0.0f, u, dp[x] != 0, d);
      }
    });
  }

  const cv::Mat& coverage() const { return coverage_; }

 private:
  cv::Mat coverage_;  // CV_8U 255/0
  WrinkleMapOptions options_;
  double sigma_small_ = 0.0, sigma_large_ = 0.0, sigma_gradient_ = 0.0;
  cv::Mat m_, den_small_, den_large_, den_gradient_;
};

}  // namespace internal

using internal::DogFilter;

cv::Mat DogResponse(const cv::Mat& gray_texture, const WrinkleMapOptions& options, const cv::Mat& coverage,
                    const std::string& what) {
  options.Check();
  RequireGray(gray_texture, what);
  const DogFilter filter(PrepareCoverage(coverage, gray_texture.rows, what), options);
  return filter.Response(filter.Masked(gray_texture, what));
}

cv::Mat FlattenByReference(const cv::Mat& texture, const cv::Mat& reference, const cv::Mat& coverage,
                           TextureReference mode, double reference_mean) {
  Require(mode != TextureReference::kNone,
          "FlattenByReference: mode 'none' flattens nothing (expected 'ratio' or 'difference')");
  const bool ratio = mode == TextureReference::kRatio;
  RequireGray(texture, "FlattenByReference texture");
  RequireGray(reference, "FlattenByReference reference");
  Require(texture.size() == reference.size() && (coverage.empty() || coverage.size() == texture.size()),
          fmt::format("FlattenByReference: texture {}×{}, reference {}×{}, coverage {}×{}", texture.cols, texture.rows,
                      reference.cols, reference.rows, coverage.cols, coverage.rows));
  constexpr float kMinReference = 1e-4f;
  auto usable = [&](int y, int x) {
    return (coverage.empty() || coverage.at<uint8_t>(y, x)) && reference.at<float>(y, x) > kMinReference;
  };
  if (reference_mean < 0) reference_mean = ReferenceMean(reference, coverage);
  cv::Mat out(texture.size(), CV_32F, cv::Scalar(0));
  for (int y = 0; y < texture.rows; ++y) {
    const float* t = texture.ptr<float>(y);
    const float* r = reference.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < texture.cols; ++x)
      if (usable(y, x) && t[x] > kMinReference)
        o[x] = static_cast<float>(ratio ? t[x] * reference_mean / r[x] : t[x] - r[x] + reference_mean);
  }
  return out;
}

double FlatteningLevel(const WrinkleMapOptions& options, const cv::Mat& reference, const cv::Mat& coverage) {
  return options.texture_reference_level > 0 ? options.texture_reference_level : ReferenceMean(reference, coverage);
}

double ReferenceMean(const cv::Mat& reference, const cv::Mat& coverage) {
  RequireGray(reference, "ReferenceMean reference");
  cv::Mat usable = reference > 1e-4f;
  if (!coverage.empty()) cv::bitwise_and(usable, coverage != 0, usable);
  return cv::countNonZero(usable) > 0 ? cv::mean(reference, usable)[0] : 0.0;
}

cv::Mat MedianTexture(const std::vector<cv::Mat>& textures, const std::vector<cv::Mat>& seen) {
  Require(!textures.empty(), "MedianTexture: no textures");
  Require(seen.empty() || seen.size() == textures.size(),
          fmt::format("MedianTexture: {} textures and {} seen masks", textures.size(), seen.size()));
  for (size_t k = 0; k < textures.size(); ++k) {
    RequireGray(textures[k], fmt::format("MedianTexture texture {}", k));
    Require(textures[k].size() == textures[0].size() && (seen.empty() || seen[k].empty() || seen[k].size() == textures[0].size()),
            fmt::format("MedianTexture: texture or mask {} differs in size from the first", k));
  }
  cv::Mat out(textures[0].size(), CV_32F, cv::Scalar(0));
  ForRows(out.rows, [&](int y) {
    std::vector<float> v;
    v.reserve(textures.size());
    float* o = out.ptr<float>(y);
    for (int x = 0; x < out.cols; ++x) {
      v.clear();
      for (size_t k = 0; k < textures.size(); ++k)
        if (seen.empty() || seen[k].empty() || seen[k].at<uint8_t>(y, x)) v.push_back(textures[k].at<float>(y, x));
      if (v.empty()) continue;
      const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
      std::nth_element(v.begin(), mid, v.end());
      o[x] = *mid;
    }
  });
  return out;
}

cv::Mat AwayFromRims(const cv::Mat& coverage, double texels) {
  Require(coverage.type() == CV_8U, "AwayFromRims: the coverage must be CV_8U");
  if (texels <= 0) return coverage.clone();
  cv::Mat padded, distance;
  cv::copyMakeBorder(coverage, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::distanceTransform(padded != 0, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  return distance(cv::Rect(1, 1, coverage.cols, coverage.rows)) >= texels;
}

cv::Mat ValidRegionMask(const std::vector<RegionMask>& regions, const std::vector<std::string>& names,
                        int map_size, const cv::Mat& coverage) {
  Require(map_size > 0, fmt::format("ValidRegionMask: map size {} must be > 0", map_size));
  const cv::Mat cov = PrepareCoverage(coverage, map_size, "ValidRegionMask");
  if (names.empty()) return cov;
  cv::Mat valid(map_size, map_size, CV_8U, cv::Scalar(0));
  for (const std::string& name : names) {
    const RegionMask* region = nullptr;
    for (const RegionMask& r : regions) {
      if (r.name == name) region = &r;
    }
    if (region == nullptr) {
      std::vector<std::string> available;
      for (const RegionMask& r : regions) available.push_back(r.name);
      throw Error(fmt::format("ValidRegionMask: unknown region '{}' (the rig has: {})", name,
                              available.empty() ? std::string("no regions") : fmt::format("{}", fmt::join(available, ", "))));
    }
    const cv::Mat& m = region->mask;
    Require(!m.empty() && m.type() == CV_8UC1 && m.rows == m.cols,
            fmt::format("ValidRegionMask: region '{}' mask must be a square non-empty CV_8UC1 image, got {}x{} type {}",
                        name, m.cols, m.rows, m.type()));
    // Nearest texel centre: texel i of the map has u = (i + 0.5)/S, which lies in
    // mask texel floor(u · M).
    const int M = m.rows;
    std::vector<int> src(map_size);
    for (int i = 0; i < map_size; ++i) {
      src[i] = std::min(M - 1, static_cast<int>(std::floor((i + 0.5) * M / map_size)));
    }
    for (int y = 0; y < map_size; ++y) {
      const uint8_t* row = m.ptr<uint8_t>(src[y]);
      uint8_t* o = valid.ptr<uint8_t>(y);
      for (int x = 0; x < map_size; ++x) {
        if (row[src[x]]) o[x] = 255;
      }
    }
  }
  cv::bitwise_and(valid, cov, valid);
  return valid;
}

cv::Mat PatchRegionMask(const std::vector<RegionMask>& regions, const WrinkleMapOptions& options, int map_size,
                        const cv::Mat& coverage) {
  cv::Mat valid = ValidRegionMask(regions, options.patch_regions, map_size, coverage);
  std::vector<std::string> present;
  for (const std::string& name : options.patch_exclude_regions) {
    for (const RegionMask& r : regions) {
      if (r.name == name) {
        present.push_back(name);
        break;
      }
    }
  }
  if (present.empty()) return valid;
  cv::Mat excluded = ValidRegionMask(regions, present, map_size);
  const int margin = static_cast<int>(std::lround(options.patch_exclude_margin * SigmaScale(options, map_size)));
  if (margin > 0) {
    const cv::Mat disk = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * margin + 1, 2 * margin + 1));
    cv::dilate(excluded, excluded, disk);
  }
  valid.setTo(0, excluded);
  return valid;
}

cv::Mat WrinkleProbability(const std::vector<cv::Mat>& responses, const cv::Mat& valid, double alpha) {
  Require(!responses.empty(), "WrinkleProbability: no responses (need at least one texture)");
  const cv::Size size = responses[0].size();
  for (size_t j = 0; j < responses.size(); ++j) {
    Require(responses[j].type() == CV_32FC1,
            fmt::format("WrinkleProbability: response {} must be CV_32FC1, got type {}", j, responses[j].type()));
    Require(responses[j].size() == size,
            fmt::format("WrinkleProbability: response {} is {}x{}, response 0 is {}x{}", j, responses[j].cols,
                        responses[j].rows, size.width, size.height));
  }
  Require(valid.empty() || (valid.type() == CV_8UC1 && valid.size() == size),
          fmt::format("WrinkleProbability: valid mask must be CV_8UC1 {}x{}, got {}x{} type {}", size.width,
                      size.height, valid.cols, valid.rows, valid.type()));
  const float a = static_cast<float>(alpha);
  const float inv_j = 1.0f / static_cast<float>(responses.size());
  cv::Mat w(size, CV_32F);
  ForRows(size.height, [&](int y) {
    float* o = w.ptr<float>(y);
    const uint8_t* v = valid.empty() ? nullptr : valid.ptr<uint8_t>(y);
    for (int x = 0; x < size.width; ++x) {
      float sum = 0.0f;
      if (!v || v[x]) {
        for (const cv::Mat& r : responses) {
          const float rj = r.ptr<float>(y)[x];
          if (rj > a) sum += rj;
        }
      }
      o[x] = sum * inv_j;
    }
  });
  return w;
}

WrinkleMapBuilder::WrinkleMapBuilder(int map_size, const cv::Mat& coverage, const std::vector<RegionMask>& regions,
                                     const WrinkleMapOptions& options)
    : options_(options), size_(map_size) {
  options.Check();
  Require(map_size >= 2, fmt::format("WrinkleMapBuilder: map size {} must be >= 2", map_size));
  coverage_ = PrepareCoverage(coverage, map_size, "WrinkleMapBuilder");
  valid_ = PatchRegionMask(regions, options, map_size, coverage_);
  filter_ = std::make_shared<const DogFilter>(coverage_, options_);
  response_sum_ = cv::Mat(map_size, map_size, CV_32F, cv::Scalar(0));
  count_ = cv::Mat(map_size, map_size, CV_32S, cv::Scalar(0));
  orientation_sum_ = cv::Mat(map_size, map_size, CV_32FC2, cv::Scalar(0, 0));
}

cv::Mat WrinkleMapBuilder::Add(const cv::Mat& gray_texture, const std::string& what, const cv::Mat& counts) {
  RequireGray(gray_texture, what);
  Require(gray_texture.rows == size_,
          fmt::format("{}: texture is {}x{}, expected {}x{} like the other textures of this wrinkle map", what,
                      gray_texture.cols, gray_texture.rows, size_, size_));
  Require(counts.empty() || (counts.type() == CV_8UC1 && counts.rows == size_ && counts.cols == size_),
          fmt::format("{}: the mask of counted texels must be CV_8U {}x{}", what, size_, size_));
  const DogFilter& filter = *filter_;
  const cv::Mat tm = filter.Masked(gray_texture, what);
  cv::Mat r = filter.Response(tm);
  cv::Mat gx, gy;
  filter.Gradient(tm, &gx, &gy);
  const float a = static_cast<float>(options_.wrinkle_threshold);
  ForRows(size_, [&](int y) {
    const float* rp = r.ptr<float>(y);
    const float* px = gx.ptr<float>(y);
    const float* py = gy.ptr<float>(y);
    float* sum = response_sum_.ptr<float>(y);
    int* cnt = count_.ptr<int>(y);
    cv::Vec2f* ori = orientation_sum_.ptr<cv::Vec2f>(y);
    const uint8_t* k = counts.empty() ? nullptr : counts.ptr<uint8_t>(y);
    for (int x = 0; x < size_; ++x) {
      if (rp[x] > a && (k == nullptr || k[x] != 0)) {  // [r_j(p) > α], Sec. 4.2
        sum[x] += rp[x];
        cnt[x] += 1;
        ori[x][0] += px[x] * px[x] - py[x] * py[x];
        ori[x][1] += 2.0f * px[x] * py[x];
      }
    }
  });
  ++num_textures_;
  return r;
}

WrinkleMap WrinkleMapBuilder::Finish() const {
  Require(num_textures_ > 0, "WrinkleMapBuilder::Finish: no textures were added (need at least one)");
  WrinkleMap out;
  out.num_textures = num_textures_;
  out.valid = valid_.clone();
  out.coverage = coverage_.clone();
  out.contributions = count_.clone();
  // W(p) = (1/J) Σ_j [r_j(p) > α] r_j(p) on the valid region (Sec. 4.2, Difference 3).
  const float inv_j = 1.0f / static_cast<float>(num_textures_);
  out.probability = cv::Mat(size_, size_, CV_32F);
  ForRows(size_, [&](int y) {
    const float* s = response_sum_.ptr<float>(y);
    const uint8_t* v = valid_.ptr<uint8_t>(y);
    float* o = out.probability.ptr<float>(y);
    for (int x = 0; x < size_; ++x) o[x] = v[x] ? s[x] * inv_j : 0.0f;
  });
  // O = G_o * Σ v / G_o * Σ [·]: the average doubled-angle vector of the
  // contributing texels, lightly smoothed (Difference 4).
  const double sigma_o = options_.orientation_smoothing_sigma * SigmaScale(options_, size_);
  cv::Mat count_f;
  count_.convertTo(count_f, CV_32F);
  const cv::Mat num = Blur(orientation_sum_, sigma_o);
  const cv::Mat den = Blur(count_f, sigma_o);
  out.orientation = cv::Mat(size_, size_, CV_32FC2);
  out.angle = cv::Mat(size_, size_, CV_32F);
  const double phi0 = options_.orientation_reference_deg * std::numbers::pi / 180.0;
  const float fixed = WrapAngle(phi0);  // orient_patches = false: e1 along φ_0
  ForRows(size_, [&](int y) {
    const cv::Vec2f* n = num.ptr<cv::Vec2f>(y);
    const float* d = den.ptr<float>(y);
    cv::Vec2f* o = out.orientation.ptr<cv::Vec2f>(y);
    float* th = out.angle.ptr<float>(y);
    for (int x = 0; x < size_; ++x) {
      o[x] = d[x] > kMinWeight ? cv::Vec2f(n[x][0] / d[x], n[x][1] / d[x]) : cv::Vec2f(0.0f, 0.0f);
      th[x] = options_.orient_patches ? PatchAngle(o[x], phi0) : fixed;
    }
  });
  return out;
}

WrinkleMap ComputeWrinkleMap(const std::vector<cv::Mat>& textures, const cv::Mat& coverage,
                             const std::vector<RegionMask>& regions, const WrinkleMapOptions& options,
                             std::vector<cv::Mat>* responses) {
  Require(!textures.empty(), "ComputeWrinkleMap: no textures (need at least one)");
  RequireGray(textures[0], "ComputeWrinkleMap: texture 0");
  WrinkleMapBuilder builder(textures[0].rows, coverage, regions, options);
  if (responses) responses->clear();
  for (size_t j = 0; j < textures.size(); ++j) {
    cv::Mat r = builder.Add(textures[j], fmt::format("ComputeWrinkleMap: texture {}", j));
    if (responses) responses->push_back(std::move(r));
  }
  return builder.Finish();
}

}  // namespace crease
