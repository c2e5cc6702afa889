#include "synth/scanned_head.h"

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "synth/hires_surface.h"

namespace crease {

void ScannedHeadOptions::VisitFields(OptionVisitor& v) {
  v.Field("units_to_mm", units_to_mm);
  v.Field("flip_v", flip_v);
  v.Field("displacement_scale_mm", displacement_scale_mm);
  v.Field("displacement_midlevel", displacement_midlevel);
  v.Field("grid_resolution", grid_resolution);
  v.Field("phong_alpha", phong_alpha);
}

void ScannedHeadOptions::Check() const {
  const char* o = "ScannedHeadOptions";
  CheckGt(o, "units_to_mm", units_to_mm, 0.0);
  CheckGe(o, "grid_resolution", grid_resolution, 16);
  CheckLe(o, "grid_resolution", grid_resolution, 8192);
  CheckGe(o, "phong_alpha", phong_alpha, 0.0);
  CheckLe(o, "phong_alpha", phong_alpha, 1.0);
}

ScannedHead LoadScannedHead(const std::filesystem::path& mesh_path, const std::filesystem::path& albedo_path,
                            const std::filesystem::path& displacement_path, const ScannedHeadOptions& options) {
  options.Check();
  const std::string ext = LowerExtension(mesh_path);
  Require(ext == ".obj" || ext == ".ply",
          fmt::format("{}: scanned heads are read from OBJ or PLY (glTF is not supported yet)", mesh_path.string()));
  TriMesh scan = ReadMesh(mesh_path);
  ValidateMesh(scan, mesh_path.string(), {.uv = true});
  scan.V *= options.units_to_mm;
  if (options.flip_v) scan.UV.col(1) = (1.0 - scan.UV.col(1).array()).matrix();
  scan.N = VertexNormals(scan);

  ScannedHead head;
  head.source_vertices = scan.num_vertices();
  cv::Mat albedo = ReadImage(albedo_path);
  Require(albedo.channels() == 3 || albedo.channels() == 4 || albedo.channels() == 1,
          fmt::format("{}: the albedo texture must be grey, RGB or RGBA", albedo_path.string()));
  if (albedo.channels() == 4) cv::cvtColor(albedo, albedo, cv::COLOR_RGBA2RGB);
  if (albedo.channels() == 1) cv::cvtColor(albedo, albedo, cv::COLOR_GRAY2RGB);
  cv::min(albedo, 1.0, albedo);
  cv::max(albedo, 0.0, albedo);
  head.materials.albedo = albedo;
  head.materials.specular = cv::Mat(albedo.size(), CV_32FC1, cv::Scalar(MaterialPreset("skin").specular));
  head.materials.roughness = cv::Mat(albedo.size(), CV_32FC1, cv::Scalar(MaterialPreset("skin").roughness));
  head.materials.face = MaterialPreset("skin");
  head.materials.face.textured = true;

  if (displacement_path.empty()) {
    head.surface = scan;
    return head;
  }
  cv::Mat disp = ReadImage(displacement_path, /*srgb=*/false);
  Require(disp.channels() == 1 || disp.channels() == 3,
          fmt::format("{}: a displacement map must have one channel (or three equal ones)", displacement_path.string()));
  if (disp.channels() == 3) cv::extractChannel(disp, disp, 0);
  Require(disp.rows == disp.cols,
          fmt::format("{}: displacement maps must be square ({}x{})", displacement_path.string(), disp.cols, disp.rows));
  Require(cv::checkRange(disp), fmt::format("{}: the displacement map holds NaN or infinite values", displacement_path.string()));
  disp = (disp - options.displacement_midlevel) * options.displacement_scale_mm;
  // Resample on a UV grid the way the studio builds its actors: the scan is a rig without blendshapes.
  FaceRig as_rig;
  as_rig.neutral = scan;
  as_rig.neutral.N.resize(0, 3);
  const HiResLayout layout = BuildHiResLayout(as_rig, options.grid_resolution, disp.rows);
  Require(layout.num_vertices() > 0,
          fmt::format("{}: no triangle of the UV layout lies inside [0,1]²", mesh_path.string()));
  head.surface = BuildHiResSurface(layout, scan, disp, options.phong_alpha);
  return head;
}

}  // namespace crease
