// Online capture (paper Sec. 5): from the global tracker's coarse mesh L^t to the
// high-fidelity mesh H^t, one frame at a time.
//
//   frame I^t ──► global tracker (tracker.h; done by the caller) ──► L^t, landmarks
//             ──► visibility (the previous frame's depth buffer, frame_texture.h)
//             ──► flow refinement (Sec. 5.1, flow_refinement.h) ──► L~^t
//             ──► texture T^t in the rig's UV layout (frame_texture.h)
//             ──► [first frame] mesoscopic map D^HF (Sec. 5.3)
//             ──► [first N frames] wrinkle map, then the fixed patch layout (Sec. 5.2)
//             ──► detail regression D^t (Sec. 5.2, detail_regression.h)
//             ──► H^t = L~^t + (D^t + D^HF) · n (Sec. 5.3, hifi_mesh.h)
//
// The wrinkle map needs the textures of the first N frames before any patch can
// be placed (Sec. 5.2), so CaptureSession buffers those frames (their textures,
// ~4 MB each at 1024²) and returns them all, with their D^t, once the layout is
// fixed; from then on every frame is returned as soon as it is processed. A
// researcher therefore gets D^t for every frame; a live system sees a latency of
// N frames once, at the start. Flush() fixes the layout early when the input ends
// before N frames.
//
// The rig: detail regression needs the rig made compatible with the training
// lowpass G (Sec. 4.1, MakeRigCompatible): the displacement maps were extracted
// relative to it. The session is given that rig (CompatibleRig below); the tracker
// should track with the same rig so that L^t and H^t share one surface.
//
// Differences from the paper:
//   1. The paper extracts T^t from L~^t on the GPU and renders H^t with hardware
//      displacement mapping; here both run on the CPU (TBB), and H^t is a dense mesh
//      on a regular UV grid over the face chart (hifi_mesh.h).
//   2. The first N frames get their D^t once the layout is fixed (see above); the
//      paper does not say what is shown during those frames.
//   3. Frames where the tracker lost the face carry no refinement, texture or detail;
//      the refinement restarts from the projections of L^t on the next tracked frame.
#pragma once

#include <deque>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "pipeline/capture/detail_regression.h"
#include "pipeline/capture/flow_refinement.h"
#include "pipeline/capture/frame_texture.h"
#include "pipeline/capture/hifi_mesh.h"
#include "pipeline/capture/tracker.h"
#include "pipeline/training/detail_model.h"

namespace crease {

class OptionVisitor;

// Frame `frame`'s map of a folder of per-frame maps NNNNNN.exr (channel 0, mm, the
// rig's UV layout), as CV_32F R×R (resampled when its size differs). `option` names
// the option that asked for it. Throws Error when the file is missing or not square.
cv::Mat ReadFrameMap(const std::string& dir, int frame, int R, const char* option);

// A displacement map (CV_32F, mm, positive outwards) as the gray texture a groove
// would give under light from the front: T = 0.5 + 0.5 · D / 1 mm, clamped to
// [0, 1], resampled to R×R (CaptureOptions::wrinkle_map_from_maps).
cv::Mat WrinkleTextureFromDisplacement(const cv::Mat& displacement, int R);

struct CaptureOptions {
  TrackerOptions tracker;            // the global tracker (Sec. 5, DDE in the paper)
  FlowRefinementOptions refinement;  // Sec. 5.1
  FrameTextureOptions texture;       // Sec. 5.1 (T^t); map_resolution follows the model
  DetailRegressionOptions detail;    // Sec. 5.2
  MesoscopicOptions mesoscopic;      // Sec. 5.3
  HifiMeshOptions hifi;              // Sec. 5.3
  // Ablation switches (not in the paper): without refinement T^t is extracted from
  // L^t and H^t built on L^t; without detail D^t = 0; without mesoscopic D^HF = 0.
  bool refine = true;
  bool regress_detail = true;
  bool mesoscopic_detail = true;
  // Build H^t every frame (into a buffer the session reuses; its time counts in the
  // per-frame figures, as the paper's GPU displacement mapping does). Either way the
  // caller gets H^t of any completed frame from HifiMesh().
  bool build_hifi_mesh = true;
  // Issue 17's ladder rung R1 (not in the paper): a folder of per-frame displacement
  // maps NNNNNN.exr (mm, the rig's UV layout; e.g. the truth written by `crease eval
  // --set truth_maps_dir=…`) that the wrinkle map (Sec. 5.2) is built from instead
  // of the first frames' textures, each drawn as a texture lit from the front
  // (WrinkleTextureFromDisplacement): the patches then sit where the lines truly
  // are, and only the regression from T^t is real. Empty = the paper's.
  std::string wrinkle_map_from_maps;
  // Issue 17's ladder rung R2-oracle (not in the paper): a folder of the frames' true
  // D* maps NNNNNN.exr (as `crease truth-maps` writes them with the model's G). D^t is
  // then assembled from each frame's own truth on the capture's patches instead of
  // regressed from T^t (DetailRegressor::AssembleFromTruth): the ceiling of the
  // layout, gate, PCA, merge and fill, what a perfect regressor would give. Empty =
  // the paper's regression.
  std::string detail_from_truth_maps;

  // All fields of all stages, flattened (keys are unique).
  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Per-stage wall time of one frame, ms (file I/O excluded).
struct CaptureTiming {
  double landmarks_ms = 0, fit_ms = 0;  // the global tracker (copied from TrackedFrame)
  double visibility_ms = 0, refine_ms = 0, texture_ms = 0, mesoscopic_ms = 0;
  double detail_ms = 0, hifi_ms = 0;
  DetailTiming detail;  // its sub-steps
  // Adding the frame's texture to the wrinkle map (the first N frames only; a
  // one-off cost like the mesoscopic map, not part of the per-frame totals below).
  double wrinkle_map_ms = 0;
  double tracking_ms() const { return landmarks_ms + fit_ms + visibility_ms + refine_ms; }
  double detail_total_ms() const { return texture_ms + mesoscopic_ms + detail_ms + hifi_ms; }
  double total_ms() const { return tracking_ms() + detail_total_ms(); }
};

struct CapturedFrame {
  int frame = 0;
  TrackedFrame tracked;       // the global tracker's output
  bool has_mesh = false;      // tracked: L^t, L~^t and T^t are set
  bool has_detail = false;    // D^t is set (the layout was fixed and the frame tracked)
  MatX3d coarse;              // L^t, #V×3, camera frame, mm
  MatX3d refined;             // L~^t, #V×3, camera frame, mm (= L^t without refinement)
  RefinedFrame refinement;    // flow statistics (empty without refinement)
  FrameTexture texture;       // T^t and its seen mask
  cv::Mat displacement;       // D^t, CV_32F R×R, mm
  CaptureTiming timing;
};

// The rig made compatible with the model's lowpass G (Sec. 4.1; MakeRigCompatible),
// the rig capture tracks and displaces. With G = 0 it is `rig` itself.
FaceRig CompatibleRig(const FaceRig& rig, const DetailModel& model);

class CaptureSession {
 public:
  // `rig`: the compatible rig (CompatibleRig); `model`: the trained detail model;
  // `intrinsics`: the camera of the frames. Precomputes the UV raster, the flow
  // refinement's geodesics and the mesh stencils. Throws Error when the rig lacks
  // a UV chart, the model's map size disagrees with the options, or options fail Check().
  CaptureSession(const FaceRig& rig, const DetailModel& model, const CameraIntrinsics& intrinsics,
                 const CaptureOptions& options);
  ~CaptureSession();

  // Processes frame `index` (linear float RGB CV_32FC3, sized like the intrinsics)
  // with the global tracker's result for it and the tracker's identity α. Returns
  // the frames completed by this call, in order: nothing while the wrinkle map is
  // being built (the first N frames), then those N frames at once, then one frame
  // per call.
  // Process = Begin, then Finish on each frame it returns.
  std::vector<CapturedFrame> Process(int index, const cv::Mat& frame, const TrackedFrame& tracked,
                                     const Eigen::VectorXd& identity);
  // Fixes the layout if it is not yet fixed (input shorter than N frames) and
  // returns the buffered frames, finished.
  std::vector<CapturedFrame> Flush();

  // The two halves of Process, for a capture that overlaps frames (RunCapture):
  // Begin does the per-frame work that carries state from frame to frame (the flow
  // refinement L~^t, the texture T^t and its blend over time, visibility, D^HF of
  // the first frame, the wrinkle map of the first N frames) and returns the frames
  // ready for Finish, in order, as Process would return them; Finish does the rest
  // (D^t, Sec. 5.2, and H^t, Sec. 5.3). Begin(t + 1) may run concurrently with
  // Finish of frames an earlier Begin returned: the two touch disjoint state (Finish
  // only reads D^HF and the layout, which Begin fixes before it returns a first
  // frame). Calls of Begin, and calls of Finish, must each be in frame order. The
  // results are those of Process, byte for byte.
  std::vector<CapturedFrame> Begin(int index, const cv::Mat& frame, const TrackedFrame& tracked,
                                   const Eigen::VectorXd& identity);
  void Finish(CapturedFrame* frame);
  // Flush's Begin half: the buffered frames, the layout fixed, not yet finished.
  std::vector<CapturedFrame> EndInput();

  // H^t of a completed frame (built anew).
  TriMesh HifiMesh(const CapturedFrame& frame) const;
  // The combined map D^t + D^HF of a frame (what displaces H^t).
  cv::Mat CombinedDisplacement(const CapturedFrame& frame) const;

  bool layout_fixed() const;
  const DetailRegressor& detail() const { return *detail_; }
  const cv::Mat& mesoscopic() const { return mesoscopic_; }  // D^HF (empty before the first textured frame)
  const FrameTextureExtractor& texture_extractor() const { return *texture_; }
  const FaceRig& rig() const { return rig_; }
  const CaptureOptions& options() const { return options_; }

 private:
  void BeginTracked(const cv::Mat& frame, const TrackedFrame& tracked, const Eigen::VectorXd& identity,
                    CapturedFrame* out);

  FaceRig rig_;
  CaptureOptions options_;
  CameraIntrinsics intrinsics_;
  int map_resolution_ = 0;
  std::unique_ptr<FrameTextureExtractor> texture_;
  std::unique_ptr<FlowRefiner> refiner_;
  std::unique_ptr<DetailRegressor> detail_;
  std::unique_ptr<HifiMeshBuilder> hifi_;
  cv::Mat mesoscopic_;
  TriMesh hifi_scratch_;
  cv::Mat combined_scratch_;  // D^t + D^HF of the frame being finished
  std::deque<CapturedFrame> pending_;  // frames waiting for the layout
  bool was_tracked_ = false;
  std::vector<uint8_t> previous_visible_;  // per rig vertex, from the last texture's depth buffer
  FrameTexture texture_history_;  // T_s^{t−1} (frame_texture.h, Difference 4); empty after a lost face
};

}  // namespace crease
