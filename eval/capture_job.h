// A capture from files (paper Sec. 5): the job `crease capture` runs, callable from
// C++. It opens the frames, resolves the rig and the camera by the rules of
// eval/frame_tracker.h, reads the detail model, makes the rig compatible with the
// model's lowpass (Sec. 4.1), builds the global tracker (FrameTracker, with its
// experimental controls) and the CaptureSession, times that set-up, and runs the
// capture (RunCapture, pipeline/capture/capture_run.h). It lives in eval because the
// controls read the studio's truth.
//
//   CaptureFiles files;
//   files.input = "sequence";
//   files.model = "model.cdm";
//   const CaptureSummary s = CaptureFromFiles(files, CaptureOptions{}, run, log);
#pragma once

#include <functional>
#include <string>

#include "eval/frame_tracker.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/capture_run.h"

namespace crease {

// What a capture reads.
struct CaptureFiles {
  std::string input;        // video file, image folder or crease sequence dataset (OpenFrameSource)
  std::string model;        // the detail model (.cdm)
  std::string rig;          // the rig (.crig); empty: the dataset's tracking rig (TrackingRigPath)
  std::string camera;       // camera JSON; empty: the dataset's calibration, else fov_deg (ResolveIntrinsics)
  double fov_deg = 50.0;    // horizontal field of view without a calibration, degrees
  TrackingControl control;  // experimental controls (never a default)
};

// Captures `files.input` into `run.out` with `options` (checked). `run`'s provenance
// (input, model_path, source_rig) and setup_s are filled here; its other fields are
// used as given. `log` receives the two set-up lines `crease capture` prints (the
// compatible rig's and the session's times), without their newlines. Throws Error as
// the pieces do (OpenFrameSource, TrackingRigPath, ResolveIntrinsics, ReadDetailModel,
// FrameTracker, RunCapture).
CaptureSummary CaptureFromFiles(const CaptureFiles& files, const CaptureOptions& options, CaptureRunOptions run,
                                const std::function<void(const std::string&)>& log = {});

}  // namespace crease
