// crease mesh info | convert | render
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/mesh_info.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/preview_render.h"
#include "core/timer.h"
#include "core/vtk_io.h"
#include "synth/scanned_head.h"

namespace crease::app {
namespace fs = std::filesystem;

namespace {

// Any mesh crease reads: PLY, OBJ, VTP (with its per-vertex fields) or glTF
// (.gltf, .glb: metres to mm, the file's UVs as they are).
TriMesh ReadMeshFile(const std::string& path, std::vector<VertexField>* fields) {
  const std::string ext = LowerExtension(path);
  if (ext == ".vtp") return ReadVtp(path, fields);
  if (ext == ".gltf" || ext == ".glb") return ReadGltfMesh(path);
  return ReadAnyMesh(path);
}

// `mesh info --json`: the mesh's summary and its per-vertex fields.
nlohmann::json MeshInfo(const fs::path& path, const TriMesh& mesh, const std::vector<VertexField>& fields) {
  nlohmann::json j = MeshInfoJson(mesh, path.string());
  nlohmann::json f = nlohmann::json::array();
  for (const auto& field : fields) f.push_back({{"name", field.name}, {"components", field.values.cols()}});
  j["fields"] = f;
  return j;
}

void WriteMeshFile(const fs::path& out, const TriMesh& mesh, bool ascii, bool single,
                   const std::vector<VertexField>& fields) {
  const std::string ext = LowerExtension(out);
  if (ext == ".ply") {
    WritePly(out, mesh, {.binary = !ascii, .double_precision = !single});
  } else if (ext == ".vtp") {
    WriteVtp(out, mesh, fields, !ascii);
  } else {
    WriteAnyMesh(out, mesh);
  }
}

}  // namespace

void AddMeshCommands(CLI::App& app) {
  auto* mesh = app.add_subcommand("mesh", "Inspect, convert and render triangle meshes (PLY, OBJ, VTP)");
  mesh->require_subcommand(1);

  // mesh info
  {
    auto* cmd = mesh->add_subcommand("info", "Print a mesh's size, bounds, topology and fields; validates it");
    struct Args {
      std::string file;
      bool as_json = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("FILE", a->file, "Mesh file (.ply, .obj, .vtp)")->required();
    cmd->add_flag("--json", a->as_json, "Print JSON instead of text");
    cmd->callback([a] {
      std::vector<VertexField> fields;
      const TriMesh m = ReadMeshFile(a->file, &fields);
      ValidateMesh(m, a->file);
      const nlohmann::json j = MeshInfo(a->file, m, fields);
      if (a->as_json) {
        std::printf("%s\n", j.dump(2).c_str());
        return;
      }
      std::printf("%s\n", a->file.c_str());
      std::printf("  vertices           %d\n", m.num_vertices());
      std::printf("  triangles          %d\n", m.num_faces());
      std::printf("  uv                 %s\n", m.has_uv() ? "yes" : "no");
      std::printf("  normals            %s\n", m.has_normals() ? "yes" : "no");
      const auto& ext = j["extent_mm"];
      std::printf("  extent (mm)        %.3f x %.3f x %.3f\n", ext[0].get<double>(), ext[1].get<double>(),
                  ext[2].get<double>());
      std::printf("  surface area (mm2) %.3f\n", j["surface_area_mm2"].get<double>());
      std::printf("  mean edge (mm)     %.4f\n", j["mean_edge_length_mm"].get<double>());
      std::printf("  edges              %d (%d boundary, %d non-manifold)\n", j["edges"].get<int>(),
                  j["boundary_edges"].get<int>(), j["non_manifold_edges"].get<int>());
      for (const auto& f : fields) {
        std::printf("  field              %s (%ld components)\n", f.name.c_str(), static_cast<long>(f.values.cols()));
      }
    });
  }

  // mesh convert
  {
    auto* cmd = mesh->add_subcommand("convert", "Convert between PLY, OBJ and VTP (VTP fields are kept VTP to VTP)");
    struct Args {
      std::string in, out;
      bool ascii = false, single = false, normals = false;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("IN", a->in, "Input mesh (.ply, .obj, .vtp)")->required();
    cmd->add_option("OUT", a->out, "Output mesh (.ply, .obj, .vtp)")->required();
    cmd->add_flag("--ascii", a->ascii, "ASCII PLY / VTP instead of binary");
    cmd->add_flag("--float", a->single, "PLY: 32-bit float coordinates instead of 64-bit");
    cmd->add_flag("--normals", a->normals, "Compute area-weighted vertex normals and write them");
    cmd->callback([a] {
      std::vector<VertexField> fields;
      TriMesh m = ReadMeshFile(a->in, &fields);
      ValidateMesh(m, a->in);
      if (a->normals) m.N = VertexNormals(m);
      WriteMeshFile(a->out, m, a->ascii, a->single, fields);
      std::printf("wrote %s (%d vertices, %d triangles)\n", a->out.c_str(), m.num_vertices(), m.num_faces());
    });
  }

  // mesh render
  {
    auto* cmd = mesh->add_subcommand("render", "Ray-trace a shaded preview image of a mesh (Embree)");
    struct Args {
      std::string in, out, field;
      PreviewRenderOptions opt;
      bool no_shadows = false, diverging = false;
      std::vector<double> range;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("FILE", a->in, "Mesh (.ply, .obj, .vtp)")->required();
    cmd->add_option("--out,-o", a->out, "Output image (.png, .exr, .jpg)")->required();
    cmd->add_option("--width", a->opt.width, "Image width (pixels)")->capture_default_str();
    cmd->add_option("--height", a->opt.height, "Image height (pixels)")->capture_default_str();
    cmd->add_option("--fov", a->opt.fov_deg, "Horizontal field of view (degrees)")->capture_default_str();
    cmd->add_option("--azimuth", a->opt.azimuth_deg, "Camera orbit about +y (degrees)")->capture_default_str();
    cmd->add_option("--elevation", a->opt.elevation_deg, "Camera orbit upwards (degrees)")->capture_default_str();
    cmd->add_flag("--no-shadows", a->no_shadows, "Do not trace shadow rays");
    cmd->add_option("--field", a->field, "VTP input: colour by this per-vertex scalar field (or vector magnitude)");
    cmd->add_option("--range", a->range, "Colour range LO HI for --field (default: the field's min and max)")
        ->expected(2);
    cmd->add_flag("--diverging", a->diverging, "Use a blue-white-red map for --field (signed data)");
    cmd->callback([a] {
      a->opt.shadows = !a->no_shadows;
      std::vector<VertexField> fields;
      const TriMesh m = ReadMeshFile(a->in, &fields);
      MatX3d colors;
      if (!a->field.empty()) {
        const VertexField* f = nullptr;
        for (const auto& x : fields) f = x.name == a->field ? &x : f;
        if (!f) throw Error(fmt::format("{}: has no per-vertex field '{}'", a->in, a->field));
        const Eigen::VectorXd s = f->values.cols() == 1 ? Eigen::VectorXd(f->values.col(0))
                                                        : Eigen::VectorXd(f->values.rowwise().norm());
        const double lo = a->range.size() == 2 ? a->range[0] : s.minCoeff();
        const double hi = a->range.size() == 2 ? a->range[1] : s.maxCoeff();
        colors = ScalarToColors(s, lo, hi, a->diverging);
      }
      TimingReport timing;
      PreviewRender r;
      {
        ScopedTimer t(&timing, "render");
        r = RenderPreview(m, a->opt, colors);
      }
      WriteImage(a->out, r.image);
      std::printf("wrote %s (%dx%d, %d triangles, %.0f ms, %d pixels on the mesh)\n", a->out.c_str(), a->opt.width,
                  a->opt.height, m.num_faces(), 1e3 * timing.TotalSeconds(), r.covered_pixels);
    });
  }
}

}  // namespace crease::app
