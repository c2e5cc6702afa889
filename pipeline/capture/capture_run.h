// Running and recording a capture (paper Sec. 5): the job `crease capture` runs,
// callable from C++. Frames from a FrameSource go through a global tracker (L^t)
// and a CaptureSession (L~^t, T^t, D^t, H^t), and every frame the session returns
// is written to one output folder (docs/formats.md describes it). By default frame
// t+1's tracking, refinement and texture run beside frame t's detail regression and
// H^t (CaptureRunOptions::overlap_frames), with the serial order's outputs:
//   capture.json                the CaptureSummary (CaptureSummary::ToJson)
//   timings.csv                 per-frame stage times, ms
//   rig.crig                    the rig captured with (the session's, model-compatible)
//   frames/NNNNNN.json, .cfr    per-frame record (tracking_record.h, with the flow
//                               statistics and stage times) and arrays (capture_io.h)
//   displacement/NNNNNN.exr     D^t (half float), unless !write_maps
//   textures/NNNNNN.png         T^t (sRGB gray), with write_textures
//   meshes/{coarse,refined,hifi}/NNNNNN.{ply,vtp} and {coarse,refined,hifi}.pvd:
//                               L^t, L~^t and H^t of every mesh_every-th frame, unless !write_meshes
//   maps/mesoscopic.exr, maps/wrinkle_map.{exr,png}   the session's per-actor maps
//   previews/NNNNNN.png         every 30th frame of the preview video, with a preview
//   pairs.cpr                   the video's regression pairs (T^t, D*), with pairs_truth_maps
// The folder is written under a temporary name and renamed when complete.
//
//   FrameTracker tracker(...);                       // a GlobalTracker
//   CaptureSession session(rig, model, K, options);
//   const CaptureSummary s = RunCapture(run, options, model, K, frames.get(), &tracker, &session);
//   std::printf("%s", s.BriefReport().c_str());
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/timer.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/tracker.h"
#include "pipeline/training/detail_model.h"

namespace crease {

// The global tracker a capture calls once per frame (L^t, Sec. 5): a FaceTracker
// behind it, or an experimental control that reads a dataset's ground truth (the
// CLI's FrameTracker).
class GlobalTracker {
 public:
  virtual ~GlobalTracker() = default;
  // Tracks `image` (linear float RGB), frame number `index`.
  virtual TrackedFrame Track(const cv::Mat& image, int index) = 0;
  // The identity α the frames are tracked with (#identity modes).
  virtual Eigen::VectorXd identity() const = 0;
  // The landmark source, recorded in capture.json ("dlib", "regressor", "ground-truth-prior", …).
  virtual std::string source_name() const = 0;
};

struct CaptureRunOptions {
  std::filesystem::path out;   // the output folder (required)
  bool overwrite = false;      // replace an existing output folder
  std::string preview;         // preview video (.avi: MJPG, .mp4: mp4v): the frame with L~^t beside D^t; empty: none
  int max_frames = -1;         // stop after this many frames (negative: all)
  int mesh_every = 1;          // write the meshes of frames whose number is a multiple of this, ≥ 1
  bool write_meshes = true;    // per-frame PLY/VTP meshes L^t, L~^t, H^t
  bool write_maps = true;      // per-frame displacement maps D^t (EXR)
  bool write_textures = false;  // per-frame textures T^t (PNG)
  // Overlap frames on the cores (not in the paper, which runs on a GPU): frame t+1's
  // tracking, flow refinement and texture (CaptureSession::Begin) run beside frame
  // t's detail regression and H^t (CaptureSession::Finish). The outputs are those
  // of the serial order, byte for byte; the speed is then the wall clock per frame.
  // false: one frame after another (each stage's time alone).
  bool overlap_frames = true;
  // Issue 17's rung R2-pairs (not in the paper): a folder of the frames' true D* maps
  // NNNNNN.exr (`crease truth-maps`, with the model's G). With it the folder also gets
  // pairs.cpr: the video's own regression pairs of every pairs_every-th frame with
  // detail (DetailRegressor::CutPairs: T^t's patches on the capture's layout as the
  // regressor reads them, D*'s on the same patches; one "actor" per frame, named
  // frame_NNNNNN), to score a model on them with `crease model eval-pairs` beside the
  // scans' pairs. Empty: no pairs.
  std::string pairs_truth_maps;
  int pairs_every = 1;
  // Provenance, recorded in capture.json as given.
  std::string input;           // the frames' path
  std::string model_path;      // the detail model's file
  std::string source_rig;      // the rig file the session's rig was made from
  double setup_s = 0.0;        // seconds spent before the run (rig compatibility, session set-up)

  // Throws Error naming the field: an empty out, mesh_every < 1, pairs_every < 1.
  void Check() const;
};

// What a capture did (Ceres's Solver::Summary is the model): the frames, the
// session's per-actor results, the speed and its split, and where it all went.
struct CaptureSummary {
  // Provenance (CaptureRunOptions) and the landmark source (GlobalTracker::source_name).
  std::string input, model, source_rig, landmark_source;

  int frames = 0;                  // frames read from the source
  int tracked_frames = 0;          // with L^t and L~^t (has_mesh)
  int detail_frames = 0;           // with D^t (has_detail)
  std::vector<int> frame_indices;  // of the returned frames, in order
  int lost_frames() const { return frames - tracked_frames; }

  int map_resolution = 0;                // the model's texture / displacement map size, texels
  std::string detail_extraction_json;    // the model's detail extraction options (G: eval's truth), JSON
  int patches = 0;                       // patches of the session's layout (0 when it was never fixed)
  int wrinkle_frames = 0;                // frames in the wrinkle map (the first N, Sec. 5.2)

  // Speed in the steady state: frames with D^t, no detection, not the first
  // textured frame; file I/O excluded. With overlapped frames the wall clock of the
  // steps that finished one such frame while beginning a tracked, undetected one (or
  // none, at the end); else each frame's stage times summed.
  bool overlapped = false;      // CaptureRunOptions::overlap_frames
  int steady_frames = 0;
  double ms_per_frame = 0.0;    // 0 without steady frames
  double stage_ms_per_frame = 0.0;  // the steady frames' stage times summed (= ms_per_frame when not overlapped)
  double fps = 0.0;             // 1000 / ms_per_frame; 0 without steady frames (paper: 18 fps, Sec. 6)
  double tracking_share = 0.0;  // of the steady time: landmarks, rig fit, visibility, flow refinement (paper: 58 %)
  double detail_share = 0.0;    // texture, mesoscopic, detail regression, H^t (paper: 42 %)
  std::vector<TimingReport::Entry> timing;  // per stage, summed over the frames with D^t, s
  double setup_s = 0.0;         // CaptureRunOptions::setup_s

  Eigen::VectorXd identity;     // GlobalTracker::identity() at the end
  std::string options_json;     // the CaptureOptions the session was built with (OptionsToJson)

  // Where it went: the output folder, its capture.json and timings.csv, the preview (empty: none).
  std::filesystem::path out, capture_json, timings_csv;
  std::string preview;

  // The frame counts, the stage-time table and the steady-state speed, as `crease capture` prints them.
  std::string BriefReport() const;
  // capture.json: everything above but the output paths (2-space indented JSON).
  std::string ToJson() const;
};

// Runs `frames` through `tracker` and `session` and writes the output folder of
// `options` (above). `capture_options`, `model` and `intrinsics` are those the
// session was built with; capture.json records `capture_options` as given (the
// session's own copy has texture.map_resolution set to the model's).
// Throws Error for bad options, a source without frames (naming options.input), an
// existing folder without overwrite, or a preview video that cannot be written; the
// folder is then not left behind.
CaptureSummary RunCapture(const CaptureRunOptions& options, const CaptureOptions& capture_options,
                          const DetailModel& model, const CameraIntrinsics& intrinsics, FrameSource* frames,
                          GlobalTracker* tracker, CaptureSession* session);

}  // namespace crease
