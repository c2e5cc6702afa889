#include "eval/track_run.h"

#include <algorithm>
#include <memory>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/vtk_io.h"
#include "eval/rig_correspondence.h"
#include "eval/tracking_metrics.h"
#include "pipeline/capture/tracking_record.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

nlohmann::json SummaryJson(const TrackSummary& s) {
  json j;
  j["input"] = s.input;
  j["landmark_source"] = s.landmark_source;
  j["frames"] = s.frames;
  j["tracked_frames"] = s.tracked_frames;
  j["detections"] = s.detections;
  j["landmarks_ms"] = s.landmarks_ms;
  j["fit_ms"] = s.fit_ms;
  j["tracking_fps"] = s.tracking_fps();
  j["steady_frames"] = s.steady_frames;
  j["steady_ms"] = s.steady_ms;
  j["identity"] = std::vector<double>(s.identity.data(), s.identity.data() + s.identity.size());
  j["options"] = json::parse(s.options_json);
  if (s.error.frames > 0) {
    j["error"] = {{"frames", s.error.frames},
                  {"landmark_px", s.error.landmark_px},
                  {"landmark_iod", s.error.landmark_iod},
                  {"fit_landmark_px", s.error.fit_landmark_px},
                  {"vertex_px", s.error.vertex_px}};
  }
  return j;
}

// Where a run's frames go: the per-frame records, the meshes and the preview video.
class TrackRecorder {
 public:
  TrackRecorder(const TrackRunOptions& options, const FrameSourceInfo& info, const FaceRig& rig)
      : options_(options), info_(info), rig_(rig), face_F_(FaceChartTriangles(rig)) {
    fs::create_directories(options.out / "frames");
    if (options.write_meshes) {
      fs::create_directories(options.out / "meshes");
      series_ = std::make_unique<PvdWriter>(options.out / "tracking.pvd");
    }
    if (!options.preview.empty()) {
      const bool mp4 = LowerExtension(options.preview) == ".mp4";
      const int fourcc = mp4 ? cv::VideoWriter::fourcc('m', 'p', '4', 'v') : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
      writer_.open(options.preview, fourcc, info.fps, cv::Size(info.width, info.height));
      Require(writer_.isOpened(), fmt::format("{}: cannot write this video (try .avi)", options.preview));
    }
  }
  // The tracked mesh of frame t (vertices V) as PLY and VTP, added to tracking.pvd.
  void WriteMesh(const TrackedFrame& t, const MatX3d& V) {
    if (!series_) return;
    const TriMesh mesh = RigMeshWithVertices(rig_, V);
    WritePly(options_.out / "meshes" / fmt::format("{:06d}.ply", t.frame), mesh);
    const fs::path vtp = options_.out / "meshes" / fmt::format("{:06d}.vtp", t.frame);
    WriteVtp(vtp, mesh);
    series_->Add(t.frame / info_.fps, vtp);
    series_->Write();
  }
  // The per-frame record, and the frame with the landmarks and mesh into the preview.
  void WriteFrame(const TrackedFrame& t, const json& record, const cv::Mat& image, const MatX2d& projected) {
    WriteJsonFile(options_.out / "frames" / fmt::format("{:06d}.json", t.frame), record);
    if (!writer_.isOpened()) return;
    cv::Mat bgr = PreviewBgr(image);
    DrawTracking(t, projected, face_F_, &bgr);
    writer_.write(bgr);
  }

 private:
  const TrackRunOptions& options_;
  const FrameSourceInfo& info_;
  const FaceRig& rig_;
  MatX3i face_F_;
  std::unique_ptr<PvdWriter> series_;
  cv::VideoWriter writer_;
};

// The truth of a crease sequence dataset, for the per-frame errors: through a surface
// correspondence when the tracking rig is not the dataset's.
struct TruthSource {
  fs::path dataset;  // empty: no truth
  RigCorrespondence correspondence;
};

TruthSource OpenTruth(const FrameSourceInfo& info, const FaceRig& rig) {
  TruthSource t;
  if (info.kind != "dataset" || !fs::is_directory(info.path / "truth")) return t;
  t.dataset = info.path;
  if (fs::exists(info.path / "rig.crig")) t.correspondence = CorrespondRigs(rig, ReadRig(info.path / "rig.crig"));
  return t;
}

void AddError(const FrameTrackingError& e, TrackErrorSummary* s) {
  s->landmark_px += e.landmark_px;
  s->landmark_iod += e.landmark_iod;
  s->fit_landmark_px += e.fit_landmark_px;
  s->vertex_px += e.vertex_px;
  ++s->frames;
}

void FinishError(TrackErrorSummary* s) {
  if (s->frames == 0) return;
  s->landmark_px /= s->frames;
  s->landmark_iod /= s->frames;
  s->fit_landmark_px /= s->frames;
  s->vertex_px /= s->frames;
}

}  // namespace

void TrackRunOptions::Check() const { Require(!out.empty(), "TrackRunOptions: the output folder is empty"); }

double TrackSummary::tracking_fps() const { return 1000.0 / std::max(landmarks_ms + fit_ms, 1e-9); }

std::string TrackSummary::BriefReport() const {
  std::string s;
  if (correspondence_matched >= 0) {
    s += fmt::format("the tracking rig differs from the dataset's: vertex errors through a surface correspondence "
                     "({} of its vertices matched)\n", correspondence_matched);
  }
  s += fmt::format("tracked {} of {} frames ({} detections); landmarks {:.2f} ms, rig fit {:.2f} ms per frame ({:.0f} "
                   "fps)\n", tracked_frames, frames, detections, landmarks_ms, fit_ms, tracking_fps());
  if (steady_frames > 0) {
    s += fmt::format("after detection and the identity phase ({} frames): {:.2f} ms per frame ({:.0f} fps)\n",
                     steady_frames, steady_ms, 1000.0 / std::max(steady_ms, 1e-9));
  }
  if (error.frames > 0) {
    s += fmt::format("against ground truth ({} tracked frames): landmarks {:.2f} px ({:.3f} IOD), fitted rig's "
                     "landmarks {:.2f} px, visible vertices {:.2f} px\n", error.frames, error.landmark_px,
                     error.landmark_iod, error.fit_landmark_px, error.vertex_px);
  }
  return s;
}

std::string TrackSummary::ToJson() const { return SummaryJson(*this).dump(2); }

TrackSummary RunTracking(const TrackRunOptions& options, const TrackerOptions& tracker_options, const FaceRig& rig,
                         const CameraIntrinsics& intrinsics, FrameSource* frames, FrameTracker* tracker) {
  options.Check();
  const FrameSourceInfo& info = frames->info();
  const LandmarkRigFitter& fitter = tracker->fitter();
  const TruthSource truth = OpenTruth(info, rig);
  TrackRecorder recorder(options, info, rig);
  TrackSummary s;
  s.input = options.input;
  s.landmark_source = tracker->source_name();
  s.options_json = OptionsToJson(tracker_options);
  if (!truth.dataset.empty() && !truth.correspondence.same_topology) s.correspondence_matched = truth.correspondence.matched;
  const int total = options.max_frames > 0 && (info.frame_count < 0 || options.max_frames < info.frame_count)
                        ? options.max_frames : info.frame_count;
  Progress progress("tracking", std::max(total, 1));
  double steady_ms = 0.0;
  cv::Mat image;
  while ((options.max_frames < 0 || s.frames < options.max_frames) && frames->Next(&image)) {
    const TrackedFrame t = tracker->Track(image, frames->index());
    ++s.frames;
    s.tracked_frames += t.tracked;
    s.detections += t.detected;
    s.landmarks_ms += t.landmarks_ms;
    s.fit_ms += t.fit_ms;
    if (t.tracked && !t.detected && fitter.identity_fixed()) {  // after detection and the identity phase
      steady_ms += t.landmarks_ms + t.fit_ms;
      ++s.steady_frames;
    }
    json record = TrackedFrameJson(t, rig);
    record["landmarks_ms"] = t.landmarks_ms;
    record["fit_ms"] = t.fit_ms;
    MatX2d projected;
    if (t.tracked) {
      const MatX3d V = fitter.HeadVertices(t.fit);
      projected = Camera(intrinsics, t.fit.cam_from_head).ProjectAll(V);
      recorder.WriteMesh(t, V);
      if (!truth.dataset.empty()) {
        const FrameTruth frame_truth = truth.correspondence.MapTruth(ReadFrameTruth(truth.dataset, t.frame, -1));
        const FrameTrackingError e = CompareToTruth(frame_truth, t.landmarks, fitter.ProjectLandmarks(t.fit), projected);
        record["error"] = {{"landmark_px", e.landmark_px},
                           {"landmark_iod", e.landmark_iod},
                           {"fit_landmark_px", e.fit_landmark_px},
                           {"vertex_px", e.vertex_px}};
        AddError(e, &s.error);
      }
    }
    recorder.WriteFrame(t, record, image, projected);
    progress.Advance();
  }
  progress.Finish();
  Require(s.frames > 0, fmt::format("{}: no frames", options.input));
  s.landmarks_ms /= s.frames;
  s.fit_ms /= s.frames;
  s.steady_ms = s.steady_frames ? steady_ms / s.steady_frames : 0.0;
  FinishError(&s.error);
  s.identity = fitter.identity();
  WriteJsonFile(options.out / "summary.json", SummaryJson(s));
  return s;
}

}  // namespace crease
