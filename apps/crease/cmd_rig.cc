// crease rig import | info | evaluate
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/painted_regions.h"
#include "core/rig_import.h"
#include "core/rig_info.h"
#include "core/vtk_io.h"

namespace crease::app {
namespace fs = std::filesystem;

namespace {

// rig import
struct ImportArgs {
  std::string objs, units, face_range, face_mask, parts, landmarks, out;
  RigImportOptions opt;
  RigWriteOptions write;
  bool keep_v = false;
};

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
  for (const fs::path& p : AddPaintedRegions(fs::path(a.objs) / "regions", &rig)) {
    std::printf("region '%s' from %s\n", p.stem().string().c_str(), p.string().c_str());
  }
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
      WriteImage(a->regions_png, RegionPicture(rig, 1024));
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
  const Eigen::VectorXd b = ParseNamedCoefficients(a.expressions, rig.expression_names, "expression");
  const Eigen::VectorXd alpha = ParseNamedCoefficients(a.identity, rig.identity_names, "identity");
  const TriMesh mesh = rig.Evaluate(alpha, b);
  if (LowerExtension(a.out) == ".vtp") {
    const MatX3d d = mesh.V - rig.neutral.V;
    WriteVtp(a.out, mesh,
             {{"displacement_mm", Eigen::MatrixXd(d)},
              {"displacement_magnitude_mm", Eigen::MatrixXd(d.rowwise().norm())},
              {"region", VertexRegionIndices(rig, mesh)}});
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
