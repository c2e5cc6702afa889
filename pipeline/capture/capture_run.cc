#include "pipeline/capture/capture_run.h"

#include <algorithm>
#include <functional>
#include <map>
#include <memory>
#include <utility>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <tbb/parallel_invoke.h>

#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/picture.h"
#include "core/progress.h"
#include "core/vtk_io.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/capture/tracking_record.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/trainer.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

void CaptureRunOptions::Check() const {
  Require(!out.empty(), "CaptureRunOptions.out: no output folder given");
  Require(mesh_every >= 1, fmt::format("CaptureRunOptions.mesh_every = {}: must be at least 1", mesh_every));
  Require(pairs_every >= 1, fmt::format("CaptureRunOptions.pairs_every = {}: must be at least 1", pairs_every));
}

namespace {

constexpr double kPreviewRangeMm = 0.3;  // the preview's D^t colour range, ± mm
constexpr int kPreviewStillEvery = 30;   // a still of the preview every N-th frame number

constexpr char kCsvHeader[] =
    "frame,tracked,detected,landmarks_ms,fit_ms,visibility_ms,refine_ms,texture_ms,mesoscopic_ms,detail_ms,"
    "hifi_ms,total_ms,flow_trusted,flow_recovered,flow_reset\n";

// The frame's record: TrackedFrameJson, the flow statistics of a refined frame, the stage times.
json CapturedFrameJson(const CapturedFrame& f, const FaceRig& rig) {
  json j = TrackedFrameJson(f.tracked, rig);
  const RefinedFrame& r = f.refinement;
  if (f.tracked.tracked && r.vertices.rows() > 0) {
    j["refinement"] = {{"trusted", r.trusted},
                       {"recovered", r.recovered},
                       {"reset", r.reset},
                       {"invisible", r.invisible},
                       {"pull", r.pull},
                       {"tracker_noise_px", r.tracker_noise_px},
                       {"step_sigma_px", r.step_sigma_px},
                       {"gate_outliers", r.gate_outliers},
                       {"reference_tracked", r.reference_tracked},
                       {"cam_from_head", PoseJson(r.fit.cam_from_head)}};
  }
  const CaptureTiming& ct = f.timing;
  if (ct.detail.reference_shift >= 0) j["reference_shift"] = ct.detail.reference_shift;  // coarse texels
  j["timing_ms"] = {{"landmarks", ct.landmarks_ms}, {"fit", ct.fit_ms},          {"visibility", ct.visibility_ms},
                    {"refine", ct.refine_ms},       {"texture", ct.texture_ms},  {"mesoscopic", ct.mesoscopic_ms},
                    {"detail", ct.detail_ms},       {"hifi", ct.hifi_ms},        {"wrinkle_map", ct.wrinkle_map_ms},
                    {"total", ct.total_ms()}};
  return j;
}

// The frame's row of timings.csv (kCsvHeader).
std::string CsvRow(const CapturedFrame& f) {
  const CaptureTiming& ct = f.timing;
  return fmt::format("{},{},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{}\n", f.frame,
                     f.has_mesh ? 1 : 0, f.tracked.detected ? 1 : 0, ct.landmarks_ms, ct.fit_ms, ct.visibility_ms,
                     ct.refine_ms, ct.texture_ms, ct.mesoscopic_ms, ct.detail_ms, ct.hifi_ms, ct.total_ms(),
                     f.refinement.trusted, f.refinement.recovered, f.refinement.reset);
}

// The stage times of a frame with D^t, into the run's table.
void AddStageTimes(const CaptureTiming& ct, TimingReport* timing) {
  timing->Add("global tracker: landmarks", ct.landmarks_ms / 1e3);
  timing->Add("global tracker: rig fit", ct.fit_ms / 1e3);
  timing->Add("visibility (depth buffer)", ct.visibility_ms / 1e3);
  timing->Add("flow refinement (Sec. 5.1)", ct.refine_ms / 1e3);
  timing->Add("texture T^t", ct.texture_ms / 1e3);
  timing->Add("detail regression (Sec. 5.2)", ct.detail_ms / 1e3);
  timing->Add("H^t (Sec. 5.3)", ct.hifi_ms / 1e3);
  if (ct.wrinkle_map_ms > 0) timing->Add("once: wrinkle map (first N frames)", ct.wrinkle_map_ms / 1e3);
  if (ct.mesoscopic_ms > 0) timing->Add("once: mesoscopic map (first frame)", ct.mesoscopic_ms / 1e3);
}

// Sums over the steady-state frames: with D^t, no detection, not the first textured frame.
struct SteadyState {
  int frames = 0;
  double total_ms = 0, tracking_ms = 0, detail_ms = 0;  // stage times summed
  int wall_frames = 0;  // overlapped frames: the steps that finished one steady frame
  double wall_ms = 0;
  static bool IsSteady(const CapturedFrame& f) {
    return f.has_detail && !f.tracked.detected && f.timing.mesoscopic_ms == 0;
  }
  void Add(const CapturedFrame& f) {
    if (!IsSteady(f)) return;
    const CaptureTiming& ct = f.timing;
    ++frames;
    total_ms += ct.total_ms();
    tracking_ms += ct.tracking_ms();
    detail_ms += ct.detail_total_ms();
  }
  // One overlapped step of `ms`: it finished `finished` while beginning the frame
  // tracked as `begun` (nullptr: none, the last step).
  void AddStep(double ms, const std::vector<CapturedFrame>& finished, const TrackedFrame* begun) {
    if (finished.size() != 1 || !IsSteady(finished[0])) return;
    if (begun && (!begun->tracked || begun->detected)) return;
    ++wall_frames;
    wall_ms += ms;
  }
};

// A mesh time series: meshes/NAME/NNNNNN.{ply,vtp} and NAME.pvd.
struct MeshSeries {
  std::string name;
  std::unique_ptr<PvdWriter> pvd;
};

// The table and the JSON of a summary's stage times (TimingReport::ToTable, ToJson).
std::string TimingTable(const std::vector<TimingReport::Entry>& entries) {
  TimingReport report;
  for (const TimingReport::Entry& e : entries) report.Add(e.name, e.total_seconds, e.count);
  return report.ToTable();
}
json TimingJson(const std::vector<TimingReport::Entry>& entries) {
  TimingReport report;
  for (const TimingReport::Entry& e : entries) report.Add(e.name, e.total_seconds, e.count);
  return json::parse(report.ToJson());
}

// capture.json (CaptureSummary::ToJson).
json SummaryJson(const CaptureSummary& s) {
  json j;
  j["input"] = s.input;
  j["model"] = s.model;
  j["rig"] = "rig.crig";
  j["source_rig"] = s.source_rig;
  j["landmark_source"] = s.landmark_source;
  j["frames"] = s.frames;
  j["frame_indices"] = s.frame_indices;
  j["tracked_frames"] = s.tracked_frames;
  j["detail_frames"] = s.detail_frames;
  j["map_resolution"] = s.map_resolution;
  j["detail_extraction"] = json::parse(s.detail_extraction_json);  // the model's G (eval's truth)
  j["patches"] = s.patches;
  j["wrinkle_frames"] = s.wrinkle_frames;
  j["overlapped"] = s.overlapped;
  j["steady_frames"] = s.steady_frames;
  j["fps"] = s.fps;
  j["ms_per_frame"] = s.ms_per_frame;
  j["stage_ms_per_frame"] = s.stage_ms_per_frame;
  j["tracking_share"] = s.tracking_share;
  j["detail_share"] = s.detail_share;
  j["timing"] = TimingJson(s.timing);
  j["setup_s"] = s.setup_s;
  j["identity"] = std::vector<double>(s.identity.data(), s.identity.data() + s.identity.size());
  j["options"] = json::parse(s.options_json);
  return j;
}

// Writes one capture folder, frame by frame as the session returns them.
class CaptureRecorder {
 public:
  CaptureRecorder(const CaptureRunOptions& options, const CameraIntrinsics& intrinsics, const FrameSourceInfo& info,
                  const CaptureSession& session, const fs::path& dir);
  // Keeps the frame for the preview until the session returns it (the first N frames wait for the wrinkle map).
  void Keep(int index, const cv::Mat& frame);
  void Record(const CapturedFrame& f);
  // The wall clock of one overlapped step (SteadyState::AddStep).
  void AddStep(double ms, const std::vector<CapturedFrame>& finished, const TrackedFrame* begun) {
    steady_.AddStep(ms, finished, begun);
  }
  // Writes the session's maps, timings.csv and capture.json; returns the summary of `frames` frames.
  CaptureSummary Finish(int frames, const CaptureOptions& capture_options, const DetailModel& model,
                        const GlobalTracker& tracker) const;

 private:
  void CreateFolders();
  void OpenPreview();
  void WriteMaps(const CapturedFrame& f) const;
  void WriteMeshes(const CapturedFrame& f);
  void WritePreview(const CapturedFrame& f);
  void CutPairs(const CapturedFrame& f);
  void WritePairs(const DetailModel& model) const;

  const CaptureRunOptions& options_;
  const CameraIntrinsics& intrinsics_;
  const FrameSourceInfo& info_;
  const CaptureSession& session_;
  const fs::path dir_;
  const MatX3i face_F_;
  std::vector<MeshSeries> series_;
  cv::VideoWriter writer_;
  std::map<int, cv::Mat> pending_images_;
  TimingReport timing_;
  std::string csv_ = kCsvHeader;
  std::vector<int> indices_;
  int tracked_ = 0, with_detail_ = 0;
  SteadyState steady_;
  // pairs_truth_maps: the frames' pairs (DetailRegressor::CutPairs), one block per frame.
  std::vector<Eigen::MatrixXf> pair_texture_, pair_displacement_;
  std::vector<int> pair_frames_;
};

CaptureRecorder::CaptureRecorder(const CaptureRunOptions& options, const CameraIntrinsics& intrinsics,
                                 const FrameSourceInfo& info, const CaptureSession& session, const fs::path& dir)
    : options_(options),
      intrinsics_(intrinsics),
      info_(info),
      session_(session),
      dir_(dir),
      face_F_(FaceChartTriangles(session.rig())) {
  CreateFolders();
  WriteRig(dir_ / "rig.crig", session_.rig());
  OpenPreview();
}

void CaptureRecorder::CreateFolders() {
  fs::create_directories(dir_ / "frames");
  fs::create_directories(dir_ / "maps");
  if (options_.write_maps) fs::create_directories(dir_ / "displacement");
  if (options_.write_textures) fs::create_directories(dir_ / "textures");
  if (!options_.write_meshes) return;
  for (const char* name : {"coarse", "refined", "hifi"}) {
    fs::create_directories(dir_ / "meshes" / name);
    series_.push_back({name, std::make_unique<PvdWriter>(dir_ / fmt::format("{}.pvd", name))});
  }
}

void CaptureRecorder::OpenPreview() {
  if (options_.preview.empty()) return;
  const std::string ext = LowerExtension(options_.preview);
  const int fourcc =
      ext == ".mp4" ? cv::VideoWriter::fourcc('m', 'p', '4', 'v') : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  // The frame with, beside it, a square panel of D^t as high as the frame.
  writer_.open(options_.preview, fourcc, info_.fps, cv::Size(info_.width + info_.height, info_.height));
  Require(writer_.isOpened(), fmt::format("{}: cannot write this video (try .avi)", options_.preview));
  fs::create_directories(dir_ / "previews");
}

void CaptureRecorder::Keep(int index, const cv::Mat& frame) {
  if (writer_.isOpened()) pending_images_[index] = frame.clone();
}

void CaptureRecorder::Record(const CapturedFrame& f) {
  indices_.push_back(f.frame);
  tracked_ += f.has_mesh;
  with_detail_ += f.has_detail;
  WriteJsonFile(dir_ / "frames" / fmt::format("{:06d}.json", f.frame), CapturedFrameJson(f, session_.rig()));
  WriteCaptureFrameArrays(dir_ / "frames" / fmt::format("{:06d}.cfr", f.frame), MakeCaptureFrameArrays(f));
  csv_ += CsvRow(f);
  if (f.has_detail) AddStageTimes(f.timing, &timing_);
  steady_.Add(f);
  WriteMaps(f);
  WriteMeshes(f);
  WritePreview(f);
  CutPairs(f);
}

void CaptureRecorder::CutPairs(const CapturedFrame& f) {
  if (options_.pairs_truth_maps.empty() || !f.has_detail || f.frame % options_.pairs_every != 0) return;
  const int R = session_.detail().map_size();
  const cv::Mat truth = ReadFrameMap(options_.pairs_truth_maps, f.frame, R, "pairs_truth_maps");
  Eigen::MatrixXf t, d;
  session_.detail().CutPairs(f.texture.gray, f.texture.seen, truth, &t, &d);
  pair_texture_.push_back(std::move(t));
  pair_displacement_.push_back(std::move(d));
  pair_frames_.push_back(f.frame);
}

// pairs.cpr: the frames' pairs as a training pair file (WriteTrainingPairs), with the
// model's extraction options so that `crease model eval-pairs` reads them as its own.
void CaptureRecorder::WritePairs(const DetailModel& model) const {
  if (options_.pairs_truth_maps.empty()) return;
  TrainingPairs pairs;
  pairs.options_json = nlohmann::json::parse(model.training_json).value("options", nlohmann::json::object()).dump();
  pairs.scan_set = options_.input;
  pairs.scans = static_cast<int>(pair_frames_.size());
  pairs.actors = pairs.scans;
  Eigen::Index rows = 0;
  for (const Eigen::MatrixXf& t : pair_texture_) rows += t.rows();
  const Eigen::Index n = pair_texture_.empty() ? 0 : pair_texture_.front().cols();
  pairs.texture.resize(rows, n);
  pairs.displacement.resize(rows, n);
  Eigen::Index row = 0;
  for (size_t k = 0; k < pair_frames_.size(); ++k) {
    const Eigen::Index m = pair_texture_[k].rows();
    pairs.texture.middleRows(row, m) = pair_texture_[k];
    pairs.displacement.middleRows(row, m) = pair_displacement_[k];
    pairs.actor.insert(pairs.actor.end(), static_cast<size_t>(m), static_cast<int32_t>(k));
    pairs.actor_names.push_back(fmt::format("frame_{:06d}", pair_frames_[k]));
    row += m;
  }
  WriteTrainingPairs(dir_ / "pairs.cpr", pairs);
}

void CaptureRecorder::WriteMaps(const CapturedFrame& f) const {
  if (f.has_mesh && options_.write_textures) {
    WriteImage(dir_ / "textures" / fmt::format("{:06d}.png", f.frame), f.texture.gray);
  }
  if (f.has_detail && options_.write_maps) {
    // Half floats: D^t is a fraction of a millimetre, so 11 bits of mantissa keep it to
    // ~0.1 µm, and a paper-size sequence's maps take half the disk.
    WriteImage(dir_ / "displacement" / fmt::format("{:06d}.exr", f.frame), f.displacement, {.half = true});
  }
}

void CaptureRecorder::WriteMeshes(const CapturedFrame& f) {
  if (!f.has_mesh || !options_.write_meshes || f.frame % options_.mesh_every != 0) return;
  const double time_s = f.frame / info_.fps;
  const FaceRig& rig = session_.rig();
  const std::vector<std::pair<int, TriMesh>> meshes = {
      {0, RigMeshWithVertices(rig, f.coarse)}, {1, RigMeshWithVertices(rig, f.refined)}, {2, session_.HifiMesh(f)}};
  for (const auto& [k, mesh] : meshes) {
    const fs::path base = dir_ / "meshes" / series_[k].name / fmt::format("{:06d}", f.frame);
    WritePly(base.string() + ".ply", mesh);
    WriteVtp(base.string() + ".vtp", mesh);
    series_[k].pvd->Add(time_s, base.string() + ".vtp");
    series_[k].pvd->Write();
  }
}

void CaptureRecorder::WritePreview(const CapturedFrame& f) {
  if (!writer_.isOpened()) return;
  auto it = pending_images_.find(f.frame);
  cv::Mat bgr = PreviewBgr(it->second);
  pending_images_.erase(it);
  MatX2d projected;
  if (f.has_mesh) {
    const Camera cam(intrinsics_, Rigid3d());
    projected.resize(f.refined.rows(), 2);
    for (int i = 0; i < f.refined.rows(); ++i) {
      projected.row(i) = cam.ProjectCamPoint(f.refined.row(i).transpose()).transpose();
    }
  }
  DrawTracking(f.tracked, projected, face_F_, &bgr);
  const int panel = info_.height;
  cv::Mat side = cv::Mat::zeros(panel, panel, CV_8UC3);
  if (f.has_detail) {
    cv::resize(DisplacementPicture(f.displacement, kPreviewRangeMm, cv::Mat(), /*bgr=*/true), side, side.size(), 0,
               0, cv::INTER_AREA);
  }
  cv::putText(side, fmt::format("D^t  +/-{:.1f} mm", kPreviewRangeMm), cv::Point(8, 18), cv::FONT_HERSHEY_SIMPLEX,
              0.5, cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
  cv::Mat both;
  cv::hconcat(bgr, side, both);
  writer_.write(both);
  // Stills of the preview, to look at without a video player.
  if (f.frame % kPreviewStillEvery == 0) {
    cv::imwrite((dir_ / "previews" / fmt::format("{:06d}.png", f.frame)).string(), both);
  }
}

CaptureSummary CaptureRecorder::Finish(int frames, const CaptureOptions& capture_options, const DetailModel& model,
                                       const GlobalTracker& tracker) const {
  // Per-actor maps of the session.
  if (!session_.mesoscopic().empty()) WriteImage(dir_ / "maps" / "mesoscopic.exr", session_.mesoscopic());
  if (session_.layout_fixed()) {
    const WrinkleMap& wm = session_.detail().wrinkle_map();
    WriteImage(dir_ / "maps" / "wrinkle_map.exr", wm.probability);
    WriteImage(dir_ / "maps" / "wrinkle_map.png", DrawPatchLayout(wm.probability, session_.detail().layout(), wm.valid));
  }
  WriteFileAtomic(dir_ / "timings.csv", [&](std::ostream& o) { o << csv_; });
  WritePairs(model);

  CaptureSummary s;
  s.input = options_.input;
  s.model = options_.model_path;
  s.source_rig = options_.source_rig;
  s.landmark_source = tracker.source_name();
  s.frames = frames;
  s.tracked_frames = tracked_;
  s.detail_frames = with_detail_;
  s.frame_indices = indices_;
  s.map_resolution = model.map_resolution;
  s.detail_extraction_json = OptionsToJson(model.detail);
  s.patches = session_.layout_fixed() ? session_.detail().layout().num_patches() : 0;
  s.wrinkle_frames = session_.layout_fixed() ? session_.detail().frames_added() : 0;
  s.overlapped = options_.overlap_frames;
  s.stage_ms_per_frame = steady_.frames ? steady_.total_ms / steady_.frames : 0.0;
  s.steady_frames = s.overlapped ? steady_.wall_frames : steady_.frames;
  s.ms_per_frame = !s.overlapped                ? s.stage_ms_per_frame
                   : steady_.wall_frames > 0 ? steady_.wall_ms / steady_.wall_frames
                                             : 0.0;
  s.fps = s.ms_per_frame > 0 ? 1000.0 / s.ms_per_frame : 0.0;
  s.tracking_share = steady_.total_ms > 0 ? steady_.tracking_ms / steady_.total_ms : 0.0;
  s.detail_share = steady_.total_ms > 0 ? steady_.detail_ms / steady_.total_ms : 0.0;
  s.timing = timing_.Entries();
  s.setup_s = options_.setup_s;
  s.identity = tracker.identity();
  s.options_json = OptionsToJson(capture_options);
  WriteJsonFile(dir_ / "capture.json", SummaryJson(s));
  return s;
}

}  // namespace

std::string CaptureSummary::BriefReport() const {
  std::string s = fmt::format("captured {} frames: {} tracked, {} with detail, {} patches from a wrinkle map of {} frames\n",
                              frames, tracked_frames, detail_frames, patches, wrinkle_frames);
  s += TimingTable(timing);
  if (steady_frames > 0 && overlapped) {
    s += fmt::format("steady state ({} frames, file I/O excluded, frames overlapped on the cores): {:.1f} ms per frame "
                     "= {:.1f} fps (wall clock; the stage times sum to {:.1f} ms); tracking {:.0f} %, detail {:.0f} % of "
                     "the stage times (paper: 18 fps on a GTX 980, 58 % / 42 %)\n",
                     steady_frames, ms_per_frame, fps, stage_ms_per_frame, 100 * tracking_share, 100 * detail_share);
  } else if (steady_frames > 0) {
    s += fmt::format("steady state ({} frames, file I/O excluded): {:.1f} ms per frame = {:.1f} fps; tracking {:.0f} %, "
                     "detail {:.0f} % (paper: 18 fps on a GTX 980, 58 % / 42 %)\n",
                     steady_frames, ms_per_frame, fps, 100 * tracking_share, 100 * detail_share);
  }
  return s;
}

std::string CaptureSummary::ToJson() const { return SummaryJson(*this).dump(2); }

namespace {

// One frame after another: tracked, begun and finished, then recorded. Returns the
// number of frames read.
int RunFramesInOrder(const CaptureRunOptions& options, FrameSource* frames, GlobalTracker* tracker,
                     CaptureSession* session, CaptureRecorder* recorder, Progress* progress) {
  cv::Mat frame;
  int n = 0;
  while ((options.max_frames < 0 || n < options.max_frames) && frames->Next(&frame)) {
    const int index = frames->index();
    const TrackedFrame t = tracker->Track(frame, index);
    recorder->Keep(index, frame);
    for (const CapturedFrame& f : session->Process(index, frame, t, tracker->identity())) recorder->Record(f);
    ++n;
    progress->Advance();
  }
  for (const CapturedFrame& f : session->Flush()) recorder->Record(f);
  return n;
}

// Frames overlapped on the cores (CaptureRunOptions::overlap_frames): each step
// tracks and begins the next frame beside the Finish of the frames begun before
// (tbb::parallel_invoke; each half keeps its own order), then records those. The
// session's Begin/Finish contract makes the outputs those of RunFramesInOrder.
int RunFramesOverlapped(const CaptureRunOptions& options, FrameSource* frames, GlobalTracker* tracker,
                        CaptureSession* session, CaptureRecorder* recorder, Progress* progress) {
  std::vector<CapturedFrame> ready;  // begun, to finish in the next step
  // One step: `begin` beside the Finish of `ready`, timed; then `ready` is recorded.
  const auto step = [&](const std::function<void()>& begin, const TrackedFrame* begun) {
    const ScopedTimer timer(nullptr, "");
    tbb::parallel_invoke(begin, [&] {
      for (CapturedFrame& f : ready) session->Finish(&f);
    });
    recorder->AddStep(1e3 * timer.Elapsed(), ready, begun);
    for (const CapturedFrame& f : ready) recorder->Record(f);
  };
  cv::Mat frame;
  int n = 0;
  while ((options.max_frames < 0 || n < options.max_frames) && frames->Next(&frame)) {
    const int index = frames->index();
    recorder->Keep(index, frame);
    TrackedFrame t;
    std::vector<CapturedFrame> begun;
    step(
        [&] {
          t = tracker->Track(frame, index);
          begun = session->Begin(index, frame, t, tracker->identity());
        },
        &t);
    ready = std::move(begun);
    ++n;
    progress->Advance();
  }
  for (CapturedFrame& f : session->EndInput()) ready.push_back(std::move(f));
  step([] {}, nullptr);
  return n;
}

}  // namespace

CaptureSummary RunCapture(const CaptureRunOptions& options, const CaptureOptions& capture_options,
                          const DetailModel& model, const CameraIntrinsics& intrinsics, FrameSource* frames,
                          GlobalTracker* tracker, CaptureSession* session) {
  options.Check();
  const FrameSourceInfo& info = frames->info();
  const int total = options.max_frames > 0 && (info.frame_count < 0 || options.max_frames < info.frame_count)
                        ? options.max_frames
                        : info.frame_count;
  CaptureSummary summary;
  WriteFolderAtomic(options.out, options.overwrite, [&](const fs::path& dir) {
    CaptureRecorder recorder(options, intrinsics, info, *session, dir);
    Progress progress("capturing", std::max(total, 1));
    const int n = options.overlap_frames ? RunFramesOverlapped(options, frames, tracker, session, &recorder, &progress)
                                         : RunFramesInOrder(options, frames, tracker, session, &recorder, &progress);
    progress.Finish();
    Require(n > 0, fmt::format("{}: no frames", options.input));
    summary = recorder.Finish(n, capture_options, model, *tracker);
  });
  summary.out = options.out;
  summary.capture_json = options.out / "capture.json";
  summary.timings_csv = options.out / "timings.csv";
  summary.preview = options.preview;
  return summary;
}

}  // namespace crease
