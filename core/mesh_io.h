// Mesh files: PLY (ascii and binary, read and write) and Wavefront OBJ (read and
// write), plus the OBJ polygon model that a rig importer needs to read many
// blendshapes of one topology. VTK .vtp files live in core/vtk_io.h (target
// crease_core_vtk) so that this header and crease_core stay free of VTK.
//
// UVs are stored exactly as the file holds them: no v flip is applied on reading
// or writing. crease's convention is v growing downwards (DESIGN.md); a file
// exported with v growing upwards must be flipped by the caller.
//
// Every writer goes through WriteFileAtomic: on error no partial file is left.
// Every reader error is a crease::Error whose message starts with the file name
// ("<file>: ..." or "<file>:<line>: ...") and names the problem.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/tri_mesh.h"

namespace crease {

// ---------------------------------------------------------------------------
// OBJ polygons
// ---------------------------------------------------------------------------

// A polygon mesh as stored in an OBJ file: positions and texture coordinates are
// indexed separately per face corner. Faces are stored in CSR form: face f has the
// corners face_offsets[f] .. face_offsets[f + 1] - 1.
struct PolygonMesh {
  MatX3d positions;                  // #P×3 "v" lines, file units (mm for crease data).
  MatX2d uvs;                        // #T×2 "vt" lines as in the file; may be empty.
  std::vector<int> face_offsets{0};  // #faces+1 offsets into the corner arrays.
  std::vector<int> corner_position;  // #corners position index (0-based) per corner.
  std::vector<int> corner_uv;        // #corners uv index per corner, or empty when the
                                     // faces carry no texture coordinates.

  int num_faces() const { return static_cast<int>(face_offsets.size()) - 1; }
  int num_corners() const { return static_cast<int>(corner_position.size()); }
  bool has_corner_uv() const { return !corner_uv.empty(); }
};

// Parses "v", "vt" and "f" statements. Face corners may be written as v, v/vt,
// v/vt/vn or v//vn; negative indices are relative to the end of the list read so
// far (-1 is the last "v"). "vn", "o", "g", "s", "usemtl", "mtllib", comments and
// the other display statements (l, p, vp, lod, ...) are ignored; free-form
// geometry (curv, surf, ...) and unknown statements are errors. Extra "v" values
// (w or vertex colours) are ignored; a "vt" without v gets v = 0.
// Throws Error "<file>:<line>: <problem>" for a bad number, an index of 0 or out of
// range, a face with fewer than 3 corners or using one position twice, faces with
// and without "vt" in one file, non-finite coordinates; "<file>: ..." when the file
// is missing.
PolygonMesh ReadObjPolygons(const std::filesystem::path& path);

// A triangle mesh derived from a PolygonMesh and, per output vertex, the position
// index it came from.
struct TriangulatedMesh {
  TriMesh mesh;                      // V, F and (when the polygons carry UVs) UV; no normals.
  std::vector<int> original_vertex;  // #V position index (row of shape.positions) per vertex.
};

// Converts polygons to a TriMesh with one UV per vertex:
//  * each polygon with corners c0..c(k-1) is fan-triangulated from its first
//    corner: (c0, c1, c2), (c0, c2, c3), ..., (c0, c(k-2), c(k-1)); this is exact
//    for planar convex polygons, which quads of face scans are close to;
//  * seams are split: one output vertex per distinct (position index, uv) pair
//    used by some corner, where two "vt" indices with equal coordinates count as
//    one uv (exporters repeat texture coordinates; splitting there would cut the
//    chart along a seam that is not one);
//  * output vertices are ordered by position index, then by first appearance of the
//    pair in corner order, so the output vertices of any range of position indices
//    form one contiguous range (a region given as a range of OBJ vertex ids stays a
//    range after the split);
//  * positions used by no face are dropped.
// Throws Error starting with `what` when the polygon arrays are inconsistent
// (offsets, index ranges, a face with fewer than 3 corners).
TriangulatedMesh TriangulateAndSplitSeams(const PolygonMesh& shape, const std::string& what);

// Positions of the split vertices for another shape of the same topology:
// row i = shape.positions.row(original_vertex[i]). Throws Error when an index is out
// of range for `shape`.
MatX3d GatherPositions(const PolygonMesh& shape, const std::vector<int>& original_vertex);

// True when `a` and `b` have the same numbers of positions, UVs and faces and
// identical face_offsets, corner_position and corner_uv arrays (so that one
// TriangulateAndSplitSeams result applies to both).
bool SameTopology(const PolygonMesh& a, const PolygonMesh& b);

// ---------------------------------------------------------------------------
// TriMesh files
// ---------------------------------------------------------------------------

// Reads a PLY file (ascii, binary_little_endian or binary_big_endian). Vertex
// properties: x y z (required, any numeric type), nx ny nz (normals, used when all
// three are present), texture coordinates as u v, s t, texture_u texture_v or
// texture_s texture_t. Faces come from the list property "vertex_indices" or
// "vertex_index" (any integer types) and are fan-triangulated from their first
// corner. Other properties and elements are skipped. The result is checked with
// ValidateMesh (non-finite values, degenerate triangles, no triangles).
TriMesh ReadPly(const std::filesystem::path& path);

struct PlyWriteOptions {
  bool binary = true;            // binary_little_endian; false writes ascii.
  bool double_precision = true;  // double properties (exact round trip); false: float.
};

// Writes x y z, nx ny nz (when the mesh has normals), u v (when it has UVs) and the
// faces as "list uchar int vertex_indices". Ascii values use the shortest decimal
// form that reads back to the same double, so both modes round-trip exactly with
// double precision. Throws Error when the mesh is invalid (ValidateMesh).
void WritePly(const std::filesystem::path& path, const TriMesh& mesh,
              const PlyWriteOptions& options = {});

// ReadObjPolygons + TriangulateAndSplitSeams + ValidateMesh. Normals in the file are
// ignored, vertices used by no face are dropped.
TriMesh ReadObj(const std::filesystem::path& path);

// Writes v, vt (when the mesh has UVs), vn (when it has normals) and f, with the
// same 1-based index for all three since attributes are per vertex. Numbers use the
// shortest decimal form that reads back to the same double, so V, F and UV
// round-trip exactly through ReadObj when every vertex is used by a triangle.
void WriteObj(const std::filesystem::path& path, const TriMesh& mesh);

// Dispatch on the lower-case extension: ".ply" or ".obj". Any other extension is an
// Error listing the supported ones (.vtp is handled by core/vtk_io.h).
TriMesh ReadMesh(const std::filesystem::path& path);
void WriteMesh(const std::filesystem::path& path, const TriMesh& mesh);

}  // namespace crease
