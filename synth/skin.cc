#include "synth/skin.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/uv_raster.h"

namespace crease {
namespace {

// Brow stroke: centre line below the brow landmarks, half height at the outer
// and inner ends, mm.
constexpr double kBrowDropMm = 2.5;
constexpr double kBrowHalfOuterMm = 1.4;
constexpr double kBrowHalfInnerMm = 4.0;
// Lash line along the upper lid margin: half height at the outer and inner corner, mm.
constexpr double kLashHalfOuterMm = 1.6;
constexpr double kLashHalfInnerMm = 0.7;

}  // namespace

namespace {

using Vec2 = Eigen::Vector2d;

// Zero mean, unit RMS (in place).
void Standardise(cv::Mat& m) {
  cv::Scalar mean, stddev;
  cv::meanStdDev(m, mean, stddev);
  m -= mean[0];
  if (stddev[0] > 0) m /= stddev[0];
}

cv::Mat WhiteNoise(Rng& rng, int rows, int cols) {
  cv::Mat m(rows, cols, CV_32F);
  for (int j = 0; j < rows; ++j) {
    float* row = m.ptr<float>(j);
    for (int i = 0; i < cols; ++i) row[i] = static_cast<float>(rng.Normal());
  }
  return m;
}

cv::Point2f ToTexel(const Vec2& uv, int size) {
  return cv::Point2f(static_cast<float>(uv.x() * size - 0.5), static_cast<float>(uv.y() * size - 0.5));
}

// Adds amplitude · exp(−d²/(2σ²)) around `c` (texels) to `m` (CV_32F).
void SplatGaussian(cv::Mat& m, const cv::Point2f& c, double sigma, double amplitude) {
  const int r = static_cast<int>(std::ceil(3.0 * sigma));
  const int cx = static_cast<int>(std::lround(c.x)), cy = static_cast<int>(std::lround(c.y));
  for (int j = std::max(0, cy - r); j <= std::min(m.rows - 1, cy + r); ++j) {
    float* row = m.ptr<float>(j);
    for (int i = std::max(0, cx - r); i <= std::min(m.cols - 1, cx + r); ++i) {
      const double d2 = (i - c.x) * (i - c.x) + (j - c.y) * (j - c.y);
      row[i] += static_cast<float>(amplitude * std::exp(-d2 / (2 * sigma * sigma)));
    }
  }
}

// Adds a soft line segment a→b (texels) of Gaussian cross-section σ and
// amplitude tapered to zero at both ends.
void SplatSegment(cv::Mat& m, const cv::Point2f& a, const cv::Point2f& b, double sigma, double amplitude) {
  const double r = 3.0 * sigma;
  const int i0 = std::max(0, static_cast<int>(std::floor(std::min(a.x, b.x) - r)));
  const int i1 = std::min(m.cols - 1, static_cast<int>(std::ceil(std::max(a.x, b.x) + r)));
  const int j0 = std::max(0, static_cast<int>(std::floor(std::min(a.y, b.y) - r)));
  const int j1 = std::min(m.rows - 1, static_cast<int>(std::ceil(std::max(a.y, b.y) + r)));
  const double ex = b.x - a.x, ey = b.y - a.y, ee = ex * ex + ey * ey;
  for (int j = j0; j <= j1; ++j) {
    float* row = m.ptr<float>(j);
    for (int i = i0; i <= i1; ++i) {
      const double t = ee > 0 ? std::clamp(((i - a.x) * ex + (j - a.y) * ey) / ee, 0.0, 1.0) : 0.0;
      const double dx = a.x + t * ex - i, dy = a.y + t * ey - j;
      const double taper = std::sin(std::numbers::pi * t);
      row[i] += static_cast<float>(amplitude * taper * std::exp(-(dx * dx + dy * dy) / (2 * sigma * sigma)));
    }
  }
}

cv::Mat LipMask(const FaceAnchors& a, int size, double blur_texels) {
  cv::Mat m(size, size, CV_32F, cv::Scalar(0));
  std::vector<cv::Point> poly;
  for (const auto& p : a.lip_outline) {
    const cv::Point2f t = ToTexel(p, size);
    poly.emplace_back(static_cast<int>(std::lround(t.x)), static_cast<int>(std::lround(t.y)));
  }
  if (poly.size() >= 3) cv::fillPoly(m, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(1.0));
  if (blur_texels > 0) cv::GaussianBlur(m, m, cv::Size(0, 0), blur_texels, blur_texels, cv::BORDER_REPLICATE);
  return m;
}

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// A soft stroke along a UV polyline (outer → inner end), CV_32F size²: 1 within
// the half height (mm) that goes from half_outer_mm at the outer end to
// half_inner_mm at the inner, fading over 1 mm; the outer `taper` fraction of the
// line fades in. Empty for fewer than 2 points.
cv::Mat PolylineStroke(const std::vector<Vec2>& pts, int size, double mm_per_uv, double half_outer_mm,
                       double half_inner_mm, double taper) {
  cv::Mat m(size, size, CV_32F, cv::Scalar(0));
  if (pts.size() < 2) return m;
  std::vector<double> arc(pts.size(), 0.0);
  for (size_t b = 1; b < pts.size(); ++b) arc[b] = arc[b - 1] + (pts[b] - pts[b - 1]).norm();
  if (arc.back() <= 0) return m;
  Vec2 lo = pts[0], hi = pts[0];
  for (const auto& q : pts) {
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  const double reach = (std::max(half_outer_mm, half_inner_mm) + 1.0) / mm_per_uv;
  const int i0 = std::max(0, static_cast<int>((lo.x() - reach) * size));
  const int i1 = std::min(size - 1, static_cast<int>((hi.x() + reach) * size) + 1);
  const int j0 = std::max(0, static_cast<int>((lo.y() - reach) * size));
  const int j1 = std::min(size - 1, static_cast<int>((hi.y() + reach) * size) + 1);
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      const Vec2 x((i + 0.5) / size, (j + 0.5) / size);
      double best = 1e30, best_arc = 0;
      for (size_t b = 0; b + 1 < pts.size(); ++b) {
        const Vec2 e = pts[b + 1] - pts[b];
        const double t = std::clamp((x - pts[b]).dot(e) / std::max(e.squaredNorm(), 1e-20), 0.0, 1.0);
        const double d = (pts[b] + t * e - x).norm();
        if (d < best) {
          best = d;
          best_arc = arc[b] + t * e.norm();
        }
      }
      const double t = best_arc / arc.back();  // 0 outer, 1 inner
      const double half = half_outer_mm + (half_inner_mm - half_outer_mm) * t;
      const double fade_in = taper > 0 ? SmoothStep(0.0, taper, t) : 1.0;
      m.at<float>(j, i) = static_cast<float>((1.0 - SmoothStep(half - 0.5, half + 0.5, best * mm_per_uv)) * fade_in);
    }
  }
  return m;
}

}  // namespace

cv::Mat SmoothNoise(Rng& rng, int cells, double sigma_cells, int size) {
  Require(cells >= 2 && size >= 1, fmt::format("SmoothNoise: cells {} and size {} too small", cells, size));
  cv::Mat m = WhiteNoise(rng, cells, cells);
  if (sigma_cells > 0) cv::GaussianBlur(m, m, cv::Size(0, 0), sigma_cells, sigma_cells, cv::BORDER_REFLECT_101);
  Standardise(m);
  cv::Mat out;
  cv::resize(m, out, cv::Size(size, size), 0, 0, cv::INTER_CUBIC);
  return out;
}

MesoscopicParams GenerateMesoscopicParams(Rng& rng) {
  MesoscopicParams p;
  p.seed = rng.NextU64();
  p.pore_depth_mm = rng.Uniform(0.015, 0.045);
  p.pore_density_per_mm2 = rng.Uniform(0.5, 1.5);
  p.roughness_mm = rng.Uniform(0.006, 0.015);
  p.fine_line_depth_mm = rng.Uniform(0.008, 0.025);
  p.fine_line_density = rng.Uniform(0.2, 0.8);
  return p;
}

SkinParams GenerateSkinParams(Rng& rng) {
  SkinParams p;
  p.seed = rng.NextU64();
  p.tone = std::pow(rng.Uniform(), 1.3);
  p.redness = rng.Uniform(0.1, 0.7);
  p.variation = rng.Uniform(0.2, 0.8);
  p.blotches = rng.Uniform(0.0, 0.6);
  p.freckles = rng.Uniform() < 0.35 ? rng.Uniform(0.2, 1.0) : rng.Uniform(0.0, 0.1);
  p.lip_redness = rng.Uniform(0.3, 0.9);
  p.brow_darkness = rng.Uniform(0.4, 0.95);
  p.eye_tint = rng.Uniform(0.1, 0.7);
  p.oiliness = rng.Uniform(0.2, 0.9);
  p.specular = rng.Uniform(0.8, 1.2);
  p.roughness = rng.Uniform(0.33, 0.45);
  return p;
}

cv::Mat BuildMesoscopicMap(const FaceRig& rig, const FaceAnchors& anchors, const MesoscopicParams& params,
                           int size) {
  Require(size >= 8, fmt::format("BuildMesoscopicMap: size {} must be ≥ 8", size));
  Rng rng(params.seed);
  const double mm_per_texel = anchors.mm_per_uv / size;
  // Where pores are dense: nose and cheeks, then forehead, little elsewhere; none on the lips.
  const cv::Mat cheeks_nose = SoftRegionWeight(rig, {"nose", "left_cheek", "right_cheek"}, size, 3.0, anchors.mm_per_uv);
  const cv::Mat forehead = SoftRegionWeight(rig, {"forehead", "glabella", "chin"}, size, 3.0, anchors.mm_per_uv);
  const cv::Mat lips = LipMask(anchors, size, 0.7 / mm_per_texel);
  cv::Mat density(size, size, CV_32F);
  for (int j = 0; j < size; ++j)
    for (int i = 0; i < size; ++i)
      density.at<float>(j, i) = std::clamp(0.4f + 0.6f * cheeks_nose.at<float>(j, i) + 0.3f * forehead.at<float>(j, i),
                                           0.0f, 1.0f) * (1.0f - 0.9f * lips.at<float>(j, i));

  // Micro relief: band-passed noise (wavelengths ~0.15–0.6 mm).
  cv::Mat relief = WhiteNoise(rng, size, size);
  {
    const double s1 = std::max(0.5, 0.08 / mm_per_texel), s2 = 3.0 * s1;
    cv::Mat lo1, lo2;
    cv::GaussianBlur(relief, lo1, cv::Size(0, 0), s1, s1, cv::BORDER_REFLECT_101);
    cv::GaussianBlur(relief, lo2, cv::Size(0, 0), s2, s2, cv::BORDER_REFLECT_101);
    relief = lo1 - lo2;
    Standardise(relief);
  }
  cv::Mat meso = relief.mul(density) * params.roughness_mm;

  const double area_mm2 = anchors.mm_per_uv * anchors.mm_per_uv;  // of the unit UV square
  // Pores: Gaussian pits.
  {
    const int n = static_cast<int>(params.pore_density_per_mm2 * area_mm2);
    for (int k = 0; k < n; ++k) {
      const double v = rng.Uniform();  // v first: one draw per statement (synth/wrinkles.cc, Draws3)
      const Vec2 uv(rng.Uniform(), v);
      const double radius = rng.Uniform(0.05, 0.12);
      const double depth = params.pore_depth_mm * rng.Uniform(0.5, 1.5);
      const cv::Point2f c = ToTexel(uv, size);
      const int ci = std::clamp(static_cast<int>(c.x + 0.5f), 0, size - 1);
      const int cj = std::clamp(static_cast<int>(c.y + 0.5f), 0, size - 1);
      if (rng.Uniform() > density.at<float>(cj, ci)) continue;
      const double sigma = std::max(radius / mm_per_texel, 0.5);
      SplatGaussian(meso, c, sigma, -depth);
    }
  }
  // Fine lines: short shallow scratches in two dominant directions (±40° from lateral).
  {
    const int n = static_cast<int>(params.fine_line_density * area_mm2);
    for (int k = 0; k < n; ++k) {
      const double v = rng.Uniform();  // v first: one draw per statement (synth/wrinkles.cc, Draws3)
      const Vec2 uv(rng.Uniform(), v);
      const double family = rng.Uniform() < 0.5 ? -0.7 : 0.7;
      const double angle = family + rng.Uniform(-0.3, 0.3);
      const Vec2 dir = std::cos(angle) * anchors.lateral + std::sin(angle) * anchors.up;
      const double len_uv = rng.Uniform(0.5, 2.0) / anchors.mm_per_uv;
      const double depth = params.fine_line_depth_mm * rng.Uniform(0.4, 1.2);
      const cv::Point2f c = ToTexel(uv, size);
      const int ci = std::clamp(static_cast<int>(c.x + 0.5f), 0, size - 1);
      const int cj = std::clamp(static_cast<int>(c.y + 0.5f), 0, size - 1);
      if (rng.Uniform() > density.at<float>(cj, ci)) continue;
      SplatSegment(meso, ToTexel(uv - 0.5 * len_uv * dir, size), ToTexel(uv + 0.5 * len_uv * dir, size),
                   std::max(0.5, 0.05 / mm_per_texel), -depth);
    }
  }
  cv::min(meso, 0.08, meso);
  cv::max(meso, -0.08, meso);
  return meso;
}

double ScalpHairline::Weight(const Eigen::Vector3d& p) const {
  // (azimuth °, height above the eye line mm), piecewise linear in |θ|.
  static constexpr double kProfile[][2] = {{0, kFrontHeightMm}, {20, 60}, {60, 45}, {110, 45}, {130, -45}, {180, -45}};
  const double theta = std::abs(std::atan2(p.x(), p.z() - ear_z)) * 180.0 / std::numbers::pi;
  double h = kProfile[0][1];
  for (size_t k = 0; k + 1 < std::size(kProfile); ++k) {
    if (theta >= kProfile[k][0] && theta <= kProfile[k + 1][0]) {
      const double t = (theta - kProfile[k][0]) / (kProfile[k + 1][0] - kProfile[k][0]);
      h = kProfile[k][1] + t * (kProfile[k + 1][1] - kProfile[k][1]);
    }
  }
  return SmoothStep(-1.5, 1.5, p.y() - eye_y - h);
}

bool PaintsScalpHair(const FaceRig& rig) {
  return rig.PartIndex("hair") < 0 && rig.LandmarkIndex("ibug_68") >= 0;
}

ScalpHairline ScalpHairlineOf(const FaceRig& rig) {
  auto lm = [&](int i) {
    const int l = rig.LandmarkIndex(fmt::format("ibug_{}", i));
    Require(l >= 0, fmt::format("{}: scalp hair needs the 68 iBUG landmarks (no ibug_{})", rig.source, i));
    return Eigen::Vector3d(rig.neutral.V.row(rig.landmarks[l].vertex).transpose());
  };
  ScalpHairline h;
  for (int i = 37; i <= 48; ++i) h.eye_y += lm(i).y() / 12.0;
  h.ear_z = 0.5 * (lm(1).z() + lm(17).z());
  return h;
}

namespace {

// The scalp-hair weight of every texel of the rig's face chart (0 off the chart).
cv::Mat ScalpHairMap(const FaceRig& rig, int size) {
  const ScalpHairline line = ScalpHairlineOf(rig);
  TriMesh chart = rig.neutral;
  chart.F = FaceChartTriangles(rig);
  chart.N.resize(0, 3);
  const UvRaster raster = RasterizeUv(chart, size, size, "scalp hair: the rig's face chart");
  const cv::Mat P = InterpolateToUv(raster, chart, chart.V);
  cv::Mat w(size, size, CV_32F, cv::Scalar(0));
  const cv::Mat covered = CoverageMask(raster);
  for (int j = 0; j < size; ++j) {
    for (int i = 0; i < size; ++i) {
      if (!covered.at<uint8_t>(j, i)) continue;
      const cv::Vec3f q = P.at<cv::Vec3f>(j, i);
      w.at<float>(j, i) = static_cast<float>(line.Weight(Eigen::Vector3d(q[0], q[1], q[2])));
    }
  }
  return w;
}

}  // namespace

SkinMaps BuildSkinMaps(const FaceRig& rig, const FaceAnchors& a, const SkinParams& p, int size) {
  Require(size >= 8, fmt::format("BuildSkinMaps: size {} must be ≥ 8", size));
  Rng rng(p.seed);
  const double mm_per_texel = a.mm_per_uv / size;
  // Base tone: light → medium → dark, linear RGB.
  const Eigen::Vector3d light(0.70, 0.50, 0.41), medium(0.42, 0.26, 0.18), dark(0.12, 0.07, 0.045);
  Eigen::Vector3d base = p.tone < 0.5 ? Eigen::Vector3d(light + (medium - light) * (2 * p.tone))
                                      : Eigen::Vector3d(medium + (dark - medium) * (2 * p.tone - 1));
  base.x() *= 1.0 + 0.12 * p.redness;
  base.y() *= 1.0 - 0.06 * p.redness;

  // Fields (each from this actor's skin stream, in a fixed order).
  const int lo_cells = std::max(4, static_cast<int>(a.mm_per_uv / 8.0));    // ~8 mm cells
  const int mid_cells = std::max(4, static_cast<int>(a.mm_per_uv / 3.0));   // ~3 mm cells
  const cv::Mat n_lum = SmoothNoise(rng, lo_cells, 1.5, size);
  const cv::Mat n_hue = SmoothNoise(rng, lo_cells, 1.5, size);
  const cv::Mat n_blotch = SmoothNoise(rng, mid_cells, 2.0, size);
  const cv::Mat n_spec = SmoothNoise(rng, mid_cells, 1.0, size);
  cv::Mat n_hair = WhiteNoise(rng, size, size);
  cv::GaussianBlur(n_hair, n_hair, cv::Size(0, 0), std::max(0.5, 0.6 / mm_per_texel), 0.5, cv::BORDER_REFLECT_101);
  Standardise(n_hair);

  const cv::Mat cheeks = SoftRegionWeight(rig, {"left_cheek", "right_cheek"}, size, 8.0, a.mm_per_uv);
  const cv::Mat tzone = SoftRegionWeight(rig, {"forehead", "glabella", "nose", "chin"}, size, 5.0, a.mm_per_uv);
  const cv::Mat lips = LipMask(a, size, 1.5 / mm_per_texel);
  // Brows: soft strokes below the brow landmarks (which trace a brow's upper
  // edge in iBUG 300-W), ~3 mm tall at the outer end and ~8 mm at the inner end.
  cv::Mat brows(size, size, CV_32F, cv::Scalar(0));
  for (int k = 0; k < 2; ++k) {
    std::vector<Vec2> pts;
    for (const auto& b : a.brow[k]) pts.push_back(b - a.up * (kBrowDropMm / a.mm_per_uv));
    cv::max(brows, PolylineStroke(pts, size, a.mm_per_uv, kBrowHalfOuterMm, kBrowHalfInnerMm, 0.15), brows);
  }
  // Lash line: the dark margin of the upper lid where the lashes root (the lashes
  // themselves are not modelled), thickest at the outer corner.
  cv::Mat lashes(size, size, CV_32F, cv::Scalar(0));
  for (int k = 0; k < 2; ++k) {
    cv::max(lashes, PolylineStroke(a.upper_lid[k], size, a.mm_per_uv, kLashHalfOuterMm, kLashHalfInnerMm, 0.0), lashes);
  }
  // Freckles: multiplicative density, denser on nose and cheeks.
  cv::Mat freckles(size, size, CV_32F, cv::Scalar(0));
  const cv::Mat nose_cheeks = SoftRegionWeight(rig, {"nose", "left_cheek", "right_cheek"}, size, 6.0, a.mm_per_uv);
  {
    const int n = static_cast<int>(p.freckles * (1.0 - 0.7 * p.tone) * 0.3 * a.mm_per_uv * a.mm_per_uv / 100.0);
    for (int k = 0; k < n; ++k) {
      const double v = rng.Uniform();  // v first: one draw per statement (synth/wrinkles.cc, Draws3)
      const Vec2 uv(rng.Uniform(), v);
      const double radius = rng.Uniform(0.3, 0.9);
      const double strength = rng.Uniform(0.3, 1.0);
      const cv::Point2f c = ToTexel(uv, size);
      const int ci = std::clamp(static_cast<int>(c.x + 0.5f), 0, size - 1);
      const int cj = std::clamp(static_cast<int>(c.y + 0.5f), 0, size - 1);
      if (rng.Uniform() > 0.2 + 0.8 * nose_cheeks.at<float>(cj, ci)) continue;
      SplatGaussian(freckles, c, std::max(0.5, radius / mm_per_texel), strength);
    }
    cv::min(freckles, 1.0, freckles);
  }

  SkinMaps maps;
  const bool paint_hair = PaintsScalpHair(rig);
  maps.hair = paint_hair ? ScalpHairMap(rig, size) : cv::Mat(size, size, CV_32F, cv::Scalar(0));
  maps.albedo.create(size, size, CV_32FC3);
  maps.specular.create(size, size, CV_32F);
  maps.roughness.create(size, size, CV_32F);
  // Brow hair: light brown to near black.
  const Eigen::Vector3d hair = Eigen::Vector3d(0.16, 0.10, 0.06) +
                               (Eigen::Vector3d(0.025, 0.018, 0.013) - Eigen::Vector3d(0.16, 0.10, 0.06)) *
                                   std::max(p.brow_darkness, p.tone);
  for (int j = 0; j < size; ++j) {
    cv::Vec3f* alb = maps.albedo.ptr<cv::Vec3f>(j);
    float* spec = maps.specular.ptr<float>(j);
    float* rough = maps.roughness.ptr<float>(j);
    for (int i = 0; i < size; ++i) {
      const Vec2 uv((i + 0.5) / size, (j + 0.5) / size);
      Eigen::Vector3d c = base * (1.0 + 0.10 * p.variation * n_lum.at<float>(j, i));
      const double hue = 0.05 * p.variation * n_hue.at<float>(j, i);
      c.x() *= 1.0 + hue;
      c.z() *= 1.0 - hue;
      const double rosy = cheeks.at<float>(j, i) * p.redness;
      c = c.cwiseProduct(Eigen::Vector3d(1.0 + 0.10 * rosy, 1.0 - 0.08 * rosy, 1.0 - 0.05 * rosy));
      const double blotch = SmoothStep(0.8, 2.6, n_blotch.at<float>(j, i)) * p.blotches;
      c = c.cwiseProduct(Eigen::Vector3d(1.0 + 0.12 * blotch, 1.0 - 0.18 * blotch, 1.0 - 0.12 * blotch));
      const double fr = freckles.at<float>(j, i) * std::min(1.0, 0.5 + p.freckles);
      c = c.cwiseProduct(Eigen::Vector3d(1.0 - 0.30 * fr, 1.0 - 0.40 * fr, 1.0 - 0.50 * fr));
      const double lip = lips.at<float>(j, i) * p.lip_redness;
      c = c.cwiseProduct(Eigen::Vector3d(1.0 - 0.08 * lip, 1.0 - 0.45 * lip, 1.0 - 0.38 * lip));
      double eye = 0;
      for (int k = 0; k < 2; ++k) {
        const double d_mm = (uv - a.eye_center[k]).norm() * a.mm_per_uv;
        eye = std::max(eye, std::exp(-d_mm * d_mm / (2 * 9.0 * 9.0)));
      }
      eye *= p.eye_tint;
      c = c.cwiseProduct(Eigen::Vector3d(1.0 - 0.16 * eye, 1.0 - 0.20 * eye, 1.0 - 0.10 * eye));
      const double brow = brows.at<float>(j, i) * (0.6 + 0.4 * p.brow_darkness) *
                          std::clamp(0.8 + 0.3 * n_hair.at<float>(j, i), 0.0, 1.0);
      c = c + (hair - c) * (0.95 * brow);
      c = c + (hair - c) * (0.9 * lashes.at<float>(j, i));
      const double scalp = maps.hair.at<float>(j, i);
      c = c + (hair * std::clamp(0.85 + 0.25 * n_hair.at<float>(j, i), 0.5, 1.3) - c) * scalp;
      for (int k = 0; k < 3; ++k) alb[i][k] = static_cast<float>(std::clamp(c[k], 0.005, 0.95));
      const double t = tzone.at<float>(j, i) * p.oiliness;
      const double ns = n_spec.at<float>(j, i);
      spec[i] = static_cast<float>(std::clamp(
          p.specular * (0.75 + 0.7 * t + 0.25 * lips.at<float>(j, i)) * (1.0 + 0.12 * ns) * (1.0 - 0.5 * std::max(brow, scalp)),
          0.05, 3.0));
      rough[i] = static_cast<float>(std::clamp(
          p.roughness * (1.0 - 0.35 * t - 0.25 * lips.at<float>(j, i)) * (1.0 + 0.08 * ns) + 0.15 * (brow + scalp),
          0.1, 0.9));
    }
  }
  maps.hair_color = hair.cast<float>();
  return maps;
}

}  // namespace crease
