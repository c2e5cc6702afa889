#include "eval/capture_metrics.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <utility>

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/camera.h"
#include "core/dataset_info.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/options.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"
#include "eval/appearance_ceiling.h"
#include "eval/registered_truth.h"
#include "eval/detail_truth.h"
#include "eval/tracking_metrics.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/capture/flow_refinement.h"
#include "pipeline/capture/frame_texture.h"
#include "pipeline/capture/hifi_mesh.h"
#include "pipeline/training/texture_extraction.h"
#include "pipeline/training/wrinkle_map.h"
#include "eval/rig_correspondence.h"
#include "synth/actor.h"
#include "synth/dataset.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

void CaptureEvalOptions::VisitFields(OptionVisitor& v) {
  v.Section("appearance", appearance);
  v.Field("surface_every", surface_every);
  v.Field("band_mm", band_mm);
  v.Field("normal_band_low_mm", normal_band_low_mm);
  v.Field("detail_truth", detail_truth);
  v.Field("truth_maps_dir", truth_maps_dir);
  v.Field("registered_truth", registered_truth);
  v.Field("wrinkle_regions", wrinkle_regions);
  v.Field("rim_margin_mm", rim_margin_mm);
  v.Field("surface_max_distance_mm", surface_max_distance_mm);
  v.Field("surface_mesh_resolution", surface_mesh_resolution);
  v.Field("surface_phong_alpha", surface_phong_alpha);
  v.Field("max_frames", max_frames);
  v.Field("active_reference_rms_mm", active_reference_rms_mm);
  v.Field("offset_region", offset_region);
  v.Field("offset_search_mm", offset_search_mm);
  v.Field("offset_min_correlation", offset_min_correlation);
  v.Field("visible_face_fraction", visible_face_fraction);
  v.Field("vectors_frame", vectors_frame);
  v.Field("vectors_scale", vectors_scale);
}

void CaptureEvalOptions::Check() const {
  const char* o = "CaptureEvalOptions";
  appearance.Check();
  CheckGe(o, "surface_every", surface_every, 0);
  CheckGt(o, "band_mm", band_mm, 0.0);
  CheckGe(o, "rim_margin_mm", rim_margin_mm, 0.0);
  CheckGt(o, "normal_band_low_mm", normal_band_low_mm, 0.0);
  CheckGt(o, "surface_max_distance_mm", surface_max_distance_mm, 0.0);
  CheckGe(o, "surface_mesh_resolution", surface_mesh_resolution, 8);
  CheckGe(o, "offset_search_mm", offset_search_mm, 0.0);
  CheckGe(o, "visible_face_fraction", visible_face_fraction, 0.0);
  CheckLe(o, "visible_face_fraction", visible_face_fraction, 1.0);
}

namespace {

MatX3d Transform(const Rigid3d& T, const MatX3d& V) {
  MatX3d out(V.rows(), 3);
  for (int i = 0; i < V.rows(); ++i) out.row(i) = (T * Eigen::Vector3d(V.row(i))).transpose();
  return out;
}

// Rigid transform (no scale) taking `src` rows onto `dst` rows, over `ids`.
Rigid3d Kabsch(const MatX3d& src, const MatX3d& dst, const std::vector<int>& ids) {
  Eigen::Matrix3Xd a(3, ids.size()), b(3, ids.size());
  for (size_t k = 0; k < ids.size(); ++k) {
    a.col(static_cast<Eigen::Index>(k)) = src.row(ids[k]).transpose();
    b.col(static_cast<Eigen::Index>(k)) = dst.row(ids[k]).transpose();
  }
  const Eigen::Matrix4d M = Eigen::umeyama(a, b, false);
  return Rigid3d(Eigen::Quaterniond(Eigen::Matrix3d(M.topLeftCorner<3, 3>())), M.topRightCorner<3, 1>());
}

double MeanDistance(const MatX3d& a, const MatX3d& b, const std::vector<int>& ids) {
  double s = 0;
  for (int i : ids) s += (a.row(i) - b.row(i)).norm();
  return ids.empty() ? 0.0 : s / ids.size();
}

// A float map of R×R texels. `resample`: a square map of another size is resampled
// to R (the studio writes its truth at its own resolution, the model may use another).
cv::Mat ReadMap(const fs::path& path, int R, bool resample = false) {
  Require(fs::is_regular_file(path), fmt::format("{}: missing", path.string()));
  cv::Mat m = ReadImage(path, /*srgb=*/false);
  if (m.channels() > 1) cv::extractChannel(m, m, 0);
  if (m.depth() != CV_32F) m.convertTo(m, CV_32F);
  if (resample) m = ResampleSquareMap(m, R);
  Require(m.rows == R && m.cols == R,
          fmt::format("{}: the map is {}×{}, expected {}×{}", path.string(), m.cols, m.rows, R, R));
  return m;
}

}  // namespace

cv::Mat AlbedoMesoscopicMap(const cv::Mat& albedo, const cv::Mat& seen, const MesoscopicOptions& options) {
  Require(!albedo.empty() && albedo.rows == albedo.cols && (albedo.type() == CV_32FC3 || albedo.type() == CV_32FC1),
          fmt::format("AlbedoMesoscopicMap: the albedo must be a square CV_32FC3 or CV_32FC1 map, got {}×{} type {}",
                      albedo.cols, albedo.rows, albedo.type()));
  Require(!seen.empty() && seen.rows == seen.cols,
          fmt::format("AlbedoMesoscopicMap: the seen mask is {}×{}, expected a square map", seen.cols, seen.rows));
  return MesoscopicMap(ResampleSquareMap(Luminance(albedo), seen.rows), seen, options);
}

namespace {

json ComparisonJson(const MapComparison& c) {
  json j = MapComparisonJson(c);
  j["amplitude_ratio"] = c.reference_rms_mm > 0 ? c.extracted_rms_mm / c.reference_rms_mm : 0.0;
  return j;
}

json SurfaceJson(const SurfaceError& s) {
  return {{"samples", s.samples},
          {"distance_mm", s.distance_mm},
          {"distance_rms_mm", s.distance_rms_mm},
          {"normal_deg", s.normal_deg},
          {"wrinkle_samples", s.wrinkle_samples},
          {"wrinkle_distance_mm", s.wrinkle_distance_mm},
          {"wrinkle_normal_deg", s.wrinkle_normal_deg}};
}

json BandNormalsJson(const BandNormals& b) {
  return {{"coarse_deg", b.coarse_deg},
          {"coarse_mesoscopic_deg", b.meso_deg},
          {"detail_deg", b.detail_deg},
          {"full_deg", b.full_deg}};
}

// {region: ComparisonJson} of the per-region comparisons (their band with `band`).
json RegionComparisonsJson(const std::vector<CaptureEvalSummary::RegionComparison>& regions, bool band) {
  json j = json::object();
  for (const auto& r : regions) j[r.region] = ComparisonJson(band ? r.band : r.detail);
  return j;
}

json ExpressionComparisonsJson(const std::vector<CaptureEvalSummary::ExpressionComparison>& expressions) {
  json j = json::object();
  for (const auto& e : expressions) {
    j[e.expression] = {{"frames", e.frames},
                       {"band", ComparisonJson(e.band)},
                       {"registered_frames", e.registered_frames},
                       {"registered_band", ComparisonJson(e.registered_band)}};
  }
  return j;
}

double Amp(const MapComparison& c) { return c.reference_rms_mm > 0 ? c.extracted_rms_mm / c.reference_rms_mm : 0.0; }

// eval.md's table of CaptureEvalSummary::d_by_expression (empty without one).
std::string ExpressionTableMarkdown(const std::vector<CaptureEvalSummary::ExpressionComparison>& expressions) {
  if (expressions.empty()) return {};
  std::string o =
      "\nBy the expression held (the truth's largest weight ≥ 0.5), wrinkle regions, wrinkle band:\n\n"
      "| expression | frames | correlation | amplitude ratio | registered through the image: frames | "
      "correlation |\n|---|---|---|---|---|---|\n";
  for (const auto& e : expressions) {
    o += fmt::format("| {} | {} | {:.3f} | {:.2f} | {} | {:.3f} |\n", e.expression, e.frames, e.band.correlation,
                     Amp(e.band), e.registered_frames, e.registered_band.correlation);
  }
  return o;
}

void Accumulate(const SurfaceError& s, SurfaceError* sum) {
  sum->samples += s.samples;
  sum->distance_mm += s.distance_mm;
  sum->distance_rms_mm += s.distance_rms_mm;
  sum->normal_deg += s.normal_deg;
  sum->wrinkle_samples += s.wrinkle_samples;
  sum->wrinkle_distance_mm += s.wrinkle_distance_mm;
  sum->wrinkle_normal_deg += s.wrinkle_normal_deg;
}

void Divide(int n, SurfaceError* s) {
  if (n == 0) return;
  s->distance_mm /= n;
  s->distance_rms_mm /= n;
  s->normal_deg /= n;
  s->wrinkle_distance_mm /= n;
  s->wrinkle_normal_deg /= n;
}

// The still face's pair counts and, where there are pairs, its correlations (else
// not measured: absent, never a misleading 0).
void AddStillFaceJson(const CaptureEvalSummary& s, json* d) {
  (*d)["still_pairs"] = s.still_pairs;
  (*d)["still_active_pairs"] = s.still_active_pairs;
  (*d)["still_inactive_pairs"] = s.still_inactive_pairs;
  if (s.still_pairs > 0) {
    (*d)["still_correlation"] = s.d_still_correlation;
    (*d)["still_pooled_correlation"] = s.d_still_pooled_correlation;
  }
  if (s.still_active_pairs > 0) (*d)["still_active_correlation"] = s.d_still_active_correlation;
  if (s.still_inactive_pairs > 0) (*d)["still_inactive_correlation"] = s.d_still_inactive_correlation;
}

}  // namespace

bool BestVerticalOffset(const cv::Mat& D, const cv::Mat& G, const cv::Mat& mask, int max_shift, int* shift,
                        double* correlation) {
  double best = 0.0;
  bool found = false;
  const cv::Rect box = cv::boundingRect(mask);  // texels outside the mask never count
  for (int s = -max_shift; s <= max_shift; ++s) {
    double sd = 0, sg = 0, sdd = 0, sgg = 0, sdg = 0;
    int64_t n = 0;
    for (int y = std::max(box.y, -s); y < box.y + box.height && y + s < D.rows; ++y) {
      const float* d = D.ptr<float>(y + s);
      const float* g = G.ptr<float>(y);
      const uint8_t* m = mask.ptr<uint8_t>(y);
      const uint8_t* md = mask.ptr<uint8_t>(y + s);
      for (int x = box.x; x < box.x + box.width; ++x) {
        if (!m[x] || !md[x] || !std::isfinite(d[x]) || !std::isfinite(g[x])) continue;
        sd += d[x];
        sg += g[x];
        sdd += double(d[x]) * d[x];
        sgg += double(g[x]) * g[x];
        sdg += double(d[x]) * g[x];
        ++n;
      }
    }
    if (n < 16) continue;
    const double cov = sdg - sd * sg / n, vd = sdd - sd * sd / n, vg = sgg - sg * sg / n;
    if (vd <= 0 || vg <= 0) continue;
    const double r = cov / std::sqrt(vd * vg);
    if (r > best) {
      best = r;
      *shift = -s;  // D(y + s) matches G(y): G's line at y sits at y + s in D, so D's is −s texels higher
      found = true;
    }
  }
  *correlation = best;
  return found;
}

namespace {

// Fig. 11: two panels of the frame around the face, each vertex's 2D error drawn
// as a line from its true projection (magnified by `scale`).
cv::Mat DrawErrorVectors(const cv::Mat& frame_rgb, const MatX2d& truth, const MatX2d& err_coarse,
                         const MatX2d& err_refined, const std::vector<int>& visible, double coarse_px,
                         double refined_px, double scale) {
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (int i : visible) {
    x0 = std::min(x0, truth(i, 0));
    y0 = std::min(y0, truth(i, 1));
    x1 = std::max(x1, truth(i, 0));
    y1 = std::max(y1, truth(i, 1));
  }
  const int pad = 20;
  cv::Rect box(static_cast<int>(x0) - pad, static_cast<int>(y0) - pad, static_cast<int>(x1 - x0) + 2 * pad,
               static_cast<int>(y1 - y0) + 2 * pad);
  box &= cv::Rect(0, 0, frame_rgb.cols, frame_rgb.rows);
  if (box.width < 8 || box.height < 8) return {};
  const double zoom = std::max(1.0, 360.0 / box.height);
  auto panel = [&](const MatX2d& err, const cv::Scalar& colour, const std::string& label) {
    cv::Mat p;
    cv::resize(frame_rgb(box), p, cv::Size(), zoom, zoom, cv::INTER_CUBIC);
    p = p * 0.6;  // dim the frame under the vectors
    // One vertex per 14 × 14 px cell of the panel, so the vectors stay readable.
    std::map<std::pair<int, int>, int> cell;
    for (int i : visible) {
      if (!err.row(i).allFinite()) continue;
      cell.emplace(std::make_pair(static_cast<int>((truth(i, 0) - box.x) * zoom / 14),
                                  static_cast<int>((truth(i, 1) - box.y) * zoom / 14)),
                   i);
    }
    for (const auto& [c, i] : cell) {
      const cv::Point2d a((truth(i, 0) - box.x) * zoom, (truth(i, 1) - box.y) * zoom);
      const cv::Point2d b(a.x + scale * err(i, 0) * zoom, a.y + scale * err(i, 1) * zoom);
      cv::line(p, a, b, colour, 1, cv::LINE_AA);
      cv::circle(p, a, 1, cv::Scalar(255, 255, 255), cv::FILLED, cv::LINE_AA);
    }
    // One line per '\n', so a label stays inside its panel.
    int y = 18;
    for (size_t start = 0; start <= label.size(); y += 18) {
      const size_t end = std::min(label.find('\n', start), label.size());
      cv::putText(p, label.substr(start, end - start), cv::Point(6, y), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                  cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
      start = end + 1;
    }
    return p;
  };
  cv::Mat out;
  cv::hconcat(panel(err_coarse, cv::Scalar(255, 80, 60),
                    fmt::format("global tracker: {:.2f} px\n(vectors x{:g})", coarse_px, scale)),
              panel(err_refined, cv::Scalar(80, 255, 120), fmt::format("flow-refined: {:.2f} px", refined_px)), out);
  return out;
}

// The prior error of a tracking rig: the best fit of its linear model to a true
// coarse mesh (head frame), over the face-chart vertices, by unconstrained least
// squares: the expression weights β alone when the identity is known (a rig of the
// truth's topology, at the actor's true identity α: the tracker's identity phase at
// its best), else α and β together (another rig: no shared identity, so a lower
// bound). With β unbounded it is a lower bound of what a tracker using the rig can
// reach: the part of the truth the rig cannot represent (issue 15).
class RigPriorFit {
 public:
  // `identity`: the fixed α (#I of `rig`), or empty to fit it per frame.
  RigPriorFit(const FaceRig& rig, const std::vector<int>& ids, Eigen::VectorXd identity)
      : rig_(rig), ids_(ids), identity_(std::move(identity)) {
    const bool fit_identity = identity_.size() == 0;
    const int ni = fit_identity ? rig.num_identity() : 0, ne = rig.num_expressions();
    A_.resize(3 * static_cast<Eigen::Index>(ids.size()), ni + ne);
    for (size_t r = 0; r < ids.size(); ++r) {
      for (int k = 0; k < 3; ++k) {
        const Eigen::Index row = 3 * static_cast<Eigen::Index>(r) + k, src = 3 * ids[r] + k;
        if (ni > 0) A_.row(row).head(ni) = rig.identity_basis.row(src).cast<double>();
        if (ne > 0) A_.row(row).tail(ne) = rig.expression_basis.row(src).cast<double>();
      }
    }
    qr_.compute(A_);
    base_ = rig.EvaluatePositions(identity_, {});
  }
  // The fitted positions of every vertex for `truth_head` (#V×3, head frame).
  MatX3d Fit(const MatX3d& truth_head) const {
    Eigen::VectorXd r(3 * static_cast<Eigen::Index>(ids_.size()));
    for (size_t i = 0; i < ids_.size(); ++i) {
      r.segment<3>(3 * static_cast<Eigen::Index>(i)) = (truth_head.row(ids_[i]) - base_.row(ids_[i])).transpose();
    }
    const Eigen::VectorXd x = A_.cols() > 0 ? Eigen::VectorXd(qr_.solve(r)) : Eigen::VectorXd();
    if (identity_.size() > 0) return rig_.EvaluatePositions(identity_, x);
    const int ni = rig_.num_identity();
    return rig_.EvaluatePositions(x.head(ni), x.tail(x.size() - ni));
  }

 private:
  const FaceRig& rig_;
  std::vector<int> ids_;
  Eigen::VectorXd identity_;
  MatX3d base_;
  Eigen::MatrixXd A_;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr_;
};

}  // namespace

namespace {

// Sums of errors over points → means (each over the points it summed).
void DivideByCounts(FlowStageErrors* e) {
  auto mean = [](double* sum, int count) { *sum = count > 0 ? *sum / count : 0.0; };
  mean(&e->coarse_px, e->points);
  mean(&e->flow_px, e->points);
  mean(&e->fit_px, e->points);
  mean(&e->refined_px, e->points);
  mean(&e->trusted_px, e->trusted);
  mean(&e->trusted_coarse_px, e->trusted);
  mean(&e->recovered_px, e->recovered);
  mean(&e->recovered_coarse_px, e->recovered);
  mean(&e->reset_px, e->reset);
}

}  // namespace

FlowStageErrors MeasureFlowStages(const CaptureFrameArrays& arrays, const Camera& camera, const MatX2d& truth_px,
                                  const std::vector<char>& truth_visible, const std::vector<char>& on_face) {
  FlowStageErrors e;
  const int n = static_cast<int>(arrays.flow_vertex.size());
  for (int i = 0; i < n; ++i) {
    const int v = arrays.flow_vertex[i];
    const auto status = static_cast<FlowPointStatus>(arrays.flow_status[i]);
    if (status == FlowPointStatus::kInvisible || !on_face[v] || !truth_visible[v]) continue;
    const Eigen::RowVector2d t = truth_px.row(v);
    const double coarse = (arrays.flow_projected.row(i) - t).norm();
    const double flow = (arrays.flow_positions.row(i) - t).norm();
    const double fit = (arrays.flow_fitted.row(i) - t).norm();
    const double refined = (camera.ProjectCamPoint(arrays.refined.row(v).transpose()).transpose() - t).norm();
    if (!(std::isfinite(coarse) && std::isfinite(flow) && std::isfinite(fit) && std::isfinite(refined))) continue;
    ++e.points;
    e.coarse_px += coarse;
    e.flow_px += flow;
    e.fit_px += fit;
    e.refined_px += refined;
    if (status == FlowPointStatus::kTrusted) {
      ++e.trusted;
      e.trusted_px += flow;
      e.trusted_coarse_px += coarse;
    } else if (status == FlowPointStatus::kRecovered) {
      ++e.recovered;
      e.recovered_px += flow;
      e.recovered_coarse_px += coarse;
    } else {
      ++e.reset;
      e.reset_px += flow;
    }
  }
  DivideByCounts(&e);
  return e;
}

namespace {

// Pools the frames' flow-stage errors over their points (a frame's mean weighs by
// its point count); counts are means per frame.
FlowStageErrors PoolFlowStages(const std::vector<FrameCaptureEval>& frames, int* flow_frames) {
  FlowStageErrors p;
  int n = 0;
  for (const FrameCaptureEval& e : frames) {
    if (!e.tracked || !e.has_flow) continue;
    const FlowStageErrors& f = e.flow;
    ++n;
    p.points += f.points;
    p.trusted += f.trusted;
    p.recovered += f.recovered;
    p.reset += f.reset;
    p.coarse_px += f.coarse_px * f.points;
    p.flow_px += f.flow_px * f.points;
    p.fit_px += f.fit_px * f.points;
    p.refined_px += f.refined_px * f.points;
    p.trusted_px += f.trusted_px * f.trusted;
    p.trusted_coarse_px += f.trusted_coarse_px * f.trusted;
    p.recovered_px += f.recovered_px * f.recovered;
    p.recovered_coarse_px += f.recovered_coarse_px * f.recovered;
    p.reset_px += f.reset_px * f.reset;
  }
  DivideByCounts(&p);
  if (n > 0) {
    p.points /= n;
    p.trusted /= n;
    p.recovered /= n;
    p.reset /= n;
  }
  *flow_frames = n;
  return p;
}

// Accumulates LkFromTruth over the frames of a capture.
class LkFromTruthMeter {
 public:
  // `capture_options`: the capture's refinement options (capture.json: CaptureRunOptions).
  explicit LkFromTruthMeter(const FlowRefinementOptions& capture_options) : lk_(capture_options) {}
  // Frame `index` (8-bit gray) with its truth; `flow_vertex`: the capture's flow points.
  void Add(int index, const cv::Mat& gray8, const FrameTruth& truth, const std::vector<int>& flow_vertex) {
    if (index == previous_index_ + 1 && !previous_gray_.empty()) Measure(gray8, truth, flow_vertex);
    previous_index_ = index;
    previous_gray_ = gray8;
    previous_px_ = truth.vertices;
    previous_visible_ = truth.vertex_visible;
  }
  void Skip() { previous_index_ = -2; }
  LkFromTruth Result() const {
    LkFromTruth r;
    r.point_steps = n_;
    if (n_ > 0) {
      r.motion_px = motion_ / n_;
      r.error_px = error_ / n_;
      r.ratio = motion2_ > 0 ? projection_ / motion2_ : 0.0;
    }
    return r;
  }

 private:
  void Measure(const cv::Mat& gray8, const FrameTruth& truth, const std::vector<int>& flow_vertex) {
    std::vector<int> ids;
    std::vector<cv::Point2f> from, to;
    for (int v : flow_vertex) {
      if (v >= previous_px_.rows() || v >= truth.vertices.rows() || !previous_visible_[v] || !truth.vertex_visible[v])
        continue;
      ids.push_back(v);
      from.emplace_back(static_cast<float>(previous_px_(v, 0)), static_cast<float>(previous_px_(v, 1)));
    }
    if (ids.empty()) return;
    const std::vector<uint8_t> status = TrackLucasKanade(lk_, previous_gray_, gray8, from, &to, false);
    for (size_t k = 0; k < ids.size(); ++k) {
      if (!status[k]) continue;
      const Eigen::Vector2d m = (truth.vertices.row(ids[k]) - previous_px_.row(ids[k])).transpose();
      const Eigen::Vector2d d(to[k].x - from[k].x, to[k].y - from[k].y);
      ++n_;
      motion_ += m.norm();
      error_ += (d - m).norm();
      projection_ += d.dot(m);
      motion2_ += m.squaredNorm();
    }
  }
  FlowRefinementOptions lk_;  // the capture's LK settings
  int previous_index_ = -2;
  cv::Mat previous_gray_;
  MatX2d previous_px_;
  std::vector<char> previous_visible_;
  int n_ = 0;
  double motion_ = 0, error_ = 0, projection_ = 0, motion2_ = 0;
};

// Rung A of the detail ladder (eval/appearance_ceiling.h): the capture's T^t,
// re-extracted from the dataset's frame at the capture's L~^t with the capture's
// texture options, against D* and the wrinkle layer.
// The dataset frame `path` as 3-channel RGB (gray and RGBA converted); `linear`:
// decoded from sRGB, else the sRGB-encoded values in [0, 1].
cv::Mat ReadRgbFrame(const fs::path& path, bool linear) {
  cv::Mat img = ReadImage(path, linear);
  if (img.channels() == 1) cv::cvtColor(img, img, cv::COLOR_GRAY2RGB);
  if (img.channels() == 4) cv::cvtColor(img, img, cv::COLOR_RGBA2RGB);
  return img;
}

// The options the capture ran with (capture.json's "options"); the texture's map
// resolution is the one the capture ran at (top-level "map_resolution": the model's,
// which overrides the option).
CaptureOptions CaptureRunOptions(const json& capture_json, const std::string& what) {
  CaptureOptions o = CaptureOptionsOfJson(capture_json, what);
  o.texture.map_resolution = capture_json.value("map_resolution", o.texture.map_resolution);
  return o;
}

class AppearanceProbe {
 public:
  // `frames`: the capture's frames; `frame_path`: a frame's image. Reads the truth
  // expression of every frame and the textures of the reference frames.
  // `texture`: the capture's texture options (CaptureRunOptions).
  AppearanceProbe(const fs::path& capture, const fs::path& dataset, const FrameTextureOptions& texture, const FaceRig& rig,
                  const FaceRig& truth_rig, const CameraIntrinsics& K, const std::vector<int>& frames,
                  const std::function<fs::path(int)>& frame_path, const SequenceDatasetInfo& info, const cv::Mat& mask,
                  const AppearanceCeilingOptions& options)
      : capture_(capture), frame_path_(frame_path) {
    extractor_ = std::make_unique<FrameTextureExtractor>(rig, K, texture);
    // The reference: the tracked frames with the smallest true |β|.
    std::vector<std::pair<double, int>> by_expression;
    for (int index : frames) {
      const Eigen::VectorXd beta = ReadTruthExpression(truth_rig, info.TruthPath(index));
      by_expression.emplace_back(beta.norm(), index);
    }
    std::sort(by_expression.begin(), by_expression.end());
    std::vector<cv::Mat> textures, seen;
    for (const auto& [norm, index] : by_expression) {
      if (static_cast<int>(textures.size()) == options.reference_frames) break;
      const FrameTexture tex =
          Texture(index, ReadCaptureFrameArrays(capture_ / "frames" / fmt::format("{:06d}.cfr", index)));
      if (tex.num_seen == 0) continue;  // not tracked
      if (textures.empty()) reference_frame_ = index;
      textures.push_back(tex.gray);
      seen.push_back(tex.seen);
    }
    if (textures.empty()) return;
    meter_.emplace(MedianTexture(textures, seen), mask, 2, options);
    // The layer of the most neutral frame: its static lines, which T_ref holds too.
    reference_layer_ = ReadMap(info.DisplacementPath(reference_frame_), mask.rows, /*resample=*/true);
  }
  // Frame `index` (its capture arrays) with its truth D* (`detail`) and wrinkle layer.
  void Add(int index, const CaptureFrameArrays& arrays, const cv::Mat& detail, const cv::Mat& layer) {
    if (!meter_) return;
    const FrameTexture tex = Texture(index, arrays);
    if (tex.num_seen > 0) meter_->Add(index, tex.gray, {detail, layer - reference_layer_});
  }
  AppearanceCeiling Result() const { return meter_ ? meter_->Result() : AppearanceCeiling(); }

 private:
  // T^t of frame `index` at the capture's L~^t; empty (num_seen 0) when untracked or
  // the frame's image is missing.
  FrameTexture Texture(int index, const CaptureFrameArrays& a) const {
    if (!a.tracked || !fs::is_regular_file(frame_path_(index))) return FrameTexture();
    return extractor_->Extract(a.refined, ReadRgbFrame(frame_path_(index), /*linear=*/true));
  }

  fs::path capture_;
  std::function<fs::path(int)> frame_path_;
  std::unique_ptr<FrameTextureExtractor> extractor_;
  std::optional<AppearanceCeilingMeter> meter_;
  int reference_frame_ = -1;
  cv::Mat reference_layer_;
};

json FlowStagesJson(const FlowStageErrors& f) {
  return {{"points", f.points},           {"trusted", f.trusted},
          {"recovered", f.recovered},     {"reset", f.reset},
          {"coarse_px", f.coarse_px},     {"flow_px", f.flow_px},
          {"fit_px", f.fit_px},           {"refined_px", f.refined_px},
          {"trusted_px", f.trusted_px},   {"trusted_coarse_px", f.trusted_coarse_px},
          {"recovered_px", f.recovered_px}, {"recovered_coarse_px", f.recovered_coarse_px},
          {"reset_px", f.reset_px}};
}

}  // namespace

SurfaceError MeasureSurface(const TriMesh& h, const RayCaster& truth, double max_distance, const cv::Mat& region) {
  std::vector<Eigen::Vector3f> origins(static_cast<size_t>(h.num_vertices())), dirs(origins.size());
  for (int i = 0; i < h.num_vertices(); ++i) {
    origins[i] = h.V.row(i).cast<float>().transpose();
    dirs[i] = h.N.row(i).cast<float>().transpose().normalized();
  }
  std::vector<SignedHit> hits;
  truth.IntersectSignedBatch(origins, dirs, static_cast<float>(max_distance), &hits);
  auto in_region = [&](size_t i) {
    if (region.empty() || h.UV.rows() != h.V.rows()) return false;
    const int x = std::clamp(static_cast<int>(std::floor(h.UV(i, 0) * region.cols)), 0, region.cols - 1);
    const int y = std::clamp(static_cast<int>(std::floor(h.UV(i, 1) * region.rows)), 0, region.rows - 1);
    return region.at<uint8_t>(y, x) != 0;
  };
  SurfaceError e;
  double sum = 0, sum2 = 0, angle = 0, wsum = 0, wangle = 0;
  for (size_t i = 0; i < hits.size(); ++i) {
    if (!hits[i].valid() || !dirs[i].allFinite()) continue;
    const double d = std::abs(hits[i].t);
    const double c = std::clamp(static_cast<double>(dirs[i].dot(hits[i].geometric_normal)), -1.0, 1.0);
    const double a = std::acos(std::abs(c)) * 180.0 / M_PI;
    sum += d;
    sum2 += d * d;
    angle += a;
    ++e.samples;
    if (in_region(i)) {
      wsum += d;
      wangle += a;
      ++e.wrinkle_samples;
    }
  }
  if (e.samples > 0) {
    e.distance_mm = sum / e.samples;
    e.distance_rms_mm = std::sqrt(sum2 / e.samples);
    e.normal_deg = angle / e.samples;
  }
  if (e.wrinkle_samples > 0) {
    e.wrinkle_distance_mm = wsum / e.wrinkle_samples;
    e.wrinkle_normal_deg = wangle / e.wrinkle_samples;
  }
  return e;
}

void AddSlidTruthMoments(const cv::Mat& truth, const cv::Mat& mask, int shift_texels, MapMoments* moments) {
  Require(truth.type() == CV_32F && mask.type() == CV_8U && truth.size() == mask.size(),
          "AddSlidTruthMoments: expected a CV_32F map and a CV_8U mask of its size");
  Require(shift_texels >= 1, fmt::format("AddSlidTruthMoments: shift {} texels, expected ≥ 1", shift_texels));
  const int s = shift_texels;
  if (s >= truth.cols || s >= truth.rows) return;
  for (const cv::Point d : {cv::Point(s, 0), cv::Point(-s, 0), cv::Point(0, s), cv::Point(0, -s)}) {
    // Texel p of `from` and p + d of `to`, over the overlap of the map and its moved copy.
    const cv::Rect from(std::max(0, -d.x), std::max(0, -d.y), truth.cols - std::abs(d.x), truth.rows - std::abs(d.y));
    const cv::Rect to = from + d;
    cv::Mat both;
    cv::bitwise_and(mask(from), mask(to), both);
    moments->Add(truth(from), truth(to), both);
  }
}

double BandNormalError(const cv::Mat& estimate, const cv::Mat& truth, const cv::Mat& mask, double mm_per_texel) {
  Require(estimate.type() == CV_32F && truth.type() == CV_32F && mask.type() == CV_8U &&
              estimate.size() == truth.size() && mask.size() == truth.size(),
          "BandNormalError: two CV_32F maps and a CV_8U mask of one size");
  const double inv = 0.5 / mm_per_texel;  // central difference, per mm
  double sum = 0;
  int64_t n = 0;
  for (int j = 1; j + 1 < truth.rows; ++j) {
    const uint8_t* m = mask.ptr<uint8_t>(j);
    for (int i = 1; i + 1 < truth.cols; ++i) {
      if (!m[i]) continue;
      // The normal of z = d(x, y) is (−d_x, −d_y, 1), unnormalised.
      auto normal = [&](const cv::Mat& d) {
        return Eigen::Vector3d(-(d.at<float>(j, i + 1) - d.at<float>(j, i - 1)) * inv,
                               -(d.at<float>(j + 1, i) - d.at<float>(j - 1, i)) * inv, 1.0);
      };
      const Eigen::Vector3d a = normal(estimate), b = normal(truth);
      if (!a.allFinite() || !b.allFinite()) continue;
      sum += std::atan2(a.cross(b).norm(), a.dot(b));
      ++n;
    }
  }
  return n > 0 ? sum / n * 180.0 / M_PI : 0.0;
}

namespace {

// The constants of one evaluation: the capture and the dataset, the rigs and their
// correspondence, the camera, the face chart with its UV masks, and the truth the
// frames are measured against. Built in place once (members refer to one another:
// the prior fit and the H^t builder to `rig`), then only read.
struct CaptureEvalContext {
  CaptureEvalContext(const fs::path& capture_dir, const fs::path& dataset_dir, const CaptureEvalOptions& o);
  CaptureEvalContext(const CaptureEvalContext&) = delete;
  CaptureEvalContext& operator=(const CaptureEvalContext&) = delete;

  // The dataset's image of frame `index`.
  fs::path FramePath(int index) const { return info.FramePath(index); }
  // The band of the band normal error from a map's wrinkle band (WrinkleBand with
  // band_mask): its relief finer than normal_band_low_mm removed.
  cv::Mat NormalBand(const cv::Mat& wrinkle_band) const {
    return wrinkle_band - WrinkleBand(wrinkle_band, normal_low_mask);
  }
  // The fraction of the face-chart vertices visible in the ground truth (`vertex_visible`: #V).
  double VisibleFraction(const std::vector<char>& vertex_visible) const {
    int seen = 0;
    for (int i : face_ids) seen += vertex_visible[i] ? 1 : 0;
    return face_ids.empty() ? 0.0 : double(seen) / face_ids.size();
  }

  fs::path capture, dataset;
  const CaptureEvalOptions& options;
  json cap;                  // capture.json
  CaptureOptions cap_options;  // its options (CaptureRunOptions)
  SequenceDatasetInfo info;  // dataset.json
  FaceRig truth_rig, rig;  // the dataset's rig; the compatible rig capture used
  // A capture with another rig than the dataset's is measured through a surface
  // correspondence; D^t, in the other rig's UV layout, is then not compared.
  RigCorrespondence corr;
  CameraIntrinsics K;
  Camera cam;
  // Face-chart vertices of the rig (those with a truth correspondence), as ids and as a mask.
  std::vector<int> face_ids;
  std::vector<char> evaluated;
  // UV maps of the face chart, R×R (the capture's map resolution).
  int R = 0;
  cv::Mat coverage, wrinkle_mask, offset_mask;
  // Each wrinkle region's own mask (options.wrinkle_regions; empty regions left out).
  std::vector<std::pair<std::string, cv::Mat>> region_masks;
  double mm_per_texel = 0;
  WrinkleBandMask band_mask;
  WrinkleBandMask normal_low_mask;  // the band normal error's lower edge (normal_band_low_mm)
  int offset_shift = 0;  // texels, the wrinkle offset's search range
  // The truth moves with the actor's personal rig (its expression deviations),
  // which the tracking rig (the capture's) cannot represent exactly.
  fs::path actor_path;
  std::optional<Actor> truth_actor;
  FaceRig truth_motion;
  std::optional<RigPriorFit> prior;
  // The true high-resolution surface and H^t's builder (surface_every > 0).
  std::optional<ActorModel> actor;
  std::unique_ptr<HifiMeshBuilder> hifi;
  cv::Mat meso;       // the capture's D^HF (zero when it wrote none)
  cv::Mat meso_band;  // NormalBand(D^HF)
  MapComparison meso_truth;  // D^HF against the true mesoscopic layer (texels 0: not known)
  MapComparison meso_albedo_comparison;  // D^HF against AlbedoMesoscopicMap of the albedo (texels 0: not known)
  // The truth of D^t when it is Sec. 4.1's detail; null: the wrinkle-layer maps.
  std::unique_ptr<DetailTruth> detail_truth;
  std::vector<int> frames;  // the capture's frames evaluated
  int vectors_target = -1;  // the error-vector picture's frame

 private:
  void ReadInputs();
  void SetUpFaceChart();
  void SetUpTruthMotion();
  void SetUpSurfaceTruth();
  void ReadMesoscopic();
  void SelectFrames();
  void SetUpDetailTruth();
};

CaptureEvalContext::CaptureEvalContext(const fs::path& capture_dir, const fs::path& dataset_dir,
                                       const CaptureEvalOptions& o)
    : capture(capture_dir), dataset(dataset_dir), options(o) {
  ReadInputs();
  SetUpFaceChart();
  SetUpTruthMotion();
  SetUpSurfaceTruth();
  if (!options.truth_maps_dir.empty()) {
    fs::create_directories(options.truth_maps_dir);
    // The texels the wrinkle metrics score (255), to look at beside the maps.
    WriteImage(fs::path(options.truth_maps_dir) / "wrinkle_mask.png", wrinkle_mask);
  }
  ReadMesoscopic();
  SelectFrames();
  SetUpDetailTruth();
}

void CaptureEvalContext::ReadInputs() {
  const fs::path capture_json = capture / "capture.json";
  Require(fs::is_regular_file(capture_json),
          fmt::format("{}: missing; is {} a `crease capture` folder?", capture_json.string(), capture.string()));
  info = ReadSequenceDatasetInfo(dataset);
  cap = ReadCaptureJson(capture_json);
  cap_options = CaptureRunOptions(cap, capture_json.string());
  truth_rig = ReadRig(info.RigPath());
  rig = ReadRig(capture / "rig.crig");
  corr = CorrespondRigs(rig, truth_rig);
  K = ReadCamera(dataset / "camera.json").intrinsics;
  cam = Camera(K, Rigid3d());
}

void CaptureEvalContext::SetUpFaceChart() {
  const MatX3i face_F = FaceChartTriangles(rig);
  std::vector<char> on_face(static_cast<size_t>(rig.num_vertices()), 0);
  for (int f = 0; f < face_F.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_face[face_F(f, k)] = 1;
  for (int i = 0; i < rig.num_vertices(); ++i)
    if (on_face[i] && corr.Has(i)) face_ids.push_back(i);
  evaluated.assign(static_cast<size_t>(rig.num_vertices()), 0);
  for (int i : face_ids) evaluated[i] = 1;
  TriMesh face_mesh = rig.neutral;
  face_mesh.F = face_F;
  R = cap.value("map_resolution", 1024);
  coverage = CoverageMask(RasterizeUv(face_mesh, R, R, "rig face chart"));
  mm_per_texel = std::max(MmPerTexel(face_mesh, R), 1e-9);
  const cv::Mat skin = AwayFromRims(coverage, options.rim_margin_mm / mm_per_texel);
  wrinkle_mask = ValidRegionMask(rig.regions, options.wrinkle_regions, R, skin);
  for (const std::string& name : options.wrinkle_regions) {
    cv::Mat m = ValidRegionMask(rig.regions, {name}, R, skin);
    if (cv::countNonZero(m) > 0) region_masks.emplace_back(name, std::move(m));
  }
  band_mask = MakeWrinkleBandMask(coverage, options.band_mm / mm_per_texel);
  normal_low_mask = MakeWrinkleBandMask(coverage, options.normal_band_low_mm / mm_per_texel);
  offset_mask = ValidRegionMask(rig.regions, {options.offset_region}, R, coverage);
  offset_shift = static_cast<int>(std::lround(options.offset_search_mm / mm_per_texel));
}

void CaptureEvalContext::SetUpTruthMotion() {
  actor_path = dataset / "actor.json";
  truth_actor = fs::is_regular_file(actor_path) ? std::optional<Actor>(ReadActor(actor_path)) : std::nullopt;
  truth_motion = truth_actor ? PersonalRig(truth_rig, *truth_actor) : truth_rig;
  Eigen::VectorXd known_identity;  // the actor's α, when the tracking rig shares the truth's identity modes
  if (truth_actor && corr.same_uv) {
    known_identity = ZeroPadded(truth_actor->identity, rig.num_identity());
  }
  prior.emplace(rig, face_ids, known_identity);
}

void CaptureEvalContext::SetUpSurfaceTruth() {
  if (options.surface_every <= 0) return;
  Require(truth_actor.has_value(), fmt::format("{}: missing (needed for the surface metrics)", actor_path.string()));
  actor.emplace(truth_rig, *truth_actor);
  HifiMeshOptions ho;
  ho.hifi_mesh_resolution = options.surface_mesh_resolution;
  ho.phong_alpha = options.surface_phong_alpha;
  hifi = std::make_unique<HifiMeshBuilder>(rig, ho);
}

void CaptureEvalContext::ReadMesoscopic() {
  const fs::path meso_path = capture / "maps" / "mesoscopic.exr";
  meso = fs::is_regular_file(meso_path) ? ReadMap(meso_path, R) : cv::Mat::zeros(R, R, CV_32F);
  meso_band = NormalBand(WrinkleBand(meso, band_mask));
  const fs::path true_path = dataset / "maps" / "mesoscopic_displacement.exr";
  if (corr.same_uv && fs::is_regular_file(true_path)) {
    const cv::Mat true_band = NormalBand(WrinkleBand(ReadMap(true_path, R, /*resample=*/true), band_mask));
    meso_truth = CompareMaps(meso_band, true_band, wrinkle_mask);
  }
  const fs::path albedo_path = dataset / "maps" / "albedo.exr";
  if (corr.same_uv && fs::is_regular_file(meso_path) && fs::is_regular_file(albedo_path)) {
    const cv::Mat seen = meso != 0;  // D^HF is 0 where the first frame saw nothing
    const cv::Mat meso_albedo =
        AlbedoMesoscopicMap(ReadRgbFrame(albedo_path, /*linear=*/true), seen, cap_options.mesoscopic);
    meso_albedo_comparison = CompareMaps(meso, meso_albedo, wrinkle_mask);
    if (!options.truth_maps_dir.empty()) {
      WriteImage(fs::path(options.truth_maps_dir) / "mesoscopic_albedo.exr", meso_albedo);
    }
  }
}

void CaptureEvalContext::SelectFrames() {
  frames = cap.at("frame_indices").get<std::vector<int>>();
  if (options.max_frames >= 0 && static_cast<int>(frames.size()) > options.max_frames) frames.resize(options.max_frames);
  vectors_target = options.vectors_frame >= 0 ? options.vectors_frame
                   : frames.empty()            ? -1
                                               : frames[frames.size() / 2];
}

// The truth of D^t: Sec. 4.1's detail with the model's G (recorded in capture.json
// by crease ≥ 0.4; the defaults before), or the wrinkle-layer maps.
void CaptureEvalContext::SetUpDetailTruth() {
  if (options.detail_truth != DetailTruthKind::kExtraction || !corr.same_uv) return;
  Require(truth_actor.has_value(), fmt::format("{}: missing; detail_truth = extraction needs the actor (or use "
                                               "detail_truth = wrinkle-layer)",
                                               actor_path.string()));
  DetailExtractionOptions g;
  if (cap.contains("detail_extraction")) {
    SetOptionsFromJson(cap["detail_extraction"].dump(), (capture / "capture.json").string(), &g);
  }
  detail_truth = std::make_unique<DetailTruth>(truth_rig, *truth_actor, g);
}

// What a tracked frame leaves for the next: the jitter and still-face metrics
// compare consecutive frames.
struct PreviousFrame {
  int frame = -2;                   // −2: none (the last frame was not tracked)
  MatX2d err_coarse, err_refined;   // 2D error vectors of L^t and L~^t
  cv::Mat band_err, D;              // D^t's band minus the truth's; D^t (empty: none)
  Eigen::VectorXd beta;             // the true expression
};

// The last frame's truth maps, reused while an expression is held: D* and its
// band depend on the true expression β alone, the wrinkle layer's band on the
// layer's texels alone. Reuse gives the same bytes as recomputing (the eval's
// costliest steps: D*'s lowpass G and the bands' blurs).
struct TruthMemo {
  Eigen::VectorXd beta;
  cv::Mat G, Gb;         // D*(β) at R×R and its wrinkle band (empty: none yet)
  cv::Mat layer, Lb;     // the dataset's layer and its wrinkle band (empty: none yet)

  // D*(β) and its band: recomputed unless β equals the last one exactly.
  void Truth(const CaptureEvalContext& c, const Eigen::VectorXd& b, cv::Mat* g, cv::Mat* gb) {
    if (G.empty() || beta.size() != b.size() || beta != b) {
      beta = b;
      G = ResampleSquareMap(c.detail_truth->Detail(b), c.R);
      Gb = WrinkleBand(G, c.band_mask);
    }
    *g = G;
    *gb = Gb;
  }
  // The layer's wrinkle band: recomputed unless the layer equals the last one texel for texel.
  cv::Mat LayerBand(const CaptureEvalContext& c, const cv::Mat& l) {
    const bool same = !Lb.empty() && layer.size() == l.size() && layer.type() == l.type() && l.isContinuous() &&
                      std::memcmp(layer.data, l.data, l.total() * l.elemSize()) == 0;
    if (!same) {
      layer = l.clone();
      Lb = WrinkleBand(l, c.band_mask);
    }
    return Lb;
  }
};

// What the frame loop accumulates over the frames.
struct FrameLoopState {
  explicit FrameLoopState(const CaptureEvalContext& c)
      : lk_meter(c.cap_options.refinement),
        pooled_region(c.region_masks.size()),
        pooled_region_band(c.region_masks.size()) {
    if (c.options.appearance.enabled && c.detail_truth) {
      appearance.emplace(c.capture, c.dataset, c.cap_options.texture, c.rig, c.truth_rig, c.K, c.frames,
                         [&c](int index) { return c.FramePath(index); }, c.info, c.wrinkle_mask,
                         c.options.appearance);
    }
    if (c.options.registered_truth && c.detail_truth) {
      registration.emplace(c.rig, c.K, c.cap_options.texture);
      chart_u.create(c.R, c.R, CV_32F);
      chart_v.create(c.R, c.R, CV_32F);
      for (int j = 0; j < c.R; ++j) {
        for (int i = 0; i < c.R; ++i) {
          chart_u.at<float>(j, i) = static_cast<float>(i + 0.5);
          chart_v.at<float>(j, i) = static_cast<float>(j + 0.5);
        }
      }
    }
  }

  LkFromTruthMeter lk_meter;
  std::optional<AppearanceProbe> appearance;  // rung A of the detail ladder
  std::optional<TruthRegistration> registration;
  // Pools of the registered truth (CaptureEvalSummary::Registered), active frames.
  MapMoments reg_detail, reg_band, reg_layer_band, reg_truth_band, reg_truth_layer_band;
  int reg_frames = 0;
  std::array<MapMoments, kTruthShifts.size()> truth_shift;  // D*'s band slid (CaptureEvalSummary::truth_shift)
  CaptureEvalSummary::Landmarks landmarks;  // sums until ReduceSummary
  cv::Mat chart_u, chart_v;  // R×R: each texel's own chart coordinates, texels
  // The slide: the true texel each tracked texel sees minus its own, texels, over the
  // wrinkle regions; per registered frame the medians of its length and of its u and
  // v components (robust to texels whose pixel straddles a UV seam), summed.
  double slide_length = 0, slide_u = 0, slide_v = 0;
  int slide_frames = 0;
  // The drift: the chart coordinates the first registered frame's texels see, and
  // per later frame the median distance from them (texels), summed, and the largest.
  cv::Mat first_u, first_v;
  double drift_sum = 0, drift_max = 0;
  int drift_frames = 0;
  // Displacement pooled over the active frames (and those where the wrinkle layer is active).
  MapMoments pooled_face, pooled_wrinkle, pooled_band, pooled_layer_band;
  std::vector<MapMoments> pooled_region, pooled_region_band;  // per CaptureEvalContext::region_masks
  struct ExpressionPool {
    MapMoments band, registered_band;
    int frames = 0, registered_frames = 0;
  };
  std::map<std::string, ExpressionPool> by_expression;  // CaptureEvalSummary::d_by_expression
  int active_frames = 0, layer_active_frames = 0;
  MapMoments still_pooled;  // D^t against the previous D^t over every still pair (MeasureStillFace)
  cv::Mat error_vectors;  // Fig. 11's picture, once drawn
  int error_vectors_frame = -1;
  int tracked_count = 0;
  PreviousFrame previous;
  TruthMemo truth_memo;
};

// A tracked frame's truth at the tracking rig's vertices (head frame of the truth
// rig, then camera) and the tracking rig's best fit to it.
struct RigTruth {
  FrameTruth truth;
  Eigen::VectorXd beta;        // the true expression
  MatX3d true_cam, prior_cam;  // #V×3, camera frame, mm
};

RigTruth ReadRigTruth(const CaptureEvalContext& c, int index) {
  RigTruth t;
  t.truth = c.corr.MapTruth(ReadFrameTruth(c.dataset, index, c.truth_rig.num_vertices()));
  const Eigen::VectorXd identity = TruthIdentity(c.truth_rig, t.truth);
  t.beta = ExpressionVector(c.truth_rig, t.truth.expression);
  const MatX3d true_head = c.corr.Map(c.truth_motion.EvaluatePositions(identity, t.beta));
  t.true_cam = Transform(t.truth.cam_from_head, true_head);
  t.prior_cam =
      Transform(t.truth.cam_from_head, c.corr.FromTrackingFrame(c.prior->Fit(c.corr.ToTrackingFrame(true_head))));
  return t;
}

// What the later steps of a frame use of its tracking errors: the 2D error vectors
// of L^t and L~^t (#V×2 px, NaN off the visible face-chart vertices), those
// vertices, and L~^t rigidly aligned to the truth (#V×3, camera frame).
struct FrameTrackingVectors {
  MatX2d err_coarse, err_refined;
  std::vector<int> visible;
  MatX3d refined_aligned;
};

// 2D vertex errors of L^t, L~^t and the prior over the visible face-chart vertices.
FrameTrackingVectors MeasureVertexErrors2d(const CaptureEvalContext& c, const CaptureFrameArrays& arrays,
                                           const RigTruth& t, FrameCaptureEval* e) {
  FrameTrackingVectors v;
  v.err_coarse.resize(c.rig.num_vertices(), 2);
  v.err_coarse.setConstant(std::numeric_limits<double>::quiet_NaN());
  v.err_refined = v.err_coarse;
  double sc = 0, sr = 0;
  for (int i : c.face_ids) {
    if (!t.truth.vertex_visible[i]) continue;
    const Eigen::RowVector2d p = t.truth.vertices.row(i);
    v.err_coarse.row(i) = c.cam.ProjectCamPoint(arrays.coarse.row(i).transpose()).transpose() - p;
    v.err_refined.row(i) = c.cam.ProjectCamPoint(arrays.refined.row(i).transpose()).transpose() - p;
    e->prior_px += (c.cam.ProjectCamPoint(t.prior_cam.row(i).transpose()).transpose() - p).norm();
    sc += v.err_coarse.row(i).norm();
    sr += v.err_refined.row(i).norm();
    v.visible.push_back(i);
  }
  e->visible_vertices = static_cast<int>(v.visible.size());
  if (!v.visible.empty()) {
    e->coarse_px = sc / v.visible.size();
    e->refined_px = sr / v.visible.size();
    e->prior_px /= v.visible.size();
  }
  return v;
}

// 3D vertex errors over the face-chart vertices (camera frame), raw and after the
// rigid alignment to the truth; returns L~^t aligned.
MatX3d MeasureVertexErrors3d(const CaptureEvalContext& c, const CaptureFrameArrays& arrays, const RigTruth& t,
                             FrameCaptureEval* e) {
  e->prior_mm = MeanDistance(t.prior_cam, t.true_cam, c.face_ids);
  e->coarse_mm = MeanDistance(arrays.coarse, t.true_cam, c.face_ids);
  e->refined_mm = MeanDistance(arrays.refined, t.true_cam, c.face_ids);
  const Rigid3d align_c = Kabsch(arrays.coarse, t.true_cam, c.face_ids);
  const Rigid3d align_r = Kabsch(arrays.refined, t.true_cam, c.face_ids);
  MatX3d refined_aligned = Transform(align_r, arrays.refined);
  e->coarse_aligned_mm = MeanDistance(Transform(align_c, arrays.coarse), t.true_cam, c.face_ids);
  e->refined_aligned_mm = MeanDistance(refined_aligned, t.true_cam, c.face_ids);
  return refined_aligned;
}

// The frame (sRGB-encoded RGB in [0, 1]) when `needed` and on disk; else empty.
cv::Mat ReadFrameRgb(const CaptureEvalContext& c, int index, bool needed) {
  if (!needed || !fs::is_regular_file(c.FramePath(index))) return cv::Mat();
  return ReadRgbFrame(c.FramePath(index), /*linear=*/false);
}

// LK from the true positions (issue 16): this frame's step, or a break in the chain.
void AddLkStep(int index, const cv::Mat& img, const FrameTruth& truth, const CaptureFrameArrays& arrays,
               LkFromTruthMeter* meter) {
  if (arrays.flow_vertex.empty() || img.empty()) {
    meter->Skip();
    return;
  }
  cv::Mat gray, gray8;
  cv::cvtColor(img, gray, cv::COLOR_RGB2GRAY);
  gray.convertTo(gray8, CV_8U, 255.0);
  meter->Add(index, gray8, truth, arrays.flow_vertex);
}

// The tracking jitter: the mean change of the 2D error vectors since the previous
// frame, over this frame's visible vertices that were visible there too.
void MeasureTrackingJitter(const PreviousFrame& prev, int index, const FrameTrackingVectors& v, FrameCaptureEval* e) {
  if (prev.frame != index - 1 || prev.err_coarse.rows() != v.err_coarse.rows()) return;
  double jc = 0, jr = 0;
  int n = 0;
  for (int i : v.visible) {
    if (!prev.err_coarse.row(i).allFinite()) continue;
    jc += (v.err_coarse.row(i) - prev.err_coarse.row(i)).norm();
    jr += (v.err_refined.row(i) - prev.err_refined.row(i)).norm();
    ++n;
  }
  if (n > 0) {
    e->coarse_jitter_px = jc / n;
    e->refined_jitter_px = jr / n;
  }
}

// The landmark source's points of frame `index` (frames/NNNNNN.json "landmarks",
// when it stored 68) against the truth's, added to the sums of `sum`.
void AddLandmarkErrors(const CaptureEvalContext& c, int index, const FrameTruth& truth,
                       CaptureEvalSummary::Landmarks* sum) {
  const fs::path path = c.capture / "frames" / fmt::format("{:06d}.json", index);
  if (!fs::is_regular_file(path) || truth.landmarks.rows() != kIbugNumPoints) return;
  const json frame = ReadJsonFile(path);
  if (!frame.contains("landmarks") || !frame["landmarks"].is_array() ||
      frame["landmarks"].size() != static_cast<size_t>(kIbugNumPoints)) {
    return;
  }
  MatX2d err(kIbugNumPoints, 2);
  for (int i = 0; i < kIbugNumPoints; ++i) {
    const json& p = frame["landmarks"][static_cast<size_t>(i)];
    Require(p.is_array() && p.size() == 2 && p[0].is_number() && p[1].is_number(),
            fmt::format("{}: landmarks[{}] is not a point [x, y]", path.string(), i));
    err.row(i) = Eigen::RowVector2d(p[0].get<double>(), p[1].get<double>()) - truth.landmarks.row(i);
  }
  const double px = err.rowwise().norm().mean();
  sum->px += px;
  sum->iod += px / std::max(InterOcularDistance(truth.landmarks), 1.0);
  for (size_t g = 0; g < kIbugGroups.size(); ++g) {
    const auto part = err.middleRows(kIbugGroups[g].first, kIbugGroups[g].end - kIbugGroups[g].first);
    sum->groups[g] += Eigen::Vector3d(part.rowwise().norm().mean(), part.col(0).mean(), part.col(1).mean());
  }
  ++sum->frames;
}

// Tracking (Fig. 11): 2D and 3D vertex errors, the refinement's stages at its flow
// points, LK from the truth, the error-vector picture, and the jitter.
FrameTrackingVectors EvaluateFrameTracking(const CaptureEvalContext& c, int index, const CaptureFrameArrays& arrays,
                                           const RigTruth& t, FrameLoopState* st, FrameCaptureEval* e) {
  FrameTrackingVectors v = MeasureVertexErrors2d(c, arrays, t, e);
  if (!arrays.flow_vertex.empty()) {
    e->flow = MeasureFlowStages(arrays, c.cam, t.truth.vertices, t.truth.vertex_visible, c.evaluated);
    e->has_flow = e->flow.points > 0;
  }
  e->true_visible_fraction = c.VisibleFraction(t.truth.vertex_visible);
  // The frame, read once for LK and the error vectors.
  const bool draw_vectors =
      st->error_vectors.empty() && c.vectors_target >= 0 && index >= c.vectors_target && !v.visible.empty();
  const cv::Mat img = ReadFrameRgb(c, index, !arrays.flow_vertex.empty() || draw_vectors);
  AddLkStep(index, img, t.truth, arrays, &st->lk_meter);
  if (draw_vectors && !img.empty()) {
    cv::Mat rgb8;
    img.convertTo(rgb8, CV_8U, 255.0);
    st->error_vectors = DrawErrorVectors(rgb8, t.truth.vertices, v.err_coarse, v.err_refined, v.visible,
                                         e->coarse_px, e->refined_px, c.options.vectors_scale);
    st->error_vectors_frame = index;
  }
  v.refined_aligned = MeasureVertexErrors3d(c, arrays, t, e);
  MeasureTrackingJitter(st->previous, index, v, e);
  AddLandmarkErrors(c, index, t.truth, &st->landmarks);
  return v;
}

// The wrinkle offset (Fig. 14) in offset_region, on a frame where the truth's band is active there.
void MeasureWrinkleOffset(const CaptureEvalContext& c, const cv::Mat& Db, const cv::Mat& Gb, FrameCaptureEval* e) {
  const bool active = cv::countNonZero(c.offset_mask) > 0 &&
                      CompareMaps(Db, Gb, c.offset_mask).reference_rms_mm >= c.options.active_reference_rms_mm;
  if (!active) return;
  int shift = 0;
  if (BestVerticalOffset(Db, Gb, c.offset_mask, c.offset_shift, &shift, &e->d_offset_correlation) &&
      e->d_offset_correlation >= c.options.offset_min_correlation) {
    e->has_offset = true;
    e->d_offset_mm = shift * c.mm_per_texel;  // +: D^t's lines lie higher (v grows downwards)
  }
}

// A frame with wrinkles: the truth's wrinkle-band RMS in the wrinkle regions reaches
// active_reference_rms_mm (the frames the pooled displacement metrics count).
bool IsActiveFrame(const CaptureEvalOptions& o, const FrameCaptureEval& e) {
  return e.d_wrinkle_band.reference_rms_mm >= o.active_reference_rms_mm;
}

// D*'s band of an active frame against itself slid by each of kTruthShifts.
void PoolSlidTruth(const CaptureEvalContext& c, const cv::Mat& Gb, FrameLoopState* st) {
  for (size_t k = 0; k < kTruthShifts.size(); ++k) {
    const int shift = std::max(1, static_cast<int>(std::lround(kTruthShifts[k].mm / c.mm_per_texel)));
    AddSlidTruthMoments(Gb, c.wrinkle_mask, shift, &st->truth_shift[k]);
  }
}

// The expression a frame holds, for CaptureEvalSummary::d_by_expression: the name
// of the largest weight of β if it reaches 0.5, without a side suffix ("_L", "_R");
// empty for a face near neutral.
std::string DominantExpression(const FaceRig& rig, const Eigen::VectorXd& beta) {
  if (beta.size() == 0 || beta.size() != static_cast<Eigen::Index>(rig.expression_names.size())) return {};
  Eigen::Index k = 0;
  if (!(beta.maxCoeff(&k) >= 0.5)) return {};
  std::string name = rig.expression_names[static_cast<size_t>(k)];
  if (name.size() > 2 && (name.ends_with("_L") || name.ends_with("_R"))) name.resize(name.size() - 2);
  return name;
}

// Pools the frame's band (Db) into the displacement metrics of the frames where
// it is active: against the truth (D, G, Gb) and against the dataset's wrinkle layer
// (its band Lb, static lines included: the truth of crease ≤ 0.3) when the truth is D*;
// and by `expression`, the frame's DominantExpression (empty: none).
void PoolDisplacement(const CaptureEvalContext& c, const cv::Mat& D, const cv::Mat& G, const cv::Mat& Db,
                      const cv::Mat& Gb, const cv::Mat& Lb, const std::string& expression, const FrameCaptureEval& e,
                      FrameLoopState* st) {
  if (c.detail_truth) {
    if (CompareMaps(Db, Lb, c.wrinkle_mask).reference_rms_mm >= c.options.active_reference_rms_mm) {
      ++st->layer_active_frames;
      st->pooled_layer_band.Add(Db, Lb, c.wrinkle_mask);
    }
  }
  if (IsActiveFrame(c.options, e)) {
    ++st->active_frames;
    st->pooled_face.Add(D, G, c.coverage);
    st->pooled_wrinkle.Add(D, G, c.wrinkle_mask);
    st->pooled_band.Add(Db, Gb, c.wrinkle_mask);
    if (c.detail_truth) PoolSlidTruth(c, Gb, st);
    for (size_t k = 0; k < c.region_masks.size(); ++k) {
      st->pooled_region[k].Add(D, G, c.region_masks[k].second);
      st->pooled_region_band[k].Add(Db, Gb, c.region_masks[k].second);
    }
    if (!expression.empty()) {
      FrameLoopState::ExpressionPool& pool = st->by_expression[expression];
      ++pool.frames;
      pool.band.Add(Db, Gb, c.wrinkle_mask);
    }
  }
}

// D^t's jitter: the RMS of the change of the band error since the previous frame
// over the wrinkle regions, mm.
void MeasureDisplacementJitter(const CaptureEvalContext& c, const PreviousFrame& prev, int index,
                               const cv::Mat& band_err, FrameCaptureEval* e) {
  if (prev.frame != index - 1 || prev.band_err.empty()) return;
  const cv::Mat diff = band_err - prev.band_err;
  double sum = 0;
  int n = 0;
  for (int j = 0; j < c.R; ++j) {
    const float* p = diff.ptr<float>(j);
    const uint8_t* m = c.wrinkle_mask.ptr<uint8_t>(j);
    for (int i = 0; i < c.R; ++i) {
      if (!m[i] || !std::isfinite(p[i])) continue;
      sum += static_cast<double>(p[i]) * p[i];
      ++n;
    }
  }
  e->d_jitter_mm = n ? std::sqrt(sum / n) : 0.0;
}

// Still face: the true expression held since the previous frame; D^t against the
// previous D^t, per pair and pooled into `pooled` (e's active flag already set).
void MeasureStillFace(const CaptureEvalContext& c, const PreviousFrame& prev, int index, const cv::Mat& D,
                      const Eigen::VectorXd& beta, FrameCaptureEval* e, MapMoments* pooled) {
  if (prev.frame != index - 1 || prev.D.empty() || prev.beta.size() != beta.size() ||
      !((beta - prev.beta).cwiseAbs().maxCoeff() < 1e-6)) {
    return;
  }
  const MapComparison cmp = CompareMaps(D, prev.D, c.wrinkle_mask);
  e->still = cmp.extracted_rms_mm > 0 && cmp.reference_rms_mm > 0;  // no patch, no detail: nothing to compare
  if (!e->still) return;
  e->d_still_correlation = cmp.correlation;
  e->still_active = IsActiveFrame(c.options, *e);
  pooled->Add(D, prev.D, c.wrinkle_mask);
}

// The median of `values` (empty: 0).
double Median(std::vector<float> values) {
  if (values.empty()) return 0.0;
  auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

// A frame's slide (du, dv: R×R, texels, NaN where not registered) over the wrinkle
// regions: the medians of its length and components, added to the loop's sums.
void AddSlide(const CaptureEvalContext& c, const cv::Mat& du, const cv::Mat& dv, FrameLoopState* st) {
  std::vector<float> length, u, v;
  for (int j = 0; j < c.R; ++j) {
    for (int i = 0; i < c.R; ++i) {
      const float a = du.at<float>(j, i), b = dv.at<float>(j, i);
      if (!c.wrinkle_mask.at<uint8_t>(j, i) || !std::isfinite(a) || !std::isfinite(b)) continue;
      length.push_back(std::hypot(a, b));
      u.push_back(a);
      v.push_back(b);
    }
  }
  if (length.empty()) return;
  st->slide_length += Median(std::move(length));
  st->slide_u += Median(std::move(u));
  st->slide_v += Median(std::move(v));
  ++st->slide_frames;
}

// A frame's drift: the registered chart coordinates (u, v: R×R, texels, NaN where
// not registered) against the first registered frame's, the median distance over
// the wrinkle regions; the first registered frame is kept instead.
void AddDrift(const CaptureEvalContext& c, const cv::Mat& u, const cv::Mat& v, FrameLoopState* st) {
  if (st->first_u.empty()) {
    st->first_u = u.clone();
    st->first_v = v.clone();
    return;
  }
  std::vector<float> distance;
  for (int j = 0; j < c.R; ++j) {
    for (int i = 0; i < c.R; ++i) {
      if (!c.wrinkle_mask.at<uint8_t>(j, i)) continue;
      const float d = std::hypot(u.at<float>(j, i) - st->first_u.at<float>(j, i),
                                 v.at<float>(j, i) - st->first_v.at<float>(j, i));
      if (std::isfinite(d)) distance.push_back(d);
    }
  }
  if (distance.empty()) return;
  const double median = Median(std::move(distance));
  st->drift_sum += median;
  st->drift_max = std::max(st->drift_max, median);
  ++st->drift_frames;
}

// An active frame's D^t against the truth registered through the image at L~^t
// (eval/registered_truth.h): D* raw and banded, and the wrinkle layer's band; and
// the registered truth against the truth itself; and by `expression` as PoolDisplacement.
void PoolRegisteredTruth(const CaptureEvalContext& c, const RigTruth& t, const CaptureFrameArrays& arrays,
                         const cv::Mat& D, const cv::Mat& G, const cv::Mat& Db, const cv::Mat& Gb, const cv::Mat& Lb,
                         const std::string& expression, FrameLoopState* st) {
  const std::vector<cv::Mat> reg =
      st->registration->Register(t.true_cam, arrays.refined, {G, Gb, Lb, st->chart_u, st->chart_v});
  ++st->reg_frames;
  AddSlide(c, reg[3] - st->chart_u, reg[4] - st->chart_v, st);
  AddDrift(c, reg[3], reg[4], st);
  st->reg_detail.Add(D, reg[0], c.wrinkle_mask);
  st->reg_band.Add(Db, reg[1], c.wrinkle_mask);
  st->reg_layer_band.Add(Db, reg[2], c.wrinkle_mask);
  st->reg_truth_band.Add(reg[1], Gb, c.wrinkle_mask);
  st->reg_truth_layer_band.Add(reg[2], Lb, c.wrinkle_mask);
  if (!expression.empty()) {
    FrameLoopState::ExpressionPool& pool = st->by_expression[expression];
    ++pool.registered_frames;
    pool.registered_band.Add(Db, reg[1], c.wrinkle_mask);
  }
}

// D^t of one frame, its truth D* (empty unless the detail truth is Sec. 4.1's) and
// D^t's band minus the truth's (all empty when D^t is not compared).
struct FrameDisplacement {
  cv::Mat D, truth, band_err;
};

// The band normal error of L~^t, L~^t + D^HF, L~^t + D^t and H^t against D*, from
// the wrinkle bands of D^t (Db) and of D* (Gb): WrinkleBand is linear, so the
// band of D^t + D^HF is the sum of the bands.
BandNormals MeasureBandNormals(const CaptureEvalContext& c, const cv::Mat& Db, const cv::Mat& Gb) {
  const cv::Mat d = c.NormalBand(Db), g = c.NormalBand(Gb);
  const cv::Mat zero = cv::Mat::zeros(g.size(), CV_32F);
  BandNormals b;
  b.coarse_deg = BandNormalError(zero, g, c.wrinkle_mask, c.mm_per_texel);
  b.meso_deg = BandNormalError(c.meso_band, g, c.wrinkle_mask, c.mm_per_texel);
  b.detail_deg = BandNormalError(d, g, c.wrinkle_mask, c.mm_per_texel);
  b.full_deg = BandNormalError(d + c.meso_band, g, c.wrinkle_mask, c.mm_per_texel);
  return b;
}

// D^t against the truth: over the face and the wrinkle regions, raw and in the
// wrinkle band; the wrinkle offset, the pools, the jitter and the still face; the
// appearance probe on the same truth.
FrameDisplacement EvaluateFrameDisplacement(const CaptureEvalContext& c, int index, const CaptureFrameArrays& arrays,
                                            const RigTruth& t, FrameLoopState* st, FrameCaptureEval* e) {
  const Eigen::VectorXd& beta = t.beta;
  FrameDisplacement d;
  const fs::path d_path = c.capture / "displacement" / fmt::format("{:06d}.exr", index);
  if (!c.corr.same_uv || !fs::is_regular_file(d_path)) return d;
  d.D = ReadMap(d_path, c.R);
  const cv::Mat layer = ReadMap(c.info.DisplacementPath(index), c.R, /*resample=*/true);
  cv::Mat G = layer, Gb, Lb;
  if (c.detail_truth) {
    st->truth_memo.Truth(c, beta, &G, &Gb);
    Lb = st->truth_memo.LayerBand(c, layer);
  } else {
    Gb = WrinkleBand(G, c.band_mask);
  }
  if (!c.options.truth_maps_dir.empty()) {
    WriteImage(fs::path(c.options.truth_maps_dir) / fmt::format("{:06d}.exr", index), G);
  }
  if (st->appearance) st->appearance->Add(index, arrays, G, layer);
  e->has_displacement = true;
  e->d_face = CompareMaps(d.D, G, c.coverage);
  e->d_wrinkle = CompareMaps(d.D, G, c.wrinkle_mask);
  const cv::Mat Db = WrinkleBand(d.D, c.band_mask);
  e->d_face_band = CompareMaps(Db, Gb, c.coverage);
  e->d_wrinkle_band = CompareMaps(Db, Gb, c.wrinkle_mask);
  d.band_err = Db - Gb;
  if (c.detail_truth) {
    d.truth = G;
    e->band_normals = MeasureBandNormals(c, Db, Gb);
    e->has_band_normals = true;
  }
  MeasureWrinkleOffset(c, Db, Gb, e);
  const std::string expression = DominantExpression(c.truth_rig, beta);  // for d_by_expression
  PoolDisplacement(c, d.D, G, Db, Gb, Lb, expression, *e, st);
  if (st->registration && IsActiveFrame(c.options, *e)) {
    PoolRegisteredTruth(c, t, arrays, d.D, G, Db, Gb, Lb, expression, st);
  }
  MeasureDisplacementJitter(c, st->previous, index, d.band_err, e);
  MeasureStillFace(c, st->previous, index, d.D, beta, e, &st->still_pooled);
  return d;
}

// H^t against the true high-resolution surface (every surface_every-th tracked
// frame), for L~^t alone, with D^HF, with D^t + D^HF, and with D* + D^HF when D*
// is known (`detail`: D^t and D*, either empty when absent).
void EvaluateFrameSurface(const CaptureEvalContext& c, int tracked_count, const RigTruth& t,
                          const MatX3d& refined_aligned, const FrameDisplacement& detail, FrameCaptureEval* e) {
  if (!c.actor || (tracked_count - 1) % c.options.surface_every != 0) return;
  TriMesh truth_hires = c.actor->Frame(t.beta, true).hires;
  truth_hires.V = Transform(t.truth.cam_from_head, truth_hires.V);
  const RayCaster caster(truth_hires);
  const cv::Mat zero = cv::Mat::zeros(c.R, c.R, CV_32F);
  const double max_mm = c.options.surface_max_distance_mm;
  e->surface_coarse = MeasureSurface(c.hifi->Build(refined_aligned, zero), caster, max_mm, c.wrinkle_mask);
  e->surface_meso = MeasureSurface(c.hifi->Build(refined_aligned, c.meso), caster, max_mm, c.wrinkle_mask);
  if (!detail.D.empty()) {
    e->surface_full =
        MeasureSurface(c.hifi->Build(refined_aligned, detail.D + c.meso), caster, max_mm, c.wrinkle_mask);
  }
  if (!detail.truth.empty()) {
    e->surface_truth =
        MeasureSurface(c.hifi->Build(refined_aligned, detail.truth + c.meso), caster, max_mm, c.wrinkle_mask);
    e->has_surface_truth = true;
  }
  e->has_surface = true;
}

// One frame: tracking, displacement, surface (an untracked one: only whether the face was there to be tracked).
FrameCaptureEval EvaluateFrame(const CaptureEvalContext& c, int index, FrameLoopState* st) {
  FrameCaptureEval e;
  e.frame = index;
  const CaptureFrameArrays arrays = ReadCaptureFrameArrays(c.capture / "frames" / fmt::format("{:06d}.cfr", index));
  e.tracked = arrays.tracked;
  if (!e.tracked) {
    // Was the face there to be tracked? (the loss metrics)
    e.true_visible_fraction =
        c.VisibleFraction(c.corr.MapTruth(ReadFrameTruth(c.dataset, index, c.truth_rig.num_vertices())).vertex_visible);
    st->previous.frame = -2;
    return e;
  }
  Require(arrays.coarse.rows() == c.rig.num_vertices(),
          fmt::format("{}: {} vertices, the rig has {}", (c.capture / "frames").string(), arrays.coarse.rows(),
                      c.rig.num_vertices()));
  ++st->tracked_count;
  const RigTruth t = ReadRigTruth(c, index);
  FrameTrackingVectors v = EvaluateFrameTracking(c, index, arrays, t, st, &e);
  FrameDisplacement d = EvaluateFrameDisplacement(c, index, arrays, t, st, &e);
  EvaluateFrameSurface(c, st->tracked_count, t, v.refined_aligned, d, &e);
  st->previous = {index, std::move(v.err_coarse), std::move(v.err_refined), std::move(d.band_err), std::move(d.D),
                  t.beta};
  return e;
}

// Loss and recovery: the frames with the face visible but not tracked, and the longest run of them.
void SummariseLoss(const CaptureEvalOptions& options, CaptureEvalSummary* s) {
  int run = 0;
  for (const FrameCaptureEval& e : s->per_frame) {
    s->min_visible_fraction = std::min(s->min_visible_fraction, e.true_visible_fraction);
    if (!e.tracked && e.true_visible_fraction >= options.visible_face_fraction) {
      ++s->lost_visible_frames;
      s->longest_loss_frames = std::max(s->longest_loss_frames, ++run);
    } else {
      run = 0;
    }
  }
}

// The wrinkle offset's mean and its slide (the last quarter of the measured frames
// minus the first, Fig. 14).
void SummariseWrinkleOffset(CaptureEvalSummary* s) {
  std::vector<double> offsets;
  for (const FrameCaptureEval& e : s->per_frame)
    if (e.has_offset) offsets.push_back(e.d_offset_mm);
  s->offset_frames = static_cast<int>(offsets.size());
  if (offsets.empty()) return;
  double sum = 0;
  for (double o : offsets) sum += o;
  s->d_offset_mm = sum / offsets.size();
  const size_t q = std::max<size_t>(1, offsets.size() / 4);
  double first = 0, last = 0;
  for (size_t i = 0; i < q; ++i) {
    first += offsets[i];
    last += offsets[offsets.size() - 1 - i];
  }
  s->d_offset_slide_mm = (last - first) / q;
}

// The tracking errors averaged over the tracked frames: (per frame, in the summary).
constexpr std::pair<double FrameCaptureEval::*, double CaptureEvalSummary::*> kTrackingMeans[] = {
    {&FrameCaptureEval::coarse_px, &CaptureEvalSummary::coarse_px},
    {&FrameCaptureEval::refined_px, &CaptureEvalSummary::refined_px},
    {&FrameCaptureEval::coarse_mm, &CaptureEvalSummary::coarse_mm},
    {&FrameCaptureEval::refined_mm, &CaptureEvalSummary::refined_mm},
    {&FrameCaptureEval::coarse_aligned_mm, &CaptureEvalSummary::coarse_aligned_mm},
    {&FrameCaptureEval::refined_aligned_mm, &CaptureEvalSummary::refined_aligned_mm},
    {&FrameCaptureEval::prior_px, &CaptureEvalSummary::prior_px},
    {&FrameCaptureEval::prior_mm, &CaptureEvalSummary::prior_mm}};

// Means of the tracking errors over the tracked frames (the jitter over the frames that have one).
void AverageTracking(CaptureEvalSummary* s) {
  int jitter_frames = 0;
  for (const FrameCaptureEval& e : s->per_frame) {
    if (!e.tracked) continue;
    ++s->tracked;
    for (const auto& [frame_field, summary_field] : kTrackingMeans) s->*summary_field += e.*frame_field;
    if (e.coarse_jitter_px > 0) {
      s->coarse_jitter_px += e.coarse_jitter_px;
      s->refined_jitter_px += e.refined_jitter_px;
      ++jitter_frames;
    }
  }
  if (s->tracked > 0) {
    const double n = s->tracked;
    for (const auto& [frame_field, summary_field] : kTrackingMeans) s->*summary_field /= n;
  }
  if (jitter_frames > 0) {
    s->coarse_jitter_px /= jitter_frames;
    s->refined_jitter_px /= jitter_frames;
  }
}

// Means over the tracked frames with D^t (jitter, still face) and with surface metrics.
void AverageDisplacementAndSurface(CaptureEvalSummary* s) {
  int d_jitter_frames = 0;
  for (const FrameCaptureEval& e : s->per_frame) {
    if (!e.tracked) continue;
    if (e.has_displacement) {
      ++s->displacement_frames;
      if (e.d_jitter_mm > 0) {
        s->d_jitter_mm += e.d_jitter_mm;
        ++d_jitter_frames;
      }
      if (e.still) {
        s->d_still_correlation += e.d_still_correlation;
        ++s->still_pairs;
        (e.still_active ? s->d_still_active_correlation : s->d_still_inactive_correlation) += e.d_still_correlation;
        ++(e.still_active ? s->still_active_pairs : s->still_inactive_pairs);
      }
    }
    if (e.has_surface) {
      ++s->surface_frames;
      Accumulate(e.surface_coarse, &s->surface_coarse);
      Accumulate(e.surface_meso, &s->surface_meso);
      Accumulate(e.surface_full, &s->surface_full);
    }
    if (e.has_surface_truth) {
      ++s->surface_truth_frames;
      Accumulate(e.surface_truth, &s->surface_truth);
    }
  }
  if (d_jitter_frames > 0) s->d_jitter_mm /= d_jitter_frames;
  if (s->still_pairs > 0) s->d_still_correlation /= s->still_pairs;
  if (s->still_active_pairs > 0) s->d_still_active_correlation /= s->still_active_pairs;
  if (s->still_inactive_pairs > 0) s->d_still_inactive_correlation /= s->still_inactive_pairs;
  Divide(s->surface_frames, &s->surface_coarse);
  Divide(s->surface_frames, &s->surface_meso);
  Divide(s->surface_frames, &s->surface_full);
  Divide(s->surface_truth_frames, &s->surface_truth);
}

// The band normal errors' means over the active frames (as the pooled displacement metrics).
void AverageBandNormals(const CaptureEvalOptions& o, CaptureEvalSummary* s) {
  BandNormals& b = s->band_normals;
  for (const FrameCaptureEval& e : s->per_frame) {
    if (!e.has_band_normals || !IsActiveFrame(o, e)) continue;
    ++s->band_normal_frames;
    b.coarse_deg += e.band_normals.coarse_deg;
    b.meso_deg += e.band_normals.meso_deg;
    b.detail_deg += e.band_normals.detail_deg;
    b.full_deg += e.band_normals.full_deg;
  }
  if (s->band_normal_frames == 0) return;
  const double n = s->band_normal_frames;
  b = {b.coarse_deg / n, b.meso_deg / n, b.detail_deg / n, b.full_deg / n};
}

// The summary: the per-frame results reduced, the pools and meters read out, and
// the capture's speed copied.
CaptureEvalSummary ReduceSummary(const CaptureEvalContext& c, const FrameLoopState& st,
                                 std::vector<FrameCaptureEval> per_frame) {
  CaptureEvalSummary s;
  s.capture = c.capture.string();
  s.dataset = c.dataset.string();
  s.detail_truth = ToString(c.options.detail_truth);
  s.per_frame = std::move(per_frame);
  s.frames = static_cast<int>(s.per_frame.size());
  s.error_vectors = st.error_vectors;
  s.error_vectors_frame = st.error_vectors_frame;
  SummariseLoss(c.options, &s);
  SummariseWrinkleOffset(&s);
  s.flow = PoolFlowStages(s.per_frame, &s.flow_frames);
  s.lk_truth = st.lk_meter.Result();
  AverageTracking(&s);
  AverageDisplacementAndSurface(&s);
  AverageBandNormals(c.options, &s);
  s.mesoscopic = c.meso_truth;
  s.mesoscopic_albedo = c.meso_albedo_comparison;
  s.active_frames = st.active_frames;
  s.layer_active_frames = st.layer_active_frames;
  s.d_face = st.pooled_face.Result();
  s.d_wrinkle = st.pooled_wrinkle.Result();
  s.d_wrinkle_band = st.pooled_band.Result();
  for (size_t k = 0; k < st.pooled_region.size(); ++k)
    s.d_by_region.push_back({c.region_masks[k].first, st.pooled_region[k].Result(), st.pooled_region_band[k].Result()});
  for (const auto& [name, pool] : st.by_expression) {
    s.d_by_expression.push_back({name, pool.frames, pool.registered_frames, pool.band.Result(),
                                 pool.registered_band.Result()});
  }
  s.d_layer_band = st.pooled_layer_band.Result();
  s.d_still_pooled_correlation = st.still_pooled.Result().correlation;
  if (st.appearance) s.appearance = st.appearance->Result();
  s.registered = {st.reg_frames,           st.reg_detail.Result(),     st.reg_band.Result(),
                  st.reg_layer_band.Result(), st.reg_truth_band.Result(), st.reg_truth_layer_band.Result()};
  if (st.truth_shift[0].n > 0) {
    for (const MapMoments& m : st.truth_shift) s.truth_shift.push_back(m.Result());
  }
  s.landmarks = st.landmarks;
  if (s.landmarks.frames > 0) {
    const double n = s.landmarks.frames;
    s.landmarks.px /= n;
    s.landmarks.iod /= n;
    for (Eigen::Vector3d& g : s.landmarks.groups) g /= n;
  }
  if (st.slide_frames > 0) {
    const double scale = c.mm_per_texel / st.slide_frames;
    s.registered.slide_mm = st.slide_length * scale;
    s.registered.slide_u_mm = st.slide_u * scale;
    s.registered.slide_v_mm = st.slide_v * scale;
  }
  if (st.drift_frames > 0) {
    s.registered.drift_mm = st.drift_sum * c.mm_per_texel / st.drift_frames;
    s.registered.drift_max_mm = st.drift_max * c.mm_per_texel;
  }
  if (c.cap.contains("timing")) s.timing_json = c.cap["timing"].dump();
  s.fps = c.cap.value("fps", 0.0);
  s.overlapped = c.cap.value("overlapped", false);  // captures before crease 0.4.14 ran serially
  s.stage_ms_per_frame = c.cap.value("stage_ms_per_frame", c.cap.value("ms_per_frame", 0.0));
  s.tracking_share = c.cap.value("tracking_share", 0.0);
  s.detail_share = c.cap.value("detail_share", 0.0);
  return s;
}

}  // namespace

CaptureEvalSummary EvaluateCapture(const fs::path& capture, const fs::path& dataset,
                                   const CaptureEvalOptions& options) {
  options.Check();
  const CaptureEvalContext context(capture, dataset, options);
  FrameLoopState state(context);
  std::vector<FrameCaptureEval> per_frame;
  for (int index : context.frames) per_frame.push_back(EvaluateFrame(context, index, &state));
  return ReduceSummary(context, state, std::move(per_frame));
}

std::string CaptureEvalSummary::ToJson() const {
  json j;
  j["capture"] = capture;
  j["dataset"] = dataset;
  j["frames"] = frames;
  j["tracked_frames"] = tracked;
  j["tracking"] = {{"coarse_px", coarse_px},
                   {"refined_px", refined_px},
                   {"coarse_mm", coarse_mm},
                   {"refined_mm", refined_mm},
                   {"coarse_aligned_mm", coarse_aligned_mm},
                   {"refined_aligned_mm", refined_aligned_mm},
                   {"coarse_jitter_px", coarse_jitter_px},
                   {"refined_jitter_px", refined_jitter_px},
                   {"prior_px", prior_px},
                   {"prior_mm", prior_mm},
                   // What the refinement adds to the 2D error (px), and the ratio (the
                   // claims of tracking-refinement: no worse than + 0.1 px with a good
                   // tracker, ≤ 0.85 under model error).
                   {"refined_excess_px", refined_px - coarse_px},
                   {"refined_ratio", coarse_px > 0 ? refined_px / coarse_px : 0.0}};
  j["refinement_stages"] = flow_frames > 0 ? FlowStagesJson(flow) : json(nullptr);
  if (lk_truth.point_steps > 0) {
    j["lk_from_truth"] = {{"point_steps", lk_truth.point_steps},
                          {"motion_px", lk_truth.motion_px},
                          {"error_px", lk_truth.error_px},
                          {"ratio", lk_truth.ratio}};
  }
  j["displacement"] = {{"frames", displacement_frames},
                       {"active_frames", active_frames},
                       {"face", ComparisonJson(d_face)},
                       {"wrinkle_regions", ComparisonJson(d_wrinkle)},
                       {"wrinkle_regions_band", ComparisonJson(d_wrinkle_band)},
                       {"by_region", RegionComparisonsJson(d_by_region, false)},
                       {"by_region_band", RegionComparisonsJson(d_by_region, true)},
                       {"by_expression", ExpressionComparisonsJson(d_by_expression)},
                       {"truth", detail_truth},
                       {"wrinkle_layer_band", ComparisonJson(d_layer_band)},
                       {"wrinkle_layer_active_frames", layer_active_frames},
                       {"jitter_band_mm", d_jitter_mm},
                       {"offset_frames", offset_frames}};
  AddStillFaceJson(*this, &j["displacement"]);
  if (offset_frames > 0) {  // else not measured (null), never a misleading 0
    j["displacement"]["offset_mm"] = d_offset_mm;
    j["displacement"]["offset_slide_mm"] = d_offset_slide_mm;
  } else {
    j["displacement"]["offset_mm"] = nullptr;
    j["displacement"]["offset_slide_mm"] = nullptr;
  }
  if (landmarks.frames > 0) {  // the capture stored its landmark source's points; else absent
    json groups = json::object();
    for (size_t g = 0; g < kIbugGroups.size(); ++g) {
      groups[kIbugGroups[g].name] = {
          {"px", landmarks.groups[g].x()}, {"dx", landmarks.groups[g].y()}, {"dy", landmarks.groups[g].z()}};
    }
    j["landmarks"] = {{"frames", landmarks.frames}, {"px", landmarks.px}, {"iod", landmarks.iod}, {"parts", groups}};
  }
  if (registered.frames > 0) {  // eval/registered_truth.h; else absent
    j["registered"] = {{"frames", registered.frames},
                       {"wrinkle_regions", ComparisonJson(registered.detail)},
                       {"wrinkle_regions_band", ComparisonJson(registered.band)},
                       {"wrinkle_layer_band", ComparisonJson(registered.layer_band)},
                       {"truth_band_correlation", registered.truth_band.correlation},
                       {"truth_layer_band_correlation", registered.truth_layer_band.correlation},
                       {"slide_mm", registered.slide_mm},
                       {"slide_u_mm", registered.slide_u_mm},
                       {"slide_v_mm", registered.slide_v_mm},
                       {"drift_mm", registered.drift_mm},
                       {"drift_max_mm", registered.drift_max_mm}};
  }
  for (size_t k = 0; k < truth_shift.size(); ++k) {  // else absent
    j["truth_shift"][kTruthShifts[k].key] = truth_shift[k].correlation;
  }
  if (appearance.measured()) {  // rung A of the detail ladder (eval/appearance_ceiling.h); else absent
    j["appearance"] = {{"detail_correlation", appearance.correlation[0]},
                       {"layer_correlation", appearance.correlation[1]},
                       {"frames", appearance.frames[0] + appearance.frames[1]},
                       {"samples", appearance.samples[0] + appearance.samples[1]}};
  }
  j["loss"] = {{"lost_visible_frames", lost_visible_frames},
               {"longest_loss_frames", longest_loss_frames},
               {"min_visible_fraction", min_visible_fraction}};
  j["surface"] = {{"frames", surface_frames},
                  {"coarse", SurfaceJson(surface_coarse)},
                  {"coarse_mesoscopic", SurfaceJson(surface_meso)},
                  {"full", SurfaceJson(surface_full)}};
  if (surface_truth_frames > 0) j["surface"]["true_detail"] = SurfaceJson(surface_truth);  // else absent
  if (band_normal_frames > 0) {  // else absent
    j["surface"]["band"] = BandNormalsJson(band_normals);
    j["surface"]["band"]["frames"] = band_normal_frames;
  }
  if (mesoscopic.texels > 0) j["surface"]["mesoscopic"] = ComparisonJson(mesoscopic);  // else absent
  if (mesoscopic_albedo.texels > 0) {  // else absent
    j["surface"]["mesoscopic_albedo"] = {{"texels", mesoscopic_albedo.texels},
                                         {"correlation", mesoscopic_albedo.correlation}};
  }
  j["speed"] = {{"fps", fps},
                {"overlapped", overlapped},
                {"stage_ms_per_frame", stage_ms_per_frame},
                {"tracking_share", tracking_share},
                {"detail_share", detail_share},
                {"timing", json::parse(timing_json)}};
  json pf = json::array();
  for (const FrameCaptureEval& e : per_frame) {
    json f = {{"frame", e.frame}, {"tracked", e.tracked}, {"true_visible_fraction", e.true_visible_fraction}};
    if (e.tracked) {
      f["visible_vertices"] = e.visible_vertices;
      f["coarse_px"] = e.coarse_px;
      f["refined_px"] = e.refined_px;
      f["coarse_mm"] = e.coarse_mm;
      f["refined_mm"] = e.refined_mm;
      f["coarse_aligned_mm"] = e.coarse_aligned_mm;
      f["refined_aligned_mm"] = e.refined_aligned_mm;
      f["coarse_jitter_px"] = e.coarse_jitter_px;
      f["refined_jitter_px"] = e.refined_jitter_px;
      f["prior_px"] = e.prior_px;
      f["prior_mm"] = e.prior_mm;
      if (e.has_flow) f["refinement_stages"] = FlowStagesJson(e.flow);
      if (e.has_displacement) {
        f["displacement"] = {{"face", ComparisonJson(e.d_face)},
                             {"wrinkle_regions", ComparisonJson(e.d_wrinkle)},
                             {"face_band", ComparisonJson(e.d_face_band)},
                             {"wrinkle_regions_band", ComparisonJson(e.d_wrinkle_band)},
                             {"jitter_band_mm", e.d_jitter_mm}};
        if (e.still) {
          f["displacement"]["still_correlation"] = e.d_still_correlation;
          f["displacement"]["still_active"] = e.still_active;
        }
        if (e.has_offset) {
          f["displacement"]["offset_mm"] = e.d_offset_mm;
          f["displacement"]["offset_correlation"] = e.d_offset_correlation;
        }
      }
      if (e.has_band_normals) f["band_normals"] = BandNormalsJson(e.band_normals);
      if (e.has_surface) {
        f["surface"] = {{"coarse", SurfaceJson(e.surface_coarse)},
                        {"coarse_mesoscopic", SurfaceJson(e.surface_meso)},
                        {"full", SurfaceJson(e.surface_full)}};
        if (e.has_surface_truth) f["surface"]["true_detail"] = SurfaceJson(e.surface_truth);
      }
    }
    pf.push_back(f);
  }
  j["per_frame"] = pf;
  return j.dump(2);
}

std::string CaptureEvalSummary::ToCsv() const {
  std::ostringstream o;
  o << "frame,tracked,coarse_px,refined_px,coarse_mm,refined_mm,coarse_aligned_mm,refined_aligned_mm,"
       "coarse_jitter_px,refined_jitter_px,d_face_rmse_mm,d_face_corr,d_wrinkle_rmse_mm,d_wrinkle_corr,"
       "d_wrinkle_band_rmse_mm,d_wrinkle_band_corr,d_wrinkle_band_amplitude,d_jitter_mm,"
       "surface_coarse_normal_deg,surface_full_normal_deg,surface_coarse_mm,surface_full_mm\n";
  for (const FrameCaptureEval& e : per_frame) {
    o << fmt::format("{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f}", e.frame, e.tracked ? 1 : 0,
                     e.coarse_px, e.refined_px, e.coarse_mm, e.refined_mm, e.coarse_aligned_mm, e.refined_aligned_mm,
                     e.coarse_jitter_px, e.refined_jitter_px);
    if (e.has_displacement) {
      o << fmt::format(",{:.5f},{:.4f},{:.5f},{:.4f},{:.5f},{:.4f},{:.4f},{:.5f}", e.d_face.rmse_mm,
                       e.d_face.correlation, e.d_wrinkle.rmse_mm, e.d_wrinkle.correlation, e.d_wrinkle_band.rmse_mm,
                       e.d_wrinkle_band.correlation, Amp(e.d_wrinkle_band), e.d_jitter_mm);
    } else {
      o << ",,,,,,,,";
    }
    if (e.has_surface) {
      o << fmt::format(",{:.3f},{:.3f},{:.4f},{:.4f}", e.surface_coarse.normal_deg, e.surface_full.normal_deg,
                       e.surface_coarse.distance_mm, e.surface_full.distance_mm);
    } else {
      o << ",,,,";
    }
    o << "\n";
  }
  return o.str();
}

namespace {

// The band normal error's table and the D^HF lines of eval.md (ToMarkdown).
void WriteBandNormalsMarkdown(const CaptureEvalSummary& s, std::ostream& o) {
  if (s.band_normal_frames > 0) {
    const BandNormals& b = s.band_normals;
    o << fmt::format("## Normal error in the wrinkle band, wrinkle regions, {} frames with wrinkles\n\n"
                     "The layers' relief against D* between the band's edges (relief finer than the lower edge and "
                     "broader than the wrinkle band left out), as height fields on the chart: the wrinkles' share of "
                     "the normal error, which the surface measure above mixes with the pores, the static shape and the "
                     "tracker's error (D* itself scores 0).\n\n",
                     s.band_normal_frames);
    o << "| layers | normal error, deg | against L~^t |\n|---|---|---|\n";
    for (const auto& [name, deg] : {std::pair<const char*, double>{"L~^t (no detail)", b.coarse_deg},
                                    {"L~^t + D^HF", b.meso_deg},
                                    {"L~^t + D^t", b.detail_deg},
                                    {"H^t = L~^t + D^t + D^HF", b.full_deg}}) {
      o << fmt::format("| {} | {:.2f} | {:.2f} |\n", name, deg, b.coarse_deg > 0 ? deg / b.coarse_deg : 0.0);
    }
    o << "\n";
  }
  if (s.mesoscopic.texels > 0) {
    o << fmt::format("D^HF (Sec. 5.3) against the actor's true mesoscopic layer in the same band, wrinkle regions: "
                     "correlation {:.3f}, amplitude ratio {:.2f}\n\n",
                     s.mesoscopic.correlation, Amp(s.mesoscopic));
  }
  if (s.mesoscopic_albedo.texels > 0) {
    o << fmt::format("D^HF against the D^HF of the true albedo alone (the skin's colour through the same DoG; Sec. "
                     "5.3 reads dark as deep), wrinkle regions: correlation {:.3f} (both maps in the truth's UV "
                     "layout: a texture that slides more than the DoG's ~1 mm on the face hides the match)\n\n",
                     s.mesoscopic_albedo.correlation);
  }
}

}  // namespace

std::string CaptureEvalSummary::ToMarkdown() const {
  std::ostringstream o;
  o << fmt::format("# Capture against ground truth\n\ncapture `{}`, dataset `{}`: {} frames, {} tracked\n\n", capture,
                   dataset, frames, tracked);
  o << "## Tracking (paper Fig. 11)\n\n| | global L^t | refined L~^t |\n|---|---|---|\n";
  o << fmt::format("| 2D vertex error, px | {:.2f} | {:.2f} |\n", coarse_px, refined_px);
  o << fmt::format("| 3D vertex error, mm | {:.2f} | {:.2f} |\n", coarse_mm, refined_mm);
  o << fmt::format("| 3D vertex error after rigid alignment, mm | {:.2f} | {:.2f} |\n", coarse_aligned_mm,
                   refined_aligned_mm);
  o << fmt::format("| jitter (frame-to-frame change of the 2D error), px | {:.3f} | {:.3f} |\n\n", coarse_jitter_px,
                   refined_jitter_px);
  o << fmt::format("Prior error (the tracking rig's best least-squares fit to the true coarse mesh at the true "
                   "identity, the model error a blendshape prior cannot remove): {:.2f} px, {:.2f} mm\n\n",
                   prior_px, prior_mm);
  if (landmarks.frames > 0) {
    std::string parts;
    for (size_t g = 0; g < kIbugGroups.size(); ++g) {
      parts += fmt::format("{}{} {:.1f} px ({:+.1f}, {:+.1f})", g ? ", " : "", kIbugGroups[g].name,
                           landmarks.groups[g].x(), landmarks.groups[g].y(), landmarks.groups[g].z());
    }
    o << fmt::format("Landmark source against the true landmarks, {} frames: {:.2f} px ({:.3f} IOD); by part, mean "
                     "error (mean vector, +y down): {}\n\n",
                     landmarks.frames, landmarks.px, landmarks.iod, parts);
  }
  if (flow_frames > 0) {
    o << fmt::format("### Refinement steps at the flow points (Sec. 5.1), {} frames, {} points per frame\n\n"
                     "2D error against the true projections, px; beside each status, the error of u^t at the same "
                     "points.\n\n| step | points per frame | error, px | u^t at the same points, px |\n"
                     "|---|---|---|---|\n",
                     flow_frames, flow.points);
    o << fmt::format("| u^t (projection of L^t) | {} | {:.2f} | |\n", flow.points, flow.coarse_px);
    o << fmt::format("| ũ^t trusted (LK, passed ξ_α and ξ_β) | {} | {:.2f} | {:.2f} |\n", flow.trusted,
                     flow.trusted_px, flow.trusted_coarse_px);
    o << fmt::format("| ũ^t recovered (MLS) | {} | {:.2f} | {:.2f} |\n", flow.recovered, flow.recovered_px,
                     flow.recovered_coarse_px);
    o << fmt::format("| ũ^t reset to u^t | {} | {:.2f} | |\n", flow.reset, flow.reset_px);
    o << fmt::format("| ũ^t, all | {} | {:.2f} | {:.2f} |\n", flow.points, flow.flow_px, flow.coarse_px);
    o << fmt::format("| 3D fit F | {} | {:.2f} | {:.2f} |\n", flow.points, flow.fit_px, flow.coarse_px);
    o << fmt::format("| L~^t (F + Laplacian deformation) | {} | {:.2f} | {:.2f} |\n\n", flow.points,
                     flow.refined_px, flow.coarse_px);
    if (lk_truth.point_steps > 0) {
      o << fmt::format("LK from the true positions (the capture's LK settings, {} point-steps): true motion {:.2f} px "
                       "per frame, LK's error {:.2f} px per step, motion recovered {:.0f} %\n\n",
                       lk_truth.point_steps, lk_truth.motion_px, lk_truth.error_px, 100.0 * lk_truth.ratio);
    }
  }
  if (displacement_frames > 0) {
    o << fmt::format("## Displacement D^t (paper Sec. 5.2): {} frames, {} with wrinkles (pooled below)\n\n",
                     displacement_frames, active_frames);
    o << (detail_truth == "extraction"
              ? "Truth: Sec. 4.1's detail (eval/detail_truth.h), the wrinkle layer beyond the neutral plus the coarse "
                "expression's medium band that the compatible rig gives up.\n\n"
              : "Truth: the studio's wrinkle layer (the dataset's expression displacement maps).\n\n");
    o << "| region | RMSE, mm | correlation | amplitude ratio | true RMS, mm |\n|---|---|---|---|---|\n";
    for (const auto& [name, c] : {std::pair<const char*, const MapComparison&>{"face", d_face},
                                  {"wrinkle regions", d_wrinkle},
                                  {"wrinkle regions, wrinkle band", d_wrinkle_band},
                                  {"the wrinkle layer alone (static lines included): wrinkle regions, band",
                                   d_layer_band}}) {
      if (c.texels == 0) continue;
      o << fmt::format("| {} | {:.4f} | {:.3f} | {:.2f} | {:.4f} |\n", name, c.rmse_mm, c.correlation, Amp(c),
                       c.reference_rms_mm);
    }
    for (const auto& r : d_by_region) {
      if (r.detail.texels == 0) continue;
      o << fmt::format("| {} (band: correlation {:.3f}, amplitude {:.2f}) | {:.4f} | {:.3f} | {:.2f} | {:.4f} |\n",
                       r.region, r.band.correlation, Amp(r.band), r.detail.rmse_mm, r.detail.correlation,
                       Amp(r.detail), r.detail.reference_rms_mm);
    }
    o << ExpressionTableMarkdown(d_by_expression);
    o << fmt::format("\nD^t jitter (frame-to-frame change of the band error, wrinkle regions): {:.4f} mm\n",
                     d_jitter_mm);
    if (still_pairs > 0) {
      o << fmt::format("D^t on a still face (the true expression held), {} frame pairs: correlation with the previous "
                       "frame's {:.3f} (wrinkle regions); {} pairs where the truth holds wrinkles {:.3f}, {} "
                       "without {:.3f}; pooled over all pairs' texels {:.3f}\n",
                       still_pairs, d_still_correlation, still_active_pairs, d_still_active_correlation,
                       still_inactive_pairs, d_still_inactive_correlation, d_still_pooled_correlation);
    }
    if (registered.frames > 0) {
      o << fmt::format("Against the truth registered through the image at L~^t (what the tracked texture shows at each "
                       "texel), {} frames: D^t correlates {:.3f} with D* ({:.3f} in the wrinkle band), {:.3f} with the "
                       "wrinkle layer's band; the registration keeps {:.3f} of D*'s band and {:.3f} of the layer's "
                       "(correlation with the unregistered truth); the texture slides {:.2f} mm on the face in the "
                       "wrinkle regions ({:+.2f} mm along u, {:+.2f} mm along v; medians per frame, mean over frames) "
                       "and drifts {:.2f} mm from where it sat in the first of these frames (at most {:.2f} mm)\n",
                       registered.frames, registered.detail.correlation, registered.band.correlation,
                       registered.layer_band.correlation, registered.truth_band.correlation,
                       registered.truth_layer_band.correlation, registered.slide_mm, registered.slide_u_mm,
                       registered.slide_v_mm, registered.drift_mm, registered.drift_max_mm);
    }
    if (!truth_shift.empty()) {
      o << "D*'s wrinkle band against itself slid on the face (what a slide of the texture costs any D^t in UV):";
      for (size_t k = 0; k < truth_shift.size(); ++k) {
        o << fmt::format(" {} mm {:.3f}", kTruthShifts[k].mm, truth_shift[k].correlation);
      }
      o << "\n";
    }
    if (appearance.measured()) {
      o << fmt::format("Appearance index (a linear filter of the capture's own texture T^t/T_ref - 1, fitted on half "
                       "of {} frames and scored on the other half: how visible the detail is in the texture, not a "
                       "bound): correlation {:.3f} with the truth, {:.3f} with the wrinkle layer\n",
                       appearance.frames[0] + appearance.frames[1], appearance.correlation[0],
                       appearance.correlation[1]);
    }
    if (offset_frames > 0) {
      o << fmt::format("Wrinkle offset (the shift of D^t's lines against the true ones that correlates best; + = "
                       "higher on the face), {} frames: mean {:+.2f} mm, last quarter minus first quarter {:+.2f} mm "
                       "(Fig. 14)\n",
                       offset_frames, d_offset_mm, d_offset_slide_mm);
    }
    o << "\n";
  }
  if (lost_visible_frames > 0) {
    o << fmt::format("Face visible but not tracked: {} frames; the longest run (recovery time) {} frames\n\n",
                     lost_visible_frames, longest_loss_frames);
  }
  if (surface_frames > 0) {
    o << fmt::format("## Surface H^t against the true high-resolution surface, {} frames (rigidly aligned)\n\n",
                     surface_frames);
    o << "| layers | normal error, deg | distance, mm | wrinkle regions: normal error, deg | distance, mm |\n"
         "|---|---|---|---|---|\n";
    for (const auto& [name, e] : {std::pair<const char*, const SurfaceError&>{"L~^t (no detail)", surface_coarse},
                                  {"L~^t + D^HF", surface_meso},
                                  {"H^t = L~^t + D^t + D^HF", surface_full}}) {
      o << fmt::format("| {} | {:.2f} | {:.3f} | {:.2f} | {:.3f} |\n", name, e.normal_deg, e.distance_mm,
                       e.wrinkle_normal_deg, e.wrinkle_distance_mm);
    }
    if (surface_truth_frames > 0) {
      o << fmt::format("| L~^t + D* + D^HF (the true detail: a perfect regressor) | {:.2f} | {:.3f} | {:.2f} | {:.3f} |\n",
                       surface_truth.normal_deg, surface_truth.distance_mm, surface_truth.wrinkle_normal_deg,
                       surface_truth.wrinkle_distance_mm);
    }
    o << "\n";
  }
  WriteBandNormalsMarkdown(*this, o);
  if (fps > 0) {
    o << fmt::format("## Speed\n\n{:.1f} frames per second (file I/O excluded{}); the stage times sum to {:.1f} ms "
                     "per frame, tracking {:.0f} %, detail {:.0f} % (paper: 18 fps on a GTX 980, 58 % / 42 %)\n",
                     fps, overlapped ? "; wall clock, frames overlapped on the cores" : "", stage_ms_per_frame,
                     100 * tracking_share, 100 * detail_share);
  }
  return o.str();
}

void WriteCaptureEval(const fs::path& dir, const CaptureEvalSummary& s) {
  fs::create_directories(dir);
  const std::string md = s.ToMarkdown(), csv = s.ToCsv(), js_line = s.ToJson() + "\n";
  auto text = [](const std::string& t) {
    return [&t](const fs::path& tmp) { WriteFileAtomic(tmp, [&](std::ostream& o) { o << t; }); };
  };
  // All or nothing: a failed write left eval.json beside an older eval_frames.csv.
  std::vector<PendingFile> files = {{dir / "eval_frames.csv", text(csv)}, {dir / "eval.md", text(md)}};
  if (!s.error_vectors.empty()) {  // Fig. 11
    files.push_back({dir / "error_vectors.png",
                     [&](const fs::path& tmp) { WriteImage(tmp, s.error_vectors, {.srgb = false}); }});
  }
  files.push_back({dir / "eval.json", text(js_line)});
  WriteFilesAtomic(files);
}

}  // namespace crease
