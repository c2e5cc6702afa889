#include "synth/actor.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <array>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_ops.h"
#include "core/uv_raster.h"

namespace crease {

using nlohmann::json;

void ActorOptions::VisitFields(OptionVisitor& v) {
  v.Field("resolution", resolution);
  v.Field("surface_min_vertices", surface_min_vertices);
  v.Field("identity_stddev", identity_stddev);
  v.Field("identity_clamp", identity_clamp);
  v.Field("age_min", age_min);
  v.Field("age_max", age_max);
  v.Field("style_min", style_min);
  v.Field("style_max", style_max);
  v.Field("static_lines", static_lines);
  v.Field("expression_deviation", expression_deviation);
  v.Field("expression_deviation_wavelength_mm", expression_deviation_wavelength_mm);
  v.Field("static_shape_rms_mm", static_shape_rms_mm);
  v.Field("static_shape_wavelength_mm", static_shape_wavelength_mm);
  v.Field("mesoscopic_scale", mesoscopic_scale);
  v.Field("strain_resolution", strain_resolution);
  v.Field("strain_smoothing_mm", strain_smoothing_mm);
  v.Field("phong_alpha", phong_alpha);
  v.Field("subdivision_levels", subdivision_levels);
}

void ActorOptions::Check() const {
  const char* o = "ActorOptions";
  CheckGe(o, "resolution", resolution, 16);
  CheckLe(o, "resolution", resolution, 8192);
  CheckGe(o, "surface_min_vertices", surface_min_vertices, 0);
  CheckLe(o, "surface_min_vertices", surface_min_vertices, 20000000);
  CheckGe(o, "identity_stddev", identity_stddev, 0.0);
  CheckGt(o, "identity_clamp", identity_clamp, 0.0);
  CheckGe(o, "age_min", age_min, 0.0);
  CheckLe(o, "age_max", age_max, 1.0);
  CheckLe(o, "age_min", age_min, age_max);
  CheckGe(o, "style_min", style_min, -1.0);
  CheckLe(o, "style_max", style_max, 1.0);
  CheckLe(o, "style_min", style_min, style_max);
  CheckGe(o, "expression_deviation", expression_deviation, 0.0);
  CheckLe(o, "expression_deviation", expression_deviation, 1.0);
  CheckGt(o, "expression_deviation_wavelength_mm", expression_deviation_wavelength_mm, 0.0);
  CheckGe(o, "static_shape_rms_mm", static_shape_rms_mm, 0.0);
  CheckGt(o, "static_shape_wavelength_mm", static_shape_wavelength_mm, 0.0);
  CheckGe(o, "mesoscopic_scale", mesoscopic_scale, 0.0);
  CheckGe(o, "strain_resolution", strain_resolution, 8);
  CheckLe(o, "strain_resolution", strain_resolution, 4096);
  CheckGe(o, "strain_smoothing_mm", strain_smoothing_mm, 0.0);
  CheckGe(o, "phong_alpha", phong_alpha, 0.0);
  CheckLe(o, "phong_alpha", phong_alpha, 1.0);
  CheckGe(o, "subdivision_levels", subdivision_levels, 0);
  CheckLe(o, "subdivision_levels", subdivision_levels, 4);
}

Actor GenerateActor(const FaceRig& rig, uint64_t seed, const ActorOptions& options) {
  options.Check();
  Actor actor;
  actor.seed = seed;
  actor.options = options;
  Rng root(seed);
  Rng identity_rng = root.Fork(1);
  Rng style_rng = root.Fork(2);
  Rng wrinkle_rng = root.Fork(3);
  Rng shape_rng = root.Fork(4);
  Rng meso_rng = root.Fork(5);
  Rng skin_rng = root.Fork(6);

  actor.identity.resize(rig.num_identity());
  for (int k = 0; k < rig.num_identity(); ++k) {
    const double c = options.identity_clamp;
    actor.identity[k] = options.identity_stddev * std::clamp(identity_rng.Normal(), -c, c);
  }
  actor.style.age = style_rng.Uniform(options.age_min, options.age_max);
  actor.style.shape = style_rng.Uniform(options.style_min, options.style_max);
  actor.style.static_lines = options.static_lines;
  const FaceAnchors anchors = ComputeFaceAnchors(rig);
  actor.wrinkles = GenerateWrinkleLayout(anchors, actor.style, wrinkle_rng);
  actor.static_shape.seed = shape_rng.NextU64();
  actor.static_shape.rms_mm = options.static_shape_rms_mm * shape_rng.Uniform(0.5, 1.5);
  actor.static_shape.wavelength_mm = options.static_shape_wavelength_mm * shape_rng.Uniform(0.75, 1.33);
  actor.mesoscopic = GenerateMesoscopicParams(meso_rng);
  actor.mesoscopic.pore_depth_mm *= options.mesoscopic_scale;
  actor.mesoscopic.roughness_mm *= options.mesoscopic_scale;
  actor.mesoscopic.fine_line_depth_mm *= options.mesoscopic_scale;
  actor.skin = GenerateSkinParams(skin_rng);
  Rng deviation_rng = root.Fork(7);
  actor.expression_deviation.seed = deviation_rng.NextU64();
  actor.expression_deviation.amount = options.expression_deviation;
  actor.expression_deviation.wavelength_mm = options.expression_deviation_wavelength_mm;
  return actor;
}

FaceRig PersonalRig(const FaceRig& rig, const Actor& actor) {
  const ExpressionDeviationParams& d = actor.expression_deviation;
  if (d.amount <= 0.0 || rig.num_expressions() == 0) return rig;
  FaceRig personal = rig;
  Rng rng(d.seed);
  constexpr int kWaves = 8;               // random Fourier features of the modulation field
  constexpr double kAsymmetryMm = 60.0;   // x at which the asymmetry reaches a_b
  const double omega = 2.0 * std::numbers::pi / d.wavelength_mm;
  const int nv = rig.num_vertices();
  for (int b = 0; b < rig.num_expressions(); ++b) {
    // The spatial terms stretch the skin by about σ_x · |B_b| · (their gradient): for
    // a shape that moves far (jawOpen, ~35 mm) they are scaled down so that this
    // stretch stays near kDeviationMaxStrain, else the chin folds over itself.
    double max_delta = 0.0;
    for (int v = 0; v < nv; ++v) max_delta = std::max(max_delta, static_cast<double>(rig.expression_basis.block(3 * v, b, 3, 1).norm()));
    const double field_sigma = std::min(d.amount, kDeviationMaxStrain / (omega * std::max(max_delta, 1e-9)));
    const double asym_sigma = std::min(d.amount, kDeviationMaxStrain * kAsymmetryMm / std::max(max_delta, 1e-9));
    const double gain = 1.0 + d.amount * rng.Normal();
    const double asym = asym_sigma * rng.Normal();
    std::array<Eigen::Vector3d, kWaves> w;
    std::array<double, kWaves> phase;
    for (int k = 0; k < kWaves; ++k) {
      // z, y, x: one draw per statement, in the order GCC used (synth/wrinkles.cc, Draws3).
      const double wz = rng.Normal(), wy = rng.Normal();
      w[k] = Eigen::Vector3d(rng.Normal(), wy, wz) * omega;
      phase[k] = rng.Uniform(0.0, 2.0 * std::numbers::pi);
    }
    for (int v = 0; v < nv; ++v) {
      const Eigen::Vector3d p = rig.neutral.V.row(v).transpose();
      double n = 0.0;
      for (int k = 0; k < kWaves; ++k) n += std::cos(w[k].dot(p) + phase[k]);
      n *= field_sigma * std::sqrt(2.0 / kWaves);
      const double factor = std::clamp(gain * (1.0 + asym * std::clamp(p.x() / kAsymmetryMm, -1.5, 1.5)) * (1.0 + n),
                                       0.0, 2.0);
      personal.expression_basis.block(3 * v, b, 3, 1) *= static_cast<float>(factor);
    }
  }
  personal.source += fmt::format("; personal expression deviations (seed {}, amount {})", d.seed, d.amount);
  return personal;
}

namespace {

// `covered` (CV_8U, 0/255) with its holes (uncovered texels not connected to the
// map's border) filled.
cv::Mat FillHoles(const cv::Mat& covered) {
  cv::Mat padded;
  cv::copyMakeBorder(covered, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, 0);
  cv::floodFill(padded, cv::Point(0, 0), 128);  // the outside
  cv::Mat filled = padded(cv::Rect(1, 1, covered.cols, covered.rows)) != 128;
  return filled;
}

}  // namespace

cv::Mat ChartRimFade(const FaceRig& rig, int size, double mm_per_uv, double width_mm, bool outer_rim_only) {
  TriMesh chart;
  chart.V = rig.neutral.V;
  chart.UV = rig.neutral.UV;
  chart.F = FaceChartTriangles(rig);
  cv::Mat covered = CoverageMask(RasterizeUv(chart, size, size, "ChartRimFade: the rig's face chart"));
  if (outer_rim_only) covered = FillHoles(covered);
  cv::Mat texels;
  cv::distanceTransform(covered, texels, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  cv::Mat fade(size, size, CV_32F);
  const double mm_per_texel = mm_per_uv / size;
  for (int j = 0; j < size; ++j) {
    for (int i = 0; i < size; ++i) {
      const double t = std::clamp(texels.at<float>(j, i) * mm_per_texel / width_mm, 0.0, 1.0);
      fade.at<float>(j, i) = static_cast<float>(t * t * (3.0 - 2.0 * t));
    }
  }
  return fade;
}

cv::Mat BuildStaticShapeMap(const FaceAnchors& anchors, const StaticShapeParams& params, int size) {
  Rng rng(params.seed);
  // Two octaves of smooth noise: cells of half the wavelength and of the wavelength.
  const int fine_cells = std::max(4, static_cast<int>(std::ceil(anchors.mm_per_uv / (0.5 * params.wavelength_mm))));
  const int coarse_cells = std::max(4, fine_cells / 2);
  const cv::Mat fine = SmoothNoise(rng, fine_cells, 1.0, size);
  const cv::Mat coarse = SmoothNoise(rng, coarse_cells, 1.0, size);
  cv::Mat s = 0.6 * fine + 0.8 * coarse;
  cv::Scalar mean, stddev;
  cv::meanStdDev(s, mean, stddev);
  s = (s - mean[0]) * (stddev[0] > 0 ? params.rms_mm / stddev[0] : 0.0);
  const double limit = 3.0 * params.rms_mm;
  cv::min(s, limit, s);
  cv::max(s, -limit, s);
  return s;
}

// ---------------------------------------------------------------------------
// JSON.

namespace {

json Point(const Eigen::Vector2d& p) { return json::array({p.x(), p.y()}); }

class Reader {
 public:
  explicit Reader(std::string what) : what_(std::move(what)) {}

  [[noreturn]] void Fail(const std::string& field, const std::string& expected) const {
    throw Error(fmt::format("{}: field '{}' {}", what_, field, expected));
  }
  const json& Get(const json& obj, const std::string& prefix, const std::string& key) const {
    const std::string field = prefix.empty() ? key : prefix + "." + key;
    if (!obj.is_object()) Fail(prefix.empty() ? "(top level)" : prefix, "must be an object");
    const auto it = obj.find(key);
    if (it == obj.end()) Fail(field, "is missing");
    return *it;
  }
  double Number(const json& obj, const std::string& prefix, const std::string& key) const {
    const json& v = Get(obj, prefix, key);
    if (!v.is_number()) Fail(Name(prefix, key), "must be a number");
    const double x = v.get<double>();
    if (!std::isfinite(x)) Fail(Name(prefix, key), "must be finite");
    return x;
  }
  double Range(const json& obj, const std::string& prefix, const std::string& key, double lo, double hi) const {
    const double x = Number(obj, prefix, key);
    if (x < lo || x > hi) Fail(Name(prefix, key), fmt::format("= {} must be in [{}, {}]", x, lo, hi));
    return x;
  }
  uint64_t Unsigned(const json& obj, const std::string& prefix, const std::string& key) const {
    const json& v = Get(obj, prefix, key);
    if (!v.is_number_unsigned()) Fail(Name(prefix, key), "must be a non-negative integer");
    return v.get<uint64_t>();
  }
  bool Bool(const json& obj, const std::string& prefix, const std::string& key) const {
    const json& v = Get(obj, prefix, key);
    if (!v.is_boolean()) Fail(Name(prefix, key), "must be true or false");
    return v.get<bool>();
  }
  std::string String(const json& obj, const std::string& prefix, const std::string& key) const {
    const json& v = Get(obj, prefix, key);
    if (!v.is_string()) Fail(Name(prefix, key), "must be a string");
    return v.get<std::string>();
  }
  const json& Array(const json& obj, const std::string& prefix, const std::string& key) const {
    const json& v = Get(obj, prefix, key);
    if (!v.is_array()) Fail(Name(prefix, key), "must be an array");
    return v;
  }
  double Element(const json& arr, const std::string& field, size_t i) const {
    if (!arr[i].is_number()) Fail(fmt::format("{}[{}]", field, i), "must be a number");
    const double x = arr[i].get<double>();
    if (!std::isfinite(x)) Fail(fmt::format("{}[{}]", field, i), "must be finite");
    return x;
  }
  const std::string& what() const { return what_; }

  static std::string Name(const std::string& prefix, const std::string& key) {
    return prefix.empty() ? key : prefix + "." + key;
  }

 private:
  std::string what_;
};

}  // namespace

std::string ActorToJson(const Actor& a) {
  json j;
  j["format"] = "crease_actor";
  j["version"] = Actor::kFormatVersion;
  j["seed"] = a.seed;
  j["options"] = json::parse(OptionsToJson(a.options));
  j["identity"] = std::vector<double>(a.identity.data(), a.identity.data() + a.identity.size());
  j["style"] = {{"age", a.style.age}, {"shape", a.style.shape}, {"static_lines", a.style.static_lines}};
  j["expression_deviation"] = {{"seed", a.expression_deviation.seed},
                               {"amount", a.expression_deviation.amount},
                               {"wavelength_mm", a.expression_deviation.wavelength_mm}};
  j["static_shape"] = {{"seed", a.static_shape.seed},
                       {"rms_mm", a.static_shape.rms_mm},
                       {"wavelength_mm", a.static_shape.wavelength_mm}};
  const MesoscopicParams& m = a.mesoscopic;
  j["mesoscopic"] = {{"seed", m.seed},
                     {"pore_depth_mm", m.pore_depth_mm},
                     {"pore_density_per_mm2", m.pore_density_per_mm2},
                     {"roughness_mm", m.roughness_mm},
                     {"fine_line_depth_mm", m.fine_line_depth_mm},
                     {"fine_line_density", m.fine_line_density}};
  const SkinParams& s = a.skin;
  j["skin"] = {{"seed", s.seed},         {"tone", s.tone},
               {"redness", s.redness},   {"variation", s.variation},
               {"blotches", s.blotches}, {"freckles", s.freckles},
               {"lip_redness", s.lip_redness}, {"brow_darkness", s.brow_darkness},
               {"eye_tint", s.eye_tint}, {"oiliness", s.oiliness},
               {"specular", s.specular}, {"roughness", s.roughness}};
  json lines = json::array();
  for (const WrinkleLine& w : a.wrinkles) {
    json pts = json::array();
    for (const auto& p : w.points) pts.push_back(Point(p));
    lines.push_back({{"family", ToString(w.family)},
                     {"max_depth_mm", w.max_depth_mm},
                     {"static_depth_mm", w.static_depth_mm},
                     {"width_mm", w.width_mm},
                     {"ridge", w.ridge},
                     {"saturation", w.saturation},
                     {"points", pts},
                     {"strength", w.strength}});
  }
  j["wrinkles"] = lines;
  return j.dump(1);
}

Actor ActorFromJson(const std::string& text, const std::string& what) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for 1e400 (issue 19)
    throw Error(fmt::format("{}: malformed JSON ({})", what, e.what()));
  }
  const Reader r(what);
  if (r.String(j, "", "format") != "crease_actor") r.Fail("format", "must be \"crease_actor\"");
  const uint64_t version = r.Unsigned(j, "", "version");
  if (version != static_cast<uint64_t>(Actor::kFormatVersion)) {
    r.Fail("version", fmt::format("= {} is not supported (expected {})", version, Actor::kFormatVersion));
  }
  Actor a;
  a.source = what;
  a.seed = r.Unsigned(j, "", "seed");
  {
    const json& o = r.Get(j, "", "options");
    if (!o.is_object()) r.Fail("options", "must be an object");
    SetOptionsFromJson(o.dump(), what + ": field 'options'", &a.options);
  }
  {
    const json& id = r.Array(j, "", "identity");
    a.identity.resize(static_cast<int>(id.size()));
    for (size_t i = 0; i < id.size(); ++i) a.identity[static_cast<int>(i)] = r.Element(id, "identity", i);
  }
  {
    const json& s = r.Get(j, "", "style");
    a.style.age = r.Range(s, "style", "age", 0.0, 1.0);
    a.style.shape = r.Range(s, "style", "shape", -1.0, 1.0);
    a.style.static_lines = r.Bool(s, "style", "static_lines");
  }
  if (j.contains("expression_deviation")) {  // absent in actors written before it existed: none
    const json& d = r.Get(j, "", "expression_deviation");
    a.expression_deviation.seed = r.Unsigned(d, "expression_deviation", "seed");
    a.expression_deviation.amount = r.Range(d, "expression_deviation", "amount", 0.0, 1.0);
    a.expression_deviation.wavelength_mm = r.Range(d, "expression_deviation", "wavelength_mm", 1e-3, 1e4);
  }
  {
    const json& s = r.Get(j, "", "static_shape");
    a.static_shape.seed = r.Unsigned(s, "static_shape", "seed");
    a.static_shape.rms_mm = r.Range(s, "static_shape", "rms_mm", 0.0, 10.0);
    a.static_shape.wavelength_mm = r.Range(s, "static_shape", "wavelength_mm", 1e-3, 1e3);
  }
  {
    const json& m = r.Get(j, "", "mesoscopic");
    const std::string p = "mesoscopic";
    a.mesoscopic.seed = r.Unsigned(m, p, "seed");
    a.mesoscopic.pore_depth_mm = r.Range(m, p, "pore_depth_mm", 0.0, 1.0);
    a.mesoscopic.pore_density_per_mm2 = r.Range(m, p, "pore_density_per_mm2", 0.0, 100.0);
    a.mesoscopic.roughness_mm = r.Range(m, p, "roughness_mm", 0.0, 1.0);
    a.mesoscopic.fine_line_depth_mm = r.Range(m, p, "fine_line_depth_mm", 0.0, 1.0);
    a.mesoscopic.fine_line_density = r.Range(m, p, "fine_line_density", 0.0, 100.0);
  }
  {
    const json& s = r.Get(j, "", "skin");
    const std::string p = "skin";
    a.skin.seed = r.Unsigned(s, p, "seed");
    a.skin.tone = r.Range(s, p, "tone", 0.0, 1.0);
    a.skin.redness = r.Range(s, p, "redness", 0.0, 1.0);
    a.skin.variation = r.Range(s, p, "variation", 0.0, 1.0);
    a.skin.blotches = r.Range(s, p, "blotches", 0.0, 1.0);
    a.skin.freckles = r.Range(s, p, "freckles", 0.0, 1.0);
    a.skin.lip_redness = r.Range(s, p, "lip_redness", 0.0, 1.0);
    a.skin.brow_darkness = r.Range(s, p, "brow_darkness", 0.0, 1.0);
    a.skin.eye_tint = r.Range(s, p, "eye_tint", 0.0, 1.0);
    a.skin.oiliness = r.Range(s, p, "oiliness", 0.0, 1.0);
    a.skin.specular = r.Range(s, p, "specular", 0.0, 10.0);
    a.skin.roughness = r.Range(s, p, "roughness", 0.01, 1.0);
  }
  const json& lines = r.Array(j, "", "wrinkles");
  for (size_t k = 0; k < lines.size(); ++k) {
    const std::string p = fmt::format("wrinkles[{}]", k);
    const json& l = lines[k];
    WrinkleLine w;
    const std::string family = r.String(l, p, "family");
    try {
      w.family = WrinkleFamilyFromString(family);
    } catch (const Error& e) {
      r.Fail(p + ".family", fmt::format("= '{}' is not a wrinkle family", family));
    }
    w.max_depth_mm = r.Range(l, p, "max_depth_mm", 0.0, 20.0);
    w.static_depth_mm = r.Range(l, p, "static_depth_mm", 0.0, 20.0);
    w.width_mm = r.Range(l, p, "width_mm", 1e-3, 50.0);
    w.ridge = r.Range(l, p, "ridge", 0.0, 10.0);
    w.saturation = r.Range(l, p, "saturation", 1e-4, 10.0);
    const json& pts = r.Array(l, p, "points");
    const json& str = r.Array(l, p, "strength");
    if (pts.size() < 2) r.Fail(p + ".points", "must hold at least 2 points");
    if (str.size() != pts.size()) {
      r.Fail(p + ".strength", fmt::format("must hold one value per point ({}, not {})", pts.size(), str.size()));
    }
    for (size_t i = 0; i < pts.size(); ++i) {
      const std::string f = fmt::format("{}.points[{}]", p, i);
      if (!pts[i].is_array() || pts[i].size() != 2) r.Fail(f, "must be [u, v]");
      w.points.emplace_back(r.Element(pts[i], f, 0), r.Element(pts[i], f, 1));
      w.strength.push_back(r.Element(str, p + ".strength", i));
    }
    a.wrinkles.push_back(std::move(w));
  }
  return a;
}

void WriteActor(const std::filesystem::path& path, const Actor& actor) {
  const std::string text = ActorToJson(actor) + "\n";
  WriteFileAtomic(path, [&](std::ostream& out) { out << text; });
}

Actor ReadActor(const std::filesystem::path& path) {
  return ActorFromJson(ReadFileToString(path), path.string());
}

// ---------------------------------------------------------------------------

ActorModel::ActorModel(const FaceRig& rig, const Actor& actor) : rig_(PersonalRig(rig, actor)), actor_(actor) {
  actor_.options.Check();
  Require(rig_.neutral.has_uv(), "ActorModel: the rig has no UV coordinates");
  // An actor belongs to the rig it was made for (issue 19: 3 of 26 coefficients were
  // taken silently, the rest as zero).
  Require(actor_.identity.size() == rig_.num_identity(),
          fmt::format("{}: the actor has {} identity coefficients but the rig {} identity modes; an actor "
                      "is made for one rig (crease synth actor --rig)",
                      actor_.source.empty() ? "ActorModel" : actor_.source, actor_.identity.size(),
                      rig_.num_identity()));
  const int R = actor_.options.resolution;
  anchors_ = ComputeFaceAnchors(rig_);
  layout_ = BuildHiResLayout(rig_, R);
  int S = R;
  if (layout_.num_vertices() > 0 && layout_.num_vertices() < actor_.options.surface_min_vertices) {
    // Finer grid: vertex count grows with S², plus a margin for the chart boundary.
    const double scale = std::sqrt(static_cast<double>(actor_.options.surface_min_vertices) / layout_.num_vertices());
    S = std::min(8192, static_cast<int>(std::ceil(R * scale * 1.01)) + 1);
  }
  if (S != R || actor_.options.subdivision_levels > 0) {
    layout_ = BuildHiResLayout(rig_, S, R, actor_.options.subdivision_levels);
  }
  WrinkleStrainOptions so;
  so.resolution = actor_.options.strain_resolution;
  so.smoothing_mm = actor_.options.strain_smoothing_mm;
  strain_ = std::make_unique<StrainField>(rig_, so);
  neutral_metric_ = strain_->MetricMap(rig_.EvaluatePositions(actor_.identity, {}));
  skin_ = BuildSkinMaps(rig_, anchors_, actor_.skin, R);
  // No wrinkle under the painted scalp hair (its lines would be in the truth but in
  // no image): the families' region weights fade out with the hair.
  cv::Mat skin_weight;
  if (!skin_.hair.empty()) skin_weight = 1.0f - skin_.hair;
  std::vector<cv::Mat> weights;
  for (auto f : {WrinkleFamily::kForehead, WrinkleFamily::kGlabella, WrinkleFamily::kCrowsFeet,
                 WrinkleFamily::kNasolabial, WrinkleFamily::kUnderEye, WrinkleFamily::kBunny}) {
    weights.push_back(SoftRegionWeight(rig_, WrinkleFamilyRegions(f), R, 2.0, anchors_.mm_per_uv));
    if (!skin_weight.empty()) weights.back() = weights.back().mul(skin_weight);
  }
  wrinkles_ = std::make_unique<WrinkleField>(actor_.wrinkles, R, anchors_.mm_per_uv, weights, neutral_metric_);
  static_ = BuildStaticShapeMap(anchors_, actor_.static_shape, R);
  static_ = static_.mul(ChartRimFade(rig_, R, anchors_.mm_per_uv, kStaticShapeRimFadeMm));
  meso_ = BuildMesoscopicMap(rig_, anchors_, actor_.mesoscopic, R);
}

cv::Mat ActorModel::ExpressionDisplacement(const MatX3d& V) const {
  return wrinkles_->Displacement(strain_->MetricMap(V));
}

ActorFrame ActorModel::Frame(const Eigen::VectorXd& expression, bool build_hires) const {
  const auto start = std::chrono::steady_clock::now();
  ActorFrame f;
  f.identity = actor_.identity;
  f.expression = expression;
  f.coarse.V = rig_.EvaluatePositions(actor_.identity, expression);
  f.coarse.F = rig_.neutral.F;
  f.coarse.UV = rig_.neutral.UV;
  f.coarse.N = VertexNormals(f.coarse);
  f.expression_displacement = ExpressionDisplacement(f.coarse.V);
  f.static_displacement = static_;
  f.mesoscopic_displacement = meso_;
  if (build_hires) {
    cv::Mat total = f.expression_displacement + static_;
    total += meso_;
    f.hires = BuildHiResSurface(layout_, f.coarse, total, actor_.options.phong_alpha);
  }
  f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return f;
}

}  // namespace crease
