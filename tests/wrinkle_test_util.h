// Synthetic textures and options shared by the wrinkle-map and patch tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>

#include <opencv2/core/mat.hpp>

#include "pipeline/training/wrinkle_map.h"

namespace crease::testing {

// Options with σ in texels of the test maps (no 1024² scaling).
inline WrinkleMapOptions TexelOptions() {
  WrinkleMapOptions o;
  o.dog_reference_resolution = 0;
  o.patch_regions.clear();
  return o;
}

// A 0.5 gray S×S texture with a dark Gaussian line (depth, σ = width texels)
// through (cx, cy) along the direction of angle `line_deg` (texel coordinates,
// x right, y down).
inline cv::Mat LineTexture(int S, double line_deg, double depth = 0.2, double width = 2.0, double cx = -1, double cy = -1) {
  if (cx < 0) cx = 0.5 * (S - 1);
  if (cy < 0) cy = 0.5 * (S - 1);
  const double phi = line_deg * std::numbers::pi / 180.0;
  const double nx = -std::sin(phi), ny = std::cos(phi);
  cv::Mat t(S, S, CV_32F);
  for (int y = 0; y < S; ++y) {
    for (int x = 0; x < S; ++x) {
      const double d = (x - cx) * nx + (y - cy) * ny;
      t.at<float>(y, x) = static_cast<float>(0.5 - depth * std::exp(-d * d / (2 * width * width)));
    }
  }
  return t;
}

// |a − b| between two orientations (lines), degrees in [0, 90].
inline double AngleDiffMod180(double a_deg, double b_deg) {
  const double d = std::fmod(std::abs(a_deg - b_deg), 180.0);
  return std::min(d, 180.0 - d);
}

}  // namespace crease::testing
