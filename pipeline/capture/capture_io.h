// The per-frame geometry `crease capture` writes and `crease eval` reads back:
// frames/NNNNNN.cfr, a core/array_file.h container (magic "CREASCFR", version 1)
// with the coarse mesh L^t and the refined mesh L~^t of the frame (float32 #V×3,
// camera frame, mm) and the tracker's 68 landmarks (float32 68×2 px), plus a JSON
// header {"frame", "tracked", "num_vertices"}. docs/formats.md describes the whole
// capture folder.
#pragma once

#include <cstdint>
#include <filesystem>

#include "core/types.h"

namespace crease {

struct CaptureFrameArrays {
  static constexpr uint32_t kFormatVersion = 1;
  int frame = 0;
  bool tracked = false;
  MatX3d coarse;     // L^t (empty when not tracked)
  MatX3d refined;    // L~^t (empty when not tracked)
  MatX2d landmarks;  // 68×2 px (may be empty)
};

void WriteCaptureFrameArrays(const std::filesystem::path& path, const CaptureFrameArrays& frame);
// Throws Error naming the file when it is missing, of another kind or version, or
// its arrays disagree with the header.
CaptureFrameArrays ReadCaptureFrameArrays(const std::filesystem::path& path);

}  // namespace crease
