// Skin BRDF of the studio renderer (issue 3, part 3): a Lambertian diffuse lobe
// plus a microfacet specular lobe — GGX/Trowbridge–Reitz distribution D, separable
// Smith masking–shadowing G, Schlick Fresnel F (Walter et al. 2007):
//
//   f(l, v) = ρ_d · (1 − ρ_s·E_s(n·v)) / π  +  ρ_s · D(h) G(l, v) F(v·h) / (4 (n·l)(n·v))
//
// where E_s(μ) = ∫ D G F / (4 (n·l) μ) (n·l) dω_l is the directional albedo of the
// specular lobe (precomputed, F0·A(μ, α) + B(μ, α), split-sum tables). Energy: for
// every view direction ∫ f cos θ_l dω_l = ρ_d (1 − ρ_s E_s) + ρ_s E_s ≤ 1 when
// ρ_d, ρ_s ≤ 1, and = 1 for white Lambert (ρ_d = 1, ρ_s = 0).
//
// All directions are unit vectors in one frame; n is the shading normal, v points
// from the surface towards the viewer, l towards the light. Single precision (hot loop).
#pragma once

#include <string>
#include <vector>

#include "core/types.h"

namespace crease {

// Surface parameters of one point (a part's constants, or values from the maps).
struct Material {
  Eigen::Vector3f albedo{0.60f, 0.42f, 0.34f};  // ρ_d, linear RGB diffuse albedo in [0, 1]
  float specular = 0.5f;    // ρ_s in [0, 1]: scale of the specular lobe (the "specular intensity" map)
  float roughness = 0.45f;  // perceptual roughness r in [0.02, 1]; GGX α = r² (the "roughness" map)
  float f0 = 0.028f;        // Fresnel reflectance at normal incidence (skin, refractive index ≈ 1.4)
  bool textured = true;     // where the hit's UV lies in the face chart [0, 1]², the material maps
                            // override albedo / specular / roughness (those that are given)
};

// Named materials for the parts of a head: "skin", "lips", "sclera", "iris",
// "pupil", "cavity" (mouth interior), "teeth", "hair", "white-lambert" (ρ_d = 1,
// ρ_s = 0; for tests) and "grey" (ρ_d = 0.5, ρ_s = 0). Only "skin" and "lips" are
// textured. Throws Error naming the unknown name and listing the known ones.
Material MaterialPreset(const std::string& name);
std::vector<std::string> MaterialPresetNames();

// GGX normal distribution D(h) for cos_h = n·h and α.
float GgxD(float cos_h, float alpha);
// Smith masking G1 of GGX for cos = n·ω and α (separable form: G = G1(l) G1(v)).
float SmithG1(float cos, float alpha);
// Schlick's Fresnel approximation for cos = v·h.
float SchlickFresnel(float cos, float f0);
// Directional albedo E_s(μ) of the specular lobe with ρ_s = 1 (μ = n·v), from the
// precomputed tables (bilinear in μ and perceptual roughness).
float SpecularAlbedo(float cos_v, float roughness, float f0);

// The BRDF at one shading point, prepared once per (point, view) and evaluated
// for many light directions.
class PreparedBrdf {
 public:
  PreparedBrdf() = default;
  PreparedBrdf(const Material& m, const Eigen::Vector3f& n, const Eigen::Vector3f& v);

  // Diffuse part without the albedo: (1 − ρ_s E_s(n·v)) / π (so the diffuse BRDF is
  // albedo() · diffuse_weight()); the renderer keeps it separate for subsurface blur.
  float diffuse_weight() const { return kd_; }
  const Eigen::Vector3f& albedo() const { return albedo_; }
  // Specular part ρ_s D G F / (4 (n·l)(n·v)) for light direction l (0 below the horizon).
  float Specular(const Eigen::Vector3f& l) const;
  // Full BRDF f(l, v), RGB.
  Eigen::Vector3f Eval(const Eigen::Vector3f& l) const;

 private:
  Eigen::Vector3f n_ = Eigen::Vector3f::UnitZ(), v_ = Eigen::Vector3f::UnitZ();
  Eigen::Vector3f albedo_ = Eigen::Vector3f::Zero();
  float cos_v_ = 1.0f, kd_ = 0.0f, specular_ = 0.0f, alpha_ = 1.0f, f0_ = 0.0f;
  float g1_v_ = 1.0f;
};

}  // namespace crease
