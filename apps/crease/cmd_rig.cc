// crease rig import | info | evaluate
#include <cstdio>
#include <filesystem>
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

}  // namespace

void AddRigCommands(CLI::App& app) {
  auto* rig_cmd = app.add_subcommand("rig", "Import, inspect and evaluate face rigs (blendshape models)");
  rig_cmd->require_subcommand(1);

  // rig import
  {
    auto* cmd = rig_cmd->add_subcommand("import", "Import a blendshape OBJ folder into a crease rig (.crig)");
    static std::string objs, units, face_range, face_mask, parts, landmarks, out;
    static RigImportOptions opt;
    static RigWriteOptions write;
    static bool keep_v = false;
    cmd->add_option("--objs", objs, "Folder: neutral.obj, expressions/*.obj or NAME.obj, identity/*.obj or "
                                    "identityNNN.obj, optional landmarks.json and regions/*.png")
        ->required();
    cmd->add_option("--units", units, "Units of the OBJ coordinates")->required()->check(CLI::IsMember({"mm", "cm", "m"}));
    cmd->add_option("--face-vertices", face_range,
                    "Face region as an OBJ vertex range: \"[A, B]\" includes B (ICT-FaceKit's tables), \"[A, B)\" excludes it");
    cmd->add_option("--face-mask", face_mask, "Face region as a JSON list of OBJ vertex ids");
    cmd->add_option("--parts", parts,
                    "A whole multi-part head: JSON list of {\"name\", \"vertices\": \"[A, B]\"}, one part \"face\" "
                    "(the UV chart); e.g. data/ict/ict_parts.json");
    cmd->add_option("--landmarks", landmarks,
                    "The 68 iBUG landmark OBJ vertex ids: \"1225,1888,...\", a text file of them, a JSON list, or "
                    "ICT-FaceKit's vertex_indices.json (idx_to_landmark_verts); overrides landmarks.json");
    cmd->add_option("--identity-modes", opt.max_identity_modes, "Keep only the first N identity modes (-1: all)")
        ->capture_default_str();
    cmd->add_flag("--compact", write.compact,
                  "Compact file: deltas quantised to 5 um in 16 bits, arrays zlib-compressed (format version 2)");
    cmd->add_option("--region-size", opt.region_mask_size, "Region mask resolution")->capture_default_str();
    cmd->add_flag("--keep-v", keep_v, "Do not flip v (the OBJ's v already grows downwards)");
    cmd->add_option("--out,-o", out, "Output rig file (.crig)")->required();
    cmd->callback([] {
      opt.units_to_mm = UnitsToMm(units);
      opt.flip_v = !keep_v;
      if (!face_range.empty()) {
        const VertexRange r = ParseVertexRange(face_range, "--face-vertices");
        opt.face_first = r.first;
        opt.face_last = r.end;
      }
      if (!parts.empty()) opt.parts = ReadRigParts(parts);
      if (!landmarks.empty()) opt.landmark_ids = ParseLandmarkIds(landmarks);
      if (!face_mask.empty()) {
        const nlohmann::json j = ReadJsonFile(face_mask);
        if (!j.is_array()) throw Error(fmt::format("{}: expected a JSON list of vertex ids", face_mask));
        for (const auto& v : j) {
          if (!v.is_number_integer()) throw Error(fmt::format("{}: expected a JSON list of vertex ids", face_mask));
          opt.face_vertices.push_back(v.get<int>());
        }
      }
      RigImportReport report;
      FaceRig rig = ImportObjRig(objs, opt, &report);
      // Region masks painted by hand override or add to the derived ones.
      const fs::path region_dir = fs::path(objs) / "regions";
      if (fs::is_directory(region_dir)) {
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
          for (auto& r : rig.regions) {
            if (r.name == name) {
              r.mask = mask;
              replaced = true;
            }
          }
          if (!replaced) rig.regions.push_back({name, mask});
          std::printf("region '%s' from %s\n", name.c_str(), e.path().string().c_str());
        }
      }
      WriteRig(out, rig, write);
      for (const auto& w : report.warnings) std::printf("warning: %s\n", w.c_str());
      for (const auto& [name, n] : report.part_vertices) std::printf("part %-22s %6d vertices\n", name.c_str(), n);
      std::printf("imported %d OBJ files from %s: %d of %d vertices in the face region, %d seam splits, "
                  "%d triangles dropped\n",
                  report.obj_files, objs.c_str(), report.face_region_vertices, report.original_vertices,
                  report.split_vertices, report.dropped_triangles);
      std::printf("wrote %s: %d vertices, %d triangles, %d identity modes, %d expressions, %zu landmarks, "
                  "%zu regions\n",
                  out.c_str(), rig.num_vertices(), rig.neutral.num_faces(), rig.num_identity(),
                  rig.num_expressions(), rig.landmarks.size(), rig.regions.size());
    });
  }

  // rig extract
  {
    auto* cmd = rig_cmd->add_subcommand("extract", "Keep only some parts of a multi-part rig (e.g. a face-only "
                                                  "tracking rig of a full head)");
    static std::string in, out, parts;
    cmd->add_option("RIG", in, "Rig (.crig) with parts")->required();
    cmd->add_option("--parts", parts, "Parts to keep, comma-separated (must include face)")->required();
    cmd->add_option("--out,-o", out, "Output rig (.crig)")->required();
    cmd->callback([] {
      const FaceRig rig = ReadRig(in);
      const FaceRig part = ExtractParts(rig, SplitComma(parts));
      WriteRig(out, part, {.compact = true});
      std::printf("wrote %s: %d of %d vertices, %d of %d triangles, parts %zu of %zu\n", out.c_str(),
                  part.num_vertices(), rig.num_vertices(), part.neutral.num_faces(), rig.neutral.num_faces(),
                  part.part_names.size(), rig.part_names.size());
    });
  }

  // rig info
  {
    auto* cmd = rig_cmd->add_subcommand("info", "Describe a rig: sizes, expressions, landmarks, regions");
    static std::string file, regions_png;
    static bool as_json = false;
    cmd->add_option("RIG", file, "Rig file (.crig)")->required();
    cmd->add_option("--regions-png", regions_png, "Write the UV layout with region masks and landmarks");
    cmd->add_flag("--json", as_json, "Print JSON");
    cmd->callback([] {
      const FaceRig rig = ReadRig(file);
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
      std::vector<std::string> missing;
      for (const auto& n : StandardRegionNames()) {
        if (!rig.FindRegion(n)) missing.push_back(n);
      }
      j["missing_standard_regions"] = missing;
      if (as_json) {
        std::printf("%s\n", j.dump(2).c_str());
      } else {
        std::printf("%s\n  source        %s\n  vertices      %d\n  triangles     %d\n", file.c_str(),
                    rig.source.c_str(), rig.num_vertices(), rig.neutral.num_faces());
        std::printf("  extent (mm)   %.1f x %.1f x %.1f\n", hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z());
        std::printf("  identity      %d modes\n  expressions   %d:", rig.num_identity(), rig.num_expressions());
        for (const auto& n : rig.expression_names) std::printf(" %s", n.c_str());
        std::printf("\n  landmarks     %zu\n  regions      ", rig.landmarks.size());
        for (const auto& r : rig.regions) {
          std::printf(" %s (%.1f%%)", r.name.c_str(), 100.0 * cv::countNonZero(r.mask) / r.mask.total());
        }
        std::printf("\n");
        if (!missing.empty()) {
          std::printf("  missing regions:");
          for (const auto& n : missing) std::printf(" %s", n.c_str());
          std::printf("\n");
        }
      }
      if (!regions_png.empty()) {
        WriteImage(regions_png, RegionImage(rig, 1024));
        if (!as_json) std::printf("wrote %s\n", regions_png.c_str());
      }
    });
  }

  // rig evaluate
  {
    auto* cmd = rig_cmd->add_subcommand("evaluate", "Evaluate a rig for identity and expression coefficients and "
                                                    "write the mesh (VTP adds displacement and region fields)");
    static std::string file, out;
    static std::vector<std::string> expressions, identity;
    cmd->add_option("RIG", file, "Rig file (.crig)")->required();
    cmd->add_option("--expression,-e", expressions, "Expression weight NAME=W (repeatable)");
    cmd->add_option("--identity,-i", identity, "Identity coefficient NAME=C or INDEX=C (repeatable)");
    cmd->add_option("--out,-o", out, "Output mesh (.ply, .obj, .vtp)")->required();
    cmd->callback([] {
      const FaceRig rig = ReadRig(file);
      const Eigen::VectorXd b = ParseWeights(expressions, rig.expression_names, "expression");
      const Eigen::VectorXd a = ParseWeights(identity, rig.identity_names, "identity");
      const TriMesh mesh = rig.Evaluate(a, b);
      if (LowerExtension(out) == ".vtp") {
        const MatX3d d = mesh.V - rig.neutral.V;
        Eigen::MatrixXd region = Eigen::MatrixXd::Constant(mesh.num_vertices(), 1, -1.0);
        for (int v = 0; v < mesh.num_vertices(); ++v) {
          for (size_t r = 0; r < rig.regions.size() && region(v, 0) < 0; ++r) {
            if (rig.InRegion(rig.regions[r].name, mesh.UV.row(v).transpose())) region(v, 0) = static_cast<double>(r);
          }
        }
        WriteVtp(out, mesh,
                 {{"displacement_mm", Eigen::MatrixXd(d)},
                  {"displacement_magnitude_mm", Eigen::MatrixXd(d.rowwise().norm())},
                  {"region", region}});
      } else {
        WriteAnyMesh(out, mesh);
      }
      std::printf("wrote %s (%d vertices, max displacement from the neutral %.3f mm)\n", out.c_str(),
                  mesh.num_vertices(), (mesh.V - rig.neutral.V).rowwise().norm().maxCoeff());
    });
  }
}

}  // namespace crease::app
