#include "synth/lights.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/error.h"

namespace crease {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

// Polar angle from +y, well conditioned near the poles (unlike acos).
double PolarAngle(const Eigen::Vector3f& d) {
  const double x = d.x(), y = d.y(), z = d.z();
  return std::atan2(std::sqrt(x * x + z * z), y);
}

double Luminance(const cv::Vec3f& c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

// Direction of pixel centre-relative coordinates (u, v) in [0, 1)² of a lat-long map.
Eigen::Vector3d LatLongDirection(double u, double v) {
  const double theta = kPi * v, phi = 2.0 * kPi * (u - 0.5);
  return {std::sin(theta) * std::sin(phi), std::cos(theta), std::sin(theta) * std::cos(phi)};
}

std::string JoinNames(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// Smooth step from 1 (inside) to 0 across an edge of width `soft` at `edge`.
double SoftInside(double x, double edge, double soft) {
  const double t = std::clamp((edge - x) / soft + 0.5, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// A soft round "box" light of angular radius `radius_deg` around (az, el): 1 inside.
double SoftDisc(const Eigen::Vector3d& d, double az, double el, double radius_deg) {
  const Eigen::Vector3d c(std::cos(el * kDeg) * std::sin(az * kDeg), std::sin(el * kDeg),
                          std::cos(el * kDeg) * std::cos(az * kDeg));
  const double angle = std::acos(std::clamp(d.dot(c), -1.0, 1.0)) / kDeg;
  return SoftInside(angle, radius_deg, 0.3 * radius_deg);
}

Eigen::Vector3d ProceduralRadiance(const std::string& preset, const Eigen::Vector3d& d) {
  const double el = std::asin(std::clamp(d.y(), -1.0, 1.0)) / kDeg;
  const double az = std::atan2(d.x(), d.z()) / kDeg;
  if (preset == "studio") {
    Eigen::Vector3d L(0.02, 0.02, 0.022);                                          // dim room
    if (el < 0) L = Eigen::Vector3d(0.035, 0.03, 0.027);                           // floor bounce
    L += Eigen::Vector3d(1.0, 0.97, 0.92) * 6.0 * SoftDisc(d, -40.0, 30.0, 22.0);  // key softbox
    L += Eigen::Vector3d(0.9, 0.95, 1.0) * 1.6 * SoftDisc(d, 50.0, 5.0, 28.0);     // fill
    L += Eigen::Vector3d(1.0, 1.0, 1.0) * 9.0 * SoftDisc(d, 160.0, 30.0, 10.0);    // rim
    return L;
  }
  if (preset == "overcast") {
    if (el >= 0) return Eigen::Vector3d(0.95, 0.98, 1.05) * (1.0 + 2.0 * d.y()) / 3.0;  // CIE overcast sky
    return Eigen::Vector3d(0.10, 0.095, 0.085);                                        // grey ground
  }
  // "window": a 40° × 45° window facing the subject's left-front, with mullions.
  Eigen::Vector3d L(0.015, 0.014, 0.013);
  if (el < 0) L = Eigen::Vector3d(0.03, 0.025, 0.02);
  const double wa = az + 55.0, we = el - 12.0;  // window-centred angles
  const double inside = SoftInside(std::abs(wa), 20.0, 1.5) * SoftInside(std::abs(we), 22.5, 1.5);
  const double mullion = (std::abs(wa) < 0.8 || std::abs(we) < 0.8) ? 0.1 : 1.0;
  const Eigen::Vector3d sky = Eigen::Vector3d(0.85, 0.92, 1.05) * (2.0 + 2.5 * std::max(0.0, we / 22.5));
  return L + sky * inside * mullion;
}

}  // namespace

// ---- EnvironmentMap -------------------------------------------------------------

EnvironmentMap::EnvironmentMap(const cv::Mat& latlong, const std::string& what) {
  Require(!latlong.empty() && latlong.depth() == CV_32F &&
              (latlong.channels() == 1 || latlong.channels() == 3 || latlong.channels() == 4),
          fmt::format("{}: environment map must be a non-empty CV_32F image with 1, 3 or 4 channels", what));
  Require(latlong.cols >= 2 && latlong.rows >= 1,
          fmt::format("{}: environment map must be at least 2×1 pixels, got {}×{}", what, latlong.cols, latlong.rows));
  width_ = latlong.cols;
  height_ = latlong.rows;
  image_.create(height_, width_, CV_32FC3);
  const int ch = latlong.channels();
  for (int y = 0; y < height_; ++y) {
    const float* src = latlong.ptr<float>(y);
    for (int x = 0; x < width_; ++x) {
      cv::Vec3f c;
      for (int k = 0; k < 3; ++k) c[k] = src[x * ch + (ch == 1 ? 0 : k)];
      for (int k = 0; k < 3; ++k) {
        Require(std::isfinite(c[k]) && c[k] >= 0.0f,
                fmt::format("{}: environment map pixel ({}, {}) channel {} = {} must be finite and >= 0", what, x,
                            y, k, c[k]));
      }
      image_.at<cv::Vec3f>(y, x) = c;
    }
  }
  // Pixel weights luminance·sin θ; marginal over rows, conditional within each row.
  std::vector<double> w(static_cast<size_t>(width_) * height_);
  row_cdf_.assign(static_cast<size_t>(height_) + 1, 0.0);
  col_cdf_.assign(static_cast<size_t>(height_) * (width_ + 1), 0.0);
  double total = 0.0;
  for (int y = 0; y < height_; ++y) {
    const double s = std::sin(kPi * (y + 0.5) / height_);
    double row = 0.0;
    for (int x = 0; x < width_; ++x) {
      const double wi = Luminance(image_.at<cv::Vec3f>(y, x)) * s;
      w[static_cast<size_t>(y) * width_ + x] = wi;
      row += wi;
      col_cdf_[static_cast<size_t>(y) * (width_ + 1) + x + 1] = row;
    }
    total += row;
    row_cdf_[static_cast<size_t>(y) + 1] = total;
  }
  Require(total > 0.0, fmt::format("{}: environment map has no light (all luminance is zero)", what));
  pixel_pdf_.resize(w.size());
  for (size_t i = 0; i < w.size(); ++i) pixel_pdf_[i] = static_cast<float>(w[i] / total);
}

Eigen::Vector3f EnvironmentMap::Radiance(const Eigen::Vector3f& dir) const {
  const double theta = PolarAngle(dir);
  const double phi = std::atan2(static_cast<double>(dir.x()), static_cast<double>(dir.z()));
  const int x = std::clamp(static_cast<int>((phi / (2.0 * kPi) + 0.5) * width_), 0, width_ - 1);
  const int y = std::clamp(static_cast<int>(theta / kPi * height_), 0, height_ - 1);
  const cv::Vec3f& c = image_.at<cv::Vec3f>(y, x);
  return {c[0], c[1], c[2]};
}

Eigen::Vector3f EnvironmentMap::Sample(double u1, double u2, float* pdf) const {
  // Row: invert the marginal CDF; the remainder of u1 places the point inside the row.
  const double total = row_cdf_.back();
  const double target_row = u1 * total;
  int y = static_cast<int>(std::upper_bound(row_cdf_.begin(), row_cdf_.end(), target_row) - row_cdf_.begin()) - 1;
  y = std::clamp(y, 0, height_ - 1);
  while (y > 0 && row_cdf_[static_cast<size_t>(y) + 1] - row_cdf_[static_cast<size_t>(y)] <= 0.0) --y;
  while (row_cdf_[static_cast<size_t>(y) + 1] - row_cdf_[static_cast<size_t>(y)] <= 0.0 && y < height_ - 1) ++y;
  const double row_mass = row_cdf_[static_cast<size_t>(y) + 1] - row_cdf_[static_cast<size_t>(y)];
  const double fy = std::clamp((target_row - row_cdf_[static_cast<size_t>(y)]) / row_mass, 0.0, 1.0 - 1e-12);
  const double* cdf = &col_cdf_[static_cast<size_t>(y) * (width_ + 1)];
  const double target_col = u2 * cdf[width_];
  int x = static_cast<int>(std::upper_bound(cdf, cdf + width_ + 1, target_col) - cdf) - 1;
  x = std::clamp(x, 0, width_ - 1);
  while (cdf[x + 1] - cdf[x] <= 0.0 && x < width_ - 1) ++x;
  while (cdf[x + 1] - cdf[x] <= 0.0 && x > 0) --x;
  const double fx = std::clamp((target_col - cdf[x]) / std::max(cdf[x + 1] - cdf[x], 1e-300), 0.0, 1.0 - 1e-12);
  const double u = (x + fx) / width_, v = (y + fy) / height_;
  const Eigen::Vector3d d = LatLongDirection(u, v);
  const double s = std::max(std::sin(kPi * v), 1e-6);
  *pdf = static_cast<float>(pixel_pdf_[static_cast<size_t>(y) * width_ + x] * width_ * height_ /
                            (2.0 * kPi * kPi * s));
  return d.cast<float>();
}

float EnvironmentMap::Pdf(const Eigen::Vector3f& dir) const {
  const double theta = PolarAngle(dir);
  const double phi = std::atan2(static_cast<double>(dir.x()), static_cast<double>(dir.z()));
  const int x = std::clamp(static_cast<int>((phi / (2.0 * kPi) + 0.5) * width_), 0, width_ - 1);
  const int y = std::clamp(static_cast<int>(theta / kPi * height_), 0, height_ - 1);
  const double s = std::max(std::sin(theta), 1e-6);
  return static_cast<float>(pixel_pdf_[static_cast<size_t>(y) * width_ + x] * width_ * height_ /
                            (2.0 * kPi * kPi * s));
}

Eigen::Vector3d EnvironmentMap::LambertValue(const Eigen::Vector3d& n) const {
  // Supersample each pixel 4×4 so that the cosine is integrated accurately.
  constexpr int kSub = 4;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int y = 0; y < height_; ++y) {
    for (int sy = 0; sy < kSub; ++sy) {
      const double v = (y + (sy + 0.5) / kSub) / height_;
      const double d_omega = (2.0 * kPi / (width_ * kSub)) * (kPi / (height_ * kSub)) * std::sin(kPi * v);
      for (int x = 0; x < width_; ++x) {
        const cv::Vec3f& c = image_.at<cv::Vec3f>(y, x);
        double cos_sum = 0.0;
        for (int sx = 0; sx < kSub; ++sx) {
          cos_sum += std::max(0.0, n.dot(LatLongDirection((x + (sx + 0.5) / kSub) / width_, v)));
        }
        sum += Eigen::Vector3d(c[0], c[1], c[2]) * cos_sum * d_omega;
      }
    }
  }
  return sum / kPi;
}

std::shared_ptr<const EnvironmentMap> ProceduralEnvironment(const std::string& preset, int width) {
  const auto names = ProceduralEnvironmentNames();
  Require(std::find(names.begin(), names.end(), preset) != names.end(),
          fmt::format("ProceduralEnvironment: unknown preset '{}' (known: {})", preset, JoinNames(names)));
  Require(width >= 8 && width % 2 == 0,
          fmt::format("ProceduralEnvironment: width = {} must be even and >= 8", width));
  const int height = width / 2;
  cv::Mat img(height, width, CV_32FC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector3d L = ProceduralRadiance(preset, LatLongDirection((x + 0.5) / width, (y + 0.5) / height));
      img.at<cv::Vec3f>(y, x) = cv::Vec3f(static_cast<float>(L.x()), static_cast<float>(L.y()), static_cast<float>(L.z()));
    }
  }
  // Scale: a white Lambertian surface facing front renders at 0.8 (luminance).
  const EnvironmentMap raw(img, "ProceduralEnvironment(" + preset + ")");
  const Eigen::Vector3d front = raw.LambertValue(Eigen::Vector3d::UnitZ());
  const double lum = 0.2126 * front.x() + 0.7152 * front.y() + 0.0722 * front.z();
  img.convertTo(img, -1, 0.8 / lum);
  return std::make_shared<const EnvironmentMap>(img, "ProceduralEnvironment(" + preset + ")");
}

std::vector<std::string> ProceduralEnvironmentNames() { return {"studio", "overcast", "window"}; }

// ---- Rigs -------------------------------------------------------------------------

void ValidateLightRig(const LightRig& rig) {
  auto color_ok = [](const Eigen::Vector3d& c) { return c.allFinite() && c.minCoeff() >= 0.0; };
  for (size_t i = 0; i < rig.lights.size(); ++i) {
    const std::string where = fmt::format("light rig '{}', light {}", rig.name, i);
    const Light& light = rig.lights[i];
    if (const auto* d = std::get_if<DirectionalLight>(&light)) {
      Require(d->direction.allFinite() && d->direction.norm() > 0,
              where + " (directional): direction must be finite and non-zero");
      Require(color_ok(d->color), where + " (directional): color must be finite and >= 0");
    } else if (const auto* s = std::get_if<SphereLight>(&light)) {
      Require(s->centre.allFinite() && std::isfinite(s->radius) && s->radius > 0,
              where + " (sphere): centre must be finite and radius > 0");
      Require(s->centre.norm() > s->radius, where + " (sphere): the rig origin must lie outside the light");
      Require(color_ok(s->color), where + " (sphere): color must be finite and >= 0");
      Require(s->samples >= 1, fmt::format("{} (sphere): samples = {} must be >= 1", where, s->samples));
    } else if (const auto* e = std::get_if<EnvironmentLight>(&light)) {
      Require(e->map != nullptr, where + " (environment): no map");
      Require(std::isfinite(e->scale) && e->scale >= 0 && std::isfinite(e->rotation_deg),
              where + " (environment): scale must be finite and >= 0, rotation_deg finite");
      Require(e->samples >= 1, fmt::format("{} (environment): samples = {} must be >= 1", where, e->samples));
    } else if (const auto* a = std::get_if<AmbientOcclusionLight>(&light)) {
      Require(color_ok(a->color), where + " (ambient occlusion): color must be finite and >= 0");
      Require(std::isfinite(a->max_distance_mm) && a->max_distance_mm > 0,
              where + " (ambient occlusion): max_distance_mm must be > 0");
      Require(a->samples >= 1, fmt::format("{} (ambient occlusion): samples = {} must be >= 1", where, a->samples));
    }
  }
}

Eigen::Vector3d RigDirection(double azimuth_deg, double elevation_deg, bool attached_to_camera) {
  const Eigen::Vector3d up = attached_to_camera ? Eigen::Vector3d(0, -1, 0) : Eigen::Vector3d(0, 1, 0);
  const Eigen::Vector3d front = attached_to_camera ? Eigen::Vector3d(0, 0, -1) : Eigen::Vector3d(0, 0, 1);
  const Eigen::Vector3d right = up.cross(front);
  const double az = azimuth_deg * kDeg, el = elevation_deg * kDeg;
  return (std::cos(el) * (std::cos(az) * front + std::sin(az) * right) + std::sin(el) * up).normalized();
}

DirectionalLight DirectionalFromAzimuthElevation(double azimuth_deg, double elevation_deg, double intensity,
                                                 bool attached_to_camera) {
  DirectionalLight d;
  d.direction = RigDirection(azimuth_deg, elevation_deg, attached_to_camera);
  d.color = Eigen::Vector3d::Constant(intensity);
  return d;
}

LightRig DirectionalRig(double azimuth_deg, double elevation_deg, double intensity) {
  Require(std::isfinite(azimuth_deg) && std::isfinite(elevation_deg) && std::isfinite(intensity) && intensity >= 0,
          fmt::format("DirectionalRig: azimuth {}, elevation {} and intensity {} must be finite, intensity >= 0",
                      azimuth_deg, elevation_deg, intensity));
  LightRig rig;
  rig.name = "moving-light";
  AmbientOcclusionLight ambient;
  ambient.color = Eigen::Vector3d::Constant(0.05);
  rig.lights = {DirectionalFromAzimuthElevation(azimuth_deg, elevation_deg, intensity), ambient};
  return rig;
}

LightRig MakeLightRig(const std::string& preset) {
  LightRig rig;
  rig.name = preset;
  auto ambient = [](double value) {
    AmbientOcclusionLight a;
    a.color = Eigen::Vector3d::Constant(value);
    return a;
  };
  auto sphere = [](double az, double el, double distance, double radius, const Eigen::Vector3d& color) {
    SphereLight s;
    s.centre = distance * RigDirection(az, el);
    s.radius = radius;
    s.color = color;
    return s;
  };
  if (preset == "front") {
    rig.lights = {DirectionalFromAzimuthElevation(0.0, 5.0, 0.85), ambient(0.08)};
  } else if (preset == "raking-above") {
    rig.lights = {DirectionalFromAzimuthElevation(0.0, 78.0, 1.0), ambient(0.05)};
  } else if (preset == "raking-side") {
    rig.lights = {DirectionalFromAzimuthElevation(80.0, 5.0, 1.0), ambient(0.05)};
  } else if (preset == "studio") {
    // Key : fill ≈ 6 : 1 (a classic portrait ratio), a cool rim from behind-right.
    DirectionalLight rim = DirectionalFromAzimuthElevation(155.0, 35.0, 0.5);
    rim.color = Eigen::Vector3d(0.48, 0.5, 0.55);
    rig.lights = {sphere(-40.0, 30.0, 1500.0, 300.0, Eigen::Vector3d(0.90, 0.87, 0.82)),
                  sphere(50.0, 5.0, 1500.0, 400.0, Eigen::Vector3d(0.14, 0.15, 0.16)), rim, ambient(0.04)};
  } else if (preset == "ceiling") {
    // A room's ceiling light in front of and above the face (a large, soft source at
    // 55° elevation: horizontal creases facing up catch it, those facing down shade),
    // the glow of a screen from the front as fill, weak ambient.
    rig.lights = {sphere(-15.0, 55.0, 1500.0, 450.0, Eigen::Vector3d(0.95, 0.92, 0.88)),
                  sphere(5.0, -5.0, 1500.0, 400.0, Eigen::Vector3d(0.16, 0.17, 0.19)), ambient(0.06)};
  } else if (preset == "studio-env" || preset == "overcast" || preset == "window") {
    EnvironmentLight e;
    e.map = ProceduralEnvironment(preset == "studio-env" ? "studio" : preset);
    rig.lights = {e};
  } else {
    throw Error(fmt::format("MakeLightRig: unknown light rig '{}' (known: {})", preset, JoinNames(LightRigNames())));
  }
  return rig;
}

std::vector<std::string> LightRigNames() {
  return {"front", "raking-above", "raking-side", "studio", "ceiling", "studio-env", "overcast", "window"};
}

}  // namespace crease
