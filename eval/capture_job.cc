// A capture from files (eval/capture_job.h).
#include "eval/capture_job.h"

#include <chrono>

#include <fmt/format.h>

#include "core/face_rig.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/training/detail_model.h"

namespace crease {
namespace fs = std::filesystem;

namespace {

// Seconds since `t0` (the set-up times a capture reports).
double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

CaptureSummary CaptureFromFiles(const CaptureFiles& files, const CaptureOptions& options, CaptureRunOptions run,
                                const std::function<void(const std::string&)>& log) {
  options.Check();
  auto frames = OpenFrameSource(files.input);
  const FrameSourceInfo& info = frames->info();
  const std::string rig_path = TrackingRigPath(files.rig, info);
  const CameraIntrinsics K = ResolveIntrinsics(files.camera, info, files.fov_deg);
  const DetailModel model = ReadDetailModel(files.model);
  auto t0 = std::chrono::steady_clock::now();
  const fs::path dataset_dir = info.kind == "dataset" ? info.path : fs::path();
  const FaceRig rig = CompatibleRig(ControlRig(ReadRig(rig_path), files.control, dataset_dir), model);
  const double rig_s = SecondsSince(t0);
  if (log) log(fmt::format("rig made compatible with the model's lowpass (Sec. 4.1) in {:.1f} s", rig_s));
  t0 = std::chrono::steady_clock::now();
  FrameTracker tracker(rig, K, options.tracker, files.control, dataset_dir);
  CaptureSession session(rig, model, K, options);
  const double setup_s = SecondsSince(t0);
  if (log) log(fmt::format("capture set up (UV raster, geodesics, stencils) in {:.1f} s", setup_s));
  run.input = files.input;
  run.model_path = files.model;
  run.source_rig = rig_path;
  run.setup_s = setup_s + rig_s;
  return RunCapture(run, options, model, K, frames.get(), &tracker, &session);
}

}  // namespace crease
