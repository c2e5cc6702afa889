// `crease capture` (paper Sec. 5: online capture from a video to H^t) and
// `crease eval` (its metrics against a studio sequence's ground truth), issue 6.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "apps/crease/commands.h"
#include "apps/crease/track_util.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/picture.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/timer.h"
#include "core/vtk_io.h"
#include "eval/capture_metrics.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/patches.h"

namespace crease::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct MeshSeries {
  std::string name;
  std::unique_ptr<PvdWriter> pvd;
};

}  // namespace

void AddCaptureCommands(CLI::App& app) {
  auto* cmd = app.add_subcommand("capture", "Online capture (paper Sec. 5): L^t, refined L~^t, D^t and H^t per frame");
  static TrackingFlags tf;
  static std::string model_path, out, preview, config;
  static int mesh_every = 1;
  static bool no_meshes = false, no_maps = false, write_textures = false, overwrite = false;
  static std::vector<std::string> sets;
  AddTrackingFlags(cmd, &tf);
  cmd->add_flag("--ground-truth-fit", tf.gt_fit,
                "Experimental control: the dataset's true pose, expression weights and identity as the tracker's fit "
                "(exact geometry up to the actor's personal deviations), to isolate the detail path; never a default");
  cmd->add_option("--model,-m", model_path, "Detail model (.cdm, from `crease train`)")->required();
  cmd->add_option("--out,-o", out, "Output folder (written under a temporary name, renamed when complete)")->required();
  cmd->add_option("--preview", preview, "Preview video (.avi: MJPG, .mp4: mp4v): the frame with L~^t beside D^t");
  cmd->add_option("--mesh-every", mesh_every, "Write the meshes of every N-th frame")->capture_default_str();
  cmd->add_flag("--no-meshes", no_meshes, "Skip the per-frame PLY/VTP meshes");
  cmd->add_flag("--textures", write_textures, "Also write every frame's texture T^t (textures/NNNNNN.png, sRGB gray)");
  cmd->add_flag("--no-maps", no_maps, "Skip the per-frame displacement maps D^t (EXR)");
  cmd->add_option("--config", config, "YAML of capture options (pipeline/capture/capture.h CaptureOptions)");
  cmd->add_option("--set", sets, "Capture option KEY=VALUE (repeatable), e.g. wrinkle_frames=20 refine=false");
  cmd->add_flag("--overwrite", overwrite, "Replace an existing output folder");
  cmd->callback([] {
    CaptureOptions options;
    options.tracker.landmark_source = tf.tracker_model.empty() ? tf.landmarks : "regressor";
    options.tracker.tracker_model = tf.tracker_model;
    if (!config.empty()) SetOptionsFromYaml(ReadFileToString(config), config, &options);
    if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &options);
    options.Check();
    Require(mesh_every >= 1, "--mesh-every must be at least 1");
    auto frames = OpenFrameSource(tf.input);
    const FrameSourceInfo& info = frames->info();
    const bool dataset = info.kind == "dataset";
    if (tf.rig_path.empty()) {
      Require(dataset, "--rig is required unless the input is a crease dataset");
      tf.rig_path = DatasetTrackingRig(info.path);
    }
    const CameraIntrinsics K = ResolveIntrinsics(tf.camera_path, info, tf.fov);
    const DetailModel model = ReadDetailModel(model_path);
    auto t0 = std::chrono::steady_clock::now();
    const FaceRig rig = CompatibleRig(ReadRig(tf.rig_path), model);
    const double rig_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("rig made compatible with the model's lowpass (Sec. 4.1) in %.1f s\n", rig_s);
    t0 = std::chrono::steady_clock::now();
    FrameTracker tracker(rig, K, options.tracker, tf, dataset ? info.path : fs::path());
    CaptureSession session(rig, model, K, options);
    const double setup_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("capture set up (UV raster, geodesics, stencils) in %.1f s\n", setup_s);

    const MatX3i face_F = FaceChartTriangles(rig);
    const int total = tf.max_frames > 0 && (info.frame_count < 0 || tf.max_frames < info.frame_count) ? tf.max_frames
                                                                                               : info.frame_count;
    WriteFolderAtomic(out, overwrite, [&](const fs::path& dir) {
      fs::create_directories(dir / "frames");
      fs::create_directories(dir / "maps");
      if (!no_maps) fs::create_directories(dir / "displacement");
      if (write_textures) fs::create_directories(dir / "textures");
      std::vector<MeshSeries> series;
      if (!no_meshes) {
        for (const char* name : {"coarse", "refined", "hifi"}) {
          fs::create_directories(dir / "meshes" / name);
          series.push_back({name, std::make_unique<PvdWriter>(dir / fmt::format("{}.pvd", name))});
        }
      }
      WriteRig(dir / "rig.crig", rig);
      cv::VideoWriter writer;
      const int panel = info.height;
      if (!preview.empty()) {
        const std::string ext = LowerExtension(preview);
        const int fourcc =
            ext == ".mp4" ? cv::VideoWriter::fourcc('m', 'p', '4', 'v') : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
        writer.open(preview, fourcc, info.fps, cv::Size(info.width + panel, info.height));
        Require(writer.isOpened(), fmt::format("{}: cannot write this video (try .avi)", preview));
        fs::create_directories(dir / "previews");
      }
      // Previews need the frame; keep the frames of the wrinkle-map phase until they are returned.
      std::map<int, cv::Mat> pending_images;
      TimingReport timing;
      std::ofstream csv_stream;
      std::string csv =
          "frame,tracked,detected,landmarks_ms,fit_ms,visibility_ms,refine_ms,texture_ms,mesoscopic_ms,detail_ms,"
          "hifi_ms,total_ms,flow_trusted,flow_recovered,flow_reset\n";
      std::vector<int> indices;
      int n = 0, tracked_n = 0, detail_n = 0, steady = 0;
      double steady_total = 0, steady_tracking = 0, steady_detail = 0;
      CaptureTiming steady_sum;
      const double scale_mm = 0.3;

      auto emit = [&](const CapturedFrame& f) {
        const TrackedFrame& t = f.tracked;
        indices.push_back(f.frame);
        tracked_n += f.has_mesh;
        detail_n += f.has_detail;
        const CaptureTiming& ct = f.timing;
        json j = TrackedFrameJson(t, rig);
        if (t.tracked && f.refinement.vertices.rows() > 0) {
          j["refinement"] = {{"trusted", f.refinement.trusted},
                             {"recovered", f.refinement.recovered},
                             {"reset", f.refinement.reset},
                             {"invisible", f.refinement.invisible},
                             {"pull", f.refinement.pull},
                             {"tracker_noise_px", f.refinement.tracker_noise_px},
                             {"step_sigma_px", f.refinement.step_sigma_px},
                             {"gate_outliers", f.refinement.gate_outliers},
                             {"reference_tracked", f.refinement.reference_tracked},
                             {"cam_from_head", PoseJson(f.refinement.fit.cam_from_head)}};
        }
        j["timing_ms"] = {{"landmarks", ct.landmarks_ms}, {"fit", ct.fit_ms},          {"visibility", ct.visibility_ms},
                          {"refine", ct.refine_ms},       {"texture", ct.texture_ms},  {"mesoscopic", ct.mesoscopic_ms},
                          {"detail", ct.detail_ms},       {"hifi", ct.hifi_ms},        {"wrinkle_map", ct.wrinkle_map_ms},
                          {"total", ct.total_ms()}};
        WriteJsonFile(dir / "frames" / fmt::format("{:06d}.json", f.frame), j);
        WriteCaptureFrameArrays(dir / "frames" / fmt::format("{:06d}.cfr", f.frame), MakeCaptureFrameArrays(f));
        csv += fmt::format("{},{},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{}\n", f.frame,
                           f.has_mesh ? 1 : 0, t.detected ? 1 : 0, ct.landmarks_ms, ct.fit_ms, ct.visibility_ms,
                           ct.refine_ms, ct.texture_ms, ct.mesoscopic_ms, ct.detail_ms, ct.hifi_ms, ct.total_ms(),
                           f.refinement.trusted, f.refinement.recovered, f.refinement.reset);
        if (f.has_detail) {
          timing.Add("global tracker: landmarks", ct.landmarks_ms / 1e3);
          timing.Add("global tracker: rig fit", ct.fit_ms / 1e3);
          timing.Add("visibility (depth buffer)", ct.visibility_ms / 1e3);
          timing.Add("flow refinement (Sec. 5.1)", ct.refine_ms / 1e3);
          timing.Add("texture T^t", ct.texture_ms / 1e3);
          timing.Add("detail regression (Sec. 5.2)", ct.detail_ms / 1e3);
          timing.Add("H^t (Sec. 5.3)", ct.hifi_ms / 1e3);
          if (ct.wrinkle_map_ms > 0) timing.Add("once: wrinkle map (first N frames)", ct.wrinkle_map_ms / 1e3);
          if (ct.mesoscopic_ms > 0) timing.Add("once: mesoscopic map (first frame)", ct.mesoscopic_ms / 1e3);
          if (!t.detected && ct.mesoscopic_ms == 0) {  // steady state: no detection, not the first frame
            ++steady;
            steady_total += ct.total_ms();
            steady_tracking += ct.tracking_ms();
            steady_detail += ct.detail_total_ms();
          }
        }
        if (f.has_mesh && write_textures) {
          WriteImage(dir / "textures" / fmt::format("{:06d}.png", f.frame), f.texture.gray);
        }
        if (f.has_detail && !no_maps) {
          // Half floats: D^t is a fraction of a millimetre, so 11 bits of mantissa keep it to
          // ~0.1 µm, and a paper-size sequence's maps take half the disk.
          WriteImage(dir / "displacement" / fmt::format("{:06d}.exr", f.frame), f.displacement, {.half = true});
        }
        if (f.has_mesh && !no_meshes && f.frame % mesh_every == 0) {
          const double time_s = f.frame / info.fps;
          const std::vector<std::pair<int, TriMesh>> meshes = {
              {0, RigMeshWithVertices(rig, f.coarse)},
              {1, RigMeshWithVertices(rig, f.refined)},
              {2, session.HifiMesh(f)}};
          for (const auto& [k, mesh] : meshes) {
            const fs::path base = dir / "meshes" / series[k].name / fmt::format("{:06d}", f.frame);
            WritePly(base.string() + ".ply", mesh);
            WriteVtp(base.string() + ".vtp", mesh);
            series[k].pvd->Add(time_s, base.string() + ".vtp");
            series[k].pvd->Write();
          }
        }
        if (writer.isOpened()) {
          auto it = pending_images.find(f.frame);
          cv::Mat bgr = PreviewBgr(it->second);
          pending_images.erase(it);
          MatX2d projected;
          if (f.has_mesh) {
            const Camera cam(K, Rigid3d());
            projected.resize(f.refined.rows(), 2);
            for (int i = 0; i < f.refined.rows(); ++i) projected.row(i) = cam.ProjectCamPoint(f.refined.row(i).transpose()).transpose();
          }
          DrawTracking(t, projected, face_F, &bgr);
          cv::Mat side = cv::Mat::zeros(panel, panel, CV_8UC3);
          if (f.has_detail) cv::resize(DisplacementPicture(f.displacement, scale_mm, cv::Mat(), /*bgr=*/true), side, side.size(), 0, 0, cv::INTER_AREA);
          cv::putText(side, fmt::format("D^t  +/-{:.1f} mm", scale_mm), cv::Point(8, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                      cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
          cv::Mat both;
          cv::hconcat(bgr, side, both);
          writer.write(both);
          // Stills of the preview every 30 frames, to look at without a video player.
          if (f.frame % 30 == 0) cv::imwrite((dir / "previews" / fmt::format("{:06d}.png", f.frame)).string(), both);
        }
      };

      Progress progress("capturing", std::max(total, 1));
      cv::Mat frame;
      while ((tf.max_frames < 0 || n < tf.max_frames) && frames->Next(&frame)) {
        const int index = frames->index();
        const TrackedFrame t = tracker.Track(frame, index);
        if (writer.isOpened()) pending_images[index] = frame.clone();
        for (const CapturedFrame& f : session.Process(index, frame, t, tracker.identity())) emit(f);
        ++n;
        progress.Advance();
      }
      for (const CapturedFrame& f : session.Flush()) emit(f);
      progress.Finish();
      Require(n > 0, fmt::format("{}: no frames", tf.input));

      // Per-actor maps of the session.
      if (!session.mesoscopic().empty()) WriteImage(dir / "maps" / "mesoscopic.exr", session.mesoscopic());
      if (session.layout_fixed()) {
        const WrinkleMap& wm = session.detail().wrinkle_map();
        WriteImage(dir / "maps" / "wrinkle_map.exr", wm.probability);
        WriteImage(dir / "maps" / "wrinkle_map.png", DrawPatchLayout(wm.probability, session.detail().layout(), wm.valid));
      }
      WriteFileAtomic(dir / "timings.csv", [&](std::ostream& o) { o << csv; });
      json summary;
      summary["input"] = tf.input;
      summary["model"] = model_path;
      summary["rig"] = "rig.crig";
      summary["source_rig"] = tf.rig_path;
      summary["landmark_source"] = tracker.source_name();
      summary["frames"] = n;
      summary["frame_indices"] = indices;
      summary["tracked_frames"] = tracked_n;
      summary["detail_frames"] = detail_n;
      summary["map_resolution"] = model.map_resolution;
      summary["detail_extraction"] = json::parse(OptionsToJson(model.detail));  // the model's G (eval's truth)
      summary["patches"] = session.layout_fixed() ? session.detail().layout().num_patches() : 0;
      summary["wrinkle_frames"] = session.layout_fixed() ? session.detail().frames_added() : 0;
      summary["steady_frames"] = steady;
      const double mean_total = steady ? steady_total / steady : 0.0;
      summary["fps"] = mean_total > 0 ? 1000.0 / mean_total : 0.0;
      summary["ms_per_frame"] = mean_total;
      summary["tracking_share"] = steady_total > 0 ? steady_tracking / steady_total : 0.0;
      summary["detail_share"] = steady_total > 0 ? steady_detail / steady_total : 0.0;
      summary["timing"] = json::parse(timing.ToJson());
      summary["setup_s"] = setup_s + rig_s;
      const Eigen::VectorXd identity = tracker.identity();
      summary["identity"] = std::vector<double>(identity.data(), identity.data() + identity.size());
      summary["options"] = json::parse(OptionsToJson(options));
      WriteJsonFile(dir / "capture.json", summary);
      std::printf("captured %d frames: %d tracked, %d with detail, %d patches from a wrinkle map of %d frames\n", n,
                  tracked_n, detail_n, summary["patches"].get<int>(), summary["wrinkle_frames"].get<int>());
      std::printf("%s", timing.ToTable().c_str());
      if (steady > 0) {
        std::printf("steady state (%d frames, file I/O excluded): %.1f ms per frame = %.1f fps; tracking %.0f %%, "
                    "detail %.0f %% (paper: 18 fps on a GTX 980, 58 %% / 42 %%)\n",
                    steady, mean_total, 1000.0 / mean_total, 100 * steady_tracking / steady_total,
                    100 * steady_detail / steady_total);
      }
    });
    std::printf("wrote %s\n", out.c_str());
  });

  auto* ev = app.add_subcommand("eval", "Metrics of a capture against a studio sequence's ground truth (issue 6)");
  static std::string capture_dir, dataset_dir, eval_out;
  static std::vector<std::string> eval_sets;
  ev->add_option("--capture,-c", capture_dir, "Capture folder (from `crease capture`)")->required();
  ev->add_option("--dataset,-d", dataset_dir, "Sequence dataset (from `crease synth sequence`)")->required();
  ev->add_option("--out,-o", eval_out, "Output folder (default: the capture folder)");
  ev->add_option("--set", eval_sets, "Eval option KEY=VALUE (eval/capture_metrics.h), e.g. surface_every=10");
  ev->callback([] {
    CaptureEvalOptions options;
    if (!eval_sets.empty()) SetOptionsFromJson(SetPairsToJson(eval_sets), "--set", &options);
    const CaptureEvalSummary s = EvaluateCapture(capture_dir, dataset_dir, options);
    const fs::path dir = eval_out.empty() ? fs::path(capture_dir) : fs::path(eval_out);
    fs::create_directories(dir);
    const std::string md = s.ToMarkdown(), js = s.ToJson(), csv = s.ToCsv();
    WriteFileAtomic(dir / "eval.json", [&](std::ostream& o) { o << js << "\n"; });
    WriteFileAtomic(dir / "eval_frames.csv", [&](std::ostream& o) { o << csv; });
    WriteFileAtomic(dir / "eval.md", [&](std::ostream& o) { o << md; });
    if (!s.error_vectors.empty()) {  // Fig. 11
      WriteImage(dir / "error_vectors.png", s.error_vectors, {.srgb = false});
      std::printf("wrote %s (frame %d: 2D error vectors of L^t and L~^t)\n",
                  (dir / "error_vectors.png").string().c_str(), s.error_vectors_frame);
    }
    std::printf("%s\nwrote %s/eval.{md,json} and eval_frames.csv\n", md.c_str(), dir.string().c_str());
  });
}

}  // namespace crease::app
