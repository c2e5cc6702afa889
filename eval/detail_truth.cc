#include "eval/detail_truth.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <unistd.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/dataset_info.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/picture.h"
#include "core/ray_caster.h"
#include "eval/tracking_metrics.h"
#include "pipeline/training/scan_set.h"
#include "pipeline/training/wrinkle_map.h"

namespace crease {

DetailTruth::DetailTruth(const FaceRig& rig, const Actor& actor, const DetailExtractionOptions& detail)
    : model_(rig, actor), compatible_(MakeRigCompatible(model_.rig(), detail)) {
  const FaceRig& personal = model_.rig();
  delta_ = (personal.expression_basis - compatible_.expression_basis).cast<double>();
  const int R = actor.options.resolution;
  raster_ = RasterizeUv(personal.neutral, R, R, "detail truth: the rig's face chart");
  neutral_wrinkles_ = model_.Frame(Eigen::VectorXd::Zero(personal.num_expressions()), false).expression_displacement;
  if (detail.lowpass_bandwidth_mm > 0.0) {
    lowpass_texels_ = detail.lowpass_bandwidth_mm / std::max(MmPerTexel(personal.neutral, R), 1e-9);
    chart_band_ = MakeWrinkleBandMask(CoverageMask(raster_), lowpass_texels_);
  }
  Require(neutral_wrinkles_.rows == R && neutral_wrinkles_.cols == R,
          fmt::format("detail truth: the actor's wrinkle map is {}×{}, expected {}×{}", neutral_wrinkles_.cols,
                      neutral_wrinkles_.rows, R, R));
}

cv::Mat DetailTruth::WrinkleLayer(const Eigen::VectorXd& expression) const {
  const Eigen::VectorXd w = ZeroPadded(expression, model_.rig().num_expressions());
  return model_.Frame(w, false).expression_displacement - neutral_wrinkles_;
}

cv::Mat DetailTruth::Wrinkles(const Eigen::VectorXd& expression) const {
  const cv::Mat layer = WrinkleLayer(expression);
  return lowpass_texels_ > 0.0 ? WrinkleBand(layer, chart_band_) : layer;
}

cv::Mat DetailTruth::CoarseBand(const Eigen::VectorXd& expression) const {
  const Eigen::VectorXd w = ZeroPadded(expression, compatible_.num_expressions());
  const TriMesh c = compatible_.Evaluate(ZeroPadded(model_.actor().identity, compatible_.num_identity()), w);
  const MatX3d n = VertexNormals(c);
  const Eigen::VectorXd d = delta_ * w;  // 3#V
  Eigen::MatrixXd along(c.num_vertices(), 1);
  for (int v = 0; v < c.num_vertices(); ++v) along(v, 0) = n.row(v).dot(d.segment<3>(3 * v));
  return InterpolateToUv(raster_, c, along);
}

cv::Mat DetailTruth::Detail(const Eigen::VectorXd& expression) const {
  return Wrinkles(expression) + CoarseBand(expression);
}

namespace {

// Per texel of `raster`, the signed distance along the interpolated normal from
// `coarse` (its triangles Phong-tessellated with shape factor `phong_alpha`, as
// synth/hires_surface.h; 0 = flat) to `surface`; NaN where no surface is within max_mm.
cv::Mat DistanceAlongNormals(const UvRaster& raster, const TriMesh& coarse, const TriMesh& surface, double max_mm,
                             double phong_alpha) {
  const MatX3d N = VertexNormals(coarse);
  RayCasterOptions robust;
  robust.robust = true;
  const RayCaster caster(surface, robust, "exact detail: the high-resolution surface");
  std::vector<Eigen::Vector3f> origins, directions;
  std::vector<int> texel;
  for (int k = 0; k < raster.width * raster.height; ++k) {
    const int t = raster.triangle[k];
    if (t < 0) continue;
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) {
      p += raster.barycentric[k][c] * coarse.V.row(coarse.F(t, c)).transpose();
      n += raster.barycentric[k][c] * N.row(coarse.F(t, c)).transpose();
    }
    if (!(n.norm() > 0.0)) continue;
    const double b[3] = {raster.barycentric[k][0], raster.barycentric[k][1], raster.barycentric[k][2]};
    const double* const v[3] = {coarse.V.row(coarse.F(t, 0)).data(), coarse.V.row(coarse.F(t, 1)).data(),
                                coarse.V.row(coarse.F(t, 2)).data()};
    const double* const nk[3] = {N.row(coarse.F(t, 0)).data(), N.row(coarse.F(t, 1)).data(),
                                 N.row(coarse.F(t, 2)).data()};
    PhongTessellate(phong_alpha, b, v, nk, p.data());
    origins.push_back(p.cast<float>());
    directions.push_back(n.normalized().cast<float>());
    texel.push_back(k);
  }
  std::vector<SignedHit> hits;
  caster.IntersectSignedBatch(origins, directions, static_cast<float>(max_mm), &hits);
  cv::Mat out(raster.height, raster.width, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  float* o = out.ptr<float>();
  for (size_t i = 0; i < hits.size(); ++i)
    if (hits[i].valid()) o[texel[i]] = hits[i].t;
  return out;
}

}  // namespace

cv::Mat DetailTruth::SurfaceDistance(const Eigen::VectorXd& expression, const TriMesh& surface, double phong_alpha,
                                     double max_mm) const {
  Require(phong_alpha >= 0.0 && phong_alpha <= 1.0,
          fmt::format("exact detail: phong_alpha = {} must be in [0, 1]", phong_alpha));
  const Eigen::VectorXd identity = ZeroPadded(model_.actor().identity, compatible_.num_identity());
  const Eigen::VectorXd w = ZeroPadded(expression, compatible_.num_expressions());
  return DistanceAlongNormals(raster_, compatible_.Evaluate(identity, w), surface, max_mm, phong_alpha);
}

cv::Mat DetailTruth::ExactDetail(const Eigen::VectorXd& expression, const TriMesh& surface,
                                 const cv::Mat& neutral_distance, double phong_alpha, double max_mm) const {
  return SurfaceDistance(expression, surface, phong_alpha, max_mm) - neutral_distance;
}

}  // namespace crease

namespace crease {

Eigen::VectorXd ReadTruthExpression(const FaceRig& rig, const std::filesystem::path& truth_json) {
  const nlohmann::json j = ReadJsonFile(truth_json);
  Require(j.contains("expression") && j["expression"].is_object(),
          fmt::format("{}: no \"expression\" object", truth_json.string()));
  std::vector<std::pair<std::string, double>> named;
  for (const auto& [name, w] : j["expression"].items()) {
    Require(w.is_number(), fmt::format("{}: expression '{}' is not a number", truth_json.string(), name));
    named.emplace_back(name, w.get<double>());
  }
  return ExpressionVector(rig, named);
}

namespace {

// A scan's exact detail (DetailTruth::ExactDetail) beside D^j and D*, all three in
// the wrinkle band over `valid`: the texels of `mask` where the exact detail is
// defined (a ray found the surface).
struct ExactScanDetail {
  cv::Mat valid, exact_band, extracted_band, detail_band;
};
ExactScanDetail ExactOfScan(cv::Mat exact, const cv::Mat& mask, const cv::Mat& extracted, const cv::Mat& detail,
                            double sigma) {
  ExactScanDetail e{mask.clone(), {}, {}, {}};
  e.valid.setTo(0, exact != exact);  // NaN: no surface within reach
  exact.setTo(0.0f, e.valid == 0);
  const WrinkleBandMask bm = MakeWrinkleBandMask(e.valid, sigma);
  e.exact_band = WrinkleBand(exact, bm);
  e.extracted_band = WrinkleBand(extracted, bm);
  e.detail_band = WrinkleBand(detail, bm);
  return e;
}

// `dir`/SCAN.exr: the scan's D* (mm); `dir`/SCAN.png, half size, on one colour range
// of three times D*'s RMS (at least 0.02 mm): D^j, D* and D^j − D* (top: as they are;
// middle: their wrinkle band, `extracted_band` and `detail_band`); bottom: the exact
// detail's band, D^j's band minus it, D*'s band minus it.
void WriteScanTruth(const std::filesystem::path& dir, const std::string& scan, const cv::Mat& extracted,
                    const cv::Mat& detail, const cv::Mat& mask, const cv::Mat& extracted_band,
                    const cv::Mat& detail_band, const ExactScanDetail& e) {
  std::filesystem::create_directories(dir);
  WriteImage(dir / (scan + ".exr"), detail);
  const double rms = CompareMaps(detail, cv::Mat::zeros(detail.size(), CV_32F), mask).extracted_rms_mm;
  const double range = std::max(0.02, 3.0 * rms);
  auto row = [&](const cv::Mat& a, const cv::Mat& b, const cv::Mat& c, const cv::Mat& m) {
    cv::Mat out;
    cv::hconcat(std::vector<cv::Mat>{DisplacementPicture(a, range, m), DisplacementPicture(b, range, m),
                                     DisplacementPicture(c, range, m)},
                out);
    return out;
  };
  cv::Mat picture, half;
  cv::vconcat(std::vector<cv::Mat>{row(extracted, detail, extracted - detail, mask),
                                   row(extracted_band, detail_band, extracted_band - detail_band, mask),
                                   row(e.exact_band, e.extracted_band - e.exact_band, e.detail_band - e.exact_band,
                                       e.valid)},
              picture);
  cv::resize(picture, half, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  WriteImage(dir / (scan + ".png"), half, {.srgb = false});
}

}  // namespace

ExtractionTruthReport EvaluateExtraction(const std::filesystem::path& scans, const ExtractionTruthOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const ScanSet set = ReadScanSet(scans);
  Require(!set.rig.empty(), fmt::format("{}: the scan set names no rig", (scans / "scans.json").string()));
  const FaceRig rig = ReadRig(set.rig);
  ExtractionTruthReport report;
  const int n_actors = options.max_actors > 0 ? std::min<int>(options.max_actors, static_cast<int>(set.actors.size()))
                                              : static_cast<int>(set.actors.size());
  for (int a = 0; a < n_actors; ++a) {
    const ScanActor& sa = set.actors[a];
    const DetailTruth truth(rig, ReadActor(sa.folder / "actor.json"), options.detail);
    const int R = truth.resolution();
    Require(options.detail.map_resolution == R,
            fmt::format("{}: the actor's maps are {}×{}; set map_resolution = {}", (sa.folder / "actor.json").string(),
                        R, R, R));
    std::vector<TriMesh> meshes;
    const std::vector<int> order = NeutralFirst(sa);
    for (int s : order) meshes.push_back(ReadMesh(sa.scans[s].mesh));
    std::vector<MatX3d> others;
    for (size_t j = 1; j < meshes.size(); ++j) others.push_back(meshes[j].V);
    const DetailExtractor extractor(meshes[0], options.detail, sa.scans[sa.neutral].mesh.string(), others);
    const double mm_per_texel = std::max(MmPerTexel(meshes[0], R), 1e-9);
    const double sigma = options.band_mm / mm_per_texel;
    const cv::Mat regions = ValidRegionMask(rig.regions, options.regions, R, extractor.coverage());
    const cv::Mat away = AwayFromRims(extractor.coverage(), options.rim_margin_mm / mm_per_texel);
    const Eigen::VectorXd neutral_beta = Eigen::VectorXd::Zero(rig.num_expressions());
    const cv::Mat neutral_distance = truth.SurfaceDistance(neutral_beta, meshes[0], options.exact_phong_alpha);
    for (size_t j = 0; j < meshes.size(); ++j) {
      const ScanEntry& scan = sa.scans[order[j]];
      const Eigen::VectorXd beta = ReadTruthExpression(rig, scan.mesh.parent_path() / "truth.json");
      const ExtractedDetail d = extractor.Extract(meshes[j].V, scan.mesh.string());
      cv::Mat mask, region_mask;
      cv::bitwise_and(extractor.coverage(), d.valid, mask);
      cv::bitwise_and(mask, regions, region_mask);
      const cv::Mat wrinkles = truth.Wrinkles(beta), band = truth.CoarseBand(beta);
      const cv::Mat detail = wrinkles + band;
      const WrinkleBandMask bm = MakeWrinkleBandMask(mask, sigma);
      const cv::Mat db = WrinkleBand(d.displacement, bm);
      cv::bitwise_and(mask, away, mask);
      cv::bitwise_and(region_mask, away, region_mask);
      ExtractionTruthRow row;
      row.actor = sa.name;
      row.scan = scan.name;
      row.wrinkles = CompareMaps(d.displacement, wrinkles, mask);
      row.detail = CompareMaps(d.displacement, detail, mask);
      row.wrinkles_band = CompareMaps(db, WrinkleBand(wrinkles, bm), mask);
      const cv::Mat detail_b = WrinkleBand(detail, bm);
      row.detail_band = CompareMaps(db, detail_b, mask);
      row.detail_regions = CompareMaps(d.displacement, detail, region_mask);
      row.detail_regions_band = CompareMaps(db, detail_b, region_mask);
      row.coarse_band_rms_mm = CompareMaps(band, cv::Mat::zeros(band.size(), CV_32F), mask).extracted_rms_mm;
      const ExactScanDetail exact =
          ExactOfScan(truth.ExactDetail(beta, meshes[j], neutral_distance, options.exact_phong_alpha), mask,
                      d.displacement, detail, sigma);
      row.exact_extracted_band = CompareMaps(exact.extracted_band, exact.exact_band, exact.valid);
      row.exact_detail_band = CompareMaps(exact.detail_band, exact.exact_band, exact.valid);
      if (!options.write_truth.empty()) {
        WriteScanTruth(options.write_truth / sa.name, scan.name, d.displacement, detail, mask, db, detail_b, exact);
      }
      report.rows.push_back(row);
    }
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

std::string ExtractionTruthReport::ToTable() const {
  std::string o = fmt::format("{:<10} {:<22} {:>9} {:>8} {:>8} | {:>8} {:>8} {:>8} | {:>8} {:>8} | {:>8} {:>8}\n",
                              "actor", "scan", "band RMS", "wr corr", "wr bcorr", "D* RMS", "D* corr", "D* bcorr",
                              "reg corr", "reg bcorr", "ex: D^j", "ex: D*");
  for (const auto& r : rows) {
    o += fmt::format(
        "{:<10} {:<22} {:>9.4f} {:>8.3f} {:>8.3f} | {:>8.4f} {:>8.3f} {:>8.3f} | {:>8.3f} {:>8.3f} | {:>8.3f} {:>8.3f}\n",
        r.actor, r.scan, r.coarse_band_rms_mm, r.wrinkles.correlation, r.wrinkles_band.correlation,
        r.detail.reference_rms_mm, r.detail.correlation, r.detail_band.correlation, r.detail_regions.correlation,
        r.detail_regions_band.correlation, r.exact_extracted_band.correlation, r.exact_detail_band.correlation);
  }
  o += "(band: the wrinkle band; reg: the wrinkle regions; ex: against the exact detail in the band, "
       "DetailTruth::ExactDetail)\n";
  return o;
}

std::string ExtractionTruthReport::ToJson() const {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& r : rows) {
    j.push_back({{"actor", r.actor},
                 {"scan", r.scan},
                 {"coarse_band_rms_mm", r.coarse_band_rms_mm},
                 {"wrinkles", MapComparisonJson(r.wrinkles)},
                 {"wrinkles_band", MapComparisonJson(r.wrinkles_band)},
                 {"detail", MapComparisonJson(r.detail)},
                 {"detail_band", MapComparisonJson(r.detail_band)},
                 {"detail_regions", MapComparisonJson(r.detail_regions)},
                 {"detail_regions_band", MapComparisonJson(r.detail_regions_band)},
                 {"exact_extracted_band", MapComparisonJson(r.exact_extracted_band)},
                 {"exact_detail_band", MapComparisonJson(r.exact_detail_band)}});
  }
  return nlohmann::json{{"scans", j}, {"seconds", seconds}}.dump(1);
}

int WriteDetailTruthMaps(const std::filesystem::path& dataset, const DetailExtractionOptions& detail, int frames,
                         const std::filesystem::path& out) {
  namespace fs = std::filesystem;
  const SequenceDatasetInfo info = ReadSequenceDatasetInfo(dataset);
  const int first = info.first_frame;
  const int n = frames < 0 ? info.frames : std::min(frames, info.frames);
  const FaceRig rig = ReadRig(info.RigPath());
  const DetailTruth truth(rig, ReadActor(dataset / "actor.json"), detail);
  WriteFolderAtomic(out, /*overwrite=*/true, [&](const fs::path& tmp) {
    for (int i = first; i < first + n; ++i) {
      const Eigen::VectorXd beta = ReadTruthExpression(rig, info.TruthPath(i));
      WriteImage(tmp / fmt::format("{:06d}.exr", i), ResampleSquareMap(truth.Detail(beta), detail.map_resolution));
    }
  });
  return n;
}

}  // namespace crease
