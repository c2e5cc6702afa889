// VTK XML PolyData (.vtp) meshes with per-vertex fields for ParaView, and .pvd
// collections for time series. Lives in target crease_core_vtk (links VTK); VTK
// headers stay in vtk_io.cc. PLY and OBJ are in core/mesh_io.h.
//
// Errors are crease::Error with messages starting with the file name; VTK's own
// error output is captured into those messages instead of being printed.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/tri_mesh.h"

namespace crease {

// A per-vertex array shown in ParaView (error maps, displacements, weights).
struct VertexField {
  std::string name;        // array name; unique, not "UV" or "Normals" (those are the mesh's own)
  Eigen::MatrixXd values;  // #V×k: k = 1 for a scalar, 3 for a vector; any k >= 1 is written
};

// Writes the mesh as VTK XML PolyData: points (double), triangles as polys, UVs as
// the texture-coordinate array "UV", normals as the normals array "Normals", and
// each field as a double point-data array. `binary` selects raw appended
// (zlib-compressed) data, which round-trips exactly; false writes ascii. Atomic.
// Throws Error when the mesh is invalid or a field is misnamed or mis-sized.
void WriteVtp(const std::filesystem::path& path, const TriMesh& mesh,
              const std::vector<VertexField>& fields = {}, bool binary = true);

// Reads VTK XML PolyData. Polygons are fan-triangulated from their first corner and
// triangle strips are split into triangles; vertices and lines are ignored. The
// texture-coordinate array (or an array named "UV") gives UV, the normals array
// gives N. When `fields` is given it receives every other numeric point-data array
// (#V × number of components). The mesh is checked with ValidateMesh. Throws
// Error for a missing or malformed file; every size in the file is checked
// against the file's length before VTK allocates it (core/vtp_check.h).
TriMesh ReadVtp(const std::filesystem::path& path, std::vector<VertexField>* fields = nullptr);

// A ParaView time series (.pvd collection of .vtp files). Typical use:
//   PvdWriter series(out / "tracking.pvd");
//   for (int t = 0; ...) {
//     const auto vtp = out / fmt::format("frame_{:04d}.vtp", t);
//     WriteVtp(vtp, mesh, fields);
//     series.Add(t / fps, vtp);
//     series.Write();  // after each Add, so an interrupted run leaves a valid series
//   }
class PvdWriter {
 public:
  explicit PvdWriter(const std::filesystem::path& pvd_path);

  // Adds a time step, seconds (any finite value). `vtp_file` is a path as usual
  // (absolute or relative to the working directory); it is stored relative to the
  // .pvd's folder when possible so that the series can be moved as a whole.
  void Add(double time, const std::filesystem::path& vtp_file);

  // Writes the collection XML (atomically) with all steps added so far.
  void Write() const;

  const std::filesystem::path& path() const { return path_; }
  int num_steps() const { return static_cast<int>(steps_.size()); }

 private:
  struct Step {
    double time;
    std::string file;  // as written in the XML, forward slashes
  };
  std::filesystem::path path_;
  std::filesystem::path folder_;  // absolute folder of path_, fixed at construction
  std::vector<Step> steps_;
};

// ReadMesh / WriteMesh (core/mesh_io.h: .ply, .obj) plus .vtp (without fields).
TriMesh ReadAnyMesh(const std::filesystem::path& path);
void WriteAnyMesh(const std::filesystem::path& path, const TriMesh& mesh);

}  // namespace crease
