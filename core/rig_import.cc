#include "core/rig_import.h"

#include <algorithm>
#include <map>
#include <set>
#include <regex>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include "core/error.h"
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

}  // namespace

FaceRig ImportObjRig(const fs::path& folder, const RigImportOptions& options, RigImportReport* report) {
  options.Check();
  RigImportReport local;
  RigImportReport& rep = report ? *report : local;
  Require(fs::is_directory(folder), fmt::format("{}: not a folder (expected a blendshape OBJ folder)",
                                                folder.string()));

  // 1. Classify the files.
  fs::path neutral_path;
  std::vector<ShapeFile> identity, expressions;
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
      rep.warnings.push_back(fmt::format("{} treated as an expression", p.filename().string()));
      expressions.push_back({p, p.stem().string()});
    }
  }
  std::sort(identity.begin(), identity.end(), [](auto& a, auto& b) { return a.name < b.name; });
  std::sort(expressions.begin(), expressions.end(), [](auto& a, auto& b) { return a.name < b.name; });

  // 2. The neutral defines topology, seams and the face region.
  const PolygonMesh neutral_poly = ReadObjPolygons(neutral_path);
  Require(!neutral_poly.corner_uv.empty(),
          fmt::format("{}: the neutral has no texture coordinates (vt); crease needs one UV chart",
                      neutral_path.string()));
  TriangulatedMesh tm = TriangulateAndSplitSeams(neutral_poly, neutral_path.string());
  const int n_orig = static_cast<int>(neutral_poly.positions.rows());
  rep.original_vertices = n_orig;
  std::vector<char> in_region(n_orig, 0);
  if (!options.face_vertices.empty()) {
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
  rep.face_region_vertices = static_cast<int>(std::count(in_region.begin(), in_region.end(), 1));
  CropToRegion(&tm, in_region, &rep.dropped_triangles);
  Require(tm.mesh.num_faces() > 0, fmt::format("{}: no triangle lies entirely in the face region",
                                               neutral_path.string()));
  rep.split_vertices = tm.mesh.num_vertices() -
                       static_cast<int>(std::set<int>(tm.original_vertex.begin(), tm.original_vertex.end()).size());

  FaceRig rig;
  rig.neutral = tm.mesh;
  rig.neutral.V *= options.units_to_mm;
  if (options.flip_v) rig.neutral.UV.col(1) = (1.0 - rig.neutral.UV.col(1).array()).matrix();
  rig.original_vertex = tm.original_vertex;
  rig.source = fmt::format("imported from {} ({} OBJ files, units x{} to mm)", folder.string(),
                           1 + identity.size() + expressions.size(), options.units_to_mm);

  // 3. All shapes, read in parallel; each checked against the neutral's topology.
  const int nv = rig.num_vertices();
  auto read_basis = [&](const std::vector<ShapeFile>& files, Eigen::MatrixXf* basis,
                        std::vector<std::string>* names) {
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
  };
  read_basis(identity, &rig.identity_basis, &rig.identity_names);
  read_basis(expressions, &rig.expression_basis, &rig.expression_names);
  rep.obj_files = 1 + static_cast<int>(identity.size() + expressions.size());

  // 4. Landmarks (OBJ vertex ids → the first rig vertex carrying that id).
  const fs::path lm_path = folder / "landmarks.json";
  if (fs::exists(lm_path)) {
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
    std::map<int, int> first_rig_vertex;
    for (int v = nv - 1; v >= 0; --v) first_rig_vertex[rig.original_vertex[v]] = v;
    for (const auto& [name, id] : lms) {
      auto it = first_rig_vertex.find(id);
      Require(it != first_rig_vertex.end(),
              fmt::format("{}: landmark '{}' is OBJ vertex {}, which is not in the face region",
                          lm_path.string(), name, id));
      rig.landmarks.push_back({name, it->second});
    }
  } else {
    rep.warnings.push_back("no landmarks.json: the rig has no landmarks (the tracker needs the 68 iBUG landmarks)");
  }

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
