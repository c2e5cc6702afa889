#include "synth/wrinkles.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <tuple>
#include <utility>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "synth/skin.h"

namespace crease {
namespace {

using Vec2 = Eigen::Vector2d;

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

Vec2 Perp(const Vec2& d) { return Vec2(-d.y(), d.x()); }

Vec2 Rotate(const Vec2& d, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return Vec2(c * d.x() - s * d.y(), s * d.x() + c * d.y());
}

// Centroid and extent (along `lateral` and `up`) of a region mask, in UV.
struct MaskShape {
  Vec2 centroid = Vec2::Zero();
  double width = 0.0;   // extent along lateral
  double height = 0.0;  // extent along up
  double lo_l = 0, hi_l = 0, lo_u = 0, hi_u = 0;  // bounds of (x − centroid)·lateral and ·up
  bool valid = false;
  // The point at lateral offset l and up offset u from the centroid.
  Vec2 At(const Vec2& lateral, const Vec2& up, double l, double u) const { return centroid + lateral * l + up * u; }
};

MaskShape ShapeOf(const RegionMask* r, const Vec2& lateral, const Vec2& up) {
  MaskShape s;
  if (r == nullptr || r->mask.empty()) return s;
  const int w = r->mask.cols, h = r->mask.rows;
  double n = 0;
  for (int j = 0; j < h; ++j) {
    const uint8_t* row = r->mask.ptr<uint8_t>(j);
    for (int i = 0; i < w; ++i) {
      if (row[i] == 0) continue;
      s.centroid += Vec2((i + 0.5) / w, (j + 0.5) / h);
      n += 1;
    }
  }
  if (n == 0) return s;
  s.centroid /= n;
  double lo_l = 0, hi_l = 0, lo_u = 0, hi_u = 0;
  for (int j = 0; j < h; ++j) {
    const uint8_t* row = r->mask.ptr<uint8_t>(j);
    for (int i = 0; i < w; ++i) {
      if (row[i] == 0) continue;
      const Vec2 d = Vec2((i + 0.5) / w, (j + 0.5) / h) - s.centroid;
      lo_l = std::min(lo_l, d.dot(lateral));
      hi_l = std::max(hi_l, d.dot(lateral));
      lo_u = std::min(lo_u, d.dot(up));
      hi_u = std::max(hi_u, d.dot(up));
    }
  }
  s.width = hi_l - lo_l;
  s.height = hi_u - lo_u;
  s.lo_l = lo_l;
  s.hi_l = hi_l;
  s.lo_u = lo_u;
  s.hi_u = hi_u;
  s.valid = true;
  return s;
}

Vec2 Centroid(const RegionMask* r) { return ShapeOf(r, Vec2(1, 0), Vec2(0, 1)).centroid; }

// Random draws are made one per statement, in a fixed order: the order in which
// C++ evaluates function arguments and the operands of an overloaded operator is
// unspecified, and GCC (right to left) and Clang (left to right) differ, so draws
// inside one call gave the same seed different actors under the two compilers. The
// order kept is the one GCC used, so actors made by earlier GCC builds are unchanged.
struct Draws3 {
  double ridge, width, depth;
};
// A line's ridge, width and depth factors, drawn in that order.
Draws3 DrawFinish(Rng& rng, std::pair<double, double> ridge, std::pair<double, double> width,
                  std::pair<double, double> depth) {
  Draws3 d;
  d.ridge = rng.Uniform(ridge.first, ridge.second);
  d.width = rng.Uniform(width.first, width.second);
  d.depth = rng.Uniform(depth.first, depth.second);
  return d;
}

// Builds one wrinkle line along the quadratic Bézier P0 → P2 (control P1), all
// UV, with waviness and breaks.
class LineBuilder {
 public:
  LineBuilder(const FaceAnchors& a, Rng& rng) : a_(a), rng_(rng) {}

  WrinkleLine Make(WrinkleFamily family, const Vec2& p0, const Vec2& p1, const Vec2& p2,
                   double waviness_mm, double max_breaks) {
    WrinkleLine line;
    line.family = family;
    const double s = a_.mm_per_uv;
    // Length of the Bézier, mm.
    auto bezier = [&](double t) { return (1 - t) * (1 - t) * p0 + 2 * (1 - t) * t * p1 + t * t * p2; };
    auto tangent = [&](double t) { return Vec2(2 * (1 - t) * (p1 - p0) + 2 * t * (p2 - p1)); };
    double length = 0;
    for (int k = 0; k < 64; ++k) length += (bezier((k + 1) / 64.0) - bezier(k / 64.0)).norm() * s;
    const int n = std::max(6, static_cast<int>(std::ceil(length / 0.6)) + 1);
    const double wavelength = rng_.Uniform(18.0, 40.0);  // mm
    const double phase1 = rng_.Uniform(0, 2 * std::numbers::pi);
    const double phase2 = rng_.Uniform(0, 2 * std::numbers::pi);
    // Breaks: positions along the line and gap half-widths, mm.
    std::vector<std::pair<double, double>> breaks;
    const int num_breaks = static_cast<int>(std::floor(rng_.Uniform(0.0, max_breaks + 1.0)));
    for (int b = 0; b < num_breaks; ++b) {
      const double gap = rng_.Uniform(1.5, 3.5);  // drawn first (see Draws3)
      breaks.emplace_back(rng_.Uniform(0.25, 0.75) * length, gap);
    }
    const double modulation = rng_.Uniform(0.0, 0.3);  // slow depth variation along the line
    const double mod_phase = rng_.Uniform(0, 2 * std::numbers::pi);
    for (int k = 0; k < n; ++k) {
      const double t = static_cast<double>(k) / (n - 1);
      const double arc = t * length;
      Vec2 tan = tangent(t);
      if (tan.norm() < 1e-12) tan = p2 - p0;
      tan.normalize();
      const double wave = waviness_mm * (std::sin(2 * std::numbers::pi * arc / wavelength + phase1) +
                                         0.25 * std::sin(2 * std::numbers::pi * arc / (0.47 * wavelength) + phase2));
      line.points.push_back(bezier(t) + Perp(tan) * (wave / s));
      const double taper = std::min(0.25 * length, 6.0);
      double strength = SmoothStep(0.0, taper, arc) * SmoothStep(0.0, taper, length - arc);
      for (const auto& [at, gap] : breaks) strength *= SmoothStep(0.4 * gap, gap, std::abs(arc - at));
      strength *= 1.0 - modulation * (0.5 + 0.5 * std::sin(2 * std::numbers::pi * arc / 17.0 + mod_phase));
      line.strength.push_back(strength);
    }
    return line;
  }

  // A straight-ish line of `length_mm` centred on `centre` along unit UV `dir`,
  // bowing by `sag_mm` towards Perp(dir) at its middle.
  WrinkleLine Centred(WrinkleFamily family, const Vec2& centre, const Vec2& dir, double length_mm,
                      double sag_mm, double waviness_mm, double max_breaks) {
    const double s = a_.mm_per_uv;
    const Vec2 half = dir * (0.5 * length_mm / s);
    return Make(family, centre - half, centre + Perp(dir) * (2 * sag_mm / s), centre + half, waviness_mm,
                max_breaks);
  }

 private:
  const FaceAnchors& a_;
  Rng& rng_;
};

int Count(Rng& rng, double expected, int max_count) {
  return std::clamp(static_cast<int>(std::floor(expected + rng.Uniform(-0.8, 0.99))), 0, max_count);
}

}  // namespace

double MmPerUv(const FaceRig& rig) {
  const MatX3i F = FaceChartTriangles(rig);
  double area3 = 0, area_uv = 0;
  const auto& V = rig.neutral.V;
  const auto& UV = rig.neutral.UV;
  for (int f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d e1 = V.row(F(f, 1)) - V.row(F(f, 0)), e2 = V.row(F(f, 2)) - V.row(F(f, 0));
    const Vec2 t1 = UV.row(F(f, 1)) - UV.row(F(f, 0)), t2 = UV.row(F(f, 2)) - UV.row(F(f, 0));
    area3 += 0.5 * e1.cross(e2).norm();
    area_uv += 0.5 * std::abs(t1.x() * t2.y() - t1.y() * t2.x());
  }
  Require(area_uv > 0 && area3 > 0, "rig: the face chart has zero area");
  return std::sqrt(area3 / area_uv);
}

namespace {
FaceAnchors ComputeFaceAnchorsInner(const FaceRig& rig);
}  // namespace

FaceAnchors ComputeFaceAnchors(const FaceRig& rig) {
  FaceAnchors a = ComputeFaceAnchorsInner(rig);
  Vec2 brow_mid = Vec2::Zero();
  for (int k = 0; k < 2; ++k)
    for (const auto& p : a.brow[k]) brow_mid += p;
  brow_mid /= static_cast<double>(a.brow[0].size() + a.brow[1].size());
  const MaskShape forehead = ShapeOf(rig.FindRegion("forehead"), a.lateral, a.up);
  const double iod_mm = (a.eye_center[1] - a.eye_center[0]).norm() * a.mm_per_uv;
  a.forehead_height_mm = forehead.valid
                             ? ((forehead.centroid + a.up * forehead.hi_u) - brow_mid).dot(a.up) * a.mm_per_uv
                             : 0.9 * iod_mm;
  if (PaintsScalpHair(rig)) {
    // The forehead ends at the painted hairline (synth/skin.h), not at the chart's
    // top, which runs on over the scalp (ICT-FaceKit): lines above it would lie
    // under the hair, in the truth but in no image.
    const ScalpHairline hairline = ScalpHairlineOf(rig);
    double brow_y = 0.0;
    for (int i = 18; i <= 27; ++i) {
      brow_y += rig.neutral.V(rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", i))].vertex, 1) / 10.0;
    }
    a.forehead_height_mm =
        std::min(a.forehead_height_mm, ScalpHairline::kFrontHeightMm - (brow_y - hairline.eye_y));
  }
  return a;
}

namespace {
FaceAnchors ComputeFaceAnchorsInner(const FaceRig& rig) {
  Require(rig.neutral.has_uv(), "rig: the neutral mesh has no UV coordinates");
  FaceAnchors a;
  a.mm_per_uv = MmPerUv(rig);
  bool have_landmarks = true;
  for (int k = 1; k <= 68; ++k) have_landmarks = have_landmarks && rig.LandmarkIndex(fmt::format("ibug_{}", k)) >= 0;
  if (have_landmarks) {
    auto L = [&](int k) -> Vec2 {
      return rig.neutral.UV.row(rig.landmarks[rig.LandmarkIndex(fmt::format("ibug_{}", k))].vertex).transpose();
    };
    auto mean = [&](int lo, int hi) {
      Vec2 m = Vec2::Zero();
      for (int k = lo; k <= hi; ++k) m += L(k);
      return Vec2(m / (hi - lo + 1));
    };
    a.from_landmarks = true;
    // Sides, inner and outer ends are decided from the geometry (distance from
    // the midline between the eyes), not trusted from the numbering: some rigs
    // number one eye's corners or one brow in reverse.
    const Vec2 e0 = mean(37, 42), e1 = mean(43, 48);
    const Vec2 mid = 0.5 * (e0 + e1), lat = (e1 - e0).normalized();
    auto away = [&](const Vec2& p) { return std::abs((p - mid).dot(lat)); };
    auto outer_first = [&](Vec2 p, Vec2 q) { return away(p) >= away(q) ? std::pair(p, q) : std::pair(q, p); };
    std::tie(a.eye_outer[0], a.eye_inner[0]) = outer_first(L(37), L(40));
    std::tie(a.eye_outer[1], a.eye_inner[1]) = outer_first(L(46), L(43));
    a.eye_center[0] = e0;
    a.eye_center[1] = e1;
    a.lower_lid[0] = mean(41, 42);
    a.lower_lid[1] = mean(47, 48);
    for (int k = 18; k <= 22; ++k) a.brow[0].push_back(L(k));
    for (int k = 27; k >= 23; --k) a.brow[1].push_back(L(k));
    for (int k = 37; k <= 40; ++k) a.upper_lid[0].push_back(L(k));
    for (int k = 46; k >= 43; --k) a.upper_lid[1].push_back(L(k));
    for (int k = 0; k < 2; ++k) {
      if (away(a.brow[k].front()) < away(a.brow[k].back())) std::reverse(a.brow[k].begin(), a.brow[k].end());
      if (away(a.upper_lid[k].front()) < away(a.upper_lid[k].back())) {
        std::reverse(a.upper_lid[k].begin(), a.upper_lid[k].end());
      }
    }
    a.nose_bridge_top = L(28);
    a.nose_bridge_bottom = L(30);
    a.nose_tip = L(31);
    auto side_order = [&](Vec2 p, Vec2 q) { return (p - mid).dot(lat) <= (q - mid).dot(lat) ? std::pair(p, q) : std::pair(q, p); };
    std::tie(a.nose_wing[0], a.nose_wing[1]) = side_order(L(32), L(36));
    std::tie(a.mouth_corner[0], a.mouth_corner[1]) = side_order(L(49), L(55));
    for (int k = 49; k <= 60; ++k) a.lip_outline.push_back(L(k));
    a.lateral = (a.eye_center[1] - a.eye_center[0]).normalized();
    a.up = Perp(a.lateral);
    if ((mean(18, 27) - mean(49, 60)).dot(a.up) < 0) a.up = -a.up;
    return a;
  }
  for (const char* name : {"left_eye", "right_eye", "forehead", "glabella", "nose", "mouth"}) {
    Require(rig.FindRegion(name) != nullptr,
            fmt::format("rig: neither the 68 iBUG landmarks nor the region '{}' needed to place wrinkles", name));
  }
  // Region-mask estimate. Side 0 = the subject's right = "right_eye".
  const Vec2 c0 = Centroid(rig.FindRegion("right_eye")), c1 = Centroid(rig.FindRegion("left_eye"));
  Require((c1 - c0).norm() > 1e-6, "rig: the eye regions coincide");
  a.lateral = (c1 - c0).normalized();
  a.up = Perp(a.lateral);
  if ((Centroid(rig.FindRegion("forehead")) - Centroid(rig.FindRegion("mouth"))).dot(a.up) < 0) a.up = -a.up;
  // The masks are read as RegionsFromLandmarks builds them: an eye region spans
  // from the inner eye corner to ~0.45 inter-ocular distances (iod) beyond the
  // outer one and from 0.35 iod below to 0.12 iod above the eye centre; the
  // forehead starts 0.12 iod above the brows; nose and mouth are the grown hulls
  // of the nose and lip points. Other masks give rougher anchors.
  const MaskShape eye[2] = {ShapeOf(rig.FindRegion("right_eye"), a.lateral, a.up),
                            ShapeOf(rig.FindRegion("left_eye"), a.lateral, a.up)};
  const MaskShape forehead = ShapeOf(rig.FindRegion("forehead"), a.lateral, a.up);
  for (int k = 0; k < 2; ++k) {
    const Vec2 out = a.Outward(k);
    const double sign = k == 0 ? -1.0 : 1.0;  // outward = sign · lateral
    const double inner = sign < 0 ? eye[k].hi_l : eye[k].lo_l;   // lateral offset of the inner bound
    const double l_centre = inner + sign * 0.25 * eye[k].width;
    const double u_centre = eye[k].hi_u - 0.25 * eye[k].height;
    a.eye_center[k] = eye[k].At(a.lateral, a.up, l_centre, u_centre);
    a.eye_outer[k] = a.eye_center[k] + out * (0.21 * eye[k].width);
    a.eye_inner[k] = a.eye_center[k] - out * (0.21 * eye[k].width);
    a.lower_lid[k] = a.eye_center[k] - a.up * (0.07 * eye[k].height);
  }
  const double iod = (a.eye_center[1] - a.eye_center[0]).norm();
  // Brow line: just below the forehead region's lower bound.
  const double brow_u = (forehead.centroid + a.up * forehead.lo_u).dot(a.up) - 0.1 * iod;
  for (int k = 0; k < 2; ++k) {
    const Vec2 out = a.Outward(k);
    const Vec2 from = a.eye_outer[k] + out * (0.1 * iod), to = a.eye_inner[k] - out * (0.05 * iod);
    for (int b = 0; b < 5; ++b) {
      const double t = b / 4.0;
      const Vec2 q = (1 - t) * from + t * to;
      a.brow[k].push_back(q + a.up * (brow_u - q.dot(a.up) + 0.05 * iod * std::sin(std::numbers::pi * t)));
    }
  }
  const MaskShape nose = ShapeOf(rig.FindRegion("nose"), a.lateral, a.up);
  const MaskShape mouth = ShapeOf(rig.FindRegion("mouth"), a.lateral, a.up);
  a.nose_bridge_top = nose.At(a.lateral, a.up, 0.0, nose.hi_u - 0.1 * nose.height);
  a.nose_bridge_bottom = nose.At(a.lateral, a.up, 0.0, nose.hi_u - 0.55 * nose.height);
  a.nose_tip = nose.At(a.lateral, a.up, 0.0, nose.hi_u - 0.75 * nose.height);
  for (int k = 0; k < 2; ++k) {
    a.nose_wing[k] = nose.At(a.lateral, a.up, 0.0, nose.lo_u + 0.15 * nose.height) + a.Outward(k) * (0.35 * nose.width);
    a.mouth_corner[k] = mouth.centroid + a.Outward(k) * (0.42 * mouth.width);
  }
  for (int k = 0; k < 16; ++k) {
    const double t = 2 * std::numbers::pi * k / 16;
    a.lip_outline.push_back(mouth.centroid - a.lateral * (0.42 * mouth.width * std::cos(t)) +
                            a.up * (0.4 * mouth.height * std::sin(t)));
  }
  return a;
}
}  // namespace

cv::Mat SoftRegionWeight(const FaceRig& rig, const std::vector<std::string>& names, int size,
                         double blur_mm, double mm_per_uv) {
  cv::Mat acc;
  for (const auto& name : names) {
    const RegionMask* r = rig.FindRegion(name);
    if (r == nullptr || r->mask.empty()) continue;
    cv::Mat m;
    r->mask.convertTo(m, CV_32F, 1.0 / 255.0);
    cv::resize(m, m, cv::Size(size, size), 0, 0, cv::INTER_LINEAR);
    acc = acc.empty() ? m : cv::max(acc, m);
  }
  if (acc.empty()) return cv::Mat(size, size, CV_32F, cv::Scalar(1.0f));
  if (blur_mm > 0) {
    const double sigma = blur_mm / (mm_per_uv / size);
    cv::GaussianBlur(acc, acc, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
  }
  return acc;
}

std::string ToString(WrinkleFamily family) {
  switch (family) {
    case WrinkleFamily::kForehead: return "forehead";
    case WrinkleFamily::kGlabella: return "glabella";
    case WrinkleFamily::kCrowsFeet: return "crows_feet";
    case WrinkleFamily::kNasolabial: return "nasolabial";
    case WrinkleFamily::kUnderEye: return "under_eye";
    case WrinkleFamily::kBunny: return "bunny";
  }
  return "unknown";
}

WrinkleFamily WrinkleFamilyFromString(const std::string& name) {
  for (auto f : {WrinkleFamily::kForehead, WrinkleFamily::kGlabella, WrinkleFamily::kCrowsFeet,
                 WrinkleFamily::kNasolabial, WrinkleFamily::kUnderEye, WrinkleFamily::kBunny}) {
    if (ToString(f) == name) return f;
  }
  throw Error(fmt::format("unknown wrinkle family '{}' (expected forehead, glabella, crows_feet, nasolabial, "
                          "under_eye or bunny)", name));
}

std::vector<std::string> WrinkleFamilyRegions(WrinkleFamily family) {
  switch (family) {
    case WrinkleFamily::kForehead: return {"forehead"};
    case WrinkleFamily::kGlabella: return {"glabella", "forehead"};
    case WrinkleFamily::kCrowsFeet: return {"left_eye", "right_eye", "left_cheek", "right_cheek", "forehead"};
    case WrinkleFamily::kNasolabial: return {"left_cheek", "right_cheek", "mouth", "nose"};
    case WrinkleFamily::kUnderEye: return {"left_eye", "right_eye", "left_cheek", "right_cheek"};
    case WrinkleFamily::kBunny: return {"nose", "glabella"};
  }
  return {};
}

std::vector<WrinkleLine> GenerateWrinkleLayout(const FaceAnchors& a, const WrinkleStyle& style, Rng& rng) {
  Require(style.age >= 0 && style.age <= 1, fmt::format("WrinkleStyle.age = {} must be in [0, 1]", style.age));
  Require(style.shape >= -1 && style.shape <= 1,
          fmt::format("WrinkleStyle.shape = {} must be in [-1, 1]", style.shape));
  const double age = style.age;
  const double wf = std::exp(0.5 * style.shape);    // width factor
  const double df = std::exp(-0.35 * style.shape);  // depth factor
  const double s = a.mm_per_uv;
  // Static lines appear from middle age on.
  const double static_share = style.static_lines ? SmoothStep(0.45, 1.0, age) : 0.0;
  LineBuilder lb(a, rng);
  std::vector<WrinkleLine> lines;
  auto finish = [&](WrinkleLine line, double depth, double width, double ridge, double static_max) {
    line.max_depth_mm = depth;
    line.width_mm = width;
    line.ridge = ridge;
    line.saturation = rng.Uniform(0.06, 0.14);
    line.static_depth_mm = depth * static_share * rng.Uniform(0.3, 1.0) * static_max;
    lines.push_back(std::move(line));
  };
  const Vec2 brow_top_mid = [&] {
    Vec2 m = Vec2::Zero();
    for (int k = 0; k < 2; ++k)
      for (const auto& p : a.brow[k]) m += p;
    return Vec2(m / static_cast<double>(a.brow[0].size() + a.brow[1].size()));
  }();
  const double brow_span_mm = (a.brow[0].front() - a.brow[1].front()).norm() * s;

  // Forehead lines: horizontal furrows above the brows (brow raise compresses
  // the forehead vertically, i.e. across them).
  {
    const int n = Count(rng, 1.0 + 5.0 * age, 7);
    const double spacing = rng.Uniform(6.5, 11.0);
    const double offset = rng.Uniform(11.0, 16.0);
    for (int k = 0; k < n; ++k) {
      const double h = offset + k * spacing + rng.Uniform(-1.2, 1.2);
      if (h > a.forehead_height_mm - 5.0) break;  // stay on the forehead
      const double len = brow_span_mm * rng.Uniform(0.35, 0.85) * (1.0 - 0.06 * k);
      const Vec2 c = brow_top_mid + a.up * (h / s) + a.lateral * (rng.Uniform(-0.12, 0.12) * brow_span_mm / s);
      const double waviness = rng.Uniform(0.15, 0.8), sag = rng.Uniform(-1.0, 3.5);
      WrinkleLine line = lb.Centred(WrinkleFamily::kForehead, c, a.lateral, len, sag, waviness, 2.0);
      const Draws3 d = DrawFinish(rng, {0.0, 0.25}, {0.7, 1.4}, {0.7, 1.3});
      finish(std::move(line), (0.15 + 0.55 * age) * df * d.depth, d.width * wf, d.ridge, 0.5);
    }
  }
  // Glabella frown lines: vertical lines between the inner brow ends.
  {
    const int n = Count(rng, 0.7 + 2.5 * age, 4);
    const Vec2 g = 0.5 * (a.brow[0].back() + a.brow[1].back());
    for (int k = 0; k < n; ++k) {
      const double side = (k % 2 == 0) ? -1.0 : 1.0;
      const double off = (n == 1) ? rng.Uniform(-1.5, 1.5) : side * rng.Uniform(2.5, 6.0) * (1 + 0.3 * (k / 2));
      const double tilt = side * rng.Uniform(0.0, 0.3);  // tops lean outwards
      const Vec2 dir = Rotate(a.up, -tilt * (a.lateral.dot(Perp(a.up)) > 0 ? 1 : -1));
      const double len = rng.Uniform(8.0, 15.0);
      const Vec2 c = g + a.lateral * (off / s) + a.up * ((0.35 * len - rng.Uniform(0.0, 3.0)) / s);
      const double waviness = rng.Uniform(0.1, 0.5), sag = rng.Uniform(-1.0, 1.0);
      WrinkleLine line = lb.Centred(WrinkleFamily::kGlabella, c, dir, len, sag, waviness, 0.5);
      const Draws3 d = DrawFinish(rng, {0.0, 0.3}, {0.5, 0.9}, {0.7, 1.3});
      finish(std::move(line), (0.12 + 0.45 * age) * df * d.depth, d.width * wf, d.ridge, 0.6);
    }
  }
  // Crow's feet: a fan radiating from the outer eye corners (a smile or squint
  // compresses the skin around the corner tangentially, across the rays).
  for (int side = 0; side < 2; ++side) {
    const int n = Count(rng, 0.6 + 4.0 * age, 6);
    const Vec2 out = a.Outward(side);
    const Vec2 origin = a.eye_outer[side] + out * (rng.Uniform(3.0, 6.0) / s);
    for (int k = 0; k < n; ++k) {
      const double t = n == 1 ? 0.5 : static_cast<double>(k) / (n - 1);
      const double angle = (-0.7 + 1.4 * t + rng.Uniform(-0.12, 0.12));
      const Vec2 dir = (out * std::cos(angle) + a.up * std::sin(angle)).normalized();
      const double len = rng.Uniform(7.0, 16.0);
      const Vec2 c = origin + dir * ((rng.Uniform(0.0, 3.0) + 0.5 * len) / s);
      const double waviness = rng.Uniform(0.1, 0.4), sag = rng.Uniform(-1.5, 1.5);
      WrinkleLine line = lb.Centred(WrinkleFamily::kCrowsFeet, c, dir, len, sag, waviness, 0.6);
      const Draws3 d = DrawFinish(rng, {0.0, 0.3}, {0.3, 0.6}, {0.7, 1.3});
      finish(std::move(line), (0.06 + 0.3 * age) * df * d.depth, d.width * wf, d.ridge, 0.7);
    }
  }
  // Nasolabial folds: from above the nose wing, curving outwards, past the
  // mouth corner (a smile pushes the cheek against it).
  for (int side = 0; side < 2; ++side) {
    if (rng.Uniform() > 0.3 + 0.7 * std::sqrt(age)) continue;
    const Vec2 out = a.Outward(side);
    const double rise0 = rng.Uniform(0.0, 4.0), out0 = rng.Uniform(2.5, 5.0);
    const Vec2 p0 = a.nose_wing[side] + out * (out0 / s) + a.up * (rise0 / s);
    const double drop2 = rng.Uniform(4.0, 12.0), out2 = rng.Uniform(5.0, 10.0);
    const Vec2 p2 = a.mouth_corner[side] + out * (out2 / s) - a.up * (drop2 / s);
    const Vec2 p1 = 0.5 * (p0 + p2) + out * (rng.Uniform(3.0, 7.0) / s);
    WrinkleLine line = lb.Make(WrinkleFamily::kNasolabial, p0, p1, p2, rng.Uniform(0.1, 0.5), 0.3);
    const Draws3 d = DrawFinish(rng, {0.1, 0.4}, {1.6, 2.8}, {0.8, 1.2});
    finish(std::move(line), (0.3 + 0.6 * age) * df * d.depth, d.width * wf, d.ridge, 1.0);
  }
  // Under-eye lines: arcs below the lower lid.
  for (int side = 0; side < 2; ++side) {
    const int n = Count(rng, 0.3 + 2.2 * age, 3);
    const Vec2 along = (a.eye_outer[side] - a.eye_inner[side]).normalized();
    for (int k = 0; k < n; ++k) {
      const double shift = rng.Uniform(0.0, 3.0), drop = rng.Uniform(3.0, 5.0);
      const Vec2 c = a.lower_lid[side] - a.up * ((drop + 2.5 * k) / s) + along * (shift / s);
      const Vec2 dir = along.dot(a.lateral) > 0 ? along : Vec2(-along);
      // Bow downwards in the middle, following the lid.
      const double sag = Perp(dir).dot(a.up) > 0 ? -rng.Uniform(0.5, 2.0) : rng.Uniform(0.5, 2.0);
      const double waviness = rng.Uniform(0.1, 0.3), len = rng.Uniform(8.0, 16.0);
      WrinkleLine line = lb.Centred(WrinkleFamily::kUnderEye, c, dir, len, sag, waviness, 1.0);
      const Draws3 d = DrawFinish(rng, {0.0, 0.2}, {0.3, 0.55}, {0.7, 1.3});
      finish(std::move(line), (0.04 + 0.2 * age) * df * d.depth, d.width * wf, d.ridge, 0.5);
    }
  }
  // Bunny lines: oblique lines on the sides of the nose bridge (nose wrinkler).
  for (int side = 0; side < 2; ++side) {
    const int n = Count(rng, 0.8 + 2.0 * age, 4);
    const Vec2 out = a.Outward(side);
    for (int k = 0; k < n; ++k) {
      const double t = rng.Uniform(0.15, 0.7);
      const Vec2 base = (1 - t) * a.nose_bridge_top + t * a.nose_bridge_bottom;
      const Vec2 c = base + out * (rng.Uniform(3.0, 7.0) / s);
      const double angle = rng.Uniform(0.5, 1.0);  // from horizontal, outer end lower
      const Vec2 dir = (out * std::cos(angle) - a.up * std::sin(angle)).normalized();
      const double waviness = rng.Uniform(0.05, 0.25), sag = rng.Uniform(-0.8, 0.8), len = rng.Uniform(5.0, 10.0);
      WrinkleLine line = lb.Centred(WrinkleFamily::kBunny, c, dir, len, sag, waviness, 0.3);
      const Draws3 d = DrawFinish(rng, {0.0, 0.2}, {0.35, 0.7}, {0.7, 1.3});
      finish(std::move(line), (0.06 + 0.25 * age) * df * d.depth, d.width * wf, d.ridge, 0.3);
    }
  }
  return lines;
}

double CompressionResponse(double compression, double saturation) {
  if (!(compression > 0.0)) return 0.0;
  const double x = compression / saturation;
  return 1.0 - std::exp(-x * x);
}

double WrinkleDepth(const WrinkleLine& line, double compression) {
  if (compression >= 0.0) {
    return line.static_depth_mm +
           (line.max_depth_mm - line.static_depth_mm) * CompressionResponse(compression, line.saturation);
  }
  // Stretched across the line: static lines flatten (up to half their depth).
  return line.static_depth_mm * (1.0 - 0.5 * CompressionResponse(-compression, line.saturation));
}

// ---------------------------------------------------------------------------

void WrinkleStrainOptions::VisitFields(OptionVisitor& v) {
  v.Field("resolution", resolution);
  v.Field("smoothing_mm", smoothing_mm);
}

void WrinkleStrainOptions::Check() const {
  CheckGe("WrinkleStrainOptions", "resolution", resolution, 8);
  CheckLe("WrinkleStrainOptions", "resolution", resolution, 4096);
  CheckGe("WrinkleStrainOptions", "smoothing_mm", smoothing_mm, 0.0);
}

StrainField::StrainField(const FaceRig& rig, const WrinkleStrainOptions& options) : options_(options) {
  options_.Check();
  F_ = FaceChartTriangles(rig);
  UV_ = rig.neutral.UV;
  num_vertices_ = rig.num_vertices();
  uv_inverse_.resize(F_.rows());
  uv_area_.resize(F_.rows());
  for (int f = 0; f < F_.rows(); ++f) {
    Eigen::Matrix2d T;
    T.col(0) = (UV_.row(F_(f, 1)) - UV_.row(F_(f, 0))).transpose();
    T.col(1) = (UV_.row(F_(f, 2)) - UV_.row(F_(f, 0))).transpose();
    const double det = T.determinant();
    uv_area_[f] = 0.5 * std::abs(det);
    uv_inverse_[f] = std::abs(det) > 1e-14 ? Eigen::Matrix2d(T.inverse()) : Eigen::Matrix2d::Zero();
  }
  TriMesh chart;
  chart.V = rig.neutral.V;
  chart.UV = rig.neutral.UV;
  chart.F = F_;
  raster_ = RasterizeUv(chart, options_.resolution, options_.resolution, "StrainField rig");
  cv::Mat cov(options_.resolution, options_.resolution, CV_32F);
  for (int j = 0; j < options_.resolution; ++j)
    for (int i = 0; i < options_.resolution; ++i) cov.at<float>(j, i) = raster_.covered(i, j) ? 1.0f : 0.0f;
  if (options_.smoothing_mm > 0) {
    const double mm_per_texel = MmPerUv(rig) / options_.resolution;
    sigma_texels_ = options_.smoothing_mm / mm_per_texel;
    cv::GaussianBlur(cov, cov, cv::Size(0, 0), sigma_texels_, sigma_texels_, cv::BORDER_REPLICATE);
  }
  coverage_blur_ = cov;
}

cv::Mat StrainField::MetricMap(const MatX3d& V) const {
  Require(V.rows() == num_vertices_,
          fmt::format("StrainField: {} positions for a rig of {} vertices", V.rows(), num_vertices_));
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(num_vertices_, 3);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(num_vertices_);
  for (int f = 0; f < F_.rows(); ++f) {
    Eigen::Matrix<double, 3, 2> E;
    E.col(0) = (V.row(F_(f, 1)) - V.row(F_(f, 0))).transpose();
    E.col(1) = (V.row(F_(f, 2)) - V.row(F_(f, 0))).transpose();
    const Eigen::Matrix<double, 3, 2> J = E * uv_inverse_[f];
    const Eigen::Matrix2d M = J.transpose() * J;
    const double a = uv_area_[f];
    for (int k = 0; k < 3; ++k) {
      const int v = F_(f, k);
      C(v, 0) += a * M(0, 0);
      C(v, 1) += a * M(0, 1);
      C(v, 2) += a * M(1, 1);
      w[v] += a;
    }
  }
  for (int v = 0; v < num_vertices_; ++v)
    if (w[v] > 0) C.row(v) /= w[v];
  const int R = options_.resolution;
  cv::Mat map(R, R, CV_32FC3, cv::Scalar::all(0));
  for (int j = 0; j < R; ++j) {
    cv::Vec3f* row = map.ptr<cv::Vec3f>(j);
    for (int i = 0; i < R; ++i) {
      const int idx = raster_.index(i, j);
      const int t = raster_.triangle[idx];
      if (t < 0) continue;
      const Eigen::Vector3f& b = raster_.barycentric[idx];
      for (int c = 0; c < 3; ++c) {
        row[i][c] = static_cast<float>(b[0] * C(F_(t, 0), c) + b[1] * C(F_(t, 1), c) + b[2] * C(F_(t, 2), c));
      }
    }
  }
  if (options_.smoothing_mm > 0) {
    cv::GaussianBlur(map, map, cv::Size(0, 0), sigma_texels_, sigma_texels_, cv::BORDER_REPLICATE);
    for (int j = 0; j < R; ++j) {
      cv::Vec3f* row = map.ptr<cv::Vec3f>(j);
      const float* cov = coverage_blur_.ptr<float>(j);
      for (int i = 0; i < R; ++i) row[i] = cov[i] > 1e-3f ? row[i] / cov[i] : cv::Vec3f(0, 0, 0);
    }
  }
  return map;
}

Eigen::Vector3d SampleMetric(const cv::Mat& metric, double u, double v) {
  const int R = metric.cols, H = metric.rows;
  const double x = std::clamp(u * R - 0.5, 0.0, R - 1.0), y = std::clamp(v * H - 0.5, 0.0, H - 1.0);
  const int x0 = std::min(static_cast<int>(x), R - 2 < 0 ? 0 : R - 2);
  const int y0 = std::min(static_cast<int>(y), H - 2 < 0 ? 0 : H - 2);
  const int x1 = std::min(x0 + 1, R - 1), y1 = std::min(y0 + 1, H - 1);
  const double fx = x - x0, fy = y - y0;
  const cv::Vec3f a = metric.at<cv::Vec3f>(y0, x0), b = metric.at<cv::Vec3f>(y0, x1);
  const cv::Vec3f c = metric.at<cv::Vec3f>(y1, x0), d = metric.at<cv::Vec3f>(y1, x1);
  Eigen::Vector3d out;
  for (int k = 0; k < 3; ++k) {
    out[k] = (1 - fy) * ((1 - fx) * a[k] + fx * b[k]) + fy * ((1 - fx) * c[k] + fx * d[k]);
  }
  return out;
}

// ---------------------------------------------------------------------------

WrinkleField::WrinkleField(std::vector<WrinkleLine> lines, int resolution, double mm_per_uv,
                           const std::vector<cv::Mat>& region_weights, const cv::Mat& neutral_metric)
    : lines_(std::move(lines)), resolution_(resolution) {
  Require(resolution >= 8, fmt::format("WrinkleField: resolution {} must be ≥ 8", resolution));
  Require(mm_per_uv > 0, "WrinkleField: mm_per_uv must be positive");
  const int R = resolution;
  std::vector<std::vector<WrinkleSample>> per_line(lines_.size());
  tbb::parallel_for(size_t{0}, lines_.size(), [&](size_t li) {
    const WrinkleLine& line = lines_[li];
    const int n = static_cast<int>(line.points.size());
    Require(n >= 2 && line.strength.size() == line.points.size(),
            fmt::format("wrinkle line {}: needs ≥ 2 points and one strength per point", li));
    const int fam = static_cast<int>(line.family);
    const cv::Mat* weight = fam < static_cast<int>(region_weights.size()) ? &region_weights[fam] : nullptr;
    // Vertex tangents (UV, unit) for a smooth across-direction.
    std::vector<Vec2> tan(n);
    for (int k = 0; k < n; ++k) {
      const Vec2 d = line.points[std::min(k + 1, n - 1)] - line.points[std::max(k - 1, 0)];
      tan[k] = d.norm() > 0 ? Vec2(d.normalized()) : Vec2(1, 0);
    }
    const double w = line.width_mm;
    const double reach_mm = 5.0 * w + (line.ridge > 0 ? 2.0 * w : 0.0);
    const double reach = reach_mm / mm_per_uv;
    Vec2 lo = line.points[0], hi = line.points[0];
    for (const auto& p : line.points) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const int i0 = std::max(0, static_cast<int>(std::floor((lo.x() - reach) * R)));
    const int i1 = std::min(R - 1, static_cast<int>(std::ceil((hi.x() + reach) * R)));
    const int j0 = std::max(0, static_cast<int>(std::floor((lo.y() - reach) * R)));
    const int j1 = std::min(R - 1, static_cast<int>(std::ceil((hi.y() + reach) * R)));
    auto& out = per_line[li];
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const Vec2 x((i + 0.5) / R, (j + 0.5) / R);
        double best = 1e30, best_t = 0;
        int best_k = 0;
        for (int k = 0; k + 1 < n; ++k) {
          const Vec2 a = line.points[k], e = line.points[k + 1] - a;
          const double ee = e.squaredNorm();
          const double t = ee > 0 ? std::clamp((x - a).dot(e) / ee, 0.0, 1.0) : 0.0;
          const double d2 = (a + t * e - x).squaredNorm();
          if (d2 < best) {
            best = d2;
            best_t = t;
            best_k = k;
          }
        }
        const double d = std::sqrt(best) * mm_per_uv;
        if (d > reach_mm) continue;
        const double strength = (1 - best_t) * line.strength[best_k] + best_t * line.strength[best_k + 1];
        const double region = weight != nullptr ? weight->at<float>(j, i) : 1.0;
        const double sech_c = 1.0 / std::cosh(d / w);
        const double sech_r = 1.0 / std::cosh((d - 2.2 * w) / (0.8 * w));
        const double profile = -sech_c * sech_c + line.ridge * sech_r * sech_r;
        const double value = profile * strength * region;
        if (std::abs(value) < 1e-5) continue;
        const Vec2 t = ((1 - best_t) * tan[best_k] + best_t * tan[best_k + 1]).normalized();
        const Vec2 nrm = Perp(t);
        const Eigen::Vector3d C0 = SampleMetric(neutral_metric, x.x(), x.y());
        WrinkleSample s;
        s.texel = j * R + i;
        s.line = static_cast<int>(li);
        s.value = static_cast<float>(value);
        s.nu = static_cast<float>(nrm.x());
        s.nv = static_cast<float>(nrm.y());
        s.neutral_metric = static_cast<float>(nrm.x() * nrm.x() * C0[0] + 2 * nrm.x() * nrm.y() * C0[1] +
                                              nrm.y() * nrm.y() * C0[2]);
        out.push_back(s);
      }
    }
  });
  size_t total = 0;
  for (const auto& v : per_line) total += v.size();
  samples_.reserve(total);
  for (auto& v : per_line) samples_.insert(samples_.end(), v.begin(), v.end());
}

double WrinkleField::Compression(const cv::Mat& current_metric, const WrinkleSample& s) const {
  if (!(s.neutral_metric > 0.0f)) return 0.0;
  const int R = resolution_;
  const double u = ((s.texel % R) + 0.5) / R, v = ((s.texel / R) + 0.5) / R;
  const Eigen::Vector3d C1 = SampleMetric(current_metric, u, v);
  const double m1 = s.nu * s.nu * C1[0] + 2.0 * s.nu * s.nv * C1[1] + s.nv * s.nv * C1[2];
  return 1.0 - std::sqrt(std::max(m1, 0.0) / s.neutral_metric);
}

cv::Mat WrinkleField::Displacement(const cv::Mat& current_metric) const {
  std::vector<float> contribution(samples_.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples_.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t k = r.begin(); k < r.end(); ++k) {
      const WrinkleSample& s = samples_[k];
      contribution[k] = static_cast<float>(WrinkleDepth(lines_[s.line], Compression(current_metric, s)) * s.value);
    }
  });
  cv::Mat D(resolution_, resolution_, CV_32F, cv::Scalar(0));
  float* d = D.ptr<float>();
  for (size_t k = 0; k < samples_.size(); ++k) d[samples_[k].texel] += contribution[k];
  return D;
}

double WrinkleField::CompressionAt(const cv::Mat& current_metric, int line, int i, int j) const {
  const int texel = j * resolution_ + i;
  for (const auto& s : samples_) {
    if (s.line == line && s.texel == texel) return Compression(current_metric, s);
  }
  return std::nan("");
}

}  // namespace crease
