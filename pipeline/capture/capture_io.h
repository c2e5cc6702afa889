// The per-frame geometry `crease capture` writes and `crease eval` reads back:
// frames/NNNNNN.cfr, a core/array_file.h container (magic "CREASCFR", version 1)
// with the coarse mesh L^t and the refined mesh L~^t of the frame (float32 #V×3,
// camera frame, mm) and the tracker's 68 landmarks (float32 68×2 px), plus a JSON
// header {"frame", "tracked", "num_vertices"}. A refined frame also carries its flow
// points (Sec. 5.1; optional arrays, absent in older files and unrefined frames):
// flow_vertex (i32, rig vertex ids), flow_status (u8, FlowPointStatus) and, float32
// n×2 px, flow_projected u^t (L^t), flow_positions ũ^t (after the outlier tests and
// MLS) and flow_fitted (the 3D fit F), so that `crease eval` can tell which step of
// the refinement moves the points away from the truth. docs/formats.md describes the
// whole capture folder.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "core/types.h"
#include "pipeline/capture/capture.h"

namespace crease {

struct CaptureFrameArrays {
  static constexpr uint32_t kFormatVersion = 1;
  int frame = 0;
  bool tracked = false;
  MatX3d coarse;     // L^t (empty when not tracked)
  MatX3d refined;    // L~^t (empty when not tracked)
  MatX2d landmarks;  // 68×2 px (may be empty)
  // Flow points of the refinement (all empty when the frame was not refined).
  std::vector<int> flow_vertex;
  std::vector<uint8_t> flow_status;  // FlowPointStatus
  MatX2d flow_projected, flow_positions, flow_fitted;
};

// The arrays of a captured frame (L^t, L~^t, the tracker's landmarks, the flow points).
CaptureFrameArrays MakeCaptureFrameArrays(const CapturedFrame& frame);

void WriteCaptureFrameArrays(const std::filesystem::path& path, const CaptureFrameArrays& frame);
// Throws Error naming the file when it is missing, of another kind or version, or
// its arrays disagree with the header.
// Limits of what a capture file may claim (checked before anything is allocated).
inline constexpr int64_t kMaxCaptureVertices = int64_t{1} << 28;
inline constexpr int64_t kMaxCaptureMapResolution = 16384;

CaptureFrameArrays ReadCaptureFrameArrays(const std::filesystem::path& path);

// capture.json (CaptureSummary::ToJson) as `crease eval` reads it back: a JSON object
// whose fields eval uses have the right type and range — frame_indices (required, a
// list of frame numbers), map_resolution, the objects options, detail_extraction and
// timing, the numbers fps, tracking_share and detail_share. Errors name the file and
// the field.
nlohmann::json ReadCaptureJson(const std::filesystem::path& path);

// The CaptureOptions a capture ran with: capture.json's "options" (absent: the
// defaults), read like the options of models and pair files (SetOptionsFromStoredJson):
// a key from before option sections (flat, e.g. "lk_window" or
// "refine_expression_prior_weight") is read as its new key. Errors name `what`.
CaptureOptions CaptureOptionsOfJson(const nlohmann::json& capture_json, const std::string& what);

}  // namespace crease
