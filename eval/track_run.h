// Running and recording the global face tracker alone (paper Sec. 5.1's L^t; issue 5):
// the job `crease track` runs, callable from C++. Every frame of a FrameSource goes
// through a FrameTracker, and the run writes one output folder:
//   frames/NNNNNN.json      per-frame record (pipeline/capture/tracking_record.h), its
//                           stage times and, on a crease sequence dataset with truth,
//                           its errors against the truth
//   meshes/NNNNNN.{ply,vtp} and tracking.pvd   the tracked rig mesh, unless !write_meshes
//   summary.json            the TrackSummary (TrackSummary::ToJson)
// and optionally a preview video with the landmarks and the mesh. On a dataset with
// ground truth the errors are measured per frame (eval/tracking_metrics.h), through a
// surface correspondence when the tracking rig is not the dataset's
// (eval/rig_correspondence.h).
//
//   FrameTracker tracker(rig, K, tracker_options, control, dataset);
//   const TrackSummary s = RunTracking(run, tracker_options, rig, K, frames.get(), &tracker);
//   std::printf("%s", s.BriefReport().c_str());
#pragma once

#include <filesystem>
#include <string>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/face_rig.h"
#include "eval/frame_tracker.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/tracker.h"

namespace crease {

struct TrackRunOptions {
  std::filesystem::path out;  // the output folder (required; created, files in it replaced)
  std::string preview;        // preview video (.avi: MJPG, .mp4: mp4v); empty: none
  int max_frames = -1;        // stop after this many frames (negative: all)
  bool write_meshes = true;   // per-frame PLY/VTP meshes and tracking.pvd
  std::string input;          // the frames' path, recorded as given

  // Throws Error for an empty out.
  void Check() const;
};

// Errors against the truth, averaged over the tracked frames that have it
// (FrameTrackingError, eval/tracking_metrics.h).
struct TrackErrorSummary {
  int frames = 0;                // 0: the input has no truth
  double landmark_px = 0.0;      // the landmark source's 68 points against the truth's
  double landmark_iod = 0.0;     // the same over the inter-ocular distance
  double fit_landmark_px = 0.0;  // the fitted rig's landmark projections against the truth's
  double vertex_px = 0.0;        // the fitted rig's visible vertices against the truth's projections
};

// What a tracking run did (Ceres's Solver::Summary is the model).
struct TrackSummary {
  std::string input, landmark_source;
  int frames = 0;          // frames read
  int tracked_frames = 0;  // with a fitted rig
  int detections = 0;      // frames where the face was (re)detected
  double landmarks_ms = 0.0, fit_ms = 0.0;  // per frame read, ms
  // After detection and the identity phase: frames tracked from the previous frame.
  int steady_frames = 0;
  double steady_ms = 0.0;  // landmarks + rig fit per steady frame (0 without any)
  double tracking_fps() const;
  Eigen::VectorXd identity;  // the identity α at the end
  std::string options_json;  // the TrackerOptions (OptionsToJson)
  // −1: the tracking rig is the dataset's (or there is no truth); else how many of
  // its vertices the surface correspondence matched.
  int correspondence_matched = -1;
  TrackErrorSummary error;

  // The counts, the speed and the errors, as `crease track` prints them.
  std::string BriefReport() const;
  // summary.json (2-space indented JSON).
  std::string ToJson() const;
};

// Runs `frames` through `tracker` (built with `tracker_options`, `rig` and
// `intrinsics`) and writes the folder of `options` (above). Throws Error for bad
// options, a source without frames (naming options.input), a preview video that cannot
// be written, or a tracker without a landmark fitter (the ground-truth-fit control).
TrackSummary RunTracking(const TrackRunOptions& options, const TrackerOptions& tracker_options, const FaceRig& rig,
                         const CameraIntrinsics& intrinsics, FrameSource* frames, FrameTracker* tracker);

}  // namespace crease
