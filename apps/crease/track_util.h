// The input and global-tracker flags `crease track` and `crease capture` share (the
// tracker, the camera and rig rules and the controls: eval/frame_tracker.h).
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "eval/frame_tracker.h"

namespace crease::app {

struct TrackingFlags {
  std::string input, rig_path, landmarks = "dlib", tracker_model, camera_path;
  double fov = 50.0;
  int max_frames = -1;
  bool gt_prior = false;  // the ground-truth-prior control
  bool gt_fit = false;    // the ground-truth-fit control (the truth's pose and expression)
  bool gt_surface = false;  // the same on the actor's own expression shapes (the true coarse surface)
  double noise = 0.0;     // its landmark noise, px
  uint64_t seed = 1;      // its noise seed

  TrackingControl Control() const { return {gt_prior, gt_fit, gt_surface, noise, seed}; }
};
// Adds --input, --rig, --landmarks, --tracker, --camera, --fov, --max-frames,
// --ground-truth-prior, --noise and --seed to `cmd` (`crease capture` adds
// --ground-truth-fit and --ground-truth-surface itself).
void AddTrackingFlags(CLI::App* cmd, TrackingFlags* flags);

}  // namespace crease::app
