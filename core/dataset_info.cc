#include "core/dataset_info.h"

#include <cctype>
#include <cmath>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_io.h"

namespace crease {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {
// The widest a frame pattern may pad {frame}: frame numbers have at most 10 digits.
constexpr int kMaxFrameFieldWidth = 32;
constexpr int kMaxFrames = 10'000'000;

// Checks the replacement fields of a frame pattern: {frame} or {frame:SPEC}, no
// number in SPEC (the width) above kMaxFrameFieldWidth. `where` names the key.
void CheckFrameFields(const std::string& pattern, const std::string& where) {
  for (size_t open = pattern.find('{'); open != std::string::npos; open = pattern.find('{', open)) {
    if (pattern.compare(open, 2, "{{") == 0) {  // an escaped brace
      open += 2;
      continue;
    }
    const size_t close = pattern.find('}', open);
    Require(close != std::string::npos, fmt::format("{} = \"{}\": a '{{' is not closed", where, pattern));
    const std::string field = pattern.substr(open + 1, close - open - 1);
    const size_t colon = field.find(':');
    Require(field.substr(0, colon) == "frame",
            fmt::format("{} = \"{}\": the only field is {{frame}}, not {{{}}}", where, pattern, field));
    int number = 0;
    for (char c : colon == std::string::npos ? std::string() : field.substr(colon + 1)) {
      number = std::isdigit(static_cast<unsigned char>(c)) ? number * 10 + (c - '0') : 0;
      Require(number <= kMaxFrameFieldWidth, fmt::format("{} = \"{}\": {{{}}} pads wider than {} characters",
                                                         where, pattern, field, kMaxFrameFieldWidth));
    }
    open = close + 1;
  }
}

// An integer field in [lo, hi]; `fallback` when absent (none: the key is required).
int IntField(const json& j, const char* key, int lo, int hi, std::optional<int> fallback, const fs::path& file) {
  const auto it = j.find(key);
  if (it == j.end()) {
    Require(fallback.has_value(), fmt::format("{}: the key '{}' is missing", file.string(), key));
    return *fallback;
  }
  Require(it->is_number_integer(), fmt::format("{}: {} must be an integer, not {}", file.string(), key, it->dump()));
  const int64_t v = it->get<int64_t>();
  Require(v >= lo && v <= hi, fmt::format("{}: {} = {} is outside [{}, {}]", file.string(), key, v, lo, hi));
  return static_cast<int>(v);
}

// A file name relative to the dataset folder that stays inside it.
std::string RelativeFileField(const json& j, const char* key, const std::string& fallback, const fs::path& file) {
  const auto it = j.find(key);
  if (it == j.end()) return fallback;
  Require(it->is_string() && !it->get<std::string>().empty(),
          fmt::format("{}: {} must be a file name in the dataset folder", file.string(), key));
  const fs::path p(it->get<std::string>());
  bool inside = p.is_relative();
  for (const auto& part : p) inside = inside && part != "..";
  Require(inside, fmt::format("{}: {} = \"{}\" must be a relative path inside the dataset folder", file.string(),
                              key, p.string()));
  return p.string();
}

void ReadFormat(const json& j, const fs::path& file) {
  Require(j.is_object(), fmt::format("{}: must be a JSON object (a crease sequence dataset's description)",
                                     file.string()));
  const auto format = j.find("format");
  Require(format != j.end() && format->is_string() && format->get<std::string>() == SequenceDatasetInfo::kFormat,
          fmt::format("{}: format must be \"{}\"; is this a `crease synth sequence` dataset?", file.string(),
                      SequenceDatasetInfo::kFormat));
  const int version = IntField(j, "version", 0, 1 << 30, -1, file);
  Require(version == SequenceDatasetInfo::kVersion,
          fmt::format("{}: version {} is not supported (this crease reads version {})", file.string(), version,
                      SequenceDatasetInfo::kVersion));
}

double FpsField(const json& j, const fs::path& file) {
  const auto it = j.find("fps");
  if (it == j.end()) return 30.0;
  Require(it->is_number() && std::isfinite(it->get<double>()) && it->get<double>() > 0 && it->get<double>() <= 1000,
          fmt::format("{}: fps must be a number in (0, 1000], not {}", file.string(), it->dump()));
  return it->get<double>();
}
}  // namespace

std::string DatasetFilePattern(const json& info, const fs::path& dataset_json, const std::string& key,
                               const std::string& fallback) {
  if (!info.is_object() || !info.contains("files")) return fallback;
  const json& files = info.at("files");
  const std::string where = fmt::format("{}: files.{}", dataset_json.string(), key);
  if (!files.is_object()) throw Error(fmt::format("{}: files must be an object", dataset_json.string()));
  if (!files.contains(key)) return fallback;
  const json& value = files.at(key);
  Require(value.is_string(), fmt::format("{} must be a string such as \"{}\"", where, fallback));
  const std::string pattern = value.get<std::string>();
  if (pattern.empty()) return pattern;
  CheckFrameFields(pattern, where);
  try {
    (void)fmt::format(fmt::runtime(pattern), fmt::arg("frame", 0));
  } catch (const fmt::format_error& e) {
    throw Error(fmt::format("{} = \"{}\" is not a valid pattern: {}", where, pattern, e.what()));
  }
  return pattern;
}

std::string DatasetFramePattern(const json& info, const fs::path& dataset_json) {
  const std::string pattern = DatasetFilePattern(info, dataset_json, "frame", "frames/{frame:06d}.png");
  Require(!pattern.empty(), fmt::format("{}: files.frame must not be empty", dataset_json.string()));
  return pattern;
}

bool IsSequenceDataset(const fs::path& dir) { return fs::is_regular_file(dir / "dataset.json"); }

SequenceDatasetInfo ReadSequenceDatasetInfo(const fs::path& dir) {
  SequenceDatasetInfo d;
  d.dir = dir;
  d.json_path = dir / "dataset.json";
  Require(fs::is_regular_file(d.json_path), fmt::format("{}: missing; is {} a `crease synth sequence` dataset?",
                                                        d.json_path.string(), dir.string()));
  const json j = ReadJsonFile(d.json_path);
  ReadFormat(j, d.json_path);
  if (const auto it = j.find("sequence"); it != j.end() && it->is_string()) d.sequence = it->get<std::string>();
  d.first_frame = IntField(j, "first_frame", 0, kMaxFrames, 0, d.json_path);
  d.frames = IntField(j, "frames", 1, kMaxFrames, std::nullopt, d.json_path);
  d.fps = FpsField(j, d.json_path);
  d.width = IntField(j, "width", 16, 8192, std::nullopt, d.json_path);
  d.height = IntField(j, "height", 16, 8192, std::nullopt, d.json_path);
  d.rig = RelativeFileField(j, "rig", "rig.crig", d.json_path);
  d.tracking_rig = RelativeFileField(j, "tracking_rig", "", d.json_path);
  d.frame_pattern = DatasetFramePattern(j, d.json_path);
  d.displacement_pattern = DatasetFilePattern(j, d.json_path, "expression_displacement", d.displacement_pattern);
  return d;
}

fs::path SequenceDatasetInfo::FramePath(int frame) const {
  return dir / fmt::format(fmt::runtime(frame_pattern), fmt::arg("frame", frame));
}

fs::path SequenceDatasetInfo::TruthPath(int frame) const { return dir / "truth" / fmt::format("{:06d}.json", frame); }

fs::path SequenceDatasetInfo::DisplacementPath(int frame) const {
  Require(!displacement_pattern.empty(),
          fmt::format("{}: the dataset has no per-frame displacement maps (rendered with --no-maps); render it "
                      "again without --no-maps to evaluate D^t",
                      json_path.string()));
  return dir / fmt::format(fmt::runtime(displacement_pattern), fmt::arg("frame", frame));
}

fs::path SequenceDatasetInfo::RigPath() const { return dir / rig; }

fs::path SequenceDatasetInfo::TrackingRigPath() const { return dir / (tracking_rig.empty() ? rig : tracking_rig); }

}  // namespace crease
