// crease rig import | info | evaluate
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/rig_import.h"
#include "core/vtk_io.h"

namespace crease::app {
namespace fs = std::filesystem;

namespace {

// Distinct colours for region masks (linear RGB).
const std::vector<cv::Vec3f>& RegionPalette() {
  static const std::vector<cv::Vec3f> p = {{0.90f, 0.30f, 0.10f}, {0.95f, 0.75f, 0.05f}, {0.10f, 0.45f, 0.90f},
                                           {0.05f, 0.75f, 0.85f}, {0.20f, 0.70f, 0.15f}, {0.55f, 0.85f, 0.20f},
                                           {0.75f, 0.20f, 0.75f}, {0.85f, 0.10f, 0.35f}, {0.45f, 0.30f, 0.15f}};
  return p;
}

// The rig's UV layout (wireframe) with the region masks tinted, for a person to check.
cv::Mat RegionImage(const FaceRig& rig, int size) {
  cv::Mat img(size, size, CV_32FC3, cv::Scalar(0.05, 0.05, 0.05));
  for (size_t r = 0; r < rig.regions.size(); ++r) {
    cv::Mat m;
    cv::resize(rig.regions[r].mask, m, cv::Size(size, size), 0, 0, cv::INTER_NEAREST);
    const cv::Vec3f c = RegionPalette()[r % RegionPalette().size()];
    img.setTo(cv::Scalar(c[0], c[1], c[2]) * 0.6, m);
  }
  const TriMesh& mesh = rig.neutral;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      cv::line(img, cv::Point2d(mesh.UV(a, 0) * size, mesh.UV(a, 1) * size),
               cv::Point2d(mesh.UV(b, 0) * size, mesh.UV(b, 1) * size), cv::Scalar(0.35, 0.35, 0.35), 1,
               cv::LINE_AA);
    }
  }
  for (const auto& l : rig.landmarks) {
    cv::circle(img, cv::Point2d(mesh.UV(l.vertex, 0) * size, mesh.UV(l.vertex, 1) * size), 3,
               cv::Scalar(1.0, 1.0, 1.0), cv::FILLED, cv::LINE_AA);
  }
  return img;
}

// "NAME=VALUE" pairs → vector indexed by name lookup.
Eigen::VectorXd ParseWeights(const std::vector<std::string>& pairs, const std::vector<std::string>& names,
                             const char* kind) {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(names.size()));
  for (const auto& p : pairs) {
    const auto eq = p.find('=');
    if (eq == std::string::npos) throw Error(fmt::format("--{} '{}': expected NAME=VALUE", kind, p));
    const std::string name = p.substr(0, eq);
    double value;
    try {
      size_t used = 0;
      value = std::stod(p.substr(eq + 1), &used);
      if (used != p.size() - eq - 1) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      throw Error(fmt::format("--{} '{}': '{}' is not a number", kind, p, p.substr(eq + 1)));
    }
    auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      // Identity modes may also be given by index.
      try {
        size_t used = 0;
        const int idx = std::stoi(name, &used);
        if (used == name.size() && idx >= 0 && idx < static_cast<int>(names.size())) {
          w[idx] = value;
          continue;
        }
      } catch (const std::exception&) {
      }
      std::string known;
      for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
      throw Error(fmt::format("--{}: the rig has no {} named '{}' (it has: {})", kind, kind, name, known));
    }
    w[it - names.begin()] = value;
  }
  return w;
}

// rig import
struct ImportArgs {
  std::string objs, units, face_range, face_mask, parts, landmarks, out;
  RigImportOptions opt;
  RigWriteOptions write;
  bool keep_v = false;
};

// --face-mask: a JSON list of OBJ vertex ids.
std::vector<int> ReadFaceMask(const std::string& path) {
  const nlohmann::json j = ReadJsonFile(path);
  if (!j.is_array()) throw Error(fmt::format("{}: expected a JSON list of vertex ids", path));
  std::vector<int> ids;
  for (const auto& v : j) {
    if (!v.is_number_integer()) throw Error(fmt::format("{}: expected a JSON list of vertex ids", path));
    ids.push_back(v.get<int>());
  }
  return ids;
}

// Region masks painted by hand (OBJS/regions/NAME.png) override or add to the derived ones.
void AddPaintedRegions(const fs::path& objs, FaceRig* rig) {
  const fs::path region_dir = objs / "regions";
  if (!fs::is_directory(region_dir)) return;
  for (const auto& e : fs::directory_iterator(region_dir)) {
    if (LowerExtension(e.path()) != ".png") continue;
    const cv::Mat img = ReadImage(e.path(), /*srgb=*/false);
    if (img.rows != img.cols) throw Error(fmt::format("{}: region masks must be square", e.path().string()));
    cv::Mat gray;
    if (img.channels() > 1) {
      std::vector<cv::Mat> ch;
      cv::split(img, ch);
      gray = ch[0];
    } else {
      gray = img;
    }
    cv::Mat mask = gray > 0.5f;
    const std::string name = e.path().stem().string();
    bool replaced = false;
    for (auto& r : rig->regions) {
      if (r.name == name) {
        r.mask = mask;
        replaced = true;
      }
    }
    if (!replaced) rig->regions.push_back({name, mask});
    std::printf("region '%s' from %s\n", name.c_str(), e.path().string().c_str());
  }
}

void RunImport(ImportArgs& a) {
  RigImportOptions& opt = a.opt;
  opt.units_to_mm = UnitsToMm(a.units);
  opt.flip_v = !a.keep_v;
  if (!a.face_range.empty()) {
    const VertexRange r = ParseVertexRange(a.face_range, "--face-vertices");
    opt.face_first = r.first;
    opt.face_last = r.end;
  }
  if (!a.parts.empty()) opt.parts = ReadRigParts(a.parts);
  if (!a.landmarks.empty()) opt.landmark_ids = ParseLandmarkIds(a.landmarks);
  if (!a.face_mask.empty()) {
    for (const int v : ReadFaceMask(a.face_mask)) opt.face_vertices.push_back(v);
  }
  RigImportReport report;
  FaceRig rig = ImportObjRig(a.objs, opt, &report);
  AddPaintedRegions(a.objs, &rig);
  WriteRig(a.out, rig, a.write);
  for (const auto& w : report.warnings) std::printf("warning: %s\n", w.c_str());
  for (const auto& [name, n] : report.part_vertices) std::printf("part %-22s %6d vertices\n", name.c_str(), n);
  std::printf("imported %d OBJ files from %s: %d of %d vertices in the face region, %d seam splits, "
              "%d triangles dropped\n",
              report.obj_files, a.objs.c_str(), report.face_region_vertices, report.original_vertices,
              report.split_vertices, report.dropped_triangles);
  std::printf("wrote %s: %d vertices, %d triangles, %d identity modes, %d expressions, %zu landmarks, "
              "%zu regions\n",
              a.out.c_str(), rig.num_vertices(), rig.neutral.num_faces(), rig.num_identity(), rig.num_expressions(),
              rig.landmarks.size(), rig.regions.size());
}

void AddImportCommand(CLI::App* rig_cmd) {
  auto* cmd = rig_cmd->add_subcommand("import", "Import a blendshape OBJ folder into a crease rig (.crig)");
  auto a = std::make_shared<ImportArgs>();
  cmd->add_option("--objs", a->objs, "Folder: neutral.obj, expressions/*.obj or NAME.obj, identity/*.obj or "
                                     "identityNNN.obj, optional landmarks.json and regions/*.png")
      ->required();
  cmd->add_option("--units", a->units, "Units of the OBJ coordinates")->required()->check(CLI::IsMember({"mm", "cm", "m"}));
  cmd->add_option("--face-vertices", a->face_range,
                  "Face region as an OBJ vertex range: \"[A, B]\" includes B (ICT-FaceKit's tables), \"[A, B)\" excludes it");
  cmd->add_option("--face-mask", a->face_mask, "Face region as a JSON list of OBJ vertex ids");
  cmd->add_option("--parts", a->parts,
                  "A whole multi-part head: JSON list of {\"name\", \"vertices\": \"[A, B]\"}, one part \"face\" "
                  "(the UV chart); e.g. data/ict/ict_parts.json");
  cmd->add_option("--landmarks", a->landmarks,
                  "The 68 iBUG landmark OBJ vertex ids: \"1225,1888,...\", a text file of them, a JSON list, or "
                  "ICT-FaceKit's vertex_indices.json (idx_to_landmark_verts); overrides landmarks.json");
  cmd->add_option("--identity-modes", a->opt.max_identity_modes, "Keep only the first N identity modes (-1: all)")
      ->capture_default_str();
  cmd->add_flag("--compact", a->write.compact,
                "Compact file: deltas quantised to 5 um in 16 bits, arrays zlib-compressed (format version 2)");
  cmd->add_option("--region-size", a->opt.region_mask_size, "Region mask resolution")->capture_default_str();
  cmd->add_flag("--keep-v", a->keep_v, "Do not flip v (the OBJ's v already grows downwards)");
  cmd->add_option("--out,-o", a->out, "Output rig file (.crig)")->required();
  cmd->callback([a] { RunImport(*a); });
}

// rig extract
struct ExtractArgs {
  std::string in, out, parts;
};

void AddExtractCommand(CLI::App* rig_cmd) {
  auto* cmd = rig_cmd->add_subcommand("extract", "Keep only some parts of a multi-part rig (e.g. a face-only "
                                                "tracking rig of a full head)");
  auto a = std::make_shared<ExtractArgs>();
  cmd->add_option("RIG", a->in, "Rig (.crig) with parts")->required();
  cmd->add_option("--parts", a->parts, "Parts to keep, comma-separated (must include face)")->required();
  cmd->add_option("--out,-o", a->out, "Output rig (.crig)")->required();
  cmd->callback([a] {
    const FaceRig rig = ReadRig(a->in);
    const FaceRig part = ExtractParts(rig, SplitComma(a->parts));
    WriteRig(a->out, part, {.compact = true});
    std::printf("wrote %s: %d of %d vertices, %d of %d triangles, parts %zu of %zu\n", a->out.c_str(),
                part.num_vertices(), rig.num_vertices(), part.neutral.num_faces(), rig.neutral.num_faces(),
                part.part_names.size(), rig.part_names.size());
  });
}

// rig info
struct InfoArgs {
  std::string file, regions_png;
  bool as_json = false;
};

// The standard regions (StandardRegionNames) the rig lacks.
std::vector<std::string> MissingStandardRegions(const FaceRig& rig) {
  std::vector<std::string> missing;
  for (const auto& n : StandardRegionNames()) {
    if (!rig.FindRegion(n)) missing.push_back(n);
  }
  return missing;
}

// `rig info --json`.
nlohmann::json RigInfoJson(const FaceRig& rig, const std::string& file) {
  const auto [lo, hi] = BoundingBox(rig.neutral);
  nlohmann::json j;
  j["file"] = file;
  j["source"] = rig.source;
  j["vertices"] = rig.num_vertices();
  j["triangles"] = rig.neutral.num_faces();
  j["extent_mm"] = {hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()};
  j["identity_modes"] = rig.num_identity();
  j["expressions"] = rig.expression_names;
  nlohmann::json lms = nlohmann::json::object();
  for (const auto& l : rig.landmarks) lms[l.name] = l.vertex;
  j["landmarks"] = lms;
  nlohmann::json regions = nlohmann::json::object();
  for (const auto& r : rig.regions) {
    regions[r.name] = {{"size", r.mask.rows},
                       {"coverage", static_cast<double>(cv::countNonZero(r.mask)) / r.mask.total()}};
  }
  j["regions"] = regions;
  j["missing_standard_regions"] = MissingStandardRegions(rig);
  return j;
}

// `rig info` as text.
void PrintRigInfo(const FaceRig& rig, const std::string& file) {
  const auto [lo, hi] = BoundingBox(rig.neutral);
  std::printf("%s\n  source        %s\n  vertices      %d\n  triangles     %d\n", file.c_str(), rig.source.c_str(),
              rig.num_vertices(), rig.neutral.num_faces());
  std::printf("  extent (mm)   %.1f x %.1f x %.1f\n", hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z());
  std::printf("  identity      %d modes\n  expressions   %d:", rig.num_identity(), rig.num_expressions());
  for (const auto& n : rig.expression_names) std::printf(" %s", n.c_str());
  std::printf("\n  landmarks     %zu\n  regions      ", rig.landmarks.size());
  for (const auto& r : rig.regions) {
    std::printf(" %s (%.1f%%)", r.name.c_str(), 100.0 * cv::countNonZero(r.mask) / r.mask.total());
  }
  std::printf("\n");
  const std::vector<std::string> missing = MissingStandardRegions(rig);
  if (!missing.empty()) {
    std::printf("  missing regions:");
    for (const auto& n : missing) std::printf(" %s", n.c_str());
    std::printf("\n");
  }
}

void AddInfoCommand(CLI::App* rig_cmd) {
  auto* cmd = rig_cmd->add_subcommand("info", "Describe a rig: sizes, expressions, landmarks, regions");
  auto a = std::make_shared<InfoArgs>();
  cmd->add_option("RIG", a->file, "Rig file (.crig)")->required();
  cmd->add_option("--regions-png", a->regions_png, "Write the UV layout with region masks and landmarks");
  cmd->add_flag("--json", a->as_json, "Print JSON");
  cmd->callback([a] {
    const FaceRig rig = ReadRig(a->file);
    if (a->as_json) {
      std::printf("%s\n", RigInfoJson(rig, a->file).dump(2).c_str());
    } else {
      PrintRigInfo(rig, a->file);
    }
    if (!a->regions_png.empty()) {
      WriteImage(a->regions_png, RegionImage(rig, 1024));
      if (!a->as_json) std::printf("wrote %s\n", a->regions_png.c_str());
    }
  });
}

// rig evaluate
struct EvaluateArgs {
  std::string file, out;
  std::vector<std::string> expressions, identity;
};

void RunEvaluate(const EvaluateArgs& a) {
  const FaceRig rig = ReadRig(a.file);
  const Eigen::VectorXd b = ParseWeights(a.expressions, rig.expression_names, "expression");
  const Eigen::VectorXd alpha = ParseWeights(a.identity, rig.identity_names, "identity");
  const TriMesh mesh = rig.Evaluate(alpha, b);
  if (LowerExtension(a.out) == ".vtp") {
    const MatX3d d = mesh.V - rig.neutral.V;
    Eigen::MatrixXd region = Eigen::MatrixXd::Constant(mesh.num_vertices(), 1, -1.0);
    for (int v = 0; v < mesh.num_vertices(); ++v) {
      for (size_t r = 0; r < rig.regions.size() && region(v, 0) < 0; ++r) {
        if (rig.InRegion(rig.regions[r].name, mesh.UV.row(v).transpose())) region(v, 0) = static_cast<double>(r);
      }
    }
    WriteVtp(a.out, mesh,
             {{"displacement_mm", Eigen::MatrixXd(d)},
              {"displacement_magnitude_mm", Eigen::MatrixXd(d.rowwise().norm())},
              {"region", region}});
  } else {
    WriteAnyMesh(a.out, mesh);
  }
  std::printf("wrote %s (%d vertices, max displacement from the neutral %.3f mm)\n", a.out.c_str(),
              mesh.num_vertices(), (mesh.V - rig.neutral.V).rowwise().norm().maxCoeff());
}

void AddEvaluateCommand(CLI::App* rig_cmd) {
  auto* cmd = rig_cmd->add_subcommand("evaluate", "Evaluate a rig for identity and expression coefficients and "
                                                  "write the mesh (VTP adds displacement and region fields)");
  auto a = std::make_shared<EvaluateArgs>();
  cmd->add_option("RIG", a->file, "Rig file (.crig)")->required();
  cmd->add_option("--expression,-e", a->expressions, "Expression weight NAME=W (repeatable)");
  cmd->add_option("--identity,-i", a->identity, "Identity coefficient NAME=C or INDEX=C (repeatable)");
  cmd->add_option("--out,-o", a->out, "Output mesh (.ply, .obj, .vtp)")->required();
  cmd->callback([a] { RunEvaluate(*a); });
}

}  // namespace

void AddRigCommands(CLI::App& app) {
  auto* rig_cmd = app.add_subcommand("rig", "Import, inspect and evaluate face rigs (blendshape models)");
  rig_cmd->require_subcommand(1);
  AddImportCommand(rig_cmd);
  AddExtractCommand(rig_cmd);
  AddInfoCommand(rig_cmd);
  AddEvaluateCommand(rig_cmd);
}

}  // namespace crease::app
