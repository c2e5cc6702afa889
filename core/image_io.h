// Image files through OpenImageIO (target crease_core_image; link it only where
// images are read or written — OIIO costs ~0.35 s per process start).
//
// In memory crease images are linear-light float (CV_32F, 1, 3 or 4 channels,
// channel order R, G, B[, A] — not OpenCV's BGR). Conversions happen only here:
//   * EXR/HDR/TIFF-float are stored as float, values unchanged.
//   * PNG/JPEG/8- or 16-bit TIFF are sRGB-encoded on write (linear → sRGB
//     transfer curve, clamped to [0, 1]) and decoded on read, unless
//     `ImageWriteOptions::srgb = false` (data maps such as masks, stored as value·255).
#pragma once

#include <filesystem>
#include <opencv2/core/mat.hpp>

#include "core/color.h"  // SrgbToLinear, LinearToSrgb

namespace crease {

struct ImageWriteOptions {
  bool srgb = true;      // 8/16-bit formats only: apply the sRGB transfer curve on write.
  int bits = 8;          // PNG/TIFF integer formats: 8 or 16.
  bool half = false;     // EXR: store 16-bit half floats instead of 32-bit float.
};

// Reads any format OIIO reads. Returns CV_32FC(n), n = the file's channel count.
// 8/16-bit files are decoded from sRGB to linear unless `srgb` is false.
// Errors name the file: missing, unreadable, unsupported, truncated, or a header
// claiming more than 10^8 pixels (checked before decoding), an EXR header attribute
// claiming more bytes than the file holds (checked before OpenEXR allocates it).
cv::Mat ReadImage(const std::filesystem::path& path, bool srgb = true);

// Writes a CV_32F or CV_8U image (1, 3 or 4 channels); the format follows the
// extension (.exr, .png, .jpg, .tif, .hdr). Atomic. Rejects non-finite values
// for integer formats with an Error naming the file.
void WriteImage(const std::filesystem::path& path, const cv::Mat& image,
                const ImageWriteOptions& options = {});

}  // namespace crease
