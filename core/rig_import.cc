#include "core/rig_import.h"

#include <algorithm>
#include <cctype>
#include <climits>
#include <cmath>
#include <map>
#include <set>
#include <regex>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"

namespace crease {
namespace fs = std::filesystem;

void RigImportOptions::VisitFields(OptionVisitor& v) {
  v.Field("units_to_mm", units_to_mm);
  v.Field("face_first", face_first);
  v.Field("face_last", face_last);
  v.Field("face_vertices", face_vertices);
  v.Field("landmark_ids", landmark_ids);
  v.Field("max_identity_modes", max_identity_modes);
  v.Field("region_mask_size", region_mask_size);
  v.Field("zero_threshold_mm", zero_threshold_mm);
  v.Field("flip_v", flip_v);
}

void RigImportOptions::Check() const {
  CheckGt("RigImportOptions", "units_to_mm", units_to_mm, 0.0);
  CheckGe("RigImportOptions", "face_first", face_first, 0);
  if (face_last >= 0) CheckGt("RigImportOptions", "face_last", face_last, face_first);
  CheckGe("RigImportOptions", "region_mask_size", region_mask_size, 16);
  CheckGe("RigImportOptions", "zero_threshold_mm", zero_threshold_mm, 0.0);
  CheckGe("RigImportOptions", "max_identity_modes", max_identity_modes, -1);
  if (!parts.empty()) {
    Require(face_vertices.empty() && face_first == 0 && face_last < 0,
            "RigImportOptions: give either parts or a face region (face_first/face_last/face_vertices), not both");
    bool has_face = false;
    for (const auto& p : parts) has_face = has_face || p.name == "face";
    Require(has_face, "RigImportOptions: parts must include one named \"face\" (the UV chart)");
  }
}

VertexRange ParseVertexRange(const std::string& text, const std::string& what) {
  static const std::regex re(R"(\s*\[\s*(\d+)\s*,\s*(\d+)\s*([\])])\s*)");
  std::smatch m;
  const auto bad = [&] {
    return Error(fmt::format("{}: vertex range '{}' must be written \"[A, B]\" (B included, as in ICT-FaceKit's "
                             "tables) or \"[A, B)\" (B excluded)", what, text));
  };
  if (!std::regex_match(text, m, re)) throw bad();
  VertexRange r;
  try {
    r.first = std::stoi(m[1].str());
    r.end = std::stoi(m[2].str()) + (m[3].str() == "]" ? 1 : 0);
  } catch (const std::exception&) {
    throw bad();
  }
  Require(r.end > r.first, fmt::format("{}: vertex range '{}' is empty", what, text));
  return r;
}

std::vector<RigPart> ReadRigParts(const fs::path& path) {
  const std::string what = path.string();
  const nlohmann::json j = ReadJsonFile(path);
  Require(j.is_array() && !j.empty(),
          fmt::format("{}: expected a JSON list of parts [{{\"name\": …, \"vertices\": \"[A, B]\"}}, …]", what));
  std::vector<RigPart> parts;
  std::set<std::string> names;
  std::vector<std::pair<VertexRange, std::string>> all;
  for (size_t i = 0; i < j.size(); ++i) {
    const auto& e = j[i];
    const std::string at = fmt::format("{}: part {}", what, i);
    Require(e.is_object(), at + ": expected an object with \"name\" and \"vertices\"");
    for (auto it = e.begin(); it != e.end(); ++it) {
      Require(it.key() == "name" || it.key() == "vertices",
              fmt::format("{}: unknown key '{}' (expected name, vertices)", at, it.key()));
    }
    Require(e.contains("name") && e["name"].is_string() && !e["name"].get<std::string>().empty(),
            at + ": \"name\" must be a non-empty string");
    RigPart part;
    part.name = e["name"].get<std::string>();
    Require(names.insert(part.name).second, fmt::format("{}: part name '{}' is used twice", what, part.name));
    Require(part.name != "face_rim", fmt::format("{}: the part name 'face_rim' is reserved", what));
    Require(e.contains("vertices"), at + ": missing \"vertices\"");
    const auto& r = e["vertices"];
    const std::string where = fmt::format("{} ('{}')", at, part.name);
    if (r.is_string()) {
      part.ranges.push_back(ParseVertexRange(r.get<std::string>(), where));
    } else if (r.is_array()) {
      for (const auto& x : r) {
        Require(x.is_string(), where + ": \"vertices\" must be a range string or a list of them");
        part.ranges.push_back(ParseVertexRange(x.get<std::string>(), where));
      }
    } else {
      throw Error(where + ": \"vertices\" must be a range string or a list of them");
    }
    Require(!part.ranges.empty(), where + ": no vertex range");
    for (const auto& vr : part.ranges) all.emplace_back(vr, part.name);
    parts.push_back(std::move(part));
  }
  std::sort(all.begin(), all.end(), [](auto& a, auto& b) { return a.first.first < b.first.first; });
  for (size_t i = 1; i < all.size(); ++i) {
    Require(all[i].first.first >= all[i - 1].first.end,
            fmt::format("{}: the vertex ranges of parts '{}' and '{}' overlap (vertex {})", what,
                        all[i - 1].second, all[i].second, all[i].first.first));
  }
  Require(names.count("face") == 1, fmt::format("{}: no part is named \"face\" (the UV chart)", what));
  return parts;
}

std::vector<int> ReadFaceMask(const fs::path& path) {
  const nlohmann::json j = ReadJsonFile(path);
  const std::string error = fmt::format("{}: expected a JSON list of vertex ids", path.string());
  Require(j.is_array(), error);
  std::vector<int> ids;
  for (const auto& v : j) {
    Require(v.is_number_integer(), error);
    ids.push_back(v.get<int>());
  }
  return ids;
}

std::vector<int> ParseLandmarkIds(const std::string& spec) {
  std::string text = spec, what = "--landmarks";
  std::error_code ec;
  if (fs::is_regular_file(spec, ec)) {
    what = spec;
    if (LowerExtension(spec) == ".json") {
      const nlohmann::json j = ReadJsonFile(spec);
      const nlohmann::json* list = &j;
      if (j.is_object() && j.contains("idx_to_landmark_verts")) list = &j["idx_to_landmark_verts"];
      Require(list->is_array(), fmt::format("{}: expected a JSON list of vertex ids or an object with "
                                            "\"idx_to_landmark_verts\" (ICT-FaceKit's vertex_indices.json)", spec));
      std::vector<int> ids;
      for (const auto& x : *list) {
        Require(x.is_number_integer() && x.get<int64_t>() >= 0 && x.get<int64_t>() < INT32_MAX,
                fmt::format("{}: landmark entry {} is not a vertex id", spec, ids.size()));
        ids.push_back(x.get<int>());
      }
      Require(!ids.empty(), fmt::format("{}: no landmark ids", spec));
      return ids;
    }
    text = ReadFileToString(spec);
  }
  std::vector<int> ids;
  std::string token;
  auto flush = [&] {
    if (token.empty()) return;
    Require(token.size() <= 9, fmt::format("{}: landmark id '{}' is too large", what, token));
    ids.push_back(std::stoi(token));
    token.clear();
  };
  for (const char c : text) {
    if (std::isdigit(static_cast<unsigned char>(c))) {
      token.push_back(c);
    } else if (c == ',' || std::isspace(static_cast<unsigned char>(c))) {
      flush();
    } else {
      throw Error(fmt::format("{}: unexpected '{}' in a landmark id list (expected ids separated by commas or "
                              "spaces)", what, c));
    }
  }
  flush();
  Require(!ids.empty(), fmt::format("{}: no landmark ids", what));
  return ids;
}

double UnitsToMm(const std::string& units) {
  if (units == "mm") return 1.0;
  if (units == "cm") return 10.0;
  if (units == "m") return 1000.0;
  throw Error(fmt::format("unknown units '{}': expected mm, cm or m", units));
}

namespace {

struct ShapeFile {
  fs::path path;
  std::string name;
};

std::vector<fs::path> ObjFilesIn(const fs::path& dir) {
  std::vector<fs::path> files;
  if (!fs::is_directory(dir)) return files;
  for (const auto& e : fs::directory_iterator(dir)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    if (e.is_regular_file() && ext == ".obj") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Keeps the triangles whose corners all map to face-region vertices and
// compacts the vertex set; returns old→new ids (-1 = dropped).
std::vector<int> CropToRegion(TriangulatedMesh* tm, const std::vector<char>& in_region_original,
                              int* dropped) {
  TriMesh& m = tm->mesh;
  std::vector<char> keep_vertex(m.num_vertices(), 0);
  std::vector<int> kept_faces;
  for (int f = 0; f < m.num_faces(); ++f) {
    bool inside = true;
    for (int k = 0; k < 3; ++k) {
      const int orig = tm->original_vertex[m.F(f, k)];
      inside = inside && orig < static_cast<int>(in_region_original.size()) && in_region_original[orig];
    }
    if (inside) {
      kept_faces.push_back(f);
      for (int k = 0; k < 3; ++k) keep_vertex[m.F(f, k)] = 1;
    }
  }
  *dropped = m.num_faces() - static_cast<int>(kept_faces.size());
  std::vector<int> remap(m.num_vertices(), -1);
  int n = 0;
  for (int v = 0; v < m.num_vertices(); ++v) {
    if (keep_vertex[v]) remap[v] = n++;
  }
  TriMesh out;
  out.V.resize(n, 3);
  out.UV.resize(n, 2);
  std::vector<int> orig(n);
  for (int v = 0; v < m.num_vertices(); ++v) {
    if (remap[v] < 0) continue;
    out.V.row(remap[v]) = m.V.row(v);
    out.UV.row(remap[v]) = m.UV.row(v);
    orig[remap[v]] = tm->original_vertex[v];
  }
  out.F.resize(static_cast<int>(kept_faces.size()), 3);
  for (size_t i = 0; i < kept_faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) out.F(static_cast<int>(i), k) = remap[m.F(kept_faces[i], k)];
  }
  tm->mesh = std::move(out);
  tm->original_vertex = std::move(orig);
  return remap;
}

// Parts mode (RigImportOptions::parts): each rig vertex's part from its OBJ id;
// face vertices off the [0,1]² chart become "face_rim"; every other part gets its
// own UV tile u ∈ [2 + p, 3 + p) (in the OBJ's v convention; the flip comes later).
void AssignParts(const std::vector<RigPart>& parts, const std::vector<int>& part_of_original, FaceRig* rig,
                 RigImportReport* rep) {
  for (const auto& p : parts) rig->part_names.push_back(p.name);
  const int face = rig->PartIndex("face");
  const int nv = rig->num_vertices();
  rig->vertex_part.resize(nv);
  int rim = -1;
  for (int v = 0; v < nv; ++v) {
    int p = part_of_original[rig->original_vertex[v]];
    const double u = rig->neutral.UV(v, 0), w = rig->neutral.UV(v, 1);
    if (p == face && !(u >= 0.0 && u <= 1.0 && w >= 0.0 && w <= 1.0)) {
      if (rim < 0) {
        rim = static_cast<int>(rig->part_names.size());
        rig->part_names.push_back("face_rim");
      }
      p = rim;
    }
    rig->vertex_part[v] = static_cast<uint8_t>(p);
    if (p != face) rig->neutral.UV(v, 0) = 2.0 + p + (u - std::floor(u));
  }
  Require(rig->part_names.size() <= 255, "a rig has at most 255 parts");
  std::vector<int> count(rig->part_names.size(), 0);
  for (uint8_t p : rig->vertex_part) ++count[p];
  for (size_t p = 0; p < count.size(); ++p) rep->part_vertices.emplace_back(rig->part_names[p], count[p]);
}

// Landmarks (OBJ vertex ids) → rig vertices: of the vertices carrying the id (seam
// splits), the first on the face chart, else the first. Errors name `what`.
void AddLandmarks(const std::vector<std::pair<std::string, int>>& landmarks, const std::string& what, FaceRig* rig) {
  const int face = rig->part_names.empty() ? -1 : rig->PartIndex("face");
  std::map<int, int> rig_vertex;
  auto on_chart = [&](int v) { return face < 0 || rig->vertex_part[v] == face; };
  for (int v = 0; v < rig->num_vertices(); ++v) {
    auto [it, added] = rig_vertex.emplace(rig->original_vertex[v], v);
    if (!added && !on_chart(it->second) && on_chart(v)) it->second = v;
  }
  for (const auto& [name, id] : landmarks) {
    auto it = rig_vertex.find(id);
    Require(it != rig_vertex.end(), fmt::format("{}: landmark '{}' is OBJ vertex {}, which is not in the face region",
                                                what, name, id));
    rig->landmarks.push_back({name, it->second});
  }
}

void AddLandmarks(const std::vector<int>& ids, const std::string& what, FaceRig* rig) {
  Require(ids.size() == 68, fmt::format("{}: a list of landmarks must hold the 68 iBUG vertex ids, has {}", what,
                                        ids.size()));
  const auto names = IbugLandmarkNames();
  std::vector<std::pair<std::string, int>> lms;
  for (size_t i = 0; i < ids.size(); ++i) lms.emplace_back(names[i], ids[i]);
  AddLandmarks(lms, what, rig);
}

// The OBJ files of a blendshape folder: the neutral and the identity and
// expression shapes, each list sorted by name.
struct ObjFolder {
  fs::path neutral;
  std::vector<ShapeFile> identity, expressions;
};

// Classifies the files of `folder`: the neutral (neutral.obj, else the one file
// whose name contains "neutral"), identity modes (identity_N.obj or in identity/)
// and expressions (the other files, or in expressions/).
ObjFolder ClassifyObjFiles(const fs::path& folder, const RigImportOptions& options, RigImportReport* rep) {
  ObjFolder files;
  fs::path& neutral_path = files.neutral;
  std::vector<ShapeFile>& identity = files.identity;
  std::vector<ShapeFile>& expressions = files.expressions;
  const std::regex identity_re("identity[_-]?[0-9]+", std::regex::icase);
  std::vector<fs::path> neutral_candidates;
  for (const auto& p : ObjFilesIn(folder)) {
    std::string stem = p.stem().string(), lower = stem;
    std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
    if (lower == "neutral" || lower.find("neutral") != std::string::npos) {
      neutral_candidates.push_back(p);
    } else if (std::regex_match(stem, identity_re)) {
      identity.push_back({p, stem});
    } else {
      expressions.push_back({p, stem});
    }
  }
  for (const auto& p : ObjFilesIn(folder / "identity")) identity.push_back({p, p.stem().string()});
  for (const auto& p : ObjFilesIn(folder / "expressions")) expressions.push_back({p, p.stem().string()});
  if (fs::exists(folder / "neutral.obj")) {
    neutral_path = folder / "neutral.obj";
  } else if (neutral_candidates.size() == 1) {
    neutral_path = neutral_candidates[0];
  } else if (neutral_candidates.empty()) {
    throw Error(fmt::format("{}: no neutral shape found (expected neutral.obj)", folder.string()));
  } else {
    throw Error(fmt::format("{}: several files look like the neutral ({} and {}); name one neutral.obj",
                            folder.string(), neutral_candidates[0].filename().string(),
                            neutral_candidates[1].filename().string()));
  }
  for (const auto& p : neutral_candidates) {
    if (p != neutral_path) {
      rep->warnings.push_back(fmt::format("{} treated as an expression", p.filename().string()));
      expressions.push_back({p, p.stem().string()});
    }
  }
  std::sort(identity.begin(), identity.end(), [](auto& a, auto& b) { return a.name < b.name; });
  std::sort(expressions.begin(), expressions.end(), [](auto& a, auto& b) { return a.name < b.name; });
  if (options.max_identity_modes >= 0 && static_cast<int>(identity.size()) > options.max_identity_modes) {
    identity.resize(static_cast<size_t>(options.max_identity_modes));
  }
  return files;
}

// The face region of the neutral `neutral_path` with `n_orig` vertices: per OBJ
// vertex id, 1 = kept (options.parts, else face_vertices, else the range
// [face_first, face_last)). In parts mode `part_of_original` gets each OBJ
// vertex's index in options.parts (-1 = none).
std::vector<char> FaceRegion(const RigImportOptions& options, int n_orig, const fs::path& neutral_path,
                             std::vector<int>* part_of_original) {
  std::vector<char> in_region(n_orig, 0);
  if (!options.parts.empty()) {
    part_of_original->assign(n_orig, -1);
    for (size_t p = 0; p < options.parts.size(); ++p) {
      for (const VertexRange& r : options.parts[p].ranges) {
        Require(r.end <= n_orig, fmt::format("part '{}': vertex range [{}, {}) exceeds the {} vertices of {}",
                                             options.parts[p].name, r.first, r.end, n_orig, neutral_path.string()));
        for (int v = r.first; v < r.end; ++v) {
          if ((*part_of_original)[v] >= 0) {
            throw Error(fmt::format("vertex {} is in two parts ('{}' and '{}')", v,
                                    options.parts[(*part_of_original)[v]].name, options.parts[p].name));
          }
          (*part_of_original)[v] = static_cast<int>(p);
          in_region[v] = 1;
        }
      }
    }
  } else if (!options.face_vertices.empty()) {
    for (int v : options.face_vertices) {
      Require(v >= 0 && v < n_orig, fmt::format("face vertex id {} is out of range: {} has {} vertices",
                                                v, neutral_path.string(), n_orig));
      in_region[v] = 1;
    }
  } else {
    const int last = options.face_last < 0 ? n_orig : options.face_last;
    Require(last <= n_orig, fmt::format("face vertex range {}:{} exceeds the {} vertices of {}",
                                        options.face_first, last, n_orig, neutral_path.string()));
    std::fill(in_region.begin() + options.face_first, in_region.begin() + last, 1);
  }
  return in_region;
}

// Reads the shapes `files` in parallel into `basis` (3·#V × #files, deltas from
// the neutral of `rig` in mm) and their names into `names`; each is checked
// against the topology of the neutral OBJ `neutral_poly`.
void ReadShapeBasis(const std::vector<ShapeFile>& files, const PolygonMesh& neutral_poly,
                    const fs::path& neutral_path, const FaceRig& rig, const RigImportOptions& options,
                    Eigen::MatrixXf* basis, std::vector<std::string>* names) {
  const int nv = rig.num_vertices();
  basis->resize(3 * nv, static_cast<Eigen::Index>(files.size()));
  tbb::parallel_for(size_t{0}, files.size(), [&](size_t i) {
    const PolygonMesh shape = ReadObjPolygons(files[i].path);
    if (!SameTopology(neutral_poly, shape)) {
      throw Error(fmt::format("{}: topology differs from the neutral {} ({} vs {} positions, {} vs {} faces)",
                              files[i].path.string(), neutral_path.filename().string(),
                              shape.positions.rows(), neutral_poly.positions.rows(),
                              shape.face_offsets.size() - 1, neutral_poly.face_offsets.size() - 1));
    }
    const MatX3d V = GatherPositions(shape, rig.original_vertex) * options.units_to_mm;
    if (!V.allFinite()) throw Error(fmt::format("{}: non-finite vertex coordinates", files[i].path.string()));
    MatX3d D = V - rig.neutral.V;
    if (options.zero_threshold_mm > 0) {
      D = (D.array().abs() < options.zero_threshold_mm).select(0.0, D);
    }
    basis->col(static_cast<Eigen::Index>(i)) = Eigen::Map<const Eigen::VectorXd>(D.data(), D.size()).cast<float>();
  });
  for (const auto& f : files) names->push_back(f.name);
}

// Landmarks (OBJ vertex ids → the first rig vertex carrying that id): from
// options.landmark_ids, else from the folder's landmarks.json (a list of the 68
// iBUG ids or an object {name: id}), else none (with a warning).
void ImportLandmarks(const fs::path& folder, const RigImportOptions& options, FaceRig* rig, RigImportReport* rep) {
  const fs::path lm_path = folder / "landmarks.json";
  if (!options.landmark_ids.empty()) {
    AddLandmarks(options.landmark_ids, "--landmarks", rig);
  } else if (fs::exists(lm_path)) {
    const nlohmann::json j = ReadJsonFile(lm_path);
    std::vector<std::pair<std::string, int>> lms;
    if (j.is_array()) {
      const auto names = IbugLandmarkNames();
      Require(j.size() == 68, fmt::format("{}: a list of landmarks must hold the 68 iBUG vertex ids, has {}",
                                          lm_path.string(), j.size()));
      for (size_t i = 0; i < 68; ++i) {
        Require(j[i].is_number_integer(), fmt::format("{}: entry {} is not a vertex id", lm_path.string(), i));
        lms.emplace_back(names[i], j[i].get<int>());
      }
    } else if (j.is_object()) {
      for (auto it = j.begin(); it != j.end(); ++it) {
        Require(it->is_number_integer(), fmt::format("{}: landmark '{}' is not a vertex id", lm_path.string(), it.key()));
        lms.emplace_back(it.key(), it->get<int>());
      }
    } else {
      throw Error(fmt::format("{}: expected an object {{name: vertex id}} or a list of 68 ids", lm_path.string()));
    }
    AddLandmarks(lms, lm_path.string(), rig);
  } else {
    rep->warnings.push_back("no landmarks.json: the rig has no landmarks (the tracker needs the 68 iBUG landmarks)");
  }
}

}  // namespace

FaceRig ExtractParts(const FaceRig& rig, const std::vector<std::string>& parts) {
  Require(!rig.part_names.empty(), fmt::format("ExtractParts: {} has no parts", rig.source));
  std::vector<int> new_part(rig.part_names.size(), -1);
  FaceRig out;
  for (const auto& name : parts) {
    const int p = rig.PartIndex(name);
    if (p < 0 || new_part[p] >= 0) continue;
    new_part[p] = static_cast<int>(out.part_names.size());
    out.part_names.push_back(name);
  }
  Require(out.PartIndex("face") >= 0, "ExtractParts: the part \"face\" must be kept");
  const int nv = rig.num_vertices();
  std::vector<int> map(static_cast<size_t>(nv), -1);
  std::vector<int> kept;
  for (int v = 0; v < nv; ++v) {
    if (new_part[rig.vertex_part[v]] < 0) continue;
    map[v] = static_cast<int>(kept.size());
    kept.push_back(v);
  }
  const int n = static_cast<int>(kept.size());
  out.neutral.V.resize(n, 3);
  out.neutral.UV.resize(n, 2);
  out.identity_basis.resize(3 * n, rig.num_identity());
  out.expression_basis.resize(3 * n, rig.num_expressions());
  for (int i = 0; i < n; ++i) {
    const int v = kept[i];
    out.neutral.V.row(i) = rig.neutral.V.row(v);
    out.neutral.UV.row(i) = rig.neutral.UV.row(v);
    out.identity_basis.middleRows(3 * i, 3) = rig.identity_basis.middleRows(3 * v, 3);
    out.expression_basis.middleRows(3 * i, 3) = rig.expression_basis.middleRows(3 * v, 3);
    out.vertex_part.push_back(static_cast<uint8_t>(new_part[rig.vertex_part[v]]));
    out.original_vertex.push_back(rig.original_vertex.empty() ? v : rig.original_vertex[v]);
  }
  std::vector<Eigen::Vector3i> faces;
  for (Eigen::Index f = 0; f < rig.neutral.F.rows(); ++f) {
    const Eigen::Vector3i t = rig.neutral.F.row(f).transpose();
    if (map[t[0]] >= 0 && map[t[1]] >= 0 && map[t[2]] >= 0) faces.emplace_back(map[t[0]], map[t[1]], map[t[2]]);
  }
  out.neutral.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) out.neutral.F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  for (const auto& l : rig.landmarks) {
    Require(map[l.vertex] >= 0, fmt::format("ExtractParts: landmark '{}' lies in a part that is not kept", l.name));
    out.landmarks.push_back({l.name, map[l.vertex]});
  }
  out.identity_names = rig.identity_names;
  out.expression_names = rig.expression_names;
  out.regions = rig.regions;
  std::string kept_names;
  for (const auto& name : out.part_names) kept_names += (kept_names.empty() ? "" : ", ") + name;
  out.source = rig.source + "; parts " + kept_names;
  out.Validate("ExtractParts");
  return out;
}

FaceRig ImportObjRig(const fs::path& folder, const RigImportOptions& options, RigImportReport* report) {
  options.Check();
  RigImportReport local;
  RigImportReport& rep = report ? *report : local;
  Require(fs::is_directory(folder), fmt::format("{}: not a folder (expected a blendshape OBJ folder)",
                                                folder.string()));

  // 1. Classify the files.
  const ObjFolder files = ClassifyObjFiles(folder, options, &rep);
  const fs::path& neutral_path = files.neutral;

  // 2. The neutral defines topology, seams and the face region.
  const PolygonMesh neutral_poly = ReadObjPolygons(neutral_path);
  Require(!neutral_poly.corner_uv.empty(),
          fmt::format("{}: the neutral has no texture coordinates (vt); crease needs one UV chart",
                      neutral_path.string()));
  TriangulatedMesh tm = TriangulateAndSplitSeams(neutral_poly, neutral_path.string());
  const int n_orig = static_cast<int>(neutral_poly.positions.rows());
  rep.original_vertices = n_orig;
  std::vector<int> part_of_original;  // parts mode: OBJ vertex id → index in options.parts, -1 = none
  const std::vector<char> in_region = FaceRegion(options, n_orig, neutral_path, &part_of_original);
  rep.face_region_vertices = static_cast<int>(std::count(in_region.begin(), in_region.end(), 1));
  CropToRegion(&tm, in_region, &rep.dropped_triangles);
  Require(tm.mesh.num_faces() > 0, fmt::format("{}: no triangle lies entirely in the face region",
                                               neutral_path.string()));
  rep.split_vertices = tm.mesh.num_vertices() -
                       static_cast<int>(std::set<int>(tm.original_vertex.begin(), tm.original_vertex.end()).size());

  FaceRig rig;
  rig.neutral = tm.mesh;
  rig.neutral.V *= options.units_to_mm;
  rig.original_vertex = tm.original_vertex;
  if (!options.parts.empty()) AssignParts(options.parts, part_of_original, &rig, &rep);
  if (options.flip_v) rig.neutral.UV.col(1) = (1.0 - rig.neutral.UV.col(1).array()).matrix();
  rig.source = fmt::format("imported from {} ({} OBJ files, units x{} to mm)", folder.string(),
                           1 + files.identity.size() + files.expressions.size(), options.units_to_mm);

  // 3. All shapes, read in parallel; each checked against the neutral's topology.
  ReadShapeBasis(files.identity, neutral_poly, neutral_path, rig, options, &rig.identity_basis, &rig.identity_names);
  ReadShapeBasis(files.expressions, neutral_poly, neutral_path, rig, options, &rig.expression_basis,
                 &rig.expression_names);
  rep.obj_files = 1 + static_cast<int>(files.identity.size() + files.expressions.size());

  // 4. Landmarks (OBJ vertex ids → the first rig vertex carrying that id).
  ImportLandmarks(folder, options, &rig, &rep);

  // 5. Regions from the landmarks.
  if (rig.LandmarkIndex("ibug_68") >= 0) {
    rig.regions = RegionsFromLandmarks(rig, options.region_mask_size);
  } else {
    rep.warnings.push_back("no region masks: they are derived from the 68 iBUG landmarks, which the rig lacks");
  }
  rig.Validate(folder.string());
  return rig;
}

}  // namespace crease
