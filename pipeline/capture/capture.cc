#include "pipeline/capture/capture.h"

#include <chrono>
#include <filesystem>
#include <utility>

#include <fmt/format.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/image_io.h"
#include "core/options.h"
#include "core/uv_raster.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/training/detail_extraction.h"

namespace crease {

namespace {

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// L^t in the camera frame: the rig evaluated with the fit's weights and the
// tracker's identity, moved by cam_from_head.
MatX3d CameraVertices(const FaceRig& rig, const Eigen::VectorXd& identity, const LandmarkFrameFit& fit) {
  MatX3d V = rig.EvaluatePositions(identity, fit.expression);
  const Eigen::Matrix3d R = fit.cam_from_head.rotation.toRotationMatrix();
  const Eigen::RowVector3d t = fit.cam_from_head.translation.transpose();
  for (int i = 0; i < V.rows(); ++i) V.row(i) = V.row(i) * R.transpose() + t;
  return V;
}

}  // namespace

cv::Mat ReadFrameMap(const std::string& dir, int frame, int R, const char* option) {
  const std::filesystem::path p = std::filesystem::path(dir) / fmt::format("{:06d}.exr", frame);
  Require(std::filesystem::is_regular_file(p), fmt::format("{}: missing ({} needs a map per frame)", p.string(), option));
  cv::Mat d = ReadImage(p, /*srgb=*/false);
  if (d.channels() > 1) cv::extractChannel(d, d, 0);
  Require(d.rows == d.cols, fmt::format("{}: the map is {}×{}, expected a square map", p.string(), d.cols, d.rows));
  d.convertTo(d, CV_32F);
  return d.rows == R ? d : ResampleSquareMap(d, R);
}

cv::Mat WrinkleTextureFromDisplacement(const cv::Mat& displacement, int R) {
  Require(!displacement.empty() && displacement.rows == displacement.cols,
          fmt::format("wrinkle texture: the displacement map is {}×{}, expected a square map", displacement.cols,
                      displacement.rows));
  cv::Mat d;
  displacement.convertTo(d, CV_32F);
  cv::Mat t = 0.5 + 0.5 * ResampleSquareMap(d, R);
  cv::patchNaNs(t, 0.5);
  cv::min(cv::max(t, 0.0), 1.0, t);
  return t;
}

void CaptureOptions::VisitFields(OptionVisitor& v) {
  v.Section("tracker", tracker);
  v.Section("refinement", refinement);
  v.Section("texture", texture);
  v.Section("detail", detail);
  v.Section("mesoscopic", mesoscopic);
  v.Section("hifi", hifi);
  v.Field("refine", refine);
  v.Field("regress_detail", regress_detail);
  v.Field("mesoscopic_detail", mesoscopic_detail);
  v.Field("build_hifi_mesh", build_hifi_mesh);
  v.Field("wrinkle_map_from_maps", wrinkle_map_from_maps);
  v.Field("detail_from_truth_maps", detail_from_truth_maps);
}

void CaptureOptions::Check() const {
  tracker.Check();
  refinement.Check();
  texture.Check();
  detail.Check();
  mesoscopic.Check();
  hifi.Check();
}

FaceRig CompatibleRig(const FaceRig& rig, const DetailModel& model) {
  return MakeRigCompatible(rig, model.detail);
}

CaptureSession::CaptureSession(const FaceRig& rig, const DetailModel& model, const CameraIntrinsics& intrinsics,
                               const CaptureOptions& options)
    : rig_(rig), options_(options), intrinsics_(intrinsics) {
  options_.Check();
  intrinsics_.Validate("capture camera");
  model.Validate("detail model");
  Require(rig_.neutral.has_uv(), "capture: the rig has no UV chart (texture extraction and detail need one)");
  map_resolution_ = model.map_resolution;
  // The texture must be sampled at the model's resolution: the patches and the
  // DoG of the wrinkle map are defined in its texels (Sec. 4.2).
  options_.texture.map_resolution = map_resolution_;
  texture_ = std::make_unique<FrameTextureExtractor>(rig_, intrinsics_, options_.texture);
  if (options_.refine) refiner_ = std::make_unique<FlowRefiner>(rig_, intrinsics_, options_.refinement);
  detail_ = std::make_unique<DetailRegressor>(model, rig_.regions, texture_->coverage(), options_.detail);
  hifi_ = std::make_unique<HifiMeshBuilder>(rig_, options_.hifi);
}

CaptureSession::~CaptureSession() = default;

bool CaptureSession::layout_fixed() const { return detail_->layout_fixed(); }

std::vector<CapturedFrame> CaptureSession::Process(int index, const cv::Mat& frame, const TrackedFrame& tracked,
                                                   const Eigen::VectorXd& identity) {
  std::vector<CapturedFrame> done = Begin(index, frame, tracked, identity);
  for (CapturedFrame& f : done) Finish(&f);
  return done;
}

// Begin's work on a tracked frame: L~^t, T^t (blended over time) and, on the first
// textured frame, D^HF.
void CaptureSession::BeginTracked(const cv::Mat& frame, const TrackedFrame& tracked, const Eigen::VectorXd& identity,
                                  CapturedFrame* out_frame) {
  CapturedFrame& out = *out_frame;
  if (refiner_) {
    // Visibility of the flow points: from the previous frame's depth buffer of
    // L~^{t−1} (the texture's, free) while tracking continues; a depth buffer of
    // L^t on the first frame and after a loss. L^t itself is evaluated by the
    // refiner (RefinedFrame::coarse_vertices); it is evaluated here only when
    // the visibility needs it first.
    auto t0 = std::chrono::steady_clock::now();
    if (!was_tracked_ || previous_visible_.size() != static_cast<size_t>(rig_.num_vertices())) {
      out.coarse = CameraVertices(rig_, identity, tracked.fit);
      previous_visible_ = texture_->VisibleVertices(out.coarse);
    }
    out.timing.visibility_ms = MsSince(t0);
    t0 = std::chrono::steady_clock::now();
    out.refinement = refiner_->Refine(ToGray8(frame), tracked, identity, previous_visible_);
    out.timing.refine_ms = MsSince(t0);
    if (out.refinement.coarse_vertices.rows() == rig_.num_vertices()) {
      out.coarse = out.refinement.coarse_vertices;
    } else if (out.coarse.rows() != rig_.num_vertices()) {
      out.coarse = CameraVertices(rig_, identity, tracked.fit);
    }
    out.refined = out.refinement.vertices.rows() == out.coarse.rows() ? out.refinement.vertices : out.coarse;
  } else {
    out.coarse = CameraVertices(rig_, identity, tracked.fit);
    out.refined = out.coarse;
  }
  auto t0 = std::chrono::steady_clock::now();
  texture_->Extract(out.refined, frame, &out.texture, &previous_visible_);
  if (options_.texture.temporal_weight > 0) {
    BlendTextureHistory(options_.texture.temporal_weight, &out.texture, &texture_history_);
  }
  out.timing.texture_ms = MsSince(t0);
  out.has_mesh = true;
  if (mesoscopic_.empty()) {
    t0 = std::chrono::steady_clock::now();
    if (options_.mesoscopic_detail) {
      mesoscopic_ = MesoscopicMap(out.texture.gray, out.texture.seen, options_.mesoscopic);
    } else {
      mesoscopic_ = cv::Mat::zeros(map_resolution_, map_resolution_, CV_32F);
    }
    out.timing.mesoscopic_ms = MsSince(t0);
  }
}

std::vector<CapturedFrame> CaptureSession::Begin(int index, const cv::Mat& frame, const TrackedFrame& tracked,
                                                 const Eigen::VectorXd& identity) {
  Require(!frame.empty(), fmt::format("capture: frame {} is empty", index));
  Require(frame.cols == intrinsics_.width && frame.rows == intrinsics_.height,
          fmt::format("capture: frame {} is {}×{} but the camera is {}×{}", index, frame.cols, frame.rows,
                      intrinsics_.width, intrinsics_.height));
  CapturedFrame out;
  out.frame = index;
  out.tracked = tracked;
  out.timing.landmarks_ms = tracked.landmarks_ms;
  out.timing.fit_ms = tracked.fit_ms;
  if (tracked.tracked) {
    BeginTracked(frame, tracked, identity, &out);
  } else {
    if (refiner_) refiner_->Reset();
    texture_history_ = FrameTexture();  // a lost face: nothing to blend the next texture with
  }
  was_tracked_ = tracked.tracked;

  std::vector<CapturedFrame> done;
  if (detail_->layout_fixed()) {
    done.push_back(std::move(out));
    return done;
  }
  if (out.has_mesh) {
    const auto t0 = std::chrono::steady_clock::now();
    const double expression = out.tracked.fit.expression.norm();  // how far from the neutral
    if (options_.wrinkle_map_from_maps.empty()) {
      detail_->AddWrinkleFrame(out.texture.gray, out.texture.seen, expression);
    } else {
      const cv::Mat d = ReadFrameMap(options_.wrinkle_map_from_maps, out.frame, map_resolution_, "wrinkle_map_from_maps");
      detail_->AddWrinkleFrame(out.texture.gray, out.texture.seen, expression,
                               WrinkleTextureFromDisplacement(d, map_resolution_));
    }
    out.timing.wrinkle_map_ms = MsSince(t0);
  }
  pending_.push_back(std::move(out));
  if (detail_->frames_added() >= options_.detail.wrinkle_frames) done = EndInput();
  return done;
}

std::vector<CapturedFrame> CaptureSession::Flush() {
  std::vector<CapturedFrame> done = EndInput();
  for (CapturedFrame& f : done) Finish(&f);
  return done;
}

std::vector<CapturedFrame> CaptureSession::EndInput() {
  std::vector<CapturedFrame> done;
  if (pending_.empty()) return done;
  if (!detail_->layout_fixed()) {
    if (detail_->frames_added() == 0) {
      // No frame was tracked: nothing to build a wrinkle map from. Return the
      // frames as they are (no mesh, no detail); the layout stays open.
      while (!pending_.empty()) {
        done.push_back(std::move(pending_.front()));
        pending_.pop_front();
      }
      return done;
    }
    detail_->FixLayout();
  }
  while (!pending_.empty()) {
    done.push_back(std::move(pending_.front()));
    pending_.pop_front();
  }
  return done;
}

void CaptureSession::Finish(CapturedFrame* frame) {
  if (!frame->has_mesh) return;
  auto t0 = std::chrono::steady_clock::now();
  if (options_.regress_detail && !options_.detail_from_truth_maps.empty()) {
    const cv::Mat truth =
        ReadFrameMap(options_.detail_from_truth_maps, frame->frame, map_resolution_, "detail_from_truth_maps");
    frame->displacement =
        detail_->AssembleFromTruth(frame->texture.gray, frame->texture.seen, truth, &frame->timing.detail);
  } else if (options_.regress_detail) {
    frame->displacement = detail_->Regress(frame->texture.gray, frame->texture.seen, &frame->timing.detail);
  } else {
    frame->displacement = cv::Mat::zeros(map_resolution_, map_resolution_, CV_32F);
  }
  frame->has_detail = true;
  frame->timing.detail_ms += MsSince(t0);
  if (options_.build_hifi_mesh) {
    t0 = std::chrono::steady_clock::now();
    // D^t + D^HF into a reused buffer (no 4 MB allocation per frame).
    if (mesoscopic_.empty()) {
      frame->displacement.copyTo(combined_scratch_);
    } else {
      cv::add(frame->displacement, mesoscopic_, combined_scratch_);
    }
    hifi_->BuildInto(frame->refined, combined_scratch_, &hifi_scratch_);
    frame->timing.hifi_ms = MsSince(t0);
  }
}

cv::Mat CaptureSession::CombinedDisplacement(const CapturedFrame& frame) const {
  Require(frame.has_mesh, fmt::format("capture: frame {} has no mesh", frame.frame));
  cv::Mat d = frame.has_detail ? frame.displacement.clone() : cv::Mat::zeros(map_resolution_, map_resolution_, CV_32F);
  if (!mesoscopic_.empty()) d += mesoscopic_;
  return d;
}

TriMesh CaptureSession::HifiMesh(const CapturedFrame& frame) const {
  return hifi_->Build(frame.refined, CombinedDisplacement(frame));
}

}  // namespace crease
