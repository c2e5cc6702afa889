// The per-frame record of a tracked frame and its preview drawing, shared by
// `crease track` and the capture run (capture_run.h): the frame's JSON (landmarks,
// pose, expression weights by name), the rig's mesh with the tracked vertices, and
// the landmarks and wireframe drawn over the frame.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/camera.h"
#include "core/tri_mesh.h"
#include "core/types.h"
#include "pipeline/capture/tracker.h"

namespace crease {

// {"rotation_wxyz": [w, x, y, z], "translation_mm": [x, y, z]}.
nlohmann::json PoseJson(const Rigid3d& pose);

// The per-frame record `crease track` and `crease capture` write: frame, tracked, detected, confidence,
// landmarks (px) and, when tracked, cam_from_head, expression weights by name and rms_px.
nlohmann::json TrackedFrameJson(const TrackedFrame& t, const FaceRig& rig);

// The rig's mesh (topology, UVs) with vertices V and no normals, for writing.
TriMesh RigMeshWithVertices(const FaceRig& rig, const MatX3d& V);

// Linear float RGB → 8-bit sRGB BGR (for previews).
cv::Mat PreviewBgr(const cv::Mat& linear_rgb);
// Draws the landmarks (green), a faint wireframe of `projected` (#V×2 px) over the
// face chart triangles, and the tracking state onto `bgr`.
void DrawTracking(const TrackedFrame& t, const MatX2d& projected, const MatX3i& face_F, cv::Mat* bgr);

}  // namespace crease
