// Camera sensor model of the studio (issue 3, part 3): exposure, Poisson–Gaussian
// noise in linear space, saturation, sRGB encoding, 8-bit quantisation and optional
// JPEG compression — applied to a linear render (synth/renderer.h). Motion blur is
// rendered, not simulated here: see RenderMotionBlurred in synth/renderer.h.
//
// Noise model (per pixel and channel, in electrons): the exposed linear value
// x·exposure maps to a mean of x·exposure·full_well_electrons photo-electrons;
//   e = Poisson(x·exposure·full_well) + Normal(0, read_noise_electrons²)
//   value = clamp(e / full_well, 0, 1)
// so, away from the clamp, mean = x·exposure and
//   variance = x·exposure / full_well + (read_noise_electrons / full_well)².
// Randomness: one seed drawn from the Rng passed in, one generator per image row
// derived from it: the same seed gives the same bytes for any number of threads.
#pragma once

#include <opencv2/core/mat.hpp>

#include "core/options.h"
#include "core/rng.h"

namespace crease {

struct SensorOptions {
  double exposure = 1.0;                // linear scale (exposure time × gain) before noise and clipping
  bool noise = true;                    // Poisson–Gaussian noise
  double full_well_electrons = 5000.0;  // photo-electrons at linear value 1 (sets the shot-noise level)
  double read_noise_electrons = 4.0;    // σ of the Gaussian read noise, electrons
  int jpeg_quality = 0;                 // 0 = no compression, else OpenCV JPEG quality in [1, 100]

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

struct SensorImage {
  cv::Mat linear;   // CV_32FC(n): exposed, noisy, clipped to [0, 1], before quantisation
  cv::Mat srgb8;    // CV_8UC(n): sRGB-encoded and quantised (after JPEG when enabled), R, G, B order
  cv::Mat decoded;  // CV_32FC(n): srgb8 decoded back to linear — what a method reading the frame sees
};

// `linear`: CV_32FC1 or CV_32FC3 linear-light image (finite, ≥ 0). Throws Error otherwise.
SensorImage ApplySensor(const cv::Mat& linear, const SensorOptions& options, Rng& rng);

// Linear [0, 1] (clamped) → 8-bit sRGB (IEC 61966-2-1, exact rounding); CV_32FC(n) → CV_8UC(n).
cv::Mat EncodeSrgb8(const cv::Mat& linear);
// 8-bit sRGB → linear float; CV_8UC(n) → CV_32FC(n).
cv::Mat DecodeSrgb8(const cv::Mat& srgb8);
// JPEG round trip at `quality` in [1, 100] (OpenCV imencode/imdecode), 1 or 3
// channels in R, G, B order.
cv::Mat JpegRoundTrip(const cv::Mat& srgb8, int quality);

// A Poisson-distributed integer with mean `lambda` ≥ 0 (Knuth's method below 12,
// Hörmann's PTRS transformed rejection above), from `rng` only.
int64_t SamplePoisson(double lambda, Rng& rng);

}  // namespace crease
