// Tracking accuracy against a studio sequence's ground truth (issue 5; the paper's
// Fig. 11 measures the same for L^t and the refined L~^t): the 2D landmark error
// of the landmark source, and the 2D error of the fitted rig's vertices.
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/types.h"
#include "pipeline/capture/tracker.h"

namespace crease {

// One frame of a sequence dataset's truth (synth/dataset.h).
struct FrameTruth {
  MatX2d landmarks;                    // 68×2 px
  std::vector<char> landmark_visible;  // 68
  MatX2d vertices;                     // #V×2 px, every coarse rig vertex
  std::vector<char> vertex_visible;    // #V
  Rigid3d cam_from_head;
  Eigen::VectorXd identity;                         // rig identity coefficients α
  std::vector<std::pair<std::string, double>> expression;  // rig expression weights by name
};

// Reads truth/NNNNNN.json and truth/NNNNNN_vertices.bin; errors name the file.
// num_vertices: the truth rig's vertex count, or -1 for as many as the file holds.
FrameTruth ReadFrameTruth(const std::filesystem::path& dataset, int frame, int num_vertices);

struct FrameTrackingError {
  double landmark_px = 0.0;        // mean over the 68 points of |source − truth|
  double landmark_iod = 0.0;       // the same / inter-ocular distance (outer eye corners)
  double fit_landmark_px = 0.0;    // the rig's projected landmarks against the truth
  double vertex_px = 0.0;          // mean over visible vertices of |projected L^t − truth|
  int visible_vertices = 0;
};

// `landmarks`: the source's 68×2; `projected_vertices`: the fitted rig's vertices
// projected with the fitted pose (#V×2); `projected_landmarks`: its 68 landmarks.
FrameTrackingError CompareToTruth(const FrameTruth& truth, const MatX2d& landmarks, const MatX2d& projected_landmarks,
                                  const MatX2d& projected_vertices);

// Expression weights by name → the rig's vector (names the rig lacks are ignored).
Eigen::VectorXd ExpressionVector(const FaceRig& rig, const std::vector<std::pair<std::string, double>>& named);

// The ground-truth-fit control (issue 17's exact-geometry rungs): frame `frame` as a
// perfect global tracker would report it — the truth's pose, its expression weights
// (by name) and its landmark projections. `rig` must share the truth rig's head
// frame and expression shapes (the dataset's rig or a part of it, such as its
// tracking rig); the actor's personal expression deviations remain (the prior error).
TrackedFrame TruthAsTrackedFrame(const FaceRig& rig, const FrameTruth& truth, int frame);
// The truth's identity α for `rig`: its first #I coefficients, zero-padded.
Eigen::VectorXd TruthIdentity(const FaceRig& rig, const FrameTruth& truth);

}  // namespace crease
