#include "synth/sequence.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/options.h"
#include "core/rng.h"

namespace crease {
namespace {

const std::vector<std::string>& PoseFields() {
  static const std::vector<std::string> f = {"yaw_deg", "pitch_deg", "roll_deg", "tx_mm", "ty_mm", "tz_mm"};
  return f;
}
const std::vector<std::string>& LightFields() {
  static const std::vector<std::string> f = {"azimuth_deg", "elevation_deg", "intensity"};
  return f;
}
const std::vector<std::string>& OccluderFields() {
  static const std::vector<std::string> f = {"x_mm", "y_mm", "z_mm", "radius_mm"};
  return f;
}

// Channel keys: (t, value), sorted by t.
using Track = std::vector<std::pair<double, double>>;

double Sample(const Track& track, double t, const std::string& interpolation) {
  if (t <= track.front().first) return track.front().second;
  if (t >= track.back().first) return track.back().second;
  size_t k = 0;
  while (k + 1 < track.size() && track[k + 1].first <= t) ++k;
  const auto [t0, v0] = track[k];
  const auto [t1, v1] = track[k + 1];
  const double h = t1 - t0;
  const double u = h > 0 ? (t - t0) / h : 1.0;
  if (interpolation == "linear") return v0 + (v1 - v0) * u;
  if (interpolation == "smooth") return v0 + (v1 - v0) * u * u * (3.0 - 2.0 * u);
  // Catmull–Rom (cardinal spline on non-uniform keys): tangents from the neighbours.
  auto slope = [&](size_t i) {
    if (i == 0 || i + 1 >= track.size()) return 0.0;
    return (track[i + 1].second - track[i - 1].second) / (track[i + 1].first - track[i - 1].first);
  };
  const double m0 = slope(k) * h, m1 = slope(k + 1) * h;
  const double u2 = u * u, u3 = u2 * u;
  return (2 * u3 - 3 * u2 + 1) * v0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * v1 + (u3 - u2) * m1;
}

std::map<std::string, Track> Tracks(const std::vector<Keyframe>& keys) {
  std::map<std::string, Track> tracks;
  for (const auto& k : keys) {
    for (const auto& [channel, value] : k.values) tracks[channel].emplace_back(k.t, value);
  }
  return tracks;
}

}  // namespace

int Sequence::num_frames() const { return static_cast<int>(std::lround(duration_s * fps)) + 1; }

SequenceFrame Sequence::At(double time_s) const {
  SequenceFrame f;
  f.time_s = time_s;
  f.light_elevation_deg = 15.0;
  for (const auto& [channel, track] : Tracks(keys)) {
    const double v = Sample(track, time_s, interpolation);
    const auto colon = channel.find(':');
    const std::string group = channel.substr(0, colon), field = channel.substr(colon + 1);
    if (group == "expression") {
      f.expression[field] = std::clamp(v, 0.0, 1.0);
    } else if (group == "pose") {
      double* dst[] = {&f.yaw_deg, &f.pitch_deg, &f.roll_deg, &f.tx_mm, &f.ty_mm, &f.tz_mm};
      *dst[std::find(PoseFields().begin(), PoseFields().end(), field) - PoseFields().begin()] = v;
    } else if (group == "light") {
      double* dst[] = {&f.light_azimuth_deg, &f.light_elevation_deg, &f.light_intensity};
      *dst[std::find(LightFields().begin(), LightFields().end(), field) - LightFields().begin()] = v;
    } else if (group == "occluder") {
      f.has_occluder = true;
      double* dst[] = {&f.occluder_x_mm, &f.occluder_y_mm, &f.occluder_z_mm, &f.occluder_radius_mm};
      *dst[std::find(OccluderFields().begin(), OccluderFields().end(), field) - OccluderFields().begin()] = v;
    }
  }
  return f;
}

SequenceFrame Sequence::Frame(int index) const {
  Require(index >= 0 && index < num_frames(),
          fmt::format("sequence '{}': frame {} is out of range (it has {} frames)", name, index, num_frames()));
  SequenceFrame f = At(index / fps);
  f.index = index;
  return f;
}

std::vector<std::string> Sequence::ExpressionNames() const {
  std::set<std::string> names;
  for (const auto& k : keys) {
    for (const auto& [channel, v] : k.values) {
      if (channel.rfind("expression:", 0) == 0) names.insert(channel.substr(11));
    }
  }
  return {names.begin(), names.end()};
}

void Sequence::Validate(const std::string& what) const {
  Require(std::isfinite(fps) && fps > 0 && fps <= 1000, fmt::format("{}: fps = {} must be in (0, 1000]", what, fps));
  Require(!keys.empty(), fmt::format("{}: the sequence has no keys", what));
  Require(interpolation == "linear" || interpolation == "smooth" || interpolation == "catmull-rom",
          fmt::format("{}: interpolation '{}' must be linear, smooth or catmull-rom", what, interpolation));
  for (size_t i = 0; i < keys.size(); ++i) {
    Require(std::isfinite(keys[i].t) && keys[i].t >= 0,
            fmt::format("{}: key {}: time t = {} must be >= 0", what, i, keys[i].t));
    if (i > 0) {
      Require(keys[i].t > keys[i - 1].t,
              fmt::format("{}: key {}: times must increase (t = {} after t = {})", what, i, keys[i].t, keys[i - 1].t));
    }
    for (const auto& [channel, v] : keys[i].values) {
      Require(std::isfinite(v), fmt::format("{}: key {}: {} is not a finite number", what, i, channel));
    }
  }
  Require(duration_s >= keys.back().t,
          fmt::format("{}: duration {} s is shorter than the last key ({} s)", what, duration_s, keys.back().t));
  Require(num_frames() <= 1000000, fmt::format("{}: too many frames ({})", what, num_frames()));
}

// ---------------------------------------------------------------------------
// Presets

namespace {

using ChannelValues = std::vector<std::pair<std::string, double>>;

struct PresetBuilder {
  Sequence s;
  void Key(double t, const ChannelValues& values) {
    auto it = std::find_if(s.keys.begin(), s.keys.end(), [&](const Keyframe& k) { return std::abs(k.t - t) < 1e-9; });
    if (it == s.keys.end()) {
      s.keys.push_back({t, {}});
      it = s.keys.end() - 1;
    }
    for (const auto& [c, v] : values) it->values[c] = v;
  }
  Sequence Done(double duration) {
    std::sort(s.keys.begin(), s.keys.end(), [](const Keyframe& a, const Keyframe& b) { return a.t < b.t; });
    s.duration_s = duration;
    s.Validate("preset " + s.name);
    return s;
  }
};

// A hold of `values` ramping up over `ramp` s to start at t0, held until t1,
// released by t1 + ramp; channels listed are keyed to 0 around it.
void Pulse(PresetBuilder& b, double t0, double t1, double ramp, const ChannelValues& values) {
  for (const auto& [c, v] : values) {
    b.Key(t0 - ramp, {{c, 0.0}});
    b.Key(t0, {{c, v}});
    b.Key(t1, {{c, v}});
    b.Key(t1 + ramp, {{c, 0.0}});
  }
}

// scan-holds' timing, seconds at its own length: neutral until kLead, then per
// scan expression a ramp up, a hold, a ramp down and a neutral gap.
struct ScanHoldTiming {
  static constexpr double kLead = 0.6, kRamp = 0.3, kHold = 1.0, kGap = 0.4;
  static constexpr double kPeriod = 2 * kRamp + kHold + kGap;
  static int Count() { return static_cast<int>(ScanExpressionSpecs().size()); }
  static double Start(int i) { return kLead + kRamp + i * kPeriod; }  // first instant at full weight
  static double Length() { return kLead + Count() * kPeriod; }
  // The factor of every time for the preset made `seconds` long (≤ 0: its own length).
  static double Scale(double seconds) { return seconds > 0 ? seconds / Length() : 1.0; }
};

Sequence ScanHolds(PresetBuilder& b, double seconds) {
  const int n = ScanHoldTiming::Count();
  const double k = ScanHoldTiming::Scale(seconds);
  for (int i = 0; i < n; ++i) {
    ChannelValues values;
    for (const auto& [name, w] : ParseExpressionWeights(ScanExpressionSpecs()[i])) {
      values.emplace_back("expression:" + name, w);
    }
    const double t0 = ScanHoldTiming::Start(i) * k;
    Pulse(b, t0, t0 + ScanHoldTiming::kHold * k, ScanHoldTiming::kRamp * k, values);
  }
  b.Key(0, {{"pose:yaw_deg", 0}, {"pose:pitch_deg", 0}});
  return b.Done(ScanHoldTiming::Length() * k);
}

}  // namespace

std::vector<std::string> SequencePresetNames() {
  return {"wrinkle-workout", "talking", "moving-light", "fast-motion", "occlusion", "workout-talking", "scan-holds"};
}

const std::vector<std::string>& ScanExpressionSpecs() {
  static const std::vector<std::string> specs = {"browInnerUp=1,browOuterUp=1", "browDown=1",
                                                 "mouthSmile=1,cheekSquint=0.8,eyeSquint=0.7", "noseSneer=1"};
  return specs;
}

std::map<std::string, double> ParseExpressionWeights(const std::string& spec) {
  std::map<std::string, double> weights;
  size_t start = 0;
  while (start < spec.size()) {
    size_t end = spec.find(',', start);
    if (end == std::string::npos) end = spec.size();
    const std::string item = spec.substr(start, end - start);
    start = end + 1;
    if (item.empty()) continue;
    const auto [name, w] = ParseNameValue(item, "expression", "WEIGHT");
    weights[name] = w;
  }
  return weights;
}

std::pair<int, int> ScanHoldFrames(int index, double fps, double seconds) {
  Require(index >= 0 && index < ScanHoldTiming::Count(),
          fmt::format("scan-holds: hold {} is out of range (it has {})", index, ScanHoldTiming::Count()));
  Require(std::isfinite(fps) && fps > 0, fmt::format("scan-holds: fps = {} must be > 0", fps));
  const double k = ScanHoldTiming::Scale(seconds);
  const double t0 = ScanHoldTiming::Start(index) * k, t1 = t0 + ScanHoldTiming::kHold * k;
  return {static_cast<int>(std::ceil(t0 * fps - 1e-9)), static_cast<int>(std::floor(t1 * fps + 1e-9))};
}

Sequence MakePresetSequence(const std::string& preset, double seconds) {
  PresetBuilder b;
  b.s.name = preset;
  if (preset == "wrinkle-workout") {
    // Extreme expressions one after another (each ~1 s), neutral in between.
    const double d = seconds > 0 ? seconds : 8.0, k = d / 8.0;
    // No light keys: the studio's light rig (`--light`) lights it, so the same
    // performance can be compared under front and raking light.
    Pulse(b, 0.8 * k, 1.4 * k, 0.4 * k, {{"expression:browInnerUp", 1.0}, {"expression:browOuterUp", 1.0}});
    Pulse(b, 2.4 * k, 2.9 * k, 0.4 * k, {{"expression:browDown", 1.0}});
    Pulse(b, 3.8 * k, 4.3 * k, 0.4 * k,
          {{"expression:mouthSmile", 1.0}, {"expression:cheekSquint", 0.8}, {"expression:eyeSquint", 0.7}});
    Pulse(b, 5.2 * k, 5.6 * k, 0.4 * k, {{"expression:noseSneer", 1.0}});
    Pulse(b, 6.4 * k, 6.8 * k, 0.35 * k, {{"expression:jawOpen", 0.8}, {"expression:mouthStretch", 0.6}});
    b.Key(0, {{"pose:yaw_deg", 0}, {"pose:pitch_deg", 0}});
    return b.Done(d);
  }
  if (preset == "talking") {
    const double d = seconds > 0 ? seconds : 6.0;
    b.s.interpolation = "catmull-rom";
    Rng rng(20150808);  // fixed: the preset is the same everywhere
    for (double t = 0; t <= d + 1e-9; t += 0.125) {  // syllables at 4 Hz
      b.Key(t, {{"expression:jawOpen", rng.Uniform(0.05, 0.35)}});
    }
    for (double t = 0; t <= d + 1e-9; t += 0.75) {
      b.Key(t, {{"expression:mouthSmile", rng.Uniform() < 0.4 ? rng.Uniform(0.1, 0.4) : 0.0},
                {"expression:browInnerUp", rng.Uniform() < 0.3 ? rng.Uniform(0.1, 0.5) : 0.0},
                {"expression:mouthPucker", rng.Uniform() < 0.25 ? rng.Uniform(0.1, 0.4) : 0.0},
                {"expression:eyeBlink", 0.0}});
    }
    for (double t = 1.3; t < d; t += 2.1) Pulse(b, t, t + 0.05, 0.08, {{"expression:eyeBlink", 1.0}});
    for (double t = 0; t <= d + 1e-9; t += 1.0) {
      b.Key(t, {{"pose:yaw_deg", rng.Uniform(-10, 10)}, {"pose:pitch_deg", rng.Uniform(-5, 5)},
                {"pose:roll_deg", rng.Uniform(-3, 3)}});
    }
    return b.Done(d);
  }
  if (preset == "workout-talking") {
    // What a new user does in front of the capture system (Sec. 5.2): a short
    // wrinkle workout (its frames build the wrinkle map), then talking. 4/7 of the
    // length is the workout, 0.5 s a transition, the rest talking.
    const double d = seconds > 0 ? seconds : 7.0;
    const double dw = d * 4.0 / 7.0, gap = 0.5, dt = std::max(d - dw - gap, 1.0);
    const Sequence w = MakePresetSequence("wrinkle-workout", dw), t = MakePresetSequence("talking", dt);
    b.s.keys = w.keys;
    b.s.interpolation = "smooth";
    // Every channel is keyed at the end of the workout (its last value there, 0 if
    // the workout does not use it) so that talking's channels do not leak back.
    std::map<std::string, double> last;
    for (const Keyframe& k : w.keys)
      for (const auto& [c, v] : k.values) last[c] = v;
    Keyframe junction{w.duration_s, {}};
    for (const Keyframe& k : t.keys)
      for (const auto& [c, v] : k.values) junction.values[c] = last.count(c) ? last[c] : 0.0;
    for (const auto& [c, v] : last) junction.values[c] = v;
    if (!b.s.keys.empty() && std::abs(b.s.keys.back().t - junction.t) < 1e-9) {
      for (const auto& [c, v] : junction.values) b.s.keys.back().values.emplace(c, v);
    } else {
      b.s.keys.push_back(junction);
    }
    for (Keyframe k : t.keys) {
      k.t += w.duration_s + gap;
      b.s.keys.push_back(k);
    }
    return b.Done(w.duration_s + gap + t.duration_s);
  }
  if (preset == "scan-holds") return ScanHolds(b, seconds);
  if (preset == "moving-light") {
    // Fig. 14: the expression holds while a directional light moves from the front to above.
    const double d = seconds > 0 ? seconds : 4.0;
    b.s.interpolation = "linear";
    b.Key(0, {{"expression:browInnerUp", 0}, {"expression:browOuterUp", 0}});
    b.Key(0.1 * d, {{"expression:browInnerUp", 1}, {"expression:browOuterUp", 1}});
    b.Key(0.1 * d, {{"light:azimuth_deg", 0}, {"light:elevation_deg", 0}, {"light:intensity", 1}});
    b.Key(d, {{"light:elevation_deg", 80}});
    return b.Done(d);
  }
  if (preset == "fast-motion") {
    const double d = seconds > 0 ? seconds : 3.0;
    b.s.motion_blur = true;
    b.s.interpolation = "smooth";
    double sign = 1;
    for (double t = 0; t <= d + 1e-9; t += 0.4, sign = -sign) {
      b.Key(t, {{"pose:yaw_deg", 35 * sign}, {"pose:pitch_deg", 5 * sign}});
    }
    b.Key(0, {{"expression:mouthSmile", 0.3}, {"expression:browInnerUp", 0.3}});
    return b.Done(d);
  }
  if (preset == "occlusion") {
    const double d = seconds > 0 ? seconds : 4.0;
    b.s.interpolation = "linear";
    // A ball of 70 mm radius, 250 mm in front of the head, 10 mm above the eyes: seen from
    // the studio's camera (~520 mm away) it is wider than the face, so mid-pass it
    // hides every landmark and the tracker has to lose the face and recover (Sec. 7).
    b.Key(0, {{"occluder:x_mm", 300}, {"occluder:y_mm", 10}, {"occluder:z_mm", 250}, {"occluder:radius_mm", 70}});
    b.Key(0.35 * d, {{"occluder:x_mm", 150}});
    b.Key(0.65 * d, {{"occluder:x_mm", -150}});
    b.Key(d, {{"occluder:x_mm", -300}});
    b.Key(0, {{"expression:jawOpen", 0.1}, {"expression:mouthSmile", 0.2}});
    b.Key(d, {{"expression:jawOpen", 0.2}, {"expression:mouthSmile", 0.1}});
    return b.Done(d);
  }
  std::string names;
  for (const auto& n : SequencePresetNames()) names += (names.empty() ? "" : ", ") + n;
  throw Error(fmt::format("unknown sequence preset '{}' (presets: {})", preset, names));
}

// ---------------------------------------------------------------------------
// YAML

namespace {

double Number(const YAML::Node& n, const std::string& where) {
  try {
    return n.as<double>();
  } catch (const YAML::Exception&) {
    throw Error(fmt::format("{}: expected a number", where));
  }
}

void ReadGroup(const YAML::Node& node, const std::string& group, const std::vector<std::string>* allowed,
               const std::string& where, Keyframe* key) {
  if (!node) return;
  Require(node.IsMap(), fmt::format("{}.{}: expected a mapping of names to numbers", where, group));
  for (const auto& kv : node) {
    const std::string field = kv.first.as<std::string>();
    if (allowed && std::find(allowed->begin(), allowed->end(), field) == allowed->end()) {
      std::string list;
      for (const auto& a : *allowed) list += (list.empty() ? "" : ", ") + a;
      throw Error(fmt::format("{}.{}: unknown field '{}' (fields: {})", where, group, field, list));
    }
    key->values[group + ":" + field] = Number(kv.second, fmt::format("{}.{}.{}", where, group, field));
  }
}

}  // namespace

namespace {

Sequence SequenceFromYaml(const YAML::Node& root, const std::string& what) {
  Require(root.IsMap(), fmt::format("{}: a sequence must be a YAML mapping with 'keys'", what));
  static const std::set<std::string> top = {"name", "fps", "duration_s", "interpolation", "motion_blur", "keys"};
  for (const auto& kv : root) {
    const std::string k = kv.first.as<std::string>();
    Require(top.count(k) > 0, fmt::format("{}: unknown field '{}' (fields: name, fps, duration_s, interpolation, "
                                          "motion_blur, keys)", what, k));
  }
  Sequence s;
  s.name = root["name"] ? root["name"].as<std::string>() : std::filesystem::path(what).stem().string();
  if (root["fps"]) s.fps = Number(root["fps"], what + ": fps");
  if (root["interpolation"]) s.interpolation = root["interpolation"].as<std::string>();
  if (root["motion_blur"]) {
    try {
      s.motion_blur = root["motion_blur"].as<bool>();
    } catch (const YAML::Exception&) {
      throw Error(fmt::format("{}: motion_blur must be true or false", what));
    }
  }
  const YAML::Node keys = root["keys"];
  Require(keys && keys.IsSequence() && keys.size() > 0, fmt::format("{}: 'keys' must be a non-empty list", what));
  for (size_t i = 0; i < keys.size(); ++i) {
    const std::string where = fmt::format("{}: keys[{}]", what, i);
    const YAML::Node k = keys[i];
    Require(k.IsMap(), where + ": expected a mapping");
    for (const auto& kv : k) {
      const std::string f = kv.first.as<std::string>();
      Require(f == "t" || f == "expression" || f == "pose" || f == "light" || f == "occluder",
              fmt::format("{}: unknown field '{}' (fields: t, expression, pose, light, occluder)", where, f));
    }
    Require(static_cast<bool>(k["t"]), where + ": missing time 't'");
    Keyframe key;
    key.t = Number(k["t"], where + ".t");
    ReadGroup(k["expression"], "expression", nullptr, where, &key);
    ReadGroup(k["pose"], "pose", &PoseFields(), where, &key);
    ReadGroup(k["light"], "light", &LightFields(), where, &key);
    ReadGroup(k["occluder"], "occluder", &OccluderFields(), where, &key);
    s.keys.push_back(std::move(key));
  }
  s.duration_s = root["duration_s"] ? Number(root["duration_s"], what + ": duration_s") : s.keys.back().t;
  s.Validate(what);
  return s;
}

}  // namespace

Sequence ParseSequenceYaml(const std::string& text, const std::string& what) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}: malformed YAML: {}", what, e.what()));
  }
  try {
    return SequenceFromYaml(root, what);
  } catch (const YAML::Exception& e) {
    // A list or mapping where a name or string belongs ("name: [a]", "[k]: 1"): yaml-cpp's
    // bad conversion, an internal error before (found by fuzz/sequence_yaml_fuzzer, issue 19).
    throw Error(fmt::format("{}:{}:{}: expected a single value here, not a list or mapping ({})", what,
                            e.mark.line + 1, e.mark.column + 1, e.msg));
  }
}

Sequence ReadSequenceYaml(const std::filesystem::path& path) {
  return ParseSequenceYaml(ReadFileToString(path), path.string());
}

std::string SequenceToYaml(const Sequence& s) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << s.name << YAML::Key << "fps" << YAML::Value
      << s.fps << YAML::Key << "duration_s" << YAML::Value << s.duration_s << YAML::Key << "interpolation"
      << YAML::Value << s.interpolation << YAML::Key << "motion_blur" << YAML::Value << s.motion_blur
      << YAML::Key << "keys" << YAML::Value << YAML::BeginSeq;
  for (const auto& k : s.keys) {
    out << YAML::BeginMap << YAML::Key << "t" << YAML::Value << k.t;
    for (const char* group : {"expression", "pose", "light", "occluder"}) {
      bool open = false;
      for (const auto& [channel, v] : k.values) {
        if (channel.rfind(std::string(group) + ":", 0) != 0) continue;
        if (!open) {
          out << YAML::Key << group << YAML::Value << YAML::BeginMap;
          open = true;
        }
        out << YAML::Key << channel.substr(channel.find(':') + 1) << YAML::Value << v;
      }
      if (open) out << YAML::EndMap;
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

std::vector<double> ExpressionWeightsForRig(const SequenceFrame& frame, const FaceRig& rig) {
  std::vector<double> w(rig.num_expressions(), 0.0);
  for (const auto& [name, value] : frame.expression) {
    const int i = rig.ExpressionIndex(name);
    if (i >= 0) {
      w[i] = std::max(w[i], value);
      continue;
    }
    const int l = rig.ExpressionIndex(name + "_L"), r = rig.ExpressionIndex(name + "_R");
    if (l >= 0 && r >= 0) {
      w[l] = std::max(w[l], value);
      w[r] = std::max(w[r], value);
      continue;
    }
    std::string known;
    for (const auto& n : rig.expression_names) known += (known.empty() ? "" : ", ") + n;
    throw Error(fmt::format("the sequence uses expression '{}', which the rig lacks (neither '{}' nor '{}_L'/'{}_R'; "
                            "the rig has: {})", name, name, name, name, known));
  }
  return w;
}

}  // namespace crease
