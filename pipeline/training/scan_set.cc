#include "pipeline/training/scan_set.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_io.h"

namespace crease {

namespace fs = std::filesystem;
using nlohmann::json;

int ScanSet::num_scans() const {
  int n = 0;
  for (const auto& a : actors) n += static_cast<int>(a.scans.size());
  return n;
}

std::vector<std::string> ScanSet::lights() const {
  std::vector<std::string> out;
  for (const auto& a : actors) {
    for (const auto& s : a.scans) {
      for (const auto& im : s.images) {
        if (std::find(out.begin(), out.end(), im.light) == out.end()) out.push_back(im.light);
      }
    }
  }
  return out;
}

namespace {

std::string GetString(const json& j, const char* key, const std::string& where) {
  Require(j.is_object() && j.contains(key) && j[key].is_string(),
          fmt::format("{}: missing string field '{}'", where, key));
  return j[key].get<std::string>();
}

// An optional string field: `fallback` when absent, an error naming it when it is not a
// string (json::value() threw nlohmann's type_error, an internal error: issue 19).
std::string OptionalString(const json& j, const char* key, const std::string& fallback, const std::string& where) {
  if (!j.contains(key)) return fallback;
  Require(j[key].is_string(), fmt::format("{}: field '{}' must be a string, got {}", where, key, j[key].dump()));
  return j[key].get<std::string>();
}

fs::path ExistingFile(const fs::path& base, const std::string& relative, const std::string& where) {
  const fs::path p = base / relative;
  Require(fs::is_regular_file(p), fmt::format("{}: file '{}' does not exist", where, p.string()));
  return p;
}

}  // namespace

ScanSet ReadScanSet(const fs::path& dir) {
  const fs::path index_path = dir / "scans.json";
  Require(fs::is_directory(dir), fmt::format("{}: not a folder", dir.string()));
  Require(fs::is_regular_file(index_path),
          fmt::format("{}: no scans.json (a scan set folder needs one; see docs/formats.md)", dir.string()));
  const json index = ReadJsonFile(index_path);
  const std::string where = index_path.string();
  Require(index.is_object() && index.contains("format") && index["format"] == "crease scan set",
          fmt::format("{}: 'format' must be \"crease scan set\"", where));
  Require(index.contains("version") && index["version"] == 2,
          fmt::format("{}: scan set version {} is not supported (this crease reads version 2; "
                      "regenerate synthetic sets with `crease synth scans`)",
                      where, index.contains("version") ? index["version"].dump() : "(none)"));
  ScanSet set;
  set.root = dir;
  if (index.contains("rig")) set.rig = ExistingFile(dir, GetString(index, "rig", where), where);
  Require(index.contains("actors") && index["actors"].is_array() && !index["actors"].empty(),
          fmt::format("{}: 'actors' must be a non-empty array", where));
  for (size_t a = 0; a < index["actors"].size(); ++a) {
    const json& ja = index["actors"][a];
    const std::string wa = fmt::format("{}: actors[{}]", where, a);
    ScanActor actor;
    actor.name = GetString(ja, "folder", wa);
    actor.folder = dir / actor.name;
    Require(fs::is_directory(actor.folder), fmt::format("{}: folder '{}' does not exist", wa, actor.folder.string()));
    Require(ja.contains("scans") && ja["scans"].is_array() && ja["scans"].size() >= 2,
            fmt::format("{}: 'scans' must list a neutral and at least one expression", wa));
    for (size_t s = 0; s < ja["scans"].size(); ++s) {
      const json& js = ja["scans"][s];
      const std::string ws = fmt::format("{}.scans[{}]", wa, s);
      ScanEntry scan;
      scan.name = GetString(js, "name", ws);
      scan.mesh = ExistingFile(actor.folder, GetString(js, "mesh", ws), ws);
      Require(js.contains("images") && js["images"].is_array() && !js["images"].empty(),
              fmt::format("{} ('{}'): 'images' must list at least one image with its camera", ws, scan.name));
      for (size_t i = 0; i < js["images"].size(); ++i) {
        const json& ji = js["images"][i];
        const std::string wi = fmt::format("{}.images[{}]", ws, i);
        ScanImage im;
        im.camera = ExistingFile(actor.folder, GetString(ji, "camera", wi), wi);
        im.image = ExistingFile(actor.folder, GetString(ji, "image", wi), wi);
        im.light = OptionalString(ji, "light", "", wi);
        scan.images.push_back(im);
      }
      if (js.contains("truth") && js["truth"].contains("expression_displacement")) {
        scan.truth_displacement =
            ExistingFile(actor.folder, GetString(js["truth"], "expression_displacement", ws + ".truth"), ws);
      }
      for (const auto& other : actor.scans) {
        Require(other.name != scan.name, fmt::format("{}: scan name '{}' appears twice", wa, scan.name));
      }
      actor.scans.push_back(std::move(scan));
    }
    const std::string neutral = OptionalString(ja, "neutral", "neutral", wa);
    actor.neutral = 0;
    bool named = false;
    for (size_t s = 0; s < actor.scans.size(); ++s) {
      if (actor.scans[s].name == neutral) {
        actor.neutral = static_cast<int>(s);
        named = true;
      }
    }
    Require(named || !ja.contains("neutral"),
            fmt::format("{}: neutral scan '{}' is not among its scans", wa, neutral));
    set.actors.push_back(std::move(actor));
  }
  return set;
}

std::vector<int> NeutralFirst(const ScanActor& actor) {
  std::vector<int> order = {actor.neutral};
  for (int s = 0; s < static_cast<int>(actor.scans.size()); ++s)
    if (s != actor.neutral) order.push_back(s);
  return order;
}

}  // namespace crease
