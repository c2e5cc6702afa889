// `crease track`: the global face tracker on a video, an image folder or a studio
// sequence (issue 5).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "apps/crease/commands.h"
#include "apps/crease/track_util.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/vtk_io.h"
#include "eval/rig_correspondence.h"
#include "eval/tracking_metrics.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/tracker.h"
#include "pipeline/capture/tracking_record.h"

namespace crease::app {

namespace fs = std::filesystem;
using nlohmann::json;

void AddTrackCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("track", "Global face tracker: landmarks and the rig fitted per frame (issue 5)");
  static TrackingFlags tf;
  static std::string out, preview;
  static bool no_meshes = false;
  static std::vector<std::string> sets;
  AddTrackingFlags(cmd, &tf);
  cmd->add_option("--out,-o", out, "Output folder")->required();
  cmd->add_option("--preview", preview, "Preview video (.avi: MJPG, .mp4: mp4v) with landmarks and mesh");
  cmd->add_flag("--no-meshes", no_meshes, "Skip the per-frame PLY/VTP meshes");
  cmd->add_option("--set", sets, "Tracker option KEY=VALUE (repeatable; pipeline/capture/tracker.h TrackerOptions)");
  cmd->callback([] {
    TrackerOptions options;
    options.landmark_source = tf.tracker_model.empty() ? FromString<LandmarkSourceKind>(tf.landmarks, "--landmarks")
                                                       : LandmarkSourceKind::kRegressor;
    options.tracker_model = tf.tracker_model;
    if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &options);
    options.Check();
    auto frames = OpenFrameSource(tf.input);
    const FrameSourceInfo& info = frames->info();
    const bool dataset = info.kind == "dataset";
    tf.rig_path = TrackingRigPath(tf.rig_path, info);
    const FaceRig rig = ReadRig(tf.rig_path);
    const CameraIntrinsics K = ResolveIntrinsics(tf.camera_path, info, tf.fov);
    Require(!tf.gt_prior || dataset, "--ground-truth-prior needs a crease sequence dataset as input");
    FrameTracker tracker(rig, K, options, tf, dataset ? info.path : fs::path());
    const LandmarkRigFitter& fitter = tracker.fitter();

    const fs::path dir(out);
    fs::create_directories(dir / "frames");
    if (!no_meshes) fs::create_directories(dir / "meshes");
    std::unique_ptr<PvdWriter> series = no_meshes ? nullptr : std::make_unique<PvdWriter>(dir / "tracking.pvd");
    cv::VideoWriter writer;
    if (!preview.empty()) {
      const std::string ext = LowerExtension(preview);
      const int fourcc = ext == ".mp4" ? cv::VideoWriter::fourcc('m', 'p', '4', 'v') : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
      writer.open(preview, fourcc, info.fps, cv::Size(info.width, info.height));
      Require(writer.isOpened(), fmt::format("{}: cannot write this video (try .avi)", preview));
    }
    const MatX3i face_F = FaceChartTriangles(rig);
    const int total = tf.max_frames > 0 && (info.frame_count < 0 || tf.max_frames < info.frame_count) ? tf.max_frames : info.frame_count;
    Progress progress("tracking", std::max(total, 1));
    cv::Mat frame;
    int n = 0, tracked = 0, detections = 0, steady = 0;
    double landmark_ms = 0, fit_ms = 0, steady_ms = 0;
    double err_lm = 0, err_lm_iod = 0, err_fit = 0, err_vertex = 0;
    int err_frames = 0;
    const bool has_truth = dataset && fs::is_directory(info.path / "truth");
    // The truth of another rig (the dataset's) is measured through a surface correspondence.
    const RigCorrespondence corr =
        has_truth && fs::exists(info.path / "rig.crig") ? CorrespondRigs(rig, ReadRig(info.path / "rig.crig"))
            : RigCorrespondence{};
    if (!corr.same_topology) {
      std::printf("the tracking rig differs from the dataset's: vertex errors through a surface correspondence "
                  "(%d of its vertices matched)\n", corr.matched);
    }
    while ((tf.max_frames < 0 || n < tf.max_frames) && frames->Next(&frame)) {
      const TrackedFrame t = tracker.Track(frame, frames->index());
      ++n;
      tracked += t.tracked;
      detections += t.detected;
      landmark_ms += t.landmarks_ms;
      fit_ms += t.fit_ms;
      if (t.tracked && !t.detected && fitter.identity_fixed()) {  // after detection and the identity phase
        steady_ms += t.landmarks_ms + t.fit_ms;
        ++steady;
      }
      json j = TrackedFrameJson(t, rig);
      j["landmarks_ms"] = t.landmarks_ms;
      j["fit_ms"] = t.fit_ms;
      MatX2d projected;
      if (t.tracked) {
        const MatX3d V = fitter.HeadVertices(t.fit);
        const Camera cam(K, t.fit.cam_from_head);
        projected = cam.ProjectAll(V);
        if (!no_meshes) {
          const TriMesh mesh = RigMeshWithVertices(rig, V);
          WritePly(dir / "meshes" / fmt::format("{:06d}.ply", t.frame), mesh);
          const fs::path vtp = dir / "meshes" / fmt::format("{:06d}.vtp", t.frame);
          WriteVtp(vtp, mesh);
          series->Add(t.frame / info.fps, vtp);
          series->Write();
        }
        if (has_truth) {
          const FrameTruth truth = corr.MapTruth(ReadFrameTruth(info.path, t.frame, -1));
          const FrameTrackingError e =
              CompareToTruth(truth, t.landmarks, fitter.ProjectLandmarks(t.fit), projected);
          j["error"] = {{"landmark_px", e.landmark_px},
                        {"landmark_iod", e.landmark_iod},
                        {"fit_landmark_px", e.fit_landmark_px},
                        {"vertex_px", e.vertex_px}};
          err_lm += e.landmark_px;
          err_lm_iod += e.landmark_iod;
          err_fit += e.fit_landmark_px;
          err_vertex += e.vertex_px;
          ++err_frames;
        }
      }
      WriteJsonFile(dir / "frames" / fmt::format("{:06d}.json", t.frame), j);
      if (writer.isOpened()) {
        cv::Mat bgr = PreviewBgr(frame);
        DrawTracking(t, projected, face_F, &bgr);
        writer.write(bgr);
      }
      progress.Advance();
    }
    progress.Finish();
    Require(n > 0, fmt::format("{}: no frames", tf.input));
    json summary;
    summary["input"] = tf.input;
    summary["landmark_source"] = tracker.source_name();
    summary["frames"] = n;
    summary["tracked_frames"] = tracked;
    summary["detections"] = detections;
    summary["landmarks_ms"] = landmark_ms / n;
    summary["fit_ms"] = fit_ms / n;
    summary["tracking_fps"] = 1000.0 * n / std::max(landmark_ms + fit_ms, 1e-9);
    summary["steady_frames"] = steady;
    summary["steady_ms"] = steady ? steady_ms / steady : 0.0;
    summary["identity"] = std::vector<double>(fitter.identity().data(),
                                              fitter.identity().data() + fitter.identity().size());
    summary["options"] = json::parse(OptionsToJson(options));
    std::printf("tracked %d of %d frames (%d detections); landmarks %.2f ms, rig fit %.2f ms per frame (%.0f fps)\n",
                tracked, n, detections, landmark_ms / n, fit_ms / n, 1000.0 * n / std::max(landmark_ms + fit_ms, 1e-9));
    if (steady > 0) {
      std::printf("after detection and the identity phase (%d frames): %.2f ms per frame (%.0f fps)\n", steady,
                  steady_ms / steady, 1000.0 * steady / std::max(steady_ms, 1e-9));
    }
    if (err_frames > 0) {
      summary["error"] = {{"frames", err_frames},
                          {"landmark_px", err_lm / err_frames},
                          {"landmark_iod", err_lm_iod / err_frames},
                          {"fit_landmark_px", err_fit / err_frames},
                          {"vertex_px", err_vertex / err_frames}};
      std::printf("against ground truth (%d tracked frames): landmarks %.2f px (%.3f IOD), fitted rig's landmarks "
                  "%.2f px, visible vertices %.2f px\n",
                  err_frames, err_lm / err_frames, err_lm_iod / err_frames, err_fit / err_frames,
                  err_vertex / err_frames);
    }
    WriteJsonFile(dir / "summary.json", summary);
    std::printf("wrote %s\n", out.c_str());
  });
}

}  // namespace crease::app
