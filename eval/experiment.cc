#include "eval/experiment.h"

#include <signal.h>
#include <sys/prctl.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <condition_variable>
#include <fstream>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "core/error.h"
#include "core/file_lock.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "eval/capture_metrics.h"
#include "eval/slurm.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/tracker_training.h"
#include "pipeline/training/trainer.h"
#include "synth/actor.h"
#include "synth/dataset.h"
#include "synth/studio_rig.h"
#include "synth/sequence.h"
#include "synth/studio.h"

extern char** environ;

namespace crease {

namespace fs = std::filesystem;
using json = nlohmann::json;

void ExperimentDataset::VisitFields(OptionVisitor& v) {
  v.Field("training_actors", training_actors);
  v.Field("training_seed", training_seed);
  v.Field("scan_cameras", scan_cameras);
  v.Field("scan_lights", scan_lights);
  v.Field("scan_expressions", scan_expressions);
  v.Field("scan_expression_count", scan_expression_count);
  v.Field("scan_samples", scan_samples);
  v.Field("capture", capture);
  v.Field("test_actors", test_actors);
  v.Field("test_seed", test_seed);
  v.Field("preset", preset);
  v.Field("seconds", seconds);
  v.Field("frames", frames);
  v.Field("light", light);
  v.Field("landmarks", landmarks);
  v.Field("landmark_noise_px", landmark_noise_px);
  v.Field("tracker_seed", tracker_seed);
  v.Field("mesh_every", mesh_every);
  v.Field("exclusive_capture", exclusive_capture);
  v.Field("cache_salt", cache_salt);
  v.Field("scan_size", scan_size);
  v.Field("leave_one_actor_out", leave_one_actor_out);
  v.Field("loao_regressors", loao_regressors);
  v.Field("patch_sites", patch_sites);
  v.Field("truth_detail", truth_detail);
  v.Field("truth_targets", truth_targets);
}

void ExperimentDataset::Check() const {
  CheckGe("dataset", "training_actors", training_actors, 1);
  CheckGe("dataset", "training_seed", static_cast<double>(training_seed), 0);
  CheckGe("dataset", "scan_cameras", scan_cameras, 1);
  Require(!scan_lights.empty(), "dataset.scan_lights must name at least one light rig");
  CheckGe("dataset", "scan_samples", scan_samples, 1);
  CheckGe("dataset", "scan_expression_count", scan_expression_count, 0);
  if (scan_expression_count > 0) {
    const size_t available = scan_expressions.empty() ? ScanSetOptions().expressions.size() : scan_expressions.size();
    CheckLe("dataset", "scan_expression_count", scan_expression_count, static_cast<double>(available));
  }
  CheckGe("dataset", "test_actors", test_actors, 1);
  CheckGe("dataset", "test_seed", static_cast<double>(test_seed), 0);
  CheckOneOf("dataset", "preset", preset, SequencePresetNames());
  CheckGe("dataset", "seconds", seconds, 0.0);
  CheckGe("dataset", "landmark_noise_px", landmark_noise_px, 0.0);
  CheckGe("dataset", "mesh_every", mesh_every, 0);
  if (!scan_size.empty()) {
    int w = 0, h = 0;
    char x = 0;
    std::istringstream in(scan_size);
    Require(static_cast<bool>(in >> w >> x >> h) && x == 'x' && w > 0 && h > 0 && in.peek() == EOF,
            fmt::format("dataset.scan_size = '{}': expected WIDTHxHEIGHT, e.g. 1280x720", scan_size));
  }
  Require(!loao_regressors.empty(), "dataset.loao_regressors must name at least one regressor");
  for (const auto& r : loao_regressors) CheckOneOf("dataset", "loao_regressors", r, EnumNames<PatchRegressor>());
}

namespace {

// Validates a section's JSON object by setting it on a default Options struct
// (unknown keys and wrong types throw naming `what` and the key).
template <class Options>
void ValidateAs(const json& j, const std::string& what) {
  Options o;
  SetOptionsFromJson(j.dump(), what, &o);
}

// A section's options at their defaults, as JSON.
template <class Options>
json DefaultsOf() {
  static const json defaults = json::parse(OptionsToJson(Options()));  // once per section type
  return defaults;
}

struct SectionInfo {
  const char* name;
  void (*validate)(const json&, const std::string&);
  json (*defaults)();
};

const std::vector<SectionInfo>& Sections() {
  static const std::vector<SectionInfo> s = {
      {"dataset", &ValidateAs<ExperimentDataset>, &DefaultsOf<ExperimentDataset>},     {"rig", &ValidateAs<StudioRigOptions>, &DefaultsOf<StudioRigOptions>},
      {"actor", &ValidateAs<ActorOptions>, &DefaultsOf<ActorOptions>},            {"test_actor", &ValidateAs<ActorOptions>, &DefaultsOf<ActorOptions>},
      {"studio", &ValidateAs<StudioOptions>, &DefaultsOf<StudioOptions>},          {"training", &ValidateAs<TrainingOptions>, &DefaultsOf<TrainingOptions>},
      {"tracker", &ValidateAs<TrackerTrainingOptions>, &DefaultsOf<TrackerTrainingOptions>}, {"capture", &ValidateAs<CaptureOptions>, &DefaultsOf<CaptureOptions>},
      {"eval", &ValidateAs<CaptureEvalOptions>, &DefaultsOf<CaptureEvalOptions>},
  };
  return s;
}

const SectionInfo& FindSection(const std::string& name, const std::string& what) {
  for (const auto& s : Sections())
    if (name == s.name) return s;
  std::vector<std::string> names;
  for (const auto& s : Sections()) names.emplace_back(s.name);
  throw Error(fmt::format("{}: unknown section '{}' (sections: {})", what, name, fmt::join(names, ", ")));
}

// "section.field" → (section, field); errors name `what`.
std::pair<std::string, std::string> SplitKey(const std::string& key, const std::string& what) {
  const auto dot = key.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == key.size())
    throw Error(fmt::format("{}: '{}' must be SECTION.FIELD (e.g. training.ferns.num_ferns)", what, key));
  return {key.substr(0, dot), key.substr(dot + 1)};
}

// A section's options with dotted keys (core/options.h: the canonical form that
// cache keys and --set take); nested sections and keys set twice are resolved here.
json FlatOptions(const json& j, const std::string& what) { return json::parse(FlattenOptionKeys(j.dump(), what)); }

// Sets section.field = value on `config` and validates the section. The field may
// be dotted (capture.refinement.lk_window) and the value a mapping of a section.
void SetDotted(ExperimentConfig* config, const std::string& key, const json& value, const std::string& what) {
  const auto [section, field] = SplitKey(key, what);
  const SectionInfo& info = FindSection(section, fmt::format("{} ('{}')", what, key));
  json& obj = config->sections[section];
  if (!obj.is_object()) obj = json::object();
  json trial = obj;
  const json flat = FlatOptions(json{{field, value}}, what);
  for (const auto& [k, v] : flat.items()) trial[k] = v;
  info.validate(trial, fmt::format("{} ('{}')", what, key));
  obj = std::move(trial);
}

ExperimentDataset DatasetOf(const ExperimentConfig& c) {
  ExperimentDataset d;
  const auto it = c.sections.find("dataset");
  if (it != c.sections.end()) SetOptionsFromJson(it->second.dump(), "dataset", &d);
  return d;
}

json SectionOf(const ExperimentConfig& c, const std::string& name) {
  const auto it = c.sections.find(name);
  return it == c.sections.end() ? json::object() : it->second;
}

// A section as it enters cache keys: the options that differ from their defaults,
// so a sweep value equal to the default (the paper's K = 1280 in a sweep of F) is
// the same stage as leaving it unset.
json KeySectionOf(const ExperimentConfig& c, const std::string& name) {
  json section = SectionOf(c, name);
  const json defaults = FindSection(name, "experiment").defaults();
  for (auto it = section.begin(); it != section.end();) {
    if (defaults.contains(it.key()) && defaults[it.key()] == it.value()) {
      it = section.erase(it);
    } else {
      ++it;
    }
  }
  return section;
}

std::string ValueText(const json& v) {
  if (v.is_string()) {
    const std::string s = v.get<std::string>();
    // Plain when --set would read it back as this string; JSON-quoted otherwise.
    const json back = json::parse(s, nullptr, false);
    if (back.is_discarded() && s.find_first_of(" \t\n'\"") == std::string::npos) return s;
  }
  return v.dump();
}

// --set KEY=VALUE for every field of a section (sorted keys: stable commands).
void AppendSets(const json& section, std::vector<std::string>* argv) {
  for (const auto& [k, v] : section.items()) {
    argv->push_back("--set");
    argv->push_back(k + "=" + ValueText(v));
  }
}

std::string Join(const std::vector<std::string>& v, const char* sep) { return fmt::format("{}", fmt::join(v, sep)); }

// One sweep value: `key` is a group of c.variants (value: a label, whose settings
// are applied in order) or a section.field.
void SetSweepValue(ExperimentConfig* config, const std::string& key, const json& value, const std::string& what) {
  if (!config->variants.contains(key)) {
    SetDotted(config, key, value, what);
    return;
  }
  const json& group = config->variants.at(key);
  if (!value.is_string() || !group.contains(value.get<std::string>())) {
    std::vector<std::string> labels;
    for (const auto& [label, settings] : group.items()) labels.push_back(label);
    throw Error(fmt::format("{}: {} is not a variant of '{}' (variants: {})", what, value.dump(), key, Join(labels, ", ")));
  }
  for (const auto& [k, v] : group.at(value.get<std::string>()).items())
    SetDotted(config, k, v, fmt::format("{} (variant {}={})", what, key, value.get<std::string>()));
}

}  // namespace

std::string ShellQuote(const std::string& s, bool always) {
  if (!always && !s.empty() &&
      s.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-.,/=:+@%") ==
          std::string::npos)
    return s;
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string ExperimentCommandLine(const std::vector<std::string>& argv) {
  std::string out = "crease";
  for (const auto& a : argv) {
    out += ' ';
    out += ShellQuote(a);
  }
  return out;
}

namespace {

std::string SanitizeId(const std::string& s) {
  std::string out;
  for (char c : s) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '=' || c == '-' || c == '_') ? c : '-';
  return out;
}

}  // namespace

const std::vector<std::string>& ExperimentSections() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto& s : Sections()) n.emplace_back(s.name);
    return n;
  }();
  return names;
}

namespace {

ExperimentConfig ParseExperimentConfigImpl(const std::string& yaml_text, const std::string& what) {
  const std::string text = YamlToJsonText(yaml_text, what);
  const json j = json::parse(text);
  const nlohmann::ordered_json ordered = nlohmann::ordered_json::parse(text);  // the sweep keeps its order
  Require(j.is_object(), fmt::format("{}: an experiment config must be a YAML mapping", what));
  ExperimentConfig c;
  static const std::set<std::string> kText = {"name", "title", "paper", "description"};
  static const std::set<std::string> kReport = {"table", "figures", "claims"};
  for (const auto& [key, value] : j.items()) {
    if (kText.count(key)) {
      Require(value.is_string(), fmt::format("{}: '{}' must be text", what, key));
      const std::string s = value.get<std::string>();
      if (key == "name") c.name = s;
      if (key == "title") c.title = s;
      if (key == "paper") c.paper = s;
      if (key == "description") c.description = s;
    } else if (key == "seeds") {
      Require(value.is_number_integer() && value.get<int>() >= 1, fmt::format("{}: 'seeds' must be an integer ≥ 1", what));
      c.seeds = value.get<int>();
    } else if (kReport.count(key)) {
      c.report[key] = value;
    } else if (key == "variants") {
      Require(value.is_object(), fmt::format("{}: 'variants' must map a group to its labelled settings", what));
      for (const auto& [group, labels] : value.items()) {
        Require(labels.is_object() && !labels.empty(),
                fmt::format("{}: variants.{} must map each label to its settings", what, group));
        for (const auto& [label, settings] : labels.items()) {
          Require(settings.is_object(), fmt::format("{}: variants.{}.{} must map SECTION.FIELD to a value", what,
                                                    group, label));
          ExperimentConfig trial = c;
          for (const auto& [k, v] : settings.items())
            SetDotted(&trial, k, v, fmt::format("{}: variants.{}.{}", what, group, label));
        }
      }
      c.variants = value;
    } else if (key == "slurm") {
      CheckSlurmSection(value, what);
      c.slurm = value;
    } else if (key == "profiles") {
      Require(value.is_object(), fmt::format("{}: 'profiles' must map a profile name to its settings", what));
      c.profiles = value;
    } else if (key == "sweep") {
      Require(value.is_object(), fmt::format("{}: 'sweep' must be a mapping (mode, values)", what));
      for (const auto& [sk, sv] : value.items()) {
        if (sk == "mode") {
          Require(sv.is_string(), fmt::format("{}: sweep.mode must be none, list or grid", what));
          c.sweep.mode = sv.get<std::string>();
          CheckOneOf("sweep", "mode", c.sweep.mode, {"none", "list", "grid"});
        } else if (sk == "values") {
          Require(sv.is_object(), fmt::format("{}: sweep.values must map SECTION.FIELD to a list", what));
          for (const auto& [k, v] : ordered["sweep"]["values"].items()) c.sweep.values.emplace_back(k, json::parse(v.dump()));
        } else {
          throw Error(fmt::format("{}: unknown sweep key '{}' (mode, values)", what, sk));
        }
      }
    } else {
      bool known = false;
      for (const auto& s : Sections()) known = known || key == s.name;
      if (!known)
        throw Error(fmt::format("{}: unknown key '{}' (name, title, paper, description, seeds, sweep, profiles, slurm, "
                                "table, figures, claims, or a section: {})",
                                what, key, Join(ExperimentSections(), ", ")));
      Require(value.is_object() || value.is_null(), fmt::format("{}: section '{}' must be a mapping", what, key));
      const json obj = value.is_null() ? json::object() : FlatOptions(value, fmt::format("{} (section {})", what, key));
      FindSection(key, what).validate(obj, fmt::format("{} (section {})", what, key));
      c.sections[key] = obj;
    }
  }
  Require(!c.name.empty(), fmt::format("{}: the config has no 'name'", what));
  if (c.title.empty()) c.title = c.name;
  if (c.sweep.mode == "none" && !c.sweep.values.empty()) c.sweep.mode = "list";
  // Check the sweep keys and values, the dataset as a whole and every profile now,
  // so that a bad config fails before anything runs.
  for (const auto& [key, values] : c.sweep.values) {
    Require(values.is_array() && !values.empty(),
            fmt::format("{}: sweep value '{}' must be a non-empty list", what, key));
    for (const auto& v : values) {
      ExperimentConfig trial = c;
      SetSweepValue(&trial, key, v, fmt::format("{}: sweep", what));
    }
  }
  DatasetOf(c);
  for (const auto& [name, p] : c.profiles.items()) ApplyProfile(c, name);
  return c;
}

}  // namespace

ExperimentConfig ParseExperimentConfig(const std::string& yaml_text, const std::string& what) {
  try {
    return ParseExperimentConfigImpl(yaml_text, what);
  } catch (const Error& e) {
    // Every message names the config (option checks name only the field).
    const std::string m = e.what();
    if (m.rfind(what, 0) == 0) throw;
    throw Error(fmt::format("{}: {}", what, m));
  }
}

ExperimentConfig ReadExperimentConfig(const fs::path& path) {
  ExperimentConfig c = ParseExperimentConfig(ReadFileToString(path), path.string());
  c.source = path;
  return c;
}

std::vector<fs::path> ListExperimentConfigs(const fs::path& dir) {
  Require(fs::is_directory(dir), fmt::format("{}: no experiments folder (set CREASE_SOURCE_DIR to the crease "
                                             "source tree)", dir.string()));
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".yaml") all.push_back(e.path());
  std::sort(all.begin(), all.end());
  std::vector<fs::path> ordered;
  std::ifstream order(dir / "ORDER");
  std::string name;
  while (order >> name) {
    const fs::path p = dir / (name + ".yaml");
    if (std::find(all.begin(), all.end(), p) != all.end()) ordered.push_back(p);
  }
  for (const auto& p : all)
    if (std::find(ordered.begin(), ordered.end(), p) == ordered.end()) ordered.push_back(p);
  return ordered;
}

fs::path ResolveExperimentConfig(const std::string& name, const fs::path& dir) {
  if (fs::exists(name) && fs::is_regular_file(name)) return name;
  const fs::path p = dir / (name + ".yaml");
  if (fs::exists(p)) return p;
  std::vector<std::string> names;
  for (const auto& c : ListExperimentConfigs(dir)) names.push_back(c.stem().string());
  throw Error(fmt::format("experiment '{}': no such config file or experiment (known: {}, all)", name,
                          fmt::join(names, ", ")));
}

ExperimentConfig ApplyProfile(const ExperimentConfig& config, const std::string& profile) {
  if (profile.empty()) return config;
  const std::string what = fmt::format("{}: profile '{}'", config.source.empty() ? config.name : config.source.string(), profile);
  ExperimentConfig c = config;
  if (!config.profiles.contains(profile)) {
    // A profile the config does not mention leaves it as it is (its defaults are
    // what that profile runs), unless the name is not a profile at all.
    CheckOneOf("experiment", "profile", profile, {"quick", "paper"});
    return c;
  }
  const json& p = config.profiles.at(profile);
  Require(p.is_object(), fmt::format("{} must be a mapping (set, sweep, seeds)", what));
  for (const auto& [k, v] : p.items()) {
    if (k == "set") {
      Require(v.is_object(), fmt::format("{}: 'set' must map SECTION.FIELD to a value", what));
      for (const auto& [key, value] : v.items()) SetDotted(&c, key, value, what);
    } else if (k == "sweep") {
      Require(v.is_object(), fmt::format("{}: 'sweep' must map SECTION.FIELD to a list", what));
      for (const auto& [key, values] : v.items()) {
        Require(values.is_array() && !values.empty(), fmt::format("{}: sweep '{}' must be a non-empty list", what, key));
        for (const auto& value : values) {
          ExperimentConfig trial = c;
          SetSweepValue(&trial, key, value, what + ": sweep");
        }
        auto it = std::find_if(c.sweep.values.begin(), c.sweep.values.end(), [&key = key](const auto& e) { return e.first == key; });  // clang 14: no capture of a binding
        if (it == c.sweep.values.end()) {
          c.sweep.values.emplace_back(key, values);
          if (c.sweep.mode == "none") c.sweep.mode = "list";
        } else {
          it->second = values;
        }
      }
    } else if (k == "seeds") {
      Require(v.is_number_integer() && v.get<int>() >= 1, fmt::format("{}: 'seeds' must be an integer ≥ 1", what));
      c.seeds = v.get<int>();
    } else {
      throw Error(fmt::format("{}: unknown key '{}' (set, sweep, seeds)", what, k));
    }
  }
  DatasetOf(c);
  return c;
}

std::vector<ExperimentRun> ExpandRuns(const ExperimentConfig& config) {
  std::vector<json> points;
  if (config.sweep.mode == "none" || config.sweep.values.empty()) {
    points.push_back(json::object());
  } else if (config.sweep.mode == "list") {
    for (const auto& [key, values] : config.sweep.values)
      for (const auto& v : values) points.push_back(json{{key, v}});
  } else {  // grid: the last key varies fastest
    points.push_back(json::object());
    for (const auto& [key, values] : config.sweep.values) {
      std::vector<json> next;
      for (const auto& p : points)
        for (const auto& v : values) {
          json q = p;
          q[key] = v;
          next.push_back(q);
        }
      points = std::move(next);
    }
  }
  std::vector<ExperimentRun> runs;
  for (const auto& point : points) {
    ExperimentConfig resolved = config;
    std::vector<std::string> parts;
    // In config order (json objects sort their keys; the sweep list keeps the order).
    for (const auto& [key, values] : config.sweep.values) {
      if (!point.contains(key)) continue;
      SetSweepValue(&resolved, key, point.at(key), "sweep");
      parts.push_back(key + "=" + ValueText(point.at(key)));
    }
    const std::string base = parts.empty() ? "base" : Join(parts, "_");
    for (int s = 1; s <= config.seeds; ++s) {
      ExperimentRun r;
      r.seed = s;
      r.point = point;
      r.resolved = resolved;
      r.id = SanitizeId(fmt::format("{}_seed{}", base, s));
      runs.push_back(std::move(r));
    }
  }
  std::set<std::string> ids;
  for (const auto& r : runs)
    Require(ids.insert(r.id).second,
            fmt::format("{}: two runs share the id '{}' (a sweep lists a value twice?)", config.name, r.id));
  return runs;
}

std::vector<ExperimentRun> ShardRuns(const std::vector<ExperimentRun>& runs, int shard, int num_shards) {
  Require(num_shards >= 1 && shard >= 0 && shard < num_shards,
          fmt::format("--shard {}/{}: expected I/N with 1 ≤ I ≤ N", shard + 1, num_shards));
  std::vector<ExperimentRun> out;
  for (size_t i = static_cast<size_t>(shard); i < runs.size(); i += static_cast<size_t>(num_shards))
    out.push_back(runs[i]);
  return out;
}

namespace {

// The crease version at which each kind of stage last changed what it writes
// (StageVersions; the rule is in experiment.h). 0.4.8, 0.4.9, 0.4.10, 0.4.13 and
// 0.4.14 changed the eval alone (the band normal error, D^HF against the albedo's,
// the displacement by wrinkle region, the truth slid on the face, the still face
// split by the held truth and pooled). 0.4.14 also changed the capture's summary
// (frames overlapped on the cores: its fps is the wall clock; D^t and every other
// output unchanged).
constexpr std::pair<const char*, const char*> kStageCodeVersions[] = {
    {"rig", "0.4.7"},      {"scans", "0.4.7"},    {"pairs", "0.4.7"},      {"model", "0.4.7"},
    {"loao", "0.4.7"},     {"tracker", "0.4.7"},  {"actor", "0.4.7"},      {"sequence", "0.4.17"},
    {"truth-maps", "0.4.7"}, {"capture", "0.4.18"}, {"eval", "0.4.18"}, {"scan-truth", "0.4.16"},
};

}  // namespace

const std::string& StageVersions::Of(const std::string& kind) const {
  const auto it = by_kind.find(kind);
  if (it != by_kind.end()) return it->second;
  Require(!all.empty(), fmt::format("no cache-key version for stage kind '{}' (kStageCodeVersions, "
                                    "eval/experiment.cc)", kind));
  return all;
}

StageVersions CurrentStageVersions() {
  StageVersions v;
  for (const auto& [kind, version] : kStageCodeVersions) v.by_kind[kind] = version;
  return v;
}

std::string ExperimentKey(const json& j) {
  const std::string s = j.dump();
  uint64_t h = 1469598103934665603ull;  // FNV-1a, 64 bit
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return fmt::format("{:016x}", h);
}

namespace {

using ArgvOfDir = std::function<std::vector<std::string>(const fs::path&)>;

// The stages of one run under construction.
struct RunPlan {
  const ExperimentConfig& c;
  ExperimentDataset d;
  int64_t seed_offset = 0;  // added to the dataset's seeds: 1000 per seed of the run after the first
  fs::path cache;
  const StageVersions& versions;
  std::vector<ExperimentStage> stages;

  // Adds a stage whose key hashes `inputs` with its kind, the kind's version, the
  // cache salt and the keys it `depends` on; `argv` gets the stage's folder.
  const ExperimentStage& Add(const std::string& kind, json inputs, std::vector<std::string> depends,
                             const ArgvOfDir& argv) {
    inputs["stage"] = kind;
    inputs["crease"] = versions.Of(kind);
    inputs["salt"] = d.cache_salt;
    inputs["depends"] = depends;
    ExperimentStage s;
    s.kind = kind;
    s.key = ExperimentKey(inputs);
    s.key_inputs = std::move(inputs);
    s.dir = cache / kind / s.key;
    s.argv = argv(s.dir);
    s.depends = std::move(depends);
    s.slurm = c.slurm;
    stages.push_back(std::move(s));
    return stages.back();
  }
};

fs::path RigFile(const ExperimentStage& rig) { return rig.dir / "rig.crig"; }

ExperimentStage PlanRigStage(RunPlan& p) {
  const ExperimentConfig& c = p.c;
  return p.Add("rig", {{"rig", KeySectionOf(c, "rig")}}, {}, [&](const fs::path& dir) {
    std::vector<std::string> a = {"synth", "rig", "-o", (dir / "rig.crig").string()};
    AppendSets(SectionOf(c, "rig"), &a);
    return a;
  });
}

// The training scans of the run's training actors.
ExperimentStage PlanScanStage(RunPlan& p, const ExperimentStage& rig) {
  const ExperimentConfig& c = p.c;
  const ExperimentDataset& d = p.d;
  const fs::path rig_file = RigFile(rig);
  const int64_t training_seed = d.training_seed + p.seed_offset;
  std::vector<std::string> expressions = d.scan_expressions;
  // The first N expressions (all N of the list: the same scans, the same key).
  const size_t listed = expressions.empty() ? ScanSetOptions().expressions.size() : expressions.size();
  if (d.scan_expression_count > 0 && static_cast<size_t>(d.scan_expression_count) < listed) {
    if (expressions.empty()) expressions = ScanSetOptions().expressions;
    expressions.resize(static_cast<size_t>(d.scan_expression_count));
  }
  json scan_inputs = {{"actor", KeySectionOf(c, "actor")},
                      {"actors", d.training_actors},
                      {"seed", training_seed},
                      {"cameras", d.scan_cameras},
                      {"lights", d.scan_lights},
                      {"expressions", expressions},
                      {"samples", d.scan_samples}};
  if (!d.scan_size.empty()) scan_inputs["size"] = d.scan_size;  // (absent: the keys of earlier caches)
  return p.Add(
      "scans", scan_inputs, {rig.key}, [&](const fs::path& dir) {
        std::vector<std::string> a = {"synth",     "scans",  "--rig",     rig_file.string(),
                                      "--actors",  std::to_string(d.training_actors),
                                      "--seed",    std::to_string(training_seed),
                                      "--cameras", std::to_string(d.scan_cameras),
                                      "--lights",  Join(d.scan_lights, ","),
                                      "--samples", std::to_string(d.scan_samples)};
        if (!d.scan_size.empty()) a.insert(a.end(), {"--size", d.scan_size});
        for (const auto& e : expressions) {
          a.push_back("-e");
          a.push_back(e);
        }
        AppendSets(SectionOf(c, "actor"), &a);
        a.insert(a.end(), {"--overwrite", "-o", (dir / "scans").string()});
        return a;
      });
}

// Training in two stages: the pairs (Sec. 4.1–4.2, ~99 % of the time) and the
// regression (Sec. 4.3), so that sweeps over the PCA dimension or the cascade's
// K, F, P, β share the extraction; and, if asked, leave-one-actor-out on the
// pairs. Returns the model stage.
ExperimentStage PlanTrainingStages(RunPlan& p, const ExperimentStage& rig, const ExperimentStage& scans) {
  const ExperimentConfig& c = p.c;
  const ExperimentDataset& d = p.d;
  const fs::path rig_file = RigFile(rig);
  const auto split_regression = [](json* extraction, json* regression) {
    for (const auto& name : RegressionOptionNames()) {
      if (!extraction->contains(name)) continue;
      (*regression)[name] = (*extraction)[name];
      extraction->erase(name);
    }
  };
  json extraction = SectionOf(c, "training"), regression = json::object();
  split_regression(&extraction, &regression);
  json extraction_key = KeySectionOf(c, "training"), regression_key = json::object();
  split_regression(&extraction_key, &regression_key);
  // dataset.truth_targets: each scan's D* (crease eval-extraction --write-truth with
  // the extraction's options) as the targets.
  json pairs_inputs = {{"training", extraction_key}};
  std::vector<std::string> pairs_depends = {rig.key, scans.key};
  fs::path target_maps;
  if (d.truth_targets) {
    const ExperimentStage truth =
        p.Add("scan-truth", {{"training", extraction_key}}, {rig.key, scans.key}, [&](const fs::path& dir) {
          std::vector<std::string> a = {"eval-extraction", "--scans", (scans.dir / "scans").string(), "--write-truth",
                                        (dir / "maps").string(), "--json", (dir / "extraction.json").string()};
          AppendSets(extraction, &a);
          return a;
        });
    pairs_inputs["truth_targets"] = true;
    pairs_depends.push_back(truth.key);
    target_maps = truth.dir / "maps";
  }
  const ExperimentStage pairs = p.Add("pairs", pairs_inputs, pairs_depends, [&](const fs::path& dir) {
    std::vector<std::string> a = {"train",        "--scans",  (scans.dir / "scans").string(),
                                  "--rig",        rig_file.string(),
                                  "--save-pairs", (dir / "pairs.cpr").string(),
                                  "--report",     (dir / "report").string()};
    AppendSets(extraction, &a);
    if (!target_maps.empty())
      a.insert(a.end(), {"--set", "training_targets=maps", "--set", "target_maps=" + target_maps.string()});
    return a;
  });
  const ExperimentStage model =
      p.Add("model", {{"training", regression_key}}, {pairs.key}, [&](const fs::path& dir) {
        std::vector<std::string> a = {"train", "--pairs", (pairs.dir / "pairs.cpr").string(), "--out",
                                      (dir / "model.cdm").string(), "--report", (dir / "report").string()};
        AppendSets(regression, &a);
        return a;
      });
  if (d.leave_one_actor_out) {
    p.Add("loao", {{"training", regression_key}, {"regressors", d.loao_regressors}}, {pairs.key},
          [&](const fs::path& dir) {
            std::vector<std::string> a = {"model", "loao", "--pairs", (pairs.dir / "pairs.cpr").string(), "--regressors",
                                          Join(d.loao_regressors, ","), "--json", (dir / "loao.json").string()};
            AppendSets(regression, &a);
            return a;
          });
  }
  return model;
}

// The landmark regressor for capture (landmarks: regressor); returns its key and
// file, empty for the other landmark sources.
std::pair<std::string, fs::path> PlanTrackerStage(RunPlan& p, const ExperimentStage& rig) {
  const ExperimentConfig& c = p.c;
  const ExperimentDataset& d = p.d;
  const fs::path rig_file = RigFile(rig);
  if (d.landmarks != ExperimentLandmarks::kRegressor) return {};
  const ExperimentStage tracker = p.Add("tracker", {{"tracker", KeySectionOf(c, "tracker")}, {"seed", d.tracker_seed}},
                                        {rig.key}, [&](const fs::path& dir) {
                                          std::vector<std::string> a = {"train-tracker", "--rig", rig_file.string(),
                                                                        "-o", (dir / "tracker.ctrk").string(),
                                                                        "--seed", std::to_string(d.tracker_seed)};
                                          AppendSets(SectionOf(c, "tracker"), &a);
                                          return a;
                                        });
  return {tracker.key, tracker.dir / "tracker.ctrk"};
}

// Test actor `i` and its sequence; returns the sequence stage.
ExperimentStage PlanSequenceStages(RunPlan& p, const ExperimentStage& rig, int i) {
  const ExperimentConfig& c = p.c;
  const ExperimentDataset& d = p.d;
  const fs::path rig_file = RigFile(rig);
  const int64_t actor_seed = d.test_seed + p.seed_offset + i;
  const ExperimentStage actor =
      p.Add("actor", {{"actor", KeySectionOf(c, "test_actor")}, {"seed", actor_seed}}, {rig.key}, [&](const fs::path& dir) {
        std::vector<std::string> a = {"synth", "actor", "--rig", rig_file.string(), "--seed", std::to_string(actor_seed),
                                      "-o", (dir / "actor.json").string()};
        AppendSets(SectionOf(c, "test_actor"), &a);
        return a;
      });
  return p.Add(
      "sequence",
      {{"studio", KeySectionOf(c, "studio")},
       {"preset", d.preset},
       {"seconds", d.seconds},
       {"frames", d.frames},
       {"light", d.light}},
      {rig.key, actor.key}, [&](const fs::path& dir) {
        std::vector<std::string> a = {"synth", "sequence", "--rig", rig_file.string(), "--actor",
                                      (actor.dir / "actor.json").string(), "--preset", d.preset};
        if (d.seconds > 0) a.insert(a.end(), {"--seconds", fmt::format("{}", d.seconds)});
        if (d.frames >= 0) a.insert(a.end(), {"--frames", std::to_string(d.frames)});
        if (!d.light.empty()) a.insert(a.end(), {"--light", d.light});
        AppendSets(SectionOf(c, "studio"), &a);
        a.insert(a.end(), {"--overwrite", "-o", (dir / "dataset").string()});
        return a;
      });
}

// The true detail D* of the sequence's first `frames` frames (−1: all) with the
// model's G (rung R1: of the wrinkle frames; R2-oracle: of all); returns its key and
// folder.
std::pair<std::string, fs::path> PlanTruthMapsStage(RunPlan& p, const ExperimentStage& model,
                                                    const ExperimentStage& sequence, int frames) {
  const ExperimentStage& maps =
      p.Add("truth-maps", {{"frames", frames}}, {model.key, sequence.key}, [&](const fs::path& dir) {
        return std::vector<std::string>{"truth-maps", "-d", (sequence.dir / "dataset").string(), "-m",
                                        (model.dir / "model.cdm").string(), "--frames", std::to_string(frames),
                                        "-o", (dir / "maps").string()};
      });
  return {maps.key, maps.dir / "maps"};
}

// The capture of a test sequence (with the tracker `tracker`: key and file, if
// any) and its evaluation.
void PlanCaptureStages(RunPlan& p, const ExperimentStage& model, const ExperimentStage& sequence,
                       const std::pair<std::string, fs::path>& tracker) {
  const ExperimentConfig& c = p.c;
  const ExperimentDataset& d = p.d;
  std::vector<std::string> capture_depends = {model.key, sequence.key};
  if (!tracker.first.empty()) capture_depends.push_back(tracker.first);
  fs::path truth_maps;  // rung R1: the wrinkle map from the true detail of the wrinkle frames
  if (d.patch_sites == PatchSites::kTruth) {
    CaptureOptions capture_options;
    SetOptionsFromJson(SectionOf(c, "capture").dump(), "capture", &capture_options);
    const auto [maps_key, maps_dir] = PlanTruthMapsStage(p, model, sequence, capture_options.detail.wrinkle_frames);
    capture_depends.push_back(maps_key);
    truth_maps = maps_dir;
  }
  fs::path truth_detail;  // rung R2-oracle: D^t assembled from every frame's true detail
  if (d.truth_detail) {
    const auto [maps_key, maps_dir] = PlanTruthMapsStage(p, model, sequence, -1);
    capture_depends.push_back(maps_key);
    truth_detail = maps_dir;
  }
  json capture_inputs = {{"capture", KeySectionOf(c, "capture")},
                         {"landmarks", ToString(d.landmarks)},
                         {"noise", d.landmark_noise_px},
                         {"mesh_every", d.mesh_every}};
  if (d.exclusive_capture) capture_inputs["exclusive"] = true;  // its timings were taken alone
  if (d.patch_sites != PatchSites::kOwn) capture_inputs["patch_sites"] = ToString(d.patch_sites);
  if (d.truth_detail) capture_inputs["truth_detail"] = true;
  p.Add(
      "capture", capture_inputs,
      capture_depends, [&](const fs::path& dir) {
        std::vector<std::string> a = {"capture", "-i", (sequence.dir / "dataset").string(), "--model",
                                      (model.dir / "model.cdm").string()};
        if (d.landmarks == ExperimentLandmarks::kRegressor) {
          a.insert(a.end(), {"--tracker", tracker.second.string()});
        } else if (d.landmarks == ExperimentLandmarks::kDlib) {
          a.insert(a.end(), {"--landmarks", "dlib"});
        } else if (d.landmarks == ExperimentLandmarks::kGroundTruthFit) {
          a.push_back("--ground-truth-fit");
        } else if (d.landmarks == ExperimentLandmarks::kGroundTruthSurface) {
          a.push_back("--ground-truth-surface");
        } else {
          a.insert(a.end(), {"--ground-truth-prior", "--noise", fmt::format("{}", d.landmark_noise_px)});
        }
        if (d.mesh_every > 0) {
          a.insert(a.end(), {"--mesh-every", std::to_string(d.mesh_every)});
        } else {
          a.push_back("--no-meshes");
        }
        AppendSets(SectionOf(c, "capture"), &a);
        if (!truth_maps.empty()) a.insert(a.end(), {"--set", "wrinkle_map_from_maps=" + truth_maps.string()});
        if (!truth_detail.empty()) a.insert(a.end(), {"--set", "detail_from_truth_maps=" + truth_detail.string()});
        a.insert(a.end(), {"--overwrite", "-o", (dir / "capture").string()});
        return a;
      });
  p.stages.back().exclusive = d.exclusive_capture;
  const ExperimentStage capture = p.stages.back();
  p.Add("eval", {{"eval", KeySectionOf(c, "eval")}}, {capture.key, sequence.key}, [&](const fs::path& dir) {
    std::vector<std::string> a = {"eval", "--capture", (capture.dir / "capture").string(), "--dataset",
                                  (sequence.dir / "dataset").string(), "-o", dir.string()};
    AppendSets(SectionOf(c, "eval"), &a);
    return a;
  });
}

}  // namespace

std::vector<ExperimentStage> PlanRunStages(const ExperimentRun& run, const fs::path& cache,
                                           const StageVersions& versions) {
  RunPlan p{run.resolved, DatasetOf(run.resolved), 1000 * static_cast<int64_t>(run.seed - 1), cache, versions, {}};
  const ExperimentStage rig = PlanRigStage(p);
  const ExperimentStage scans = PlanScanStage(p, rig);
  const ExperimentStage model = PlanTrainingStages(p, rig, scans);
  if (!p.d.capture) return p.stages;
  const std::pair<std::string, fs::path> tracker = PlanTrackerStage(p, rig);
  for (int i = 0; i < p.d.test_actors; ++i) {
    const ExperimentStage sequence = PlanSequenceStages(p, rig, i);
    PlanCaptureStages(p, model, sequence, tracker);
  }
  return p.stages;
}

StageExecutor SubprocessExecutor(const fs::path& program) {
  return [program](const std::vector<std::string>& argv, const fs::path& log) -> int {
    std::vector<std::string> args = {program.string()};
    args.insert(args.end(), argv.begin(), argv.end());
    std::vector<char*> cargs;
    for (auto& a : args) cargs.push_back(a.data());
    cargs.push_back(nullptr);
    if (access(cargs[0], X_OK) != 0) {
      throw Error(fmt::format("cannot start {}: {}", program.string(), std::strerror(errno)));
    }
    const std::string log_path = log.string();
    // fork + exec rather than posix_spawn: the child asks to die with its parent
    // (prctl) before exec. Only async-signal-safe calls run between them.
    const pid_t parent = getpid();
    const int log_fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (log_fd < 0) throw Error(fmt::format("{}: cannot write the stage log: {}", log_path, std::strerror(errno)));
    const pid_t pid = fork();
    if (pid == 0) {
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (getppid() != parent) _exit(127);  // the runner died before prctl took effect
      const int null_fd = open("/dev/null", O_RDONLY);
      if (null_fd < 0 || dup2(null_fd, 0) < 0 || dup2(log_fd, 1) < 0 || dup2(log_fd, 2) < 0) _exit(127);
      execv(cargs[0], cargs.data());
      _exit(127);
    }
    const int fork_errno = errno;
    close(log_fd);
    if (pid < 0) throw Error(fmt::format("cannot start {}: {}", program.string(), std::strerror(fork_errno)));
    int status = 0;
    while (waitpid(pid, &status, 0) < 0) {
      if (errno != EINTR) throw Error(fmt::format("waiting for {}: {}", program.string(), std::strerror(errno)));
    }
    if (WIFEXITED(status)) return WEXITSTATUS(status);
    return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  };
}

namespace {

void Flatten(const json& j, const std::string& prefix, json* out) {
  if (j.is_object()) {
    for (const auto& [k, v] : j.items()) Flatten(v, prefix.empty() ? k : prefix + "." + k, out);
  } else if (j.is_number()) {
    (*out)[prefix] = j;
  } else if (j.is_boolean()) {
    (*out)[prefix] = j.get<bool>() ? 1 : 0;
  }
}

json MachineJson() {
  json m;
  m["cpus"] = std::thread::hardware_concurrency();
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) m["cpu"] = line.substr(line.find_first_not_of(' ', colon + 1));
      break;
    }
  }
  utsname u{};
  if (uname(&u) == 0) m["os"] = fmt::format("{} {} {}", u.sysname, u.release, u.machine);
  return m;
}

std::string CsvCell(const json& v) {
  if (v.is_null()) return "";
  std::string s = v.is_string() ? v.get<std::string>() : v.dump();
  if (s.find_first_of(",\"\n") != std::string::npos) {
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  }
  return s;
}

}  // namespace

json CollectRunMetrics(const std::vector<ExperimentStage>& stages) {
  json metrics = json::object(), curves = json::object(), images = json::object();
  std::vector<json> evals;
  for (const auto& s : stages) {
    if (s.kind == "pairs") {  // the extraction's report: timing, detail-extraction accuracy
      const fs::path report = s.dir / "report" / "report.json";
      if (!fs::exists(report)) continue;
      json flat = json::object();
      json r = ReadJsonFile(report);
      for (const char* k : {"pca_energy", "pca_reconstruction_rmse_mm", "ferns"}) r.erase(k);  // not computed there
      Flatten(r, "pairs", &flat);
      for (const auto& [k, v] : flat.items()) metrics[k] = v;
    } else if (s.kind == "model") {
      const fs::path report = s.dir / "report" / "report.json";
      if (!fs::exists(report)) continue;
      const json r = ReadJsonFile(report);
      json flat = json::object();
      Flatten(r, "model", &flat);
      for (const auto& [k, v] : flat.items()) metrics[k] = v;
      if (r.contains("pca_energy") && r["pca_energy"].is_array()) {
        // The first 64 dimensions (a 32² patch has 1024; the report plots the knee).
        json energy = json::array();
        for (size_t i = 0; i < std::min<size_t>(64, r["pca_energy"].size()); ++i) energy.push_back(r["pca_energy"][i]);
        curves["pca_energy"] = energy;
        int dims = -1;
        for (size_t i = 0; i < r["pca_energy"].size(); ++i) {
          if (r["pca_energy"][i].get<double>() >= 0.85) {
            dims = static_cast<int>(i) + 1;
            break;
          }
        }
        metrics["model.pca_dims_85"] = dims;
      }
    } else if (s.kind == "loao") {  // rung R0: the means over the held-out actors
      const fs::path r = s.dir / "loao.json";
      if (!fs::exists(r)) continue;
      json flat = json::object();
      Flatten(ReadJsonFile(r).at("mean"), "r0", &flat);
      for (const auto& [k, v] : flat.items()) metrics[k] = v;
    } else if (s.kind == "eval") {
      const fs::path e = s.dir / "eval.json";
      if (fs::exists(e)) evals.push_back(ReadJsonFile(e));
      // Pictures of the first sequence (Fig. 11's error vectors).
      if (!images.contains("error_vectors") && fs::exists(s.dir / "error_vectors.png"))
        images["error_vectors"] = (s.dir / "error_vectors.png").string();
    }
  }
  // The mean over the run's test sequences of every numeric metric.
  std::map<std::string, std::pair<double, int>> sums;
  for (const auto& e : evals) {
    json flat = json::object();
    json copy = e;
    copy.erase("per_frame");
    Flatten(copy, "", &flat);
    for (const auto& [k, v] : flat.items()) {
      const double x = v.get<double>();
      if (!std::isfinite(x)) continue;
      auto& acc = sums[k];
      acc.first += x;
      acc.second += 1;
    }
  }
  for (const auto& [k, acc] : sums) metrics[k] = acc.first / acc.second;
  if (!evals.empty() && evals.front().contains("per_frame") && evals.front()["per_frame"].is_array()) {
    // Each numeric field of the frames (nested ones as a.b.c), null where a frame lacks it.
    std::vector<json> frames;
    std::set<std::string> fields;
    for (const auto& f : evals.front()["per_frame"]) {
      json flat = json::object();
      Flatten(f, "", &flat);
      for (const auto& [k, v] : flat.items()) fields.insert(k);
      frames.push_back(std::move(flat));
    }
    for (const auto& field : fields) {
      if (field == "frame" || field.ends_with("texels") || field.ends_with("samples")) continue;
      json series = json::array();
      for (const auto& f : frames) series.push_back(f.contains(field) ? f[field] : json(nullptr));
      curves["per_frame." + field] = series;
    }
  }
  return json{{"metrics", metrics}, {"curves", curves}, {"images", images}};
}

namespace {

// A stage's state in the scheduler (and for the collector).
enum StageState { kPending, kRunning, kDone, kFailed };

// One experiment of a RunExperiments call: its runs and their stages.
struct PlannedExperiment {
  ExperimentConfig config;
  const ExperimentRunnerOptions* options = nullptr;
  size_t total_runs = 0;  // before sharding
  std::vector<ExperimentRun> runs;
  std::vector<std::vector<ExperimentStage>> run_stages;
  ExperimentSummary summary;
};

void CollectExperiment(PlannedExperiment& p, const std::map<std::string, size_t>& index,
                       const std::vector<int>& done, const std::vector<std::string>& failure);

// The stages of every run of every experiment of a RunExperiments call,
// deduplicated by key, and their states.
struct StagePlan {
  std::vector<PlannedExperiment> planned;
  std::vector<ExperimentStage> unique;
  std::map<std::string, size_t> index;  // key → position in `unique`
  std::vector<int> state;               // StageState of each unique stage
  std::vector<std::string> failure;     // why a failed stage failed
  std::set<std::string> cached_keys;    // stages done before this call
};

void Log(const ExperimentRunnerOptions& options, const std::string& s) {
  if (options.log) options.log(s);
}

// The keys of the stages an experiment's runs use.
std::set<std::string> OwnKeys(const PlannedExperiment& p) {
  std::set<std::string> own;
  for (const auto& stages : p.run_stages)
    for (const auto& s : stages) own.insert(s.key);
  return own;
}

// Plan: the stages of every run of every experiment, deduplicated by key (a sweep
// over capture options shares rig, scans, pairs, model, tracker and sequences;
// experiments share their base stages).
StagePlan PlanStages(const std::vector<ExperimentJob>& jobs) {
  const ExperimentRunnerOptions& first = jobs.front().options;
  StagePlan plan;
  for (const auto& job : jobs) {
    PlannedExperiment p;
    p.options = &job.options;
    p.config = ApplyProfile(job.config, job.options.profile);
    if (job.options.seeds > 0) p.config.seeds = job.options.seeds;
    const std::vector<ExperimentRun> all_runs = ExpandRuns(p.config);
    p.total_runs = all_runs.size();
    p.runs = ShardRuns(all_runs, job.options.shard, job.options.num_shards);
    std::set<std::string> own;
    for (const auto& r : p.runs) {
      p.run_stages.push_back(PlanRunStages(r, first.cache, job.options.stage_versions));
      for (const auto& s : p.run_stages.back()) {
        own.insert(s.key);
        if (plan.index.count(s.key)) continue;
        plan.index[s.key] = plan.unique.size();
        plan.unique.push_back(s);
      }
    }
    p.summary.runs = static_cast<int>(p.runs.size());
    p.summary.stages = static_cast<int>(own.size());
    plan.planned.push_back(std::move(p));
  }
  plan.state.assign(plan.unique.size(), kPending);
  plan.failure.assign(plan.unique.size(), "");
  return plan;
}

// Marks the stages the cache holds (a stage.json with the same key inputs) done,
// and logs each experiment's plan (to `first`'s log: the first job's).
void FindCachedStages(StagePlan& plan, const ExperimentRunnerOptions& first) {
  const std::vector<ExperimentStage>& unique = plan.unique;
  for (size_t i = 0; i < unique.size(); ++i)
    if (StageIsComplete(unique[i])) plan.state[i] = kDone;
  for (size_t i = 0; i < unique.size(); ++i)
    if (plan.state[i] == kDone) plan.cached_keys.insert(unique[i].key);
  for (auto& p : plan.planned) {
    for (const auto& k : OwnKeys(p)) p.summary.stages_cached += plan.cached_keys.count(k) ? 1 : 0;
    Log(first, fmt::format("{}: {} runs{}, {} stages ({} cached)", p.config.name, p.runs.size(),
                           p.options->num_shards > 1 ? fmt::format(" (shard {}/{} of {})", p.options->shard + 1,
                                                                   p.options->num_shards, p.total_runs)
                                                     : "",
                           p.summary.stages, p.summary.stages_cached));
  }
}

}  // namespace

namespace {

// ExecuteStage's work once it holds the stage's lock.
std::string MakeStage(const ExperimentStage& s, const StageExecutor& executor) {
  const auto t0 = std::chrono::steady_clock::now();
  std::error_code ec;
  fs::remove_all(s.dir, ec);  // an incomplete folder of an earlier, interrupted run
  fs::create_directories(s.dir);
  const int rc = executor(s.argv, s.dir / "log.txt");
  if (rc != 0)
    return fmt::format("{} stage failed (exit status {}): {}\n{}", s.kind, rc, ExperimentCommandLine(s.argv),
                       ReadFileTail(s.dir / "log.txt", 1500));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  WriteJsonFile(s.dir / "stage.json", json{{"kind", s.kind},
                                           {"key", s.key},
                                           {"key_inputs", s.key_inputs},
                                           {"command", ExperimentCommandLine(s.argv)},
                                           {"seconds", seconds}});
  return "";
}

}  // namespace

fs::path StageLockFile(const ExperimentStage& stage) { return stage.dir.parent_path() / (stage.key + ".lock"); }

std::string ExecuteStage(const ExperimentStage& s, const StageExecutor& executor) {
  try {
    // Held while the stage is made: a second runner (local, or a Slurm job) on the
    // same cache waits here, then finds the stage complete and makes nothing.
    const FileLock lock(StageLockFile(s));
    if (StageIsComplete(s)) return "";
    return MakeStage(s, executor);
  } catch (const std::exception& e) {
    return fmt::format("{} stage: {}", s.kind, e.what());
  }
}

bool StageIsComplete(const ExperimentStage& stage) {
  const fs::path done = stage.dir / "stage.json";
  if (!fs::exists(done)) return false;
  try {
    return ReadJsonFile(done).at("key_inputs") == stage.key_inputs;
  } catch (const std::exception&) {
    return false;  // unreadable: rebuilt
  }
}

json StageToJson(const ExperimentStage& s) {
  return json{{"kind", s.kind}, {"key", s.key},         {"key_inputs", s.key_inputs}, {"dir", s.dir.string()},
              {"argv", s.argv}, {"depends", s.depends}, {"exclusive", s.exclusive},   {"slurm", s.slurm}};
}

ExperimentStage StageFromJson(const json& j, const std::string& what) {
  ExperimentStage s;
  try {
    s.kind = j.at("kind").get<std::string>();
    s.key = j.at("key").get<std::string>();
    s.key_inputs = j.at("key_inputs");
    s.dir = j.at("dir").get<std::string>();
    s.argv = j.at("argv").get<std::vector<std::string>>();
    s.depends = j.at("depends").get<std::vector<std::string>>();
    s.exclusive = j.value("exclusive", false);
    s.slurm = j.value("slurm", json::object());
  } catch (const json::exception& e) {
    throw Error(fmt::format("{}: not a stage plan ({})", what, e.what()));
  }
  Require(ExperimentKey(s.key_inputs) == s.key,
          fmt::format("{}: the stage's key {} is not the hash of its key inputs", what, s.key));
  Require(!s.argv.empty() && s.dir.is_absolute(), fmt::format("{}: the stage has no command or no absolute folder", what));
  return s;
}

namespace {

// Runs the pending stages of a plan on worker threads, each stage once its input
// stages are done.
class StageScheduler {
 public:
  StageScheduler(StagePlan& plan, const StageExecutor& executor, const ExperimentRunnerOptions& options)
      : plan_(plan), executor_(executor), options_(options) {}

  void Run(int jobs) {
    std::vector<std::thread> threads;
    for (int j = 0; j < jobs; ++j) threads.emplace_back([this] { Work(); });
    for (auto& t : threads) t.join();
  }

 private:
  // The first pending stage whose inputs are done; fail those whose inputs failed.
  // An exclusive stage (a timed capture) starts only when nothing else runs, and
  // nothing starts beside it; once one is ready, no new stage starts before it.
  // Returns unique.size() when none may start now; `any_pending` tells whether one
  // may start later. Called under the lock.
  size_t PickStage(bool* any_pending) {
    const std::vector<ExperimentStage>& unique = plan_.unique;
    std::vector<int>& state = plan_.state;
    size_t pick = unique.size();
    *any_pending = false;
    for (size_t i = 0; i < unique.size() && !exclusive_running_; ++i) {
      if (state[i] != kPending) continue;
      bool ready = true, failed = false;
      for (const auto& dep : unique[i].depends) {
        const int ds = state[plan_.index.at(dep)];
        failed = failed || ds == kFailed;
        ready = ready && ds == kDone;
      }
      if (failed) {
        state[i] = kFailed;
        plan_.failure[i] = "an input stage failed";
        cv_.notify_all();
        continue;
      }
      *any_pending = true;
      if (ready) {
        pick = i;
        break;
      }
    }
    if (pick != unique.size() && unique[pick].exclusive && running_ > 0) pick = unique.size();  // wait for quiet
    if (exclusive_running_) *any_pending = true;
    return pick;
  }

  // A worker thread: picks, runs and records stages until none is left.
  void Work() {
    const std::vector<ExperimentStage>& unique = plan_.unique;
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      bool any_pending = false;
      const size_t pick = PickStage(&any_pending);
      if (pick == unique.size()) {
        if (!any_pending) {
          cv_.notify_all();
          return;
        }
        cv_.wait(lock);
        continue;
      }
      plan_.state[pick] = kRunning;
      ++running_;
      exclusive_running_ = unique[pick].exclusive;
      const ExperimentStage& s = unique[pick];
      Log(options_, fmt::format("  {} {} …  {}", s.kind, s.key, ExperimentCommandLine(s.argv)));
      lock.unlock();
      const std::string error = ExecuteStage(s, executor_);
      lock.lock();
      --running_;
      if (unique[pick].exclusive) exclusive_running_ = false;
      if (error.empty()) {
        plan_.state[pick] = kDone;
      } else {
        plan_.state[pick] = kFailed;
        plan_.failure[pick] = error;
        Log(options_, "  FAILED: " + error);
      }
      cv_.notify_all();
    }
  }

  StagePlan& plan_;
  const StageExecutor& executor_;
  const ExperimentRunnerOptions& options_;
  std::mutex mutex_;
  std::condition_variable cv_;
  int running_ = 0;
  bool exclusive_running_ = false;
};

}  // namespace

namespace {

// out/stages.json of each experiment that asks for it (`crease experiment status`
// reads it): the stages its runs use, in plan order, with the runs of each.
void RecordStages(const StagePlan& plan) {
  for (const auto& p : plan.planned) {
    if (!p.options->record_stages) continue;
    std::map<std::string, json> runs_of;
    for (size_t r = 0; r < p.runs.size(); ++r)
      for (const auto& s : p.run_stages[r]) runs_of[s.key].push_back(p.runs[r].id);
    json stages = json::array();
    for (size_t i = 0; i < plan.unique.size(); ++i) {
      const auto it = runs_of.find(plan.unique[i].key);
      if (it == runs_of.end()) continue;
      json s = StageToJson(plan.unique[i]);
      s["command"] = ExperimentCommandLine(plan.unique[i].argv);
      s["runs"] = it->second;
      stages.push_back(std::move(s));
    }
    fs::create_directories(p.options->out);
    WriteJsonFile(p.options->out / "stages.json",
                  json{{"experiment", p.config.name}, {"cache", p.options->cache.string()}, {"stages", stages}});
  }
}

}  // namespace

StageBackend LocalBackend(const StageExecutor& executor) {
  return [executor](const std::vector<ExperimentStage>& stages, const std::vector<bool>& cached,
                    const ExperimentRunnerOptions& options) {
    StagePlan plan;
    plan.unique = stages;
    for (size_t i = 0; i < stages.size(); ++i) {
      plan.index[stages[i].key] = i;
      plan.state.push_back(cached[i] ? kDone : kPending);
    }
    plan.failure.assign(stages.size(), "");
    StageScheduler(plan, executor, options).Run(options.jobs);
    std::vector<StageOutcome> outcomes(stages.size());
    for (size_t i = 0; i < stages.size(); ++i) {
      outcomes[i].done = plan.state[i] == kDone;
      if (!outcomes[i].done) outcomes[i].error = plan.failure[i];
    }
    return outcomes;
  };
}

std::vector<ExperimentSummary> RunExperiments(const std::vector<ExperimentJob>& jobs, const StageExecutor& executor) {
  return RunExperiments(jobs, LocalBackend(executor));
}

std::vector<ExperimentSummary> RunExperiments(const std::vector<ExperimentJob>& jobs, const StageBackend& backend) {
  const auto t_start = std::chrono::steady_clock::now();
  Require(!jobs.empty(), "no experiments to run");
  const ExperimentRunnerOptions& first = jobs.front().options;
  Require(first.jobs >= 1, "--jobs must be ≥ 1");
  for (const auto& j : jobs)
    Require(j.options.cache == first.cache && j.options.jobs == first.jobs,
            "experiments run together must share their cache and --jobs");

  StagePlan plan = PlanStages(jobs);
  FindCachedStages(plan, first);
  RecordStages(plan);
  std::vector<bool> cached(plan.unique.size());
  for (size_t i = 0; i < cached.size(); ++i) cached[i] = plan.state[i] == kDone;
  const std::vector<StageOutcome> outcomes = backend(plan.unique, cached, first);
  Require(outcomes.size() == plan.unique.size(), "the stage backend returned no outcome for some stages");
  for (size_t i = 0; i < cached.size(); ++i) {
    if (cached[i]) continue;
    plan.state[i] = outcomes[i].done ? kDone : kFailed;
    plan.failure[i] = outcomes[i].error;
  }

  std::vector<ExperimentSummary> summaries;
  for (auto& p : plan.planned) {
    for (const auto& k : OwnKeys(p)) {
      const size_t i = plan.index.at(k);
      if (plan.state[i] == kFailed) ++p.summary.stages_failed;
      if (plan.state[i] == kDone && !plan.cached_keys.count(k)) ++p.summary.stages_run;
    }
    CollectExperiment(p, plan.index, plan.state, plan.failure);
    p.summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    summaries.push_back(p.summary);
  }
  return summaries;
}

std::optional<std::string> ResultsProfile(const fs::path& out) {
  const fs::path file = out / "experiment.json";
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return std::nullopt;
  try {
    const json j = ReadJsonFile(file);
    if (!j.is_object() || !j.contains("profile") || !j["profile"].is_string()) return std::nullopt;
    return j["profile"].get<std::string>();
  } catch (const std::exception&) {
    return std::nullopt;  // unreadable: nothing to warn about
  }
}

ExperimentSummary RunExperiment(const ExperimentConfig& config, const ExperimentRunnerOptions& options,
                                const StageExecutor& executor) {
  return RunExperiments({ExperimentJob{config, options}}, executor).front();
}

namespace {

void CollectExperiment(PlannedExperiment& p, const std::map<std::string, size_t>& index,
                       const std::vector<int>& state, const std::vector<std::string>& failure) {
  const ExperimentConfig& config = p.config;
  const ExperimentRunnerOptions& options = *p.options;
  const std::vector<ExperimentRun>& runs = p.runs;
  const std::vector<std::vector<ExperimentStage>>& run_stages = p.run_stages;
  ExperimentSummary& summary = p.summary;
  // Collect: a JSON per run, then the experiment's CSV and description.
  fs::create_directories(options.out / "runs");
  std::vector<json> run_jsons;
  json runs_ok = json::array(), runs_failed = json::array();
  for (size_t r = 0; r < runs.size(); ++r) {
    json j;
    j["run_id"] = runs[r].id;
    j["experiment"] = config.name;
    j["seed"] = runs[r].seed;
    j["point"] = runs[r].point;
    json commands = json::array(), keys = json::object();
    std::string error;
    double seconds = 0.0;
    for (const auto& s : run_stages[r]) {
      commands.push_back(ExperimentCommandLine(s.argv));
      keys[s.kind] = keys.contains(s.kind) ? json(keys[s.kind].get<std::string>() + "," + s.key) : json(s.key);
      const size_t i = index.at(s.key);
      if (state[i] != kDone && error.empty())
        error = failure[i].empty() ? fmt::format("{} stage did not run", s.kind) : failure[i];
      if (state[i] == kDone) {
        try {
          seconds += ReadJsonFile(s.dir / "stage.json").value("seconds", 0.0);
        } catch (const std::exception&) {
        }
      }
    }
    j["commands"] = commands;
    j["stages"] = keys;
    j["stage_seconds"] = seconds;
    if (error.empty()) {
      try {
        const json m = CollectRunMetrics(run_stages[r]);
        j["metrics"] = m["metrics"];
        j["curves"] = m["curves"];
        j["images"] = m["images"];
      } catch (const std::exception& e) {
        error = fmt::format("collecting metrics: {}", e.what());
      }
    }
    j["status"] = error.empty() ? "ok" : "failed";
    if (!error.empty()) j["error"] = error;
    (error.empty() ? runs_ok : runs_failed).push_back(runs[r].id);
    WriteJsonFile(options.out / "runs" / (runs[r].id + ".json"), j);
    run_jsons.push_back(std::move(j));
  }
  summary.runs_ok = static_cast<int>(runs_ok.size());
  summary.runs_failed = static_cast<int>(runs_failed.size());

  // results.csv: run, seed, status, the swept keys, the metrics (union, sorted).
  std::vector<std::string> point_keys;
  for (const auto& [key, values] : config.sweep.values) point_keys.push_back(key);
  std::set<std::string> metric_keys;
  for (const auto& j : run_jsons)
    if (j.contains("metrics"))
      for (const auto& [k, v] : j["metrics"].items()) metric_keys.insert(k);
  WriteFileAtomic(options.out / "results.csv", [&](std::ostream& o) {
    o << "run_id,seed,status";
    for (const auto& k : point_keys) o << "," << CsvCell(k);
    for (const auto& k : metric_keys) o << "," << CsvCell(k);
    o << "\n";
    for (const auto& j : run_jsons) {
      o << CsvCell(j["run_id"]) << "," << j["seed"].get<int>() << "," << CsvCell(j["status"]);
      for (const auto& k : point_keys) o << "," << (j["point"].contains(k) ? CsvCell(j["point"][k]) : "");
      for (const auto& k : metric_keys)
        o << "," << (j.contains("metrics") && j["metrics"].contains(k) ? CsvCell(j["metrics"][k]) : "");
      o << "\n";
    }
  });

  json e;
  e["name"] = config.name;
  e["title"] = config.title;
  e["paper"] = config.paper;
  e["description"] = config.description;
  e["config"] = config.source.string();
  e["profile"] = options.profile;
  json seeds = json::array();
  for (int s = 1; s <= config.seeds; ++s) seeds.push_back(s);
  e["seeds"] = seeds;
  e["command"] = options.command;
  e["crease_version"] = options.build_description.empty() ? options.program_version : options.build_description;
  e["machine"] = MachineJson();
  e["jobs"] = options.jobs;
  e["shard"] = fmt::format("{}/{}", options.shard + 1, options.num_shards);
  json sweep_keys = json::array(), baseline = json::object();
  for (const auto& [key, values] : config.sweep.values) {
    sweep_keys.push_back(key);
    if (config.variants.contains(key)) {  // a group of variants has no base value
      baseline[key] = nullptr;
      continue;
    }
    const auto [section, field] = SplitKey(key, "sweep");
    const json sec = SectionOf(config, section);
    baseline[key] = sec.contains(field) ? sec[field] : json(nullptr);
  }
  e["sweep"] = json{{"mode", config.sweep.mode}, {"keys", sweep_keys}};
  e["baseline"] = baseline;
  json sections = json::object();
  for (const auto& [k, v] : config.sections) sections[k] = v;
  e["sections"] = sections;
  e["variants"] = config.variants;
  for (const char* k : {"table", "figures", "claims"}) e[k] = config.report.contains(k) ? config.report[k] : json::array();
  e["runs"] = runs_ok;
  e["runs_failed"] = runs_failed;
  e["complete"] = runs_failed.empty();
  WriteJsonFile(options.out / "experiment.json", e);
}

}  // namespace



}  // namespace crease
