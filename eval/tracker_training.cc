#include "eval/tracker_training.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/ibug.h"
#include "core/image_io.h"
#include "core/rng.h"
#include "synth/actor.h"
#include "synth/sensor.h"
#include "synth/studio.h"

namespace crease {

namespace fs = std::filesystem;

namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

double Iod(const MatX2d& s) { return std::max(1e-9, InterOcularDistance(s)); }

// The truth under a random similarity about its centroid (as ShapeRegressorOptions'
// tracking-like augmentation).
MatX2d PerturbedTruth(const MatX2d& truth, const ShapeRegressorOptions& o, Rng& rng) {
  const Eigen::RowVector2d g = truth.colwise().mean();
  const double iod = Iod(truth);
  const Eigen::RowVector2d shift(rng.Normal(0, o.perturb_translation * iod), rng.Normal(0, o.perturb_translation * iod));
  const double a = rng.Normal(0, o.perturb_rotation_deg) * std::numbers::pi / 180.0;
  const double s = std::exp(rng.Normal(0, o.perturb_scale));
  Eigen::Matrix2d R;
  R << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  MatX2d out(truth.rows(), 2);
  for (int i = 0; i < truth.rows(); ++i) out.row(i) = g + shift + s * (truth.row(i) - g) * R.transpose();
  return out;
}

// The truth's square box, jittered (as the detection-like augmentation).
FaceBox JitteredBox(const MatX2d& truth, const ShapeRegressorOptions& o, Rng& rng) {
  const FaceBox b = BoxOfPoints(truth);
  const double side = std::max(b.width, b.height) * std::exp(rng.Normal(0, o.box_jitter_scale));
  const double cx = b.x + 0.5 * b.width + rng.Normal(0, o.box_jitter_translation * side);
  const double cy = b.y + 0.5 * b.height + rng.Normal(0, o.box_jitter_translation * side);
  return {cx - 0.5 * side, cy - 0.5 * side, side, side, 0.0};
}

void Accumulate(const MatX2d& init, const MatX2d& out, const MatX2d& truth, LandmarkErrorStats* s) {
  const double iod = Iod(truth);
  const double e0 = (init - truth).rowwise().norm().mean(), e1 = (out - truth).rowwise().norm().mean();
  s->initial_px += e0;
  s->initial_iod += e0 / iod;
  s->final_px += e1;
  s->final_iod += e1 / iod;
  ++s->frames;
}

void Finish(LandmarkErrorStats* s) {
  if (s->frames == 0) return;
  s->initial_px /= s->frames;
  s->initial_iod /= s->frames;
  s->final_px /= s->frames;
  s->final_iod /= s->frames;
}

std::vector<std::string> ImageNames(const fs::path& folder) {
  Require(fs::is_directory(folder), fmt::format("{}: not a folder of labelled faces", folder.string()));
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(folder)) {
    if (e.is_regular_file() && e.path().extension() == ".png") names.push_back(e.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

MatX2d ReadPts(const fs::path& path) {
  std::ifstream in(path);
  Require(in.good(), fmt::format("{}: missing landmark file (iBUG .pts)", path.string()));
  std::string line;
  int n = -1;
  while (std::getline(in, line)) {
    if (line.rfind("n_points:", 0) == 0) {
      try {
        n = std::stoi(line.substr(9));
      } catch (const std::exception&) {
        throw Error(fmt::format("{}: 'n_points:' is not followed by a number", path.string()));
      }
    }
    if (line.find('{') != std::string::npos) break;
  }
  Require(n == 68, fmt::format("{}: expected 'n_points: 68' before '{{' (got {})", path.string(), n));
  MatX2d p(68, 2);
  for (int i = 0; i < 68; ++i) {
    Require(static_cast<bool>(in >> p(i, 0) >> p(i, 1)),
            fmt::format("{}: point {} is missing or not two numbers", path.string(), i + 1));
  }
  Require(p.allFinite(), fmt::format("{}: non-finite coordinates", path.string()));
  return p;
}

}  // namespace

void TrackerTrainingOptions::VisitFields(OptionVisitor& v) {
  v.Field("train_actors", train_actors);
  v.Field("test_actors", test_actors);
  v.Field("renders_per_actor", renders_per_actor);
  v.Field("data_seed", data_seed);
  v.Field("width", width);
  v.Field("height", height);
  v.Field("fov_deg", fov_deg);
  v.Field("max_yaw_deg", max_yaw_deg);
  v.Field("max_pitch_deg", max_pitch_deg);
  v.Field("max_roll_deg", max_roll_deg);
  v.Field("max_shift_mm", max_shift_mm);
  v.Field("max_depth_mm", max_depth_mm);
  v.Field("max_active_expressions", max_active_expressions);
  v.Field("extreme_probability", extreme_probability);
  v.Field("lights", lights);
  v.Field("exposure_min", exposure_min);
  v.Field("exposure_max", exposure_max);
  v.Field("full_well_min", full_well_min);
  v.Field("full_well_max", full_well_max);
  v.Field("jpeg_probability", jpeg_probability);
  v.Field("actor_resolution", actor_resolution);
  v.Field("test_fraction", test_fraction);
  v.Field("max_detector_tests", max_detector_tests);
  v.Section("regressor", regressor);
}

void TrackerTrainingOptions::Check() const {
  const char* o = "TrackerTrainingOptions";
  CheckGe(o, "train_actors", train_actors, 1);
  CheckGe(o, "test_actors", test_actors, 1);
  CheckGe(o, "renders_per_actor", renders_per_actor, 1);
  CheckGe(o, "width", width, 32);
  CheckGe(o, "height", height, 32);
  CheckGt(o, "fov_deg", fov_deg, 1.0);
  CheckLt(o, "fov_deg", fov_deg, 170.0);
  CheckGe(o, "max_yaw_deg", max_yaw_deg, 0.0);
  CheckLe(o, "max_yaw_deg", max_yaw_deg, 80.0);
  CheckGe(o, "max_pitch_deg", max_pitch_deg, 0.0);
  CheckLe(o, "max_pitch_deg", max_pitch_deg, 60.0);
  CheckGe(o, "max_roll_deg", max_roll_deg, 0.0);
  CheckLe(o, "max_roll_deg", max_roll_deg, 90.0);
  CheckGe(o, "max_shift_mm", max_shift_mm, 0.0);
  CheckGe(o, "max_depth_mm", max_depth_mm, 0.0);
  CheckLt(o, "max_depth_mm", max_depth_mm, 300.0);
  CheckGe(o, "max_active_expressions", max_active_expressions, 0);
  CheckGe(o, "extreme_probability", extreme_probability, 0.0);
  CheckLe(o, "extreme_probability", extreme_probability, 1.0);
  Require(!lights.empty(), "TrackerTrainingOptions.lights must not be empty");
  CheckGt(o, "exposure_min", exposure_min, 0.0);
  CheckGe(o, "exposure_max", exposure_max, exposure_min);
  CheckGt(o, "full_well_min", full_well_min, 0.0);
  CheckGe(o, "full_well_max", full_well_max, full_well_min);
  CheckGe(o, "jpeg_probability", jpeg_probability, 0.0);
  CheckLe(o, "jpeg_probability", jpeg_probability, 1.0);
  CheckGe(o, "actor_resolution", actor_resolution, 64);
  CheckGt(o, "test_fraction", test_fraction, 0.0);
  CheckLt(o, "test_fraction", test_fraction, 1.0);
  CheckGe(o, "max_detector_tests", max_detector_tests, 0);
  regressor.Check();
}

std::vector<LabelledFace> RenderLabelledFaces(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                                              const TrackerTrainingOptions& options) {
  options.Check();
  std::vector<int> ibug(68);
  for (int i = 0; i < 68; ++i) {
    ibug[i] = rig.LandmarkIndex(fmt::format("ibug_{}", i + 1));
    Require(ibug[i] >= 0, fmt::format("tracker training: the rig has no landmark ibug_{}", i + 1));
  }
  std::vector<LightRig> lights;
  for (const auto& spec : options.lights) lights.push_back(LightRigFromSpec(spec));
  ActorOptions ao;
  ao.resolution = options.actor_resolution;
  ao.surface_min_vertices = 0;
  StudioOptions so;
  so.width = options.width;
  so.height = options.height;
  so.fov_deg = options.fov_deg;
  so.samples_per_axis = 1;
  so.sensor.noise = false;  // the sensor is applied below with per-render settings
  const int E = rig.num_expressions();
  std::vector<LabelledFace> out;
  for (uint64_t actor_seed : actor_seeds) {
    const Actor actor = GenerateActor(rig, actor_seed, ao);
    const Studio studio(rig, actor, so);
    Rng rng(options.data_seed ^ (0x9E3779B97F4A7C15ULL * (actor_seed + 1)));
    for (int k = 0; k < options.renders_per_actor; ++k) {
      // Expression: a few random blendshapes, some at full weight (extreme).
      Eigen::VectorXd w = Eigen::VectorXd::Zero(E);
      const int active = E > 0 ? rng.UniformInt(0, std::min(options.max_active_expressions, E)) : 0;
      for (int a = 0; a < active; ++a) {
        const int e = static_cast<int>(rng.UniformInt(static_cast<uint64_t>(E)));
        w[e] = rng.Uniform() < options.extreme_probability ? 1.0 : rng.Uniform();
      }
      SequenceFrame pose;
      pose.yaw_deg = rng.Uniform(-options.max_yaw_deg, options.max_yaw_deg);
      pose.pitch_deg = rng.Uniform(-options.max_pitch_deg, options.max_pitch_deg);
      pose.roll_deg = rng.Uniform(-options.max_roll_deg, options.max_roll_deg);
      pose.tx_mm = rng.Uniform(-options.max_shift_mm, options.max_shift_mm);
      pose.ty_mm = rng.Uniform(-options.max_shift_mm, options.max_shift_mm);
      pose.tz_mm = rng.Uniform(-options.max_depth_mm, options.max_depth_mm);
      const size_t light = rng.UniformInt(static_cast<uint64_t>(lights.size()));
      SensorOptions sensor;
      sensor.exposure = rng.Uniform(options.exposure_min, options.exposure_max);
      sensor.full_well_electrons = rng.Uniform(options.full_well_min, options.full_well_max);
      sensor.jpeg_quality = rng.Uniform() < options.jpeg_probability ? rng.UniformInt(40, 95) : 0;
      const uint64_t render_seed = rng.NextU64();
      const StudioFrame f = studio.RenderStill(w, pose, &lights[light], nullptr, render_seed);
      Rng sensor_rng(render_seed + 1);
      LabelledFace face;
      face.name = fmt::format("actor{:06d}_{:04d}", actor_seed, k);
      face.image = ApplySensor(f.render.image, sensor, sensor_rng).srgb8;
      face.landmarks.resize(68, 2);
      for (int i = 0; i < 68; ++i) face.landmarks.row(i) = f.truth.landmark_pixels.row(ibug[i]);
      out.push_back(std::move(face));
    }
  }
  return out;
}

void WriteLabelledFaces(const fs::path& folder, const std::vector<LabelledFace>& faces) {
  fs::create_directories(folder);
  for (const LabelledFace& f : faces) {
    WriteImage(folder / (f.name + ".png"), f.image, {.srgb = false});
    const fs::path pts = folder / (f.name + ".pts");
    const fs::path tmp = folder / (f.name + ".pts.tmp");
    {
      std::ofstream out(tmp);
      out << "version: 1\nn_points: " << f.landmarks.rows() << "\n{\n";
      for (int i = 0; i < f.landmarks.rows(); ++i) out << fmt::format("{:.4f} {:.4f}\n", f.landmarks(i, 0), f.landmarks(i, 1));
      out << "}\n";
      Require(out.good(), fmt::format("{}: cannot write", tmp.string()));
    }
    fs::rename(tmp, pts);
  }
}

namespace {

// One tag of an XML file: its name ("/box" for a closing tag) and attributes.
struct XmlTag {
  std::string name;
  std::vector<std::pair<std::string, std::string>> attributes;
  int line = 0;
  const std::string* Find(const std::string& key) const {
    for (const auto& [k, v] : attributes) {
      if (k == key) return &v;
    }
    return nullptr;
  }
};

// The tags of a small XML dialect (no entities, CDATA or nesting in attributes),
// enough for dlib's imglab files; comments, declarations and text are skipped.
std::vector<XmlTag> XmlTags(const std::string& text, const std::string& what) {
  std::vector<XmlTag> tags;
  size_t i = 0;
  int line = 1;
  auto advance_to = [&](size_t j) {
    line += static_cast<int>(std::count(text.begin() + static_cast<std::ptrdiff_t>(i),
                                        text.begin() + static_cast<std::ptrdiff_t>(j), '\n'));
    i = j;
  };
  while (true) {
    const size_t open = text.find('<', i);
    if (open == std::string::npos) break;
    advance_to(open);
    if (text.compare(open, 4, "<!--") == 0) {
      const size_t end = text.find("-->", open);
      Require(end != std::string::npos, fmt::format("{}:{}: unterminated comment", what, line));
      advance_to(end + 3);
      continue;
    }
    const size_t close = text.find('>', open);
    Require(close != std::string::npos, fmt::format("{}:{}: unterminated tag", what, line));
    XmlTag tag;
    tag.line = line;
    const std::string body = text.substr(open + 1, close - open - 1);
    advance_to(close + 1);
    if (body.empty() || body[0] == '?' || body[0] == '!') continue;
    size_t k = 0;
    while (k < body.size() && !std::isspace(static_cast<unsigned char>(body[k])) && body[k] != '/') ++k;
    tag.name = body.substr(0, k);
    if (tag.name.empty() && !body.empty() && body[0] == '/') {
      size_t e = 1;
      while (e < body.size() && !std::isspace(static_cast<unsigned char>(body[e]))) ++e;
      tag.name = body.substr(0, e);
      tags.push_back(std::move(tag));
      continue;
    }
    while (k < body.size()) {
      while (k < body.size() && (std::isspace(static_cast<unsigned char>(body[k])) || body[k] == '/')) ++k;
      if (k >= body.size()) break;
      const size_t eq = body.find('=', k);
      Require(eq != std::string::npos && eq + 1 < body.size() && (body[eq + 1] == '\'' || body[eq + 1] == '"'),
              fmt::format("{}:{}: malformed attribute in <{}>", what, tag.line, tag.name));
      const char quote = body[eq + 1];
      const size_t end = body.find(quote, eq + 2);
      Require(end != std::string::npos, fmt::format("{}:{}: unterminated attribute value in <{}>", what, tag.line, tag.name));
      std::string key = body.substr(k, eq - k);
      while (!key.empty() && std::isspace(static_cast<unsigned char>(key.back()))) key.pop_back();
      tag.attributes.emplace_back(key, body.substr(eq + 2, end - eq - 2));
      k = end + 1;
    }
    tags.push_back(std::move(tag));
  }
  return tags;
}

// Coordinates of a dlib XML file beyond this (pixels) are refused as corrupt.
constexpr double kMaxXmlCoordinate = 1e6;

double XmlNumber(const XmlTag& tag, const std::string& key, const std::string& what) {
  const std::string* v = tag.Find(key);
  Require(v != nullptr, fmt::format("{}:{}: <{}> has no '{}'", what, tag.line, tag.name, key));
  try {
    size_t used = 0;
    const double x = std::stod(*v, &used);
    if (used != v->size() || !std::isfinite(x)) throw std::invalid_argument("trailing");
    return x;
  } catch (const std::exception&) {
    throw Error(fmt::format("{}:{}: <{}> {}='{}' is not a number", what, tag.line, tag.name, key, *v));
  }
}

}  // namespace

std::vector<LabelledFace> ReadDlibXmlFaces(const fs::path& xml, const DlibXmlOptions& options) {
  Require(options.crop_scale >= 1.0 && options.box_px >= 16,
          fmt::format("DlibXmlOptions: crop_scale = {} must be ≥ 1 and box_px = {} ≥ 16", options.crop_scale,
                      options.box_px));
  const std::string what = xml.string();
  std::string text;
  {
    std::ifstream in(xml, std::ios::binary);
    Require(in.good(), fmt::format("{}: cannot open", what));
    std::ostringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  const std::vector<XmlTag> tags = XmlTags(text, what);
  std::vector<LabelledFace> out;
  std::string image_file;
  cv::Mat image;  // 8-bit RGB of image_file, loaded on its first usable box
  bool image_loaded = false;
  int box_index = 0, boxes_seen = 0;
  const XmlTag* box = nullptr;
  MatX2d parts;
  std::vector<uint8_t> have;
  for (const XmlTag& tag : tags) {
    if (tag.name == "image") {
      const std::string* f = tag.Find("file");
      Require(f != nullptr, fmt::format("{}:{}: <image> has no 'file'", what, tag.line));
      image_file = *f;
      image_loaded = false;
      box_index = 0;
    } else if (tag.name == "box") {
      Require(!image_file.empty(), fmt::format("{}:{}: <box> outside an <image>", what, tag.line));
      box = &tag;
      parts = MatX2d::Zero(68, 2);
      have.assign(68, 0);
      ++boxes_seen;
    } else if (tag.name == "part" && box != nullptr) {
      const std::string* name = tag.Find("name");
      Require(name != nullptr, fmt::format("{}:{}: <part> has no 'name'", what, tag.line));
      int k = -1;
      try {
        k = std::stoi(*name);
      } catch (const std::exception&) {
      }
      if (k < 0 || k >= 68) continue;
      parts(k, 0) = XmlNumber(tag, "x", what);
      parts(k, 1) = XmlNumber(tag, "y", what);
      have[static_cast<size_t>(k)] = 1;
    } else if (tag.name == "/box" && box != nullptr) {
      const XmlTag& b = *box;
      box = nullptr;
      const int index = box_index++;
      const std::string* ignore = b.Find("ignore");
      if ((ignore != nullptr && *ignore == "1") || std::count(have.begin(), have.end(), 1) != 68) continue;
      if (!image_loaded) {
        const fs::path path = xml.parent_path() / image_file;
        Require(fs::exists(path), fmt::format("{}:{}: image '{}' not found ({})", what, b.line, image_file, path.string()));
        const cv::Mat raw = ReadImage(path, /*srgb=*/false);
        cv::Mat rgb = raw;
        if (raw.channels() == 1) cv::cvtColor(raw, rgb, cv::COLOR_GRAY2RGB);
        if (raw.channels() == 4) cv::cvtColor(raw, rgb, cv::COLOR_RGBA2RGB);
        rgb.convertTo(image, CV_8UC3, 255.0);
        image_loaded = true;
      }
      const double top = XmlNumber(b, "top", what), left = XmlNumber(b, "left", what);
      const double width = XmlNumber(b, "width", what), height = XmlNumber(b, "height", what);
      Require(width > 0 && height > 0, fmt::format("{}:{}: <box> has an empty size", what, b.line));
      const double side = std::max(width, height);
      // Issue 19 (dlib_xml_fuzzer): a box of 1e-300 px scaled the crop by 1e302 (infinite coordinates).
      Require(side >= 1.0 && side <= kMaxXmlCoordinate && std::abs(top) <= kMaxXmlCoordinate &&
                  std::abs(left) <= kMaxXmlCoordinate && parts.cwiseAbs().maxCoeff() <= kMaxXmlCoordinate,
              fmt::format("{}:{}: <box> smaller than 1 px, or a coordinate beyond ±{} px", what, b.line,
                          kMaxXmlCoordinate));
      const double s = options.box_px / side;
      const int crop = static_cast<int>(std::lround(options.crop_scale * options.box_px));
      const double cx = left + 0.5 * (width - 1.0), cy = top + 0.5 * (height - 1.0);
      // Pixel centres at integers: x' = s (x − cx) + (crop − 1) / 2.
      const double tx = 0.5 * (crop - 1) - s * cx, ty = 0.5 * (crop - 1) - s * cy;
      const cv::Mat M = (cv::Mat_<double>(2, 3) << s, 0.0, tx, 0.0, s, ty);
      LabelledFace face;
      face.name = fmt::format("{}_{}", fs::path(image_file).stem().string(), index);
      cv::warpAffine(image, face.image, M, cv::Size(crop, crop), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
      face.landmarks.resize(68, 2);
      for (int k = 0; k < 68; ++k) face.landmarks.row(k) << s * parts(k, 0) + tx, s * parts(k, 1) + ty;
      out.push_back(std::move(face));
    }
  }
  Require(!out.empty(), fmt::format("{}: no <box> with the 68 <part>s (00 … 67) among {} boxes", what, boxes_seen));
  return out;
}

LandmarkSourceEvaluation EvaluateLandmarkSource(LandmarkSource& source, const std::vector<LabelledFace>& faces) {
  LandmarkSourceEvaluation e;
  e.source = source.name();
  double seconds = 0;
  for (const LabelledFace& f : faces) {
    source.Reset();
    const auto t0 = std::chrono::steady_clock::now();
    const LandmarkResult r = source.Track(f.image);
    seconds += Seconds(t0);
    ++e.faces;
    if (!r.found) continue;
    ++e.found;
    const double err = (r.points - f.landmarks).rowwise().norm().mean();
    e.error_px += err;
    e.error_iod += err / Iod(f.landmarks);
  }
  if (e.found > 0) {
    e.error_px /= e.found;
    e.error_iod /= e.found;
  }
  e.ms_per_face = e.faces > 0 ? 1e3 * seconds / e.faces : 0.0;
  return e;
}

std::vector<LabelledFace> ReadLabelledFaces(const fs::path& folder) {
  if (fs::is_regular_file(folder) && folder.extension() == ".xml") return ReadDlibXmlFaces(folder);
  std::vector<LabelledFace> out;
  for (const std::string& name : ImageNames(folder)) {
    LabelledFace f;
    f.name = name;
    const cv::Mat raw = ReadImage(folder / (name + ".png"), /*srgb=*/false);  // value / 255
    Require(raw.channels() == 3 || raw.channels() == 1,
            fmt::format("{}: expected a gray or RGB image", (folder / (name + ".png")).string()));
    raw.convertTo(f.image, CV_MAKETYPE(CV_8U, raw.channels()), 255.0);
    f.landmarks = ReadPts(folder / (name + ".pts"));
    out.push_back(std::move(f));
  }
  Require(!out.empty(), fmt::format("{}: no NAME.png + NAME.pts pairs", folder.string()));
  return out;
}

void EvaluateShapeRegressor(const ShapeRegressor& regressor, const std::vector<LabelledFace>& faces, uint64_t seed,
                            int detector_frames, TrackerTrainingReport* report) {
  Rng rng(seed);
  double predict_s = 0;
  int predicts = 0;
  for (const LabelledFace& f : faces) {
    const MatX2d init_t = PerturbedTruth(f.landmarks, regressor.options, rng);
    const auto t0 = std::chrono::steady_clock::now();
    const MatX2d out_t = regressor.Predict(f.image, init_t);
    predict_s += Seconds(t0);
    ++predicts;
    Accumulate(init_t, out_t, f.landmarks, &report->tracking);
    const MatX2d init_b = regressor.MeanShapeInBox(JitteredBox(f.landmarks, regressor.options, rng));
    Accumulate(init_b, regressor.Predict(f.image, init_b), f.landmarks, &report->box);
  }
  Finish(&report->tracking);
  Finish(&report->box);
  report->predict_ms = predicts ? 1e3 * predict_s / predicts : 0.0;
  if (detector_frames > 0) {
    RegressorLandmarkSource source(regressor);
    const size_t n = std::min<size_t>(static_cast<size_t>(detector_frames), faces.size());
    const LandmarkSourceEvaluation e =
        EvaluateLandmarkSource(source, std::vector<LabelledFace>(faces.begin(), faces.begin() + static_cast<std::ptrdiff_t>(n)));
    report->detector_frames += e.faces;
    report->detector_found += e.found;
    report->detector_error_px = e.error_px;
    report->detector_error_iod = e.error_iod;
  }
}

void EvaluateSequenceTracking(const ShapeRegressor& regressor, const std::vector<LabelledFace>& frames,
                              TrackerTrainingReport* report) {
  RegressorLandmarkSource source(regressor);
  double sum_iod = 0, sum_px = 0, track_s = 0;
  int tracked = 0;
  for (const LabelledFace& f : frames) {
    const auto t0 = std::chrono::steady_clock::now();
    const LandmarkResult r = source.Track(f.image);
    const double s = Seconds(t0);
    ++report->sequence_frames;
    if (r.detected) {
      ++report->sequence_detections;
    } else {
      track_s += s;
      ++tracked;
    }
    if (!r.found) continue;
    ++report->sequence_found;
    const double e = (r.points - f.landmarks).rowwise().norm().mean();
    sum_px += e;
    sum_iod += e / Iod(f.landmarks);
  }
  if (report->sequence_found) {
    report->sequence_error_iod = sum_iod / report->sequence_found;
    report->sequence_error_px = sum_px / report->sequence_found;
  }
  report->sequence_track_ms = tracked ? 1e3 * track_s / tracked : 0.0;
}

TrackerTrainingResult TrainTrackerOnFaces(const std::vector<LabelledFace>& train, const std::vector<LabelledFace>& test,
                                          const TrackerTrainingOptions& options) {
  options.Check();
  Require(!train.empty() && !test.empty(), "tracker training: the training and held-out sets must not be empty");
  const auto start = std::chrono::steady_clock::now();
  std::vector<cv::Mat> images;
  std::vector<MatX2d> shapes;
  for (const LabelledFace& f : train) {
    images.push_back(f.image);
    shapes.push_back(f.landmarks);
  }
  ShapeRegressorTrainingResult trained = TrainShapeRegressor(images, shapes, options.regressor);
  TrackerTrainingResult result;
  result.regressor = std::move(trained.regressor);
  result.report.detector_calibration_faces = CalibrateDetectorBox(&result.regressor, images, shapes);
  result.report.detector_box = result.regressor.detector_box;
  result.report.training = trained.report;
  result.report.train_images = static_cast<int>(train.size());
  result.report.test_images = static_cast<int>(test.size());
  EvaluateShapeRegressor(result.regressor, test, options.data_seed + 7777, options.max_detector_tests, &result.report);
  result.report.seconds = Seconds(start);
  return result;
}

TrackerTrainingResult TrainTrackerOnRenders(const FaceRig& rig, const TrackerTrainingOptions& options,
                                            const fs::path& save_dir, const std::vector<LabelledFace>& extra_train) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  std::vector<uint64_t> train_seeds, test_seeds;
  for (int a = 0; a < options.train_actors; ++a) train_seeds.push_back(options.data_seed * 1000 + a);
  for (int a = 0; a < options.test_actors; ++a) test_seeds.push_back(options.data_seed * 1000 + 500 + a);
  std::vector<LabelledFace> train = RenderLabelledFaces(rig, train_seeds, options);
  train.insert(train.end(), extra_train.begin(), extra_train.end());
  const std::vector<LabelledFace> test = RenderLabelledFaces(rig, test_seeds, options);
  if (!save_dir.empty()) {
    WriteLabelledFaces(save_dir / "train", train);
    WriteLabelledFaces(save_dir / "test", test);
  }
  const double data_s = Seconds(start);
  TrackerTrainingResult r = TrainTrackerOnFaces(train, test, options);
  r.report.data_seconds = data_s;
  r.report.seconds = Seconds(start);
  return r;
}

TrackerTrainingResult TrainTrackerOnFolder(const fs::path& folder, const TrackerTrainingOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  std::vector<LabelledFace> train, test;
  if (fs::is_directory(folder / "train") && fs::is_directory(folder / "test")) {
    train = ReadLabelledFaces(folder / "train");
    test = ReadLabelledFaces(folder / "test");
  } else {
    std::vector<LabelledFace> all = ReadLabelledFaces(folder);
    Require(all.size() >= 2, fmt::format("{}: need at least two labelled faces to hold some out", folder.string()));
    const size_t n_test = std::clamp<size_t>(
        static_cast<size_t>(std::lround(options.test_fraction * all.size())), 1, all.size() - 1);
    test.assign(std::make_move_iterator(all.end() - n_test), std::make_move_iterator(all.end()));
    all.resize(all.size() - n_test);
    train = std::move(all);
  }
  const double data_s = Seconds(start);
  TrackerTrainingResult r = TrainTrackerOnFaces(train, test, options);
  r.report.data_seconds = data_s;
  r.report.seconds = Seconds(start);
  return r;
}

std::string TrackerTrainingReport::ToText() const {
  std::string s;
  s += fmt::format("training: {} images, {} samples (with augmentation), {:.1f} s; data {:.1f} s\n", train_images,
                   training.num_samples, training.seconds, data_seconds);
  s += "training error / IOD by stage:";
  for (double e : training.train_error_iod) s += fmt::format(" {:.3f}", e);
  s += fmt::format("\nmean |corr| of selected pixel pairs: {:.3f}\n", training.mean_abs_correlation);
  s += fmt::format("held-out ({} images), mean point-to-point error over 68 points:\n", test_images);
  s += fmt::format("  {:<34} {:>10} {:>10} {:>10} {:>10}\n", "initialisation", "init/IOD", "final/IOD", "init px",
                   "final px");
  s += fmt::format("  {:<34} {:>10.4f} {:>10.4f} {:>10.2f} {:>10.2f}\n", "tracking (perturbed truth)",
                   tracking.initial_iod, tracking.final_iod, tracking.initial_px, tracking.final_px);
  s += fmt::format("  {:<34} {:>10.4f} {:>10.4f} {:>10.2f} {:>10.2f}\n", "box (mean shape in jittered box)",
                   box.initial_iod, box.final_iod, box.initial_px, box.final_px);
  if (detector_frames > 0) {
    s += fmt::format("  detector start (HOG box + cascade): found {}/{}, error {:.4f} IOD, {:.2f} px\n", detector_found,
                     detector_frames, detector_error_iod, detector_error_px);
  }
  s += fmt::format("detector box → landmark box, from {} training detections: centre {:+.3f}, {:+.3f} sides, side × {:.3f}\n",
                   detector_calibration_faces, detector_box.x(), detector_box.y(), detector_box.z());
  if (sequence_frames > 0) {
    s += fmt::format("sequence ({} frames, tracked from the previous frame): found {}, detector runs {}, error {:.4f} "
                     "IOD, {:.2f} px, {:.3f} ms per tracked frame\n",
                     sequence_frames, sequence_found, sequence_detections, sequence_error_iod, sequence_error_px,
                     sequence_track_ms);
  }
  s += fmt::format("Predict: {:.3f} ms per image (one thread); total {:.1f} s\n", predict_ms, seconds);
  return s;
}

std::string TrackerTrainingReport::ToJson() const {
  auto stats = [](const LandmarkErrorStats& e) {
    return nlohmann::json{{"frames", e.frames},         {"initial_iod", e.initial_iod}, {"final_iod", e.final_iod},
                          {"initial_px", e.initial_px}, {"final_px", e.final_px}};
  };
  nlohmann::json j;
  j["train_images"] = train_images;
  j["test_images"] = test_images;
  j["train_samples"] = training.num_samples;
  j["train_error_iod_by_stage"] = training.train_error_iod;
  j["mean_abs_correlation"] = training.mean_abs_correlation;
  j["train_seconds"] = training.seconds;
  j["data_seconds"] = data_seconds;
  j["held_out_tracking"] = stats(tracking);
  j["held_out_box"] = stats(box);
  j["held_out_detector"] = {{"frames", detector_frames},
                            {"found", detector_found},
                            {"error_iod", detector_error_iod},
                            {"error_px", detector_error_px}};
  j["predict_ms"] = predict_ms;
  j["detector_box"] = {{"faces", detector_calibration_faces},
                       {"offset_x", detector_box.x()},
                       {"offset_y", detector_box.y()},
                       {"side_ratio", detector_box.z()}};
  if (sequence_frames > 0) {
    j["sequence"] = {{"frames", sequence_frames},       {"found", sequence_found},
                     {"detections", sequence_detections}, {"error_iod", sequence_error_iod},
                     {"error_px", sequence_error_px},   {"track_ms", sequence_track_ms}};
  }
  j["seconds"] = seconds;
  return j.dump(2);
}

}  // namespace crease
