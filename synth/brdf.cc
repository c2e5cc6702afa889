#include "synth/brdf.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "core/error.h"

namespace crease {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;
constexpr float kMinRoughness = 0.02f;
constexpr int kTableMu = 32;         // cos θ_v samples (μ_i = (i + 0.5) / 32)
constexpr int kTableRoughness = 32;  // r_j = 0.02 + 0.98 j / 31
constexpr int kTableSamples = 2048;  // Hammersley points per entry

float RadicalInverse2(uint32_t bits) {
  bits = (bits << 16u) | (bits >> 16u);
  bits = ((bits & 0x55555555u) << 1u) | ((bits & 0xAAAAAAAAu) >> 1u);
  bits = ((bits & 0x33333333u) << 2u) | ((bits & 0xCCCCCCCCu) >> 2u);
  bits = ((bits & 0x0F0F0F0Fu) << 4u) | ((bits & 0xF0F0F0F0u) >> 4u);
  bits = ((bits & 0x00FF00FFu) << 8u) | ((bits & 0xFF00FF00u) >> 8u);
  return static_cast<float>(static_cast<double>(bits) * 0x1.0p-32);
}

// Split-sum tables: E_s(μ, r, F0) = F0·A(μ, r) + B(μ, r), integrated with GGX
// importance sampling of the half vector (deterministic Hammersley points).
struct SpecularTables {
  std::array<float, kTableMu * kTableRoughness> a{}, b{};

  SpecularTables() {
    for (int j = 0; j < kTableRoughness; ++j) {
      const float r = kMinRoughness + (1.0f - kMinRoughness) * static_cast<float>(j) / (kTableRoughness - 1);
      const float alpha = r * r;
      for (int i = 0; i < kTableMu; ++i) {
        const double mu = (i + 0.5) / kTableMu;
        const Eigen::Vector3d v(std::sqrt(1.0 - mu * mu), 0.0, mu);
        double sa = 0.0, sb = 0.0;
        for (int s = 0; s < kTableSamples; ++s) {
          const double xi1 = (s + 0.5) / kTableSamples, xi2 = RadicalInverse2(static_cast<uint32_t>(s));
          const double a2 = static_cast<double>(alpha) * alpha;
          const double cos2 = (1.0 - xi1) / (1.0 + (a2 - 1.0) * xi1);
          const double ch = std::sqrt(cos2), sh = std::sqrt(std::max(0.0, 1.0 - cos2));
          const double phi = 2.0 * std::numbers::pi * xi2;
          const Eigen::Vector3d h(sh * std::cos(phi), sh * std::sin(phi), ch);
          const double vh = v.dot(h);
          const Eigen::Vector3d l = 2.0 * vh * h - v;
          if (l.z() <= 0.0 || vh <= 0.0) continue;
          const double g = SmithG1(static_cast<float>(l.z()), alpha) * SmithG1(static_cast<float>(mu), alpha);
          const double w = g * vh / (ch * mu);
          const double m1 = 1.0 - vh, fc = m1 * m1 * m1 * m1 * m1;
          sa += w * (1.0 - fc);
          sb += w * fc;
        }
        a[static_cast<size_t>(j * kTableMu + i)] = static_cast<float>(sa / kTableSamples);
        b[static_cast<size_t>(j * kTableMu + i)] = static_cast<float>(sb / kTableSamples);
      }
    }
  }
};

const SpecularTables& Tables() {
  static const SpecularTables tables;
  return tables;
}

}  // namespace

Material MaterialPreset(const std::string& name) {
  Material m;
  auto set = [&](Eigen::Vector3f albedo, float specular, float roughness, bool textured) {
    m.albedo = albedo;
    m.specular = specular;
    m.roughness = roughness;
    m.textured = textured;
  };
  if (name == "skin") {
    set({0.60f, 0.42f, 0.34f}, 0.5f, 0.45f, true);
  } else if (name == "lips") {
    set({0.55f, 0.25f, 0.24f}, 0.6f, 0.35f, true);
  } else if (name == "sclera") {
    set({0.80f, 0.76f, 0.72f}, 1.0f, 0.08f, false);
  } else if (name == "iris") {
    set({0.18f, 0.12f, 0.07f}, 1.0f, 0.08f, false);
  } else if (name == "pupil") {
    set({0.01f, 0.01f, 0.01f}, 1.0f, 0.08f, false);
  } else if (name == "cavity") {
    set({0.08f, 0.02f, 0.02f}, 0.2f, 0.5f, false);
  } else if (name == "teeth") {
    set({0.75f, 0.72f, 0.62f}, 0.6f, 0.3f, false);
  } else if (name == "hair") {
    set({0.05f, 0.035f, 0.025f}, 0.3f, 0.55f, false);
  } else if (name == "white-lambert") {
    set({1.0f, 1.0f, 1.0f}, 0.0f, 1.0f, false);
  } else if (name == "grey") {
    set({0.5f, 0.5f, 0.5f}, 0.0f, 1.0f, false);
  } else {
    std::string known;
    for (const auto& n : MaterialPresetNames()) known += (known.empty() ? "" : ", ") + n;
    throw Error(fmt::format("MaterialPreset: unknown material '{}' (known: {})", name, known));
  }
  return m;
}

std::vector<std::string> MaterialPresetNames() {
  return {"skin", "lips", "sclera", "iris", "pupil", "cavity", "teeth", "hair", "white-lambert", "grey"};
}

float GgxD(float cos_h, float alpha) {
  if (cos_h <= 0.0f) return 0.0f;
  const float a2 = alpha * alpha;
  const float d = cos_h * cos_h * (a2 - 1.0f) + 1.0f;
  return a2 / (kPi * d * d);
}

float SmithG1(float cos, float alpha) {
  if (cos <= 0.0f) return 0.0f;
  const float a2 = alpha * alpha;
  return 2.0f * cos / (cos + std::sqrt(a2 + (1.0f - a2) * cos * cos));
}

float SchlickFresnel(float cos, float f0) {
  const float m = std::clamp(1.0f - cos, 0.0f, 1.0f);
  const float m2 = m * m;
  return f0 + (1.0f - f0) * m2 * m2 * m;
}

float SpecularAlbedo(float cos_v, float roughness, float f0) {
  const SpecularTables& t = Tables();
  const float x = std::clamp(cos_v * kTableMu - 0.5f, 0.0f, static_cast<float>(kTableMu - 1));
  const float y = std::clamp((roughness - kMinRoughness) / (1.0f - kMinRoughness) * (kTableRoughness - 1), 0.0f,
                             static_cast<float>(kTableRoughness - 1));
  const int x0 = std::min(static_cast<int>(x), kTableMu - 2), y0 = std::min(static_cast<int>(y), kTableRoughness - 2);
  const float fx = x - x0, fy = y - y0;
  auto at = [&](const std::array<float, kTableMu * kTableRoughness>& a, int i, int j) {
    return a[static_cast<size_t>(j * kTableMu + i)];
  };
  auto lerp2 = [&](const std::array<float, kTableMu * kTableRoughness>& a) {
    return (1 - fy) * ((1 - fx) * at(a, x0, y0) + fx * at(a, x0 + 1, y0)) +
           fy * ((1 - fx) * at(a, x0, y0 + 1) + fx * at(a, x0 + 1, y0 + 1));
  };
  return std::clamp(f0 * lerp2(t.a) + lerp2(t.b), 0.0f, 1.0f);
}

PreparedBrdf::PreparedBrdf(const Material& m, const Eigen::Vector3f& n, const Eigen::Vector3f& v)
    : n_(n), v_(v), albedo_(m.albedo) {
  cos_v_ = std::max(n.dot(v), 1e-4f);
  const float r = std::clamp(m.roughness, kMinRoughness, 1.0f);
  alpha_ = r * r;
  specular_ = m.specular;
  f0_ = m.f0;
  g1_v_ = SmithG1(cos_v_, alpha_);
  const float es = specular_ > 0.0f ? specular_ * SpecularAlbedo(cos_v_, r, f0_) : 0.0f;
  kd_ = (1.0f - std::min(es, 1.0f)) / kPi;
}

float PreparedBrdf::Specular(const Eigen::Vector3f& l) const {
  if (specular_ <= 0.0f) return 0.0f;
  const float cos_l = n_.dot(l);
  if (cos_l <= 0.0f) return 0.0f;
  Eigen::Vector3f h = l + v_;
  const float len = h.norm();
  if (len < 1e-8f) return 0.0f;
  h /= len;
  const float vh = std::max(v_.dot(h), 0.0f);
  const float d = GgxD(n_.dot(h), alpha_);
  const float g = SmithG1(cos_l, alpha_) * g1_v_;
  return specular_ * d * g * SchlickFresnel(vh, f0_) / (4.0f * cos_l * cos_v_);
}

Eigen::Vector3f PreparedBrdf::Eval(const Eigen::Vector3f& l) const {
  if (n_.dot(l) <= 0.0f) return Eigen::Vector3f::Zero();
  return albedo_ * kd_ + Eigen::Vector3f::Constant(Specular(l));
}

}  // namespace crease
