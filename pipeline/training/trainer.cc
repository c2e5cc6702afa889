#include "pipeline/training/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "core/array_file.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/image_io.h"
#include "core/picture.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/ray_caster.h"
#include "core/uv_raster.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

void TrainingOptions::VisitFields(OptionVisitor& v) {
  v.Section("detail", detail);
  v.Section("fit", fit);
  v.Section("texture", texture);
  v.Section("wrinkle", wrinkle);
  v.Section("patch", patch);
  v.Section("pca", pca);
  v.Section("ferns", ferns);
  v.Section("baseline", baseline);
  v.Field("training_lights", training_lights);
  v.Field("max_actors", max_actors);
  v.Field("training_targets", training_targets);
  v.Field("target_maps", target_maps);
  v.Field("validation_band_mm", validation_band_mm);
  v.Field("pair_shift_texels", pair_shift_texels);
  v.Field("pair_shift_steps", pair_shift_steps);
  v.Field("target_band_mm", target_band_mm);
}

void TrainingOptions::Check() const {
  detail.Check();
  fit.Check();
  texture.Check();
  wrinkle.Check();
  patch.Check();
  pca.Check();
  ferns.Check();
  baseline.Check();
  Require(!training_lights.empty(), "TrainingOptions.training_lights must be \"all\", \"first\" or light names");
  CheckGe("TrainingOptions", "max_actors", max_actors, 0);
  CheckGe("TrainingOptions", "validation_band_mm", validation_band_mm, 0.0);
  CheckGe("TrainingOptions", "pair_shift_steps", pair_shift_steps, 0);
  CheckGe("TrainingOptions", "target_band_mm", target_band_mm, 0.0);
  Require((training_targets == TrainingTargets::kMaps) == !target_maps.empty(),
          "TrainingOptions: training_targets = maps needs target_maps (a folder), and target_maps needs it");
  CheckLe("TrainingOptions", "target_band_mm", target_band_mm, 100.0);
  Require(std::isfinite(pair_shift_texels) && pair_shift_texels > 0,
          fmt::format("TrainingOptions.pair_shift_texels = {} must be finite and > 0", pair_shift_texels));
}

namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::vector<std::string> SplitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// The light rigs whose images make textures.
std::vector<std::string> SelectLights(const ScanSet& set, const std::string& spec) {
  const std::vector<std::string> present = set.lights();
  if (spec == "all") return present;
  if (spec == "first") return {present.front()};
  std::vector<std::string> out = SplitComma(spec);
  for (const auto& l : out) {
    Require(std::find(present.begin(), present.end(), l) != present.end(),
            fmt::format("training_lights: light '{}' is not in the scan set (it has: {})", l, fmt::join(present, ", ")));
  }
  return out;
}

cv::Mat ResizeMask(const cv::Mat& mask, int size) {
  if (mask.rows == size && mask.cols == size) return mask;
  cv::Mat out;
  cv::resize(mask, out, cv::Size(size, size), 0, 0, cv::INTER_NEAREST);
  return out;
}

// A ground-truth displacement map (first channel), checked against the map size.
cv::Mat ReadTruth(const fs::path& path, int R) {
  cv::Mat truth = ReadImage(path);
  if (truth.channels() > 1) cv::extractChannel(truth, truth, 0);
  Require(truth.rows == R && truth.cols == R,
          fmt::format("{}: ground truth is {}×{}, the maps are {}×{}", path.string(), truth.cols, truth.rows, R, R));
  return truth;
}

}  // namespace

std::string TrainingSummary::ToJson() const {
  json j;
  j["seconds"] = seconds;
  j["training_pairs"] = training_pairs;
  json actors_json = json::array();
  for (const auto& a : actors) {
    actors_json.push_back({{"name", a.name},
                           {"scans", a.scans},
                           {"textures", a.textures},
                           {"patch_locations", a.patch_locations},
                           {"training_pairs", a.training_pairs},
                           {"correspondence", a.correspondence},
                           {"fit_rms_mm", a.fit_rms_mm},
                           {"wrinkle_texels", a.wrinkle_texels}});
  }
  j["actors"] = actors_json;
  json acc = json::array();
  for (const auto& s : accuracy) {
    json regions = json::object();
    for (const auto& [name, c] : s.regions) regions[name] = MapComparisonJson(c);
    json regions_band = json::object();
    for (const auto& [name, c] : s.regions_band) regions_band[name] = MapComparisonJson(c);
    acc.push_back({{"actor", s.actor},
                   {"scan", s.scan},
                   {"face", MapComparisonJson(s.face)},
                   {"regions", regions},
                   {"face_wrinkle_band", MapComparisonJson(s.face_band)},
                   {"regions_wrinkle_band", regions_band}});
  }
  j["detail_extraction_accuracy"] = acc;
  j["pca_energy"] = pca_energy;
  j["pca_reconstruction_rmse_mm"] = pca_reconstruction_rmse_mm;
  j["ferns"] = {{"samples", ferns.num_samples},
                {"checkpoint_ferns", ferns.checkpoint_ferns},
                {"train_rmse", ferns.train_rmse},
                {"mean_abs_correlation", ferns.mean_abs_correlation},
                {"empty_bin_fraction", ferns.empty_bin_fraction},
                {"seconds", ferns.seconds}};
  j["timing"] = json::parse(timing.ToJson());
  return j.dump(2);
}

std::string TrainingSummary::ToMarkdown() const {
  std::string s = "# Training summary\n\n";
  int scans = 0;
  for (const auto& a : actors) scans += a.scans;
  s += fmt::format("{} actors, {} scans, {} training patch pairs, {:.1f} s.\n\n", actors.size(), scans, training_pairs,
                   seconds);
  s += "| actor | scans | textures | rig fit | fit RMS (mm) | patches placed | pairs |\n|---|---|---|---|---|---|---|\n";
  for (const auto& a : actors) {
    double worst = 0.0;
    for (double r : a.fit_rms_mm) worst = std::max(worst, r);
    s += fmt::format("| {} | {} | {} | {} | ≤ {:.3f} | {} | {} |\n", a.name, a.scans, a.textures, a.correspondence,
                     worst, a.patch_locations, a.training_pairs);
  }
  if (!accuracy.empty()) {
    s += "\n## Detail extraction against ground truth (Sec. 4.1)\n\n";
    s += "D^j extracted from the scan meshes against the studio's medium-scale expression displacement (minus the "
         "neutral's, which M_0^j carries).\n\n";
    s += "| actor | scan | RMSE face (mm) | corr. face | GT RMS (mm) |";
    std::vector<std::string> region_names;
    for (const auto& [name, c] : accuracy.front().regions) region_names.push_back(name);
    for (const auto& r : region_names) s += fmt::format(" corr. {} |", r);
    s += "\n|---|---|---|---|---|";
    for (size_t r = 0; r < region_names.size(); ++r) s += "---|";
    s += "\n";
    for (const auto& a : accuracy) {
      s += fmt::format("| {} | {} | {:.4f} | {:.3f} | {:.4f} |", a.actor, a.scan, a.face.rmse_mm, a.face.correlation,
                       a.face.reference_rms_mm);
      for (const auto& [name, c] : a.regions) s += c.texels ? fmt::format(" {:.3f} |", c.correlation) : " – |";
      s += "\n";
    }
  }
  if (!accuracy.empty() && accuracy.front().face_band.texels > 0) {
    s += "\nThe same in the wrinkle band (both maps minus their Gaussian blur, TrainingOptions::validation_band_mm), "
         "forehead, eye and cheek regions:\n\n";
    s += "| actor | scan | RMSE face (mm) | corr. face | GT RMS face (mm) | corr. forehead | corr. glabella | corr. eyes | corr. cheeks |\n"
         "|---|---|---|---|---|---|---|---|---|\n";
    for (const auto& a : accuracy) {
      auto corr = [&](std::initializer_list<const char*> names) {
        double sum = 0;
        int n = 0;
        for (const auto& [name, c] : a.regions_band) {
          for (const char* want : names) {
            if (name == want && c.texels > 0 && c.reference_rms_mm > 1e-4) {
              sum += c.correlation;
              ++n;
            }
          }
        }
        return n ? fmt::format("{:.3f}", sum / n) : std::string("–");
      };
      s += fmt::format("| {} | {} | {:.4f} | {:.3f} | {:.4f} | {} | {} | {} | {} |\n", a.actor, a.scan, a.face_band.rmse_mm,
                       a.face_band.correlation, a.face_band.reference_rms_mm, corr({"forehead"}), corr({"glabella"}),
                       corr({"left_eye", "right_eye"}), corr({"left_cheek", "right_cheek"}));
    }
    s += "\n(– : the ground truth has no wrinkle there.)\n";
  }
  s += "\n## PCA of displacement patches (Sec. 4.3, Fig. 7)\n\n";
  for (int k : {1, 2, 4, 8, 16, 32, 64}) {
    if (k <= static_cast<int>(pca_energy.size())) s += fmt::format("- {} dimensions: {:.1f} % of the energy\n", k, 100 * pca_energy[k - 1]);
  }
  s += fmt::format("- reconstruction RMSE at the chosen dimension: {:.4f} mm\n", pca_reconstruction_rmse_mm);
  s += "\n## Fern cascade training error (Eqs. 2–4)\n\n| ferns | RMSE of coefficients |\n|---|---|\n";
  for (size_t i = 0; i < ferns.checkpoint_ferns.size(); ++i) {
    s += fmt::format("| {} | {:.4f} |\n", ferns.checkpoint_ferns[i], ferns.train_rmse[i]);
  }
  s += "\n## Time per step\n\n```\n" + timing.ToTable() + "```\n";
  return s;
}

namespace {

// Difference 6 (WrinkleMapOptions::texture_reference): each texture
// flattened by the neutral scan's texture under the same light (the first texture
// of each light: the neutral scan comes first), to FlatteningLevel.
void FlattenByNeutral(const WrinkleMapOptions& options, const std::vector<std::string>& lights,
                      const std::vector<cv::Mat>& coverage, std::vector<cv::Mat>* textures) {
  std::map<std::string, size_t> neutral;
  for (size_t t = 0; t < textures->size(); ++t) neutral.emplace(lights[t], t);
  std::map<std::string, cv::Mat> reference;
  for (const auto& [light, t] : neutral) reference[light] = (*textures)[t].clone();
  for (size_t t = 0; t < textures->size(); ++t) {
    cv::Mat seen;
    cv::bitwise_and(coverage[t], coverage[neutral[lights[t]]], seen);
    const cv::Mat& ref = reference[lights[t]];
    (*textures)[t] =
        FlattenByReference((*textures)[t], ref, seen, options.texture_reference, FlatteningLevel(options, ref, seen));
  }
}

}  // namespace

namespace {

// What the steps of ExtractTrainingPairs share: the inputs, the summary they fill,
// the log, and where report pictures go (empty: none).
struct ExtractionContext {
  const FaceRig& rig;
  const TrainingOptions& options;
  const std::vector<std::string>& lights;  // the selected light rigs
  const fs::path& report_dir;
  TrainingSummary& sum;
  const std::function<void(const std::string&)>& log_fn;

  bool pictures() const { return !report_dir.empty(); }
  void Log(const std::string& line) const {
    if (log_fn) log_fn(line);
  }
};

// The textures T^j of one actor's scans, one per scan and selected light rig, with
// each one's light, coverage, name and the scan's displacement map D^j.
struct ActorTextures {
  std::vector<cv::Mat> gray, displacement, coverage;
  std::vector<std::string> names, light;
};

// Sec. 4.1: the scan meshes of `actor` in `order` (neutral first), which must
// share one topology, and their file names.
void ReadActorScans(const ScanActor& actor, const std::vector<int>& order, std::vector<TriMesh>* meshes,
                    std::vector<std::string>* names) {
  for (int s : order) {
    meshes->push_back(ReadMesh(actor.scans[s].mesh));
    names->push_back(actor.scans[s].mesh.string());
    Require(meshes->back().F == meshes->front().F,
            fmt::format("{}: its triangles differ from the neutral scan {} (an actor's scans must share one "
                        "topology)",
                        names->back(), names->front()));
  }
}

// Sec. 4.1: the rig fitted to all of the actor's scans; with closest-point
// correspondences, the rig's UV layout then transferred from the fitted L^0 to
// M^0, and every scan cut alike.
RigFitResult FitRigToActor(const ExtractionContext& ctx, const std::string& actor_name, std::vector<TriMesh>* meshes,
                           const std::vector<std::string>& names) {
  auto t0 = Clock::now();
  RigFitResult fit = FitRigToScans(ctx.rig, *meshes, names, ctx.options.fit);
  ctx.sum.timing.Add("rig fit (Ceres)", Since(t0));
  ctx.Log(fmt::format("{}: rig fit ({} correspondences) RMS {:.3f} mm, |identity| = {:.2f}", actor_name,
                      ToString(fit.correspondence), fmt::join(fit.rms_mm, " / "), fit.identity.norm()));
  if (fit.correspondence == RigCorrespondence::kClosest) {
    t0 = Clock::now();
    std::vector<int> kept;
    const TriMesh cut =
        TransferUvsFromRig(ctx.rig, fit.fitted[0], (*meshes)[0], ctx.options.fit.max_correspondence_mm, &kept);
    for (auto& m : *meshes) {
      TriMesh c = cut;
      for (size_t i = 0; i < kept.size(); ++i) c.V.row(static_cast<int>(i)) = m.V.row(kept[i]);
      m = std::move(c);
    }
    ctx.sum.timing.Add("UV transfer", Since(t0));
    ctx.Log(fmt::format("{}: UVs transferred from the fitted rig to {} of the scan's vertices", actor_name,
                        kept.size()));
  }
  return fit;
}

// Evaluation, not a step of the method (issue 18, item 3): the extracted D^j
// against its ground truth `truth` within `mask`, over the face, each rig region
// and, with validation_band_mm > 0, their wrinkle bands; logged.
ScanAccuracy CompareWithTruth(const ExtractionContext& ctx, const std::string& actor, const std::string& scan,
                              const cv::Mat& displacement, const cv::Mat& truth, const cv::Mat& mask,
                              double mm_per_texel) {
  const int R = ctx.options.detail.map_resolution;
  ScanAccuracy acc;
  acc.actor = actor;
  acc.scan = scan;
  acc.face = CompareMaps(displacement, truth, mask);
  for (const auto& region : ctx.rig.regions) {
    cv::Mat rm;
    cv::bitwise_and(mask, ResizeMask(region.mask, R), rm);
    acc.regions.emplace_back(region.name, CompareMaps(displacement, truth, rm));
  }
  if (ctx.options.validation_band_mm > 0.0) {
    const double sigma = ctx.options.validation_band_mm / mm_per_texel;
    const cv::Mat db = WrinkleBand(displacement, mask, sigma), tb = WrinkleBand(truth, mask, sigma);
    acc.face_band = CompareMaps(db, tb, mask);
    for (const auto& region : ctx.rig.regions) {
      cv::Mat rm;
      cv::bitwise_and(mask, ResizeMask(region.mask, R), rm);
      acc.regions_band.emplace_back(region.name, CompareMaps(db, tb, rm));
    }
  }
  ctx.Log(fmt::format("{}/{}: D^j vs ground truth: RMSE {:.4f} mm (GT RMS {:.4f}), correlation {:.3f}; wrinkle band: "
                      "RMSE {:.4f} mm (GT RMS {:.4f}), correlation {:.3f}",
                      actor, scan, acc.face.rmse_mm, acc.face.reference_rms_mm, acc.face.correlation,
                      acc.face_band.rmse_mm, acc.face_band.reference_rms_mm, acc.face_band.correlation));
  return acc;
}

// Report picture displacement_<actor>_<scan>.png: D^j, beside its ground truth
// when `truth` is given, over ±`range` mm within `mask`.
void WriteDisplacementPicture(const fs::path& report_dir, const std::string& actor, const std::string& scan,
                              const cv::Mat& displacement, const cv::Mat& truth, const cv::Mat& mask, double range) {
  cv::Mat picture = DisplacementPicture(displacement, range, mask);
  if (!truth.empty()) {
    cv::Mat both;
    cv::hconcat(picture, DisplacementPicture(truth, range, mask), both);
    picture = both;
  }
  WriteImage(report_dir / fmt::format("displacement_{}_{}.png", actor, scan), picture, {.srgb = false});
}

// Report picture texture_<actor>_<scan>.png: the linear colour texture in sRGB.
void WriteTexturePicture(const fs::path& report_dir, const std::string& actor, const std::string& scan,
                         const cv::Mat& color) {
  cv::Mat srgb = color.clone();
  for (int r = 0; r < srgb.rows; ++r) {
    auto* p = srgb.ptr<float>(r);
    for (int c = 0; c < srgb.cols * 3; ++c) p[c] = static_cast<float>(LinearToSrgb(std::clamp(p[c], 0.0f, 1.0f)));
  }
  cv::Mat out8;
  srgb.convertTo(out8, CV_8UC3, 255.0);
  WriteImage(report_dir / fmt::format("texture_{}_{}.png", actor, scan), out8, {.srgb = false});
}

// Sec. 4.1: D^j of one scan, timed; with training_targets = truth the ground
// truth instead, with = maps the scan's map in target_maps. Where the scan set has
// ground truth (the expression's minus the neutral's: D^j is relative to M_0^j,
// which carries the neutral's own detail, static lines), D^j is compared with it;
// pictures. `aligned_normals` receives M_0^j's vertex normals.
cv::Mat ScanDisplacement(const ExtractionContext& ctx, const std::string& actor, const ScanEntry& scan,
                         const DetailExtractor& extractor, const MatX3d& V, const std::string& name,
                         const cv::Mat& neutral_truth, double mm_per_texel, MatX3d* aligned_normals) {
  const int R = ctx.options.detail.map_resolution;
  const auto t0 = Clock::now();
  const ExtractedDetail detail = extractor.Extract(V, name);
  *aligned_normals = detail.aligned_normals;
  ctx.sum.timing.Add("detail extraction D^j", Since(t0));
  ctx.sum.timing.Add("  G^HF (conjugate gradients)", detail.seconds_hf);
  ctx.sum.timing.Add("  G + deformation transfer", detail.seconds_transfer);
  ctx.sum.timing.Add("  M_0^j and normals", detail.seconds_aligned);
  ctx.sum.timing.Add("  rays (Embree)", detail.seconds_rays);
  cv::Mat D = detail.displacement;
  if (ctx.options.training_targets == TrainingTargets::kTruth) {
    Require(!scan.truth_displacement.empty() && !neutral_truth.empty(),
            fmt::format("{}: training_targets = truth needs the scan set's ground truth (a studio scan set)", name));
    D = ReadTruth(scan.truth_displacement, R) - neutral_truth;
  } else if (ctx.options.training_targets == TrainingTargets::kMaps) {
    const fs::path p = fs::path(ctx.options.target_maps) / actor / (scan.name + ".exr");
    Require(fs::is_regular_file(p), fmt::format("{}: missing (training_targets = maps needs a map per scan)", p.string()));
    D = ReadTruth(p, R);
    Require(cv::checkRange(D), fmt::format("{}: non-finite values", p.string()));
  }
  cv::Mat mask;  // the texels D^j holds
  cv::bitwise_and(extractor.coverage(), detail.valid, mask);
  if (ctx.options.target_band_mm > 0.0) D = WrinkleBand(D, mask, ctx.options.target_band_mm / mm_per_texel);
  if (!scan.truth_displacement.empty() && !neutral_truth.empty()) {
    cv::Mat truth = ReadTruth(scan.truth_displacement, R) - neutral_truth;
    ScanAccuracy acc = CompareWithTruth(ctx, actor, scan.name, detail.displacement, truth, mask, mm_per_texel);
    if (ctx.pictures()) {
      WriteDisplacementPicture(ctx.report_dir, actor, scan.name, detail.displacement, truth, mask,
                               std::max(0.05, 3.0 * acc.face.reference_rms_mm));
    }
    ctx.sum.accuracy.push_back(std::move(acc));
  } else if (ctx.pictures()) {
    WriteDisplacementPicture(ctx.report_dir, actor, scan.name, detail.displacement, cv::Mat(), detail.valid, 0.3);
  }
  return D;
}

// The textures T^j of one scan: one per selected light rig, from that rig's
// images, appended to `textures` with the scan's displacement D. The view angle
// is judged by M_0^j's normals (`view_normals`; texture_extraction.h, Difference 2).
void ExtractScanTextures(const ExtractionContext& ctx, const std::string& actor, const ScanEntry& scan,
                         const TriMesh& mesh, const MatX3d& view_normals, const std::string& name,
                         const UvRaster& raster, const cv::Mat& D, ActorTextures* textures) {
  const auto t0 = Clock::now();
  const RayCaster caster(mesh, {}, name);
  for (const auto& light : ctx.lights) {
    std::vector<Camera> cams;
    std::vector<cv::Mat> images;
    for (const auto& im : scan.images) {
      if (im.light != light) continue;
      cams.push_back(ReadCamera(im.camera));
      images.push_back(ReadImage(im.image));
      Require(images.back().channels() == 3 || images.back().channels() == 1,
              fmt::format("{}: expected an RGB or gray image", im.image.string()));
    }
    if (cams.empty()) continue;
    const ExtractedTexture tex = ExtractTexture(mesh, raster, &caster, cams, images, ctx.options.texture, &view_normals);
    textures->gray.push_back(tex.gray);
    textures->light.push_back(light);
    textures->coverage.push_back(tex.seen);
    textures->displacement.push_back(D);
    textures->names.push_back(fmt::format("{}/{}/{}", actor, scan.name, light));
    if (ctx.pictures() && light == ctx.lights.front()) WriteTexturePicture(ctx.report_dir, actor, scan.name, tex.color);
  }
  ctx.sum.timing.Add("texture extraction T^j", Since(t0));
}

// Sec. 4.2: the actor's wrinkle map (from its textures, over the texels that
// every texture and the detail extraction cover), the patch layout, and the
// training pairs (t, d).
TrainingPatches ActorPatchPairs(const ExtractionContext& ctx, const std::string& actor, const cv::Mat& detail_coverage,
                                ActorTextures* textures, ActorSummary* as) {
  const TrainingOptions& options = ctx.options;
  const auto t0 = Clock::now();
  if (options.wrinkle.texture_reference != TextureReference::kNone)
    FlattenByNeutral(options.wrinkle, textures->light, textures->coverage, &textures->gray);
  cv::Mat coverage = detail_coverage.clone();
  for (const auto& c : textures->coverage) cv::bitwise_and(coverage, c, coverage);
  WrinkleMapBuilder builder(options.detail.map_resolution, coverage, ctx.rig.regions, options.wrinkle);
  std::vector<cv::Mat> responses;
  for (size_t t = 0; t < textures->gray.size(); ++t)
    responses.push_back(builder.Add(textures->gray[t], textures->names[t]));
  const WrinkleMap wmap = builder.Finish();
  PatchLayoutReport layout_report;
  const PatchLayout layout = PlacePatches(wmap, options.patch, &layout_report);
  const PatchLayout pair_layout = ShiftedLayout(layout, options.pair_shift_texels, options.pair_shift_steps);
  TrainingPatches pairs =
      ExtractTrainingPatches(pair_layout, textures->gray, responses, textures->displacement, options.wrinkle);
  ctx.sum.timing.Add("wrinkle map + patches", Since(t0));
  as->patch_locations = layout.num_patches();
  as->training_pairs = pairs.size();
  as->wrinkle_texels = cv::countNonZero(wmap.probability > 0);
  ctx.Log(fmt::format("{}: wrinkle map over {} texels, {} patches placed, {} training pairs", actor,
                      as->wrinkle_texels, layout.num_patches(), pairs.size()));
  if (ctx.pictures()) {
    WriteImage(ctx.report_dir / fmt::format("wrinkle_map_{}.png", actor),
               DrawPatchLayout(wmap.probability, layout, wmap.valid), {.srgb = false});
  }
  return pairs;
}

// Secs. 4.1–4.2 for one actor: its scans read, the rig fitted, D^j and T^j for
// every scan, then the wrinkle map and the training pairs; `as` filled.
TrainingPatches ActorTrainingPairs(const ExtractionContext& ctx, const ScanActor& actor, Progress& progress,
                                   ActorSummary* as) {
  const int R = ctx.options.detail.map_resolution;
  auto t0 = Clock::now();
  const std::vector<int> order = NeutralFirst(actor);
  std::vector<TriMesh> meshes;
  std::vector<std::string> names;
  ReadActorScans(actor, order, &meshes, &names);
  as->scans = static_cast<int>(meshes.size());
  ctx.sum.timing.Add("read scans", Since(t0), as->scans);
  const RigFitResult fit = FitRigToActor(ctx, actor.name, &meshes, names);
  as->correspondence = ToString(fit.correspondence);
  as->fit_rms_mm = fit.rms_mm;

  // Sec. 4.1: D^j and T^j for every scan.
  t0 = Clock::now();
  std::vector<MatX3d> others;
  for (size_t j = 1; j < meshes.size(); ++j) others.push_back(meshes[j].V);
  const DetailExtractor extractor(meshes[0], ctx.options.detail, names[0], others);
  others.clear();
  ctx.sum.timing.Add("G^HF, G, deformation transfer: set-up", Since(t0));
  const UvRaster raster = RasterizeUv(meshes[0], R, R, names[0]);
  const double mm_per_texel = MmPerTexel(meshes[0], R);
  const ScanEntry& neutral_scan = actor.scans[actor.neutral];
  const cv::Mat neutral_truth =
      neutral_scan.truth_displacement.empty() ? cv::Mat() : ReadTruth(neutral_scan.truth_displacement, R);
  ActorTextures textures;
  for (size_t j = 0; j < meshes.size(); ++j) {
    const ScanEntry& scan = actor.scans[order[j]];
    MatX3d view_normals;
    const cv::Mat D = ScanDisplacement(ctx, actor.name, scan, extractor, meshes[j].V, names[j], neutral_truth,
                                       mm_per_texel, &view_normals);
    ExtractScanTextures(ctx, actor.name, scan, meshes[j], view_normals, names[j], raster, D, &textures);
    progress.Advance();
  }
  as->textures = static_cast<int>(textures.gray.size());
  Require(!textures.gray.empty(), fmt::format("{}: no images under the selected lights ({})", actor.name,
                                              fmt::join(ctx.lights, ", ")));
  return ActorPatchPairs(ctx, actor.name, extractor.coverage(), &textures, as);
}

}  // namespace

TrainingPairs ExtractTrainingPairs(const ScanSet& set, const FaceRig& rig, const TrainingOptions& options,
                                   const TrainingOutputs& outputs, TrainingSummary* summary,
                                   const std::function<void(const std::string&)>& log_fn) {
  options.Check();
  const auto start = Clock::now();
  TrainingSummary local;
  TrainingSummary& sum = summary ? *summary : local;
  sum.actors.clear();
  sum.accuracy.clear();
  const std::vector<std::string> lights = SelectLights(set, options.training_lights);
  const ExtractionContext ctx{rig, options, lights, outputs.report_dir, sum, log_fn};
  if (ctx.pictures()) fs::create_directories(outputs.report_dir);
  std::vector<ScanActor> actors = set.actors;
  if (options.max_actors > 0 && static_cast<int>(actors.size()) > options.max_actors) actors.resize(options.max_actors);

  std::vector<Eigen::MatrixXf> texture_patches, displacement_patches;
  std::vector<int32_t> actor_of_rows;
  int total_pairs = 0;
  int64_t steps = 0;  // every scan
  for (const auto& a : actors) steps += static_cast<int64_t>(a.scans.size());
  Progress progress("training", steps);
  for (size_t a = 0; a < actors.size(); ++a) {
    ActorSummary as;
    as.name = actors[a].name;
    TrainingPatches pairs = ActorTrainingPairs(ctx, actors[a], progress, &as);
    total_pairs += pairs.size();
    if (pairs.size() > 0) {
      actor_of_rows.insert(actor_of_rows.end(), static_cast<size_t>(pairs.size()), static_cast<int32_t>(a));
      texture_patches.push_back(std::move(pairs.texture));
      displacement_patches.push_back(std::move(pairs.displacement));
    }
    sum.actors.push_back(as);
  }
  Require(total_pairs >= 2, fmt::format("training: only {} training patch pairs (no wrinkles above alpha = {} in the "
                                        "textures' regions {}?)",
                                        total_pairs, options.wrinkle.wrinkle_threshold,
                                        fmt::join(options.wrinkle.patch_regions, ", ")));
  sum.training_pairs = total_pairs;
  // The pairs of all actors stacked, actor after actor.
  const int n = options.patch.patch_size * options.patch.patch_size;
  Eigen::MatrixXf T(total_pairs, n), Dp(total_pairs, n);
  int row = 0;
  for (size_t b = 0; b < texture_patches.size(); ++b) {
    T.middleRows(row, texture_patches[b].rows()) = texture_patches[b];
    Dp.middleRows(row, displacement_patches[b].rows()) = displacement_patches[b];
    row += static_cast<int>(texture_patches[b].rows());
  }
  texture_patches.clear();
  displacement_patches.clear();
  progress.Finish();
  TrainingPairs out;
  out.texture = std::move(T);
  out.displacement = std::move(Dp);
  out.options_json = OptionsToJson(options);
  out.scan_set = set.root.string();
  out.actors = static_cast<int>(sum.actors.size());
  for (const auto& a : sum.actors) {
    out.scans += a.scans;
    out.actor_names.push_back(a.name);
  }
  out.actor = std::move(actor_of_rows);
  out.seconds = Since(start);
  sum.seconds = out.seconds;
  return out;
}

DetailModel TrainDetailModelFromPairs(const TrainingPairs& pairs, const TrainingOptions& options,
                                      const TrainingOutputs& outputs, TrainingSummary* summary,
                                      const std::function<void(const std::string&)>& log_fn) {
  options.Check();
  const auto start = Clock::now();
  auto log = [&](const std::string& line) {
    if (log_fn) log_fn(line);
  };
  TrainingSummary local;
  TrainingSummary& sum = summary ? *summary : local;
  const bool pictures = !outputs.report_dir.empty();
  if (pictures) fs::create_directories(outputs.report_dir);
  // The features' input (FernOptions::fern_texture_normalization; capture applies
  // the same in DetailModel::RegressBatch).
  const Eigen::MatrixXf T = NormalizeTexturePatches(pairs.texture, options.ferns.fern_texture_normalization);
  const Eigen::MatrixXf& Dp = pairs.displacement;
  const int total_pairs = static_cast<int>(T.rows());
  const int n = options.patch.patch_size * options.patch.patch_size;
  Require(T.cols() == n && Dp.cols() == n && Dp.rows() == total_pairs,
          fmt::format("training pairs: {}×{} texture and {}×{} displacement patches, expected N×{} (patch_size {})",
                      T.rows(), T.cols(), Dp.rows(), Dp.cols(), n, options.patch.patch_size));
  Require(total_pairs >= 2, fmt::format("training pairs: only {} pairs", total_pairs));
  sum.training_pairs = total_pairs;
  const int R = options.detail.map_resolution;
  Progress progress("regression", 2);
  // --- Sec. 4.3: PCA of the displacement patches and the regression targets ĉ_i.
  auto t0 = Clock::now();
  PcaOptions pca_options = options.pca;
  pca_options.dimensions = std::min(pca_options.dimensions, std::min(n, total_pairs));
  DetailModel model;
  model.pca = FitPatchPca(Dp, pca_options);
  const Eigen::MatrixXf targets = model.pca.ProjectPatches(Dp);
  {
    const Eigen::MatrixXf recon =
        (model.pca.basis * targets.transpose()).colwise() + model.pca.mean;  // n × N
    sum.pca_reconstruction_rmse_mm = std::sqrt((recon - Dp.transpose()).squaredNorm() / (double(n) * total_pairs));
  }
  sum.pca_energy = model.pca.energy;
  sum.timing.Add("PCA", Since(t0));
  progress.Advance();
  log(fmt::format("PCA: {} dimensions hold {:.1f} % of the energy (85 % needs {})", model.pca.dimensions(),
                  100 * model.pca.energy[model.pca.dimensions() - 1], model.pca.DimensionsForEnergy(0.85)));
  if (pictures) {
    cv::Mat mosaic = EigenPatchMosaic(model.pca, std::min(16, model.pca.dimensions()), options.patch.patch_size);
    cv::Mat big;
    cv::resize(mosaic, big, cv::Size(), 4, 4, cv::INTER_NEAREST);
    WriteImage(outputs.report_dir / "eigen_patches.png", big);
    WriteImage(outputs.report_dir / "pairs.png", PairMosaic(pairs.texture, Dp, options.patch.patch_size, 48),
               {.srgb = false});
    std::string csv = "dimensions,energy\n";
    for (size_t k = 0; k < model.pca.energy.size(); ++k) csv += fmt::format("{},{:.6f}\n", k + 1, model.pca.energy[k]);
    std::ofstream(outputs.report_dir / "pca_energy.csv") << csv;
  }
  // --- Sec. 4.3: the fern cascade from texture patches to ĉ_i (Eqs. 2–4).
  t0 = Clock::now();
  FernTrainingResult trained = TrainFernCascade(T, targets, options.ferns);
  sum.timing.Add("fern cascade", Since(t0));
  progress.Advance();
  progress.Finish();
  sum.ferns = trained.report;
  log(fmt::format("fern cascade: K = {}, training RMSE of coefficients {:.4f} → {:.4f}", options.ferns.num_ferns,
                  trained.report.train_rmse.front(), trained.report.train_rmse.back()));
  model.cascade = std::move(trained.cascade);
  if (options.baseline.regressor != PatchRegressor::kFerns) {
    t0 = Clock::now();
    model.baseline = FitPatchBaseline(T, targets, options.baseline);
    sum.timing.Add("baseline regressor", Since(t0));
    log(fmt::format("baseline regressor '{}' fitted; capture applies it instead of the cascade",
                    ToString(options.baseline.regressor)));
  }
  model.map_resolution = R;
  model.wrinkle = options.wrinkle;
  model.patch = options.patch;
  model.detail = options.detail;
  sum.seconds = pairs.seconds + Since(start);
  json tj;
  tj["scan_set"] = pairs.scan_set;
  tj["actors"] = pairs.actors;
  tj["scans"] = pairs.scans;
  tj["training_pairs"] = total_pairs;
  tj["options"] = json::parse(OptionsToJson(options));
  tj["seconds"] = sum.seconds;
  model.training_json = tj.dump();
  return model;
}

DetailModel TrainDetailModel(const ScanSet& set, const FaceRig& rig, const TrainingOptions& options,
                             const TrainingOutputs& outputs, TrainingSummary* summary,
                             const std::function<void(const std::string&)>& log) {
  TrainingSummary local;
  TrainingSummary& sum = summary ? *summary : local;
  const TrainingPairs pairs = ExtractTrainingPairs(set, rig, options, outputs, &sum, log);
  return TrainDetailModelFromPairs(pairs, options, outputs, &sum, log);
}

namespace {

constexpr char kPairsMagic[] = "CREASPRS";
constexpr uint32_t kPairsVersion = 1;

}  // namespace

std::vector<std::string> RegressionOptionNames() {
  std::vector<std::string> names;
  for (const auto& n : OptionFieldNames<PcaOptions>()) names.push_back("pca." + n);
  for (const auto& n : OptionFieldNames<FernOptions>()) names.push_back("ferns." + n);
  for (const auto& n : OptionFieldNames<PatchBaselineOptions>()) names.push_back("baseline." + n);
  return names;
}

TrainingOptions OptionsForPairs(const TrainingPairs& pairs, const std::string& what,
                                const std::function<void(TrainingOptions*)>& edit) {
  TrainingOptions options;
  SetOptionsFromStoredJson(pairs.options_json, what, &options);
  const TrainingOptions extracted = options;
  if (edit) edit(&options);
  json a = json::parse(OptionsToJson(extracted)), b = json::parse(OptionsToJson(options));
  for (const auto& name : RegressionOptionNames()) {
    a.erase(name);
    b.erase(name);
  }
  for (const auto& [key, value] : b.items()) {
    if (a[key] != value)
      throw Error(fmt::format("{}: the pairs were extracted with {} = {}, not {}; only the PCA and cascade options ({}) "
                              "can change without extracting them again (crease train --scans … --save-pairs)",
                              what, key, a[key].dump(), value.dump(), fmt::join(RegressionOptionNames(), ", ")));
  }
  return options;
}

void WriteTrainingPairs(const fs::path& path, const TrainingPairs& pairs) {
  json header;
  header["format"] = "crease training pairs";
  header["options"] = json::parse(pairs.options_json);
  header["scan_set"] = pairs.scan_set;
  header["actors"] = pairs.actors;
  header["scans"] = pairs.scans;
  header["seconds"] = pairs.seconds;
  header["actor_names"] = pairs.actor_names;
  ArrayFileWriter w(header.dump());
  // Row-major N × w² (Eigen stores column-major: transpose into a row-major copy).
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const RowMajor t = pairs.texture, d = pairs.displacement;
  w.Add("texture", t.data(), {t.rows(), t.cols()});
  w.Add("displacement", d.data(), {d.rows(), d.cols()});
  if (!pairs.actor.empty()) w.Add("actor", pairs.actor.data(), {static_cast<int64_t>(pairs.actor.size())});
  w.Write(path, kPairsMagic, kPairsVersion);
}

TrainingPairs ReadTrainingPairs(const fs::path& path) {
  const ArrayFile f = ReadArrayFile(path, kPairsMagic, kPairsVersion, "training pairs");
  const std::string what = path.string();
  TrainingPairs p;
  json header;
  try {
    header = json::parse(f.header_json);
    p.options_json = header.at("options").dump();
    p.scan_set = header.value("scan_set", "");
    p.actors = header.value("actors", 0);
    p.scans = header.value("scans", 0);
    p.seconds = header.value("seconds", 0.0);
    p.actor_names = header.value("actor_names", std::vector<std::string>{});
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: malformed header: {}", what, e.what()));
  }
  auto matrix = [&](const char* name) {
    const auto it = f.arrays.find(name);
    Require(it != f.arrays.end() && it->second.shape.size() == 2, fmt::format("{}: no 2D array '{}'", what, name));
    const int64_t rows = it->second.shape[0], cols = it->second.shape[1];
    const std::vector<float> v = f.Get<float>(name, rows * cols, what);
    for (float x : v) Require(std::isfinite(x), fmt::format("{}: array '{}' holds a non-finite value", what, name));
    using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    return Eigen::MatrixXf(Eigen::Map<const RowMajor>(v.data(), rows, cols));
  };
  p.texture = matrix("texture");
  p.displacement = matrix("displacement");
  Require(p.texture.rows() == p.displacement.rows() && p.texture.cols() == p.displacement.cols(),
          fmt::format("{}: texture ({}×{}) and displacement ({}×{}) patches differ in shape", what, p.texture.rows(),
                      p.texture.cols(), p.displacement.rows(), p.displacement.cols()));
  if (f.arrays.count("actor")) {
    p.actor = f.Get<int32_t>("actor", p.texture.rows(), what);
    for (int32_t a : p.actor)
      Require(a >= 0 && a < static_cast<int32_t>(p.actor_names.size()),
              fmt::format("{}: array 'actor' holds {}, the header names {} actors", what, a, p.actor_names.size()));
  }
  return p;
}

TrainingPairs TrainingPairs::Rows(const std::vector<int>& rows) const {
  TrainingPairs out;
  out.options_json = options_json;
  out.scan_set = scan_set;
  out.actor_names = actor_names;
  out.texture.resize(static_cast<Eigen::Index>(rows.size()), texture.cols());
  out.displacement.resize(static_cast<Eigen::Index>(rows.size()), displacement.cols());
  std::set<int32_t> seen;
  for (size_t k = 0; k < rows.size(); ++k) {
    const int r = rows[k];
    Require(r >= 0 && r < texture.rows(), fmt::format("TrainingPairs::Rows: row {} of {}", r, texture.rows()));
    out.texture.row(static_cast<Eigen::Index>(k)) = texture.row(r);
    out.displacement.row(static_cast<Eigen::Index>(k)) = displacement.row(r);
    if (!actor.empty()) {
      out.actor.push_back(actor[r]);
      seen.insert(actor[r]);
    }
  }
  out.actors = actor.empty() ? actors : static_cast<int>(seen.size());
  out.scans = scans;
  return out;
}

TrainingPairs ReadTrainingPairs(const std::vector<fs::path>& paths) {
  Require(!paths.empty(), "ReadTrainingPairs: no pair files given");
  TrainingPairs all = ReadTrainingPairs(paths.front());
  for (size_t k = 1; k < paths.size(); ++k) {
    const TrainingPairs p = ReadTrainingPairs(paths[k]);
    Require(p.options_json == all.options_json && p.texture.cols() == all.texture.cols(),
            fmt::format("{}: extracted with other options than {} (pair files can be joined only when their "
                        "extraction agrees)",
                        paths[k].string(), paths.front().string()));
    const Eigen::Index n = all.texture.rows();
    all.texture.conservativeResize(n + p.texture.rows(), Eigen::NoChange);
    all.texture.bottomRows(p.texture.rows()) = p.texture;
    all.displacement.conservativeResize(n + p.displacement.rows(), Eigen::NoChange);
    all.displacement.bottomRows(p.displacement.rows()) = p.displacement;
    all.scan_set += ", " + p.scan_set;
    if (all.actor.empty() != p.actor.empty()) {  // one file without actor ids: none for the join
      all.actor.clear();
      all.actor_names.clear();
    } else {
      const auto offset = static_cast<int32_t>(all.actor_names.size());
      for (int32_t a : p.actor) all.actor.push_back(a + offset);
      all.actor_names.insert(all.actor_names.end(), p.actor_names.begin(), p.actor_names.end());
    }
    all.actors += p.actors;
    all.scans += p.scans;
    all.seconds += p.seconds;
  }
  return all;
}

}  // namespace crease
