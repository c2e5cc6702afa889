// Importer for a blendshape OBJ folder — the common exchange form of face rigs
// (for example a light-stage rig: quads in centimetres with per-corner UVs, a
// neutral, 57 ARKit-named expressions and 100 identity modes, where only the
// first vertices form the face region).
//
// Folder layout (all OBJ files share one topology and UV layout):
//   neutral.obj                  the neutral (also accepted: the one *.obj whose name contains "neutral")
//   identity/NAME.obj            identity modes, as full shapes (mode = shape − neutral), sorted by name;
//   or identityNNN.obj           at the top level (stem "identity" followed by digits)
//   expressions/NAME.obj         expression blendshapes as full shapes, NAME = expression name;
//   or NAME.obj                  any other top-level OBJ
//   landmarks.json (optional)    {"ibug_1": 1234, …} or [1234, …] (68 ids → "ibug_1"…"ibug_68"),
//                                ids are vertex ids of the OBJ files (0-based); RigImportOptions::
//                                landmark_ids overrides it (e.g. ICT-FaceKit's list, ParseLandmarkIds)
// Polygons are fan-triangulated, vertices carrying several UVs are split along the
// seams (FaceRig::original_vertex maps back), coordinates are scaled to mm.
//
// A whole multi-part head (e.g. ICT-FaceKit: face, head and neck, mouth socket,
// gums and tongue, teeth, eyeballs, eyelashes, …) is imported with
// RigImportOptions::parts: named vertex ranges (ReadRigParts). Every polygon whose
// corners all lie in listed parts is kept; the part "face" is the UV chart.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/options.h"

namespace crease {

// A range of OBJ vertex ids (0-based), half-open: [first, end).
struct VertexRange {
  int first = 0;
  int end = 0;
};

// Parses a range whose end is unambiguous: "[A, B]" includes B (the form of
// ICT-FaceKit's tables), "[A, B)" excludes it. "A:B" and other forms are errors
// that name `what` and show both forms.
VertexRange ParseVertexRange(const std::string& text, const std::string& what);

// A named part of a multi-part head: the OBJ vertices of its ranges.
struct RigPart {
  std::string name;
  std::vector<VertexRange> ranges;
};

// Reads a parts file: a JSON list of {"name": NAME, "vertices": RANGE or [RANGE, …]}
// with ParseVertexRange's RANGE strings, e.g.
//   [{"name": "face", "vertices": "[0, 9408]"}, {"name": "teeth", "vertices": "[17039, 21450]"}]
// One part must be named "face". Errors name the file and the entry (overlapping
// ranges, unknown keys, a duplicate name).
std::vector<RigPart> ReadRigParts(const std::filesystem::path& path);

// Landmark vertex ids from the command line: a comma- or space-separated list
// ("1225, 1888, …", ICT-FaceKit's README form) or a file holding one: a JSON list,
// a JSON object with "idx_to_landmark_verts" (ICT-FaceKit's vertex_indices.json),
// or text. 68 ids name "ibug_1" … "ibug_68". Errors name the spec or the file.
std::vector<int> ParseLandmarkIds(const std::string& spec);

// A face mask file (`crease rig import --face-mask`): a JSON list of OBJ vertex ids
// (RigImportOptions::face_vertices). Errors name the file.
std::vector<int> ReadFaceMask(const std::filesystem::path& path);

// The rig restricted to the named parts (e.g. a face-only tracking rig of a full
// head): their vertices, the triangles whose corners all lie in them, the same
// identity and expression modes, UVs, regions and OBJ ids (original_vertex; filled
// with the full rig's vertex ids when the rig has none). Parts not in the rig are
// ignored. Throws Error when the rig has no parts, when "face" is not kept, or
// when a landmark's vertex is dropped.
FaceRig ExtractParts(const FaceRig& rig, const std::vector<std::string>& parts);

struct RigImportOptions {
  double units_to_mm = 1.0;  // scale of the OBJ coordinates: 10 for cm, 1 for mm, 1000 for m
  // Face region as a half-open range [face_first, face_last) of OBJ vertex ids;
  // face_last = -1 means all vertices. Triangles with a corner outside are dropped.
  int face_first = 0;
  int face_last = -1;
  // Alternatively, an explicit list of OBJ vertex ids (overrides the range when non-empty).
  std::vector<int> face_vertices;
  // A whole multi-part head (overrides face_first/face_last/face_vertices): vertices
  // in no part are dropped with their polygons. Vertices of "face" whose UV lies
  // outside [0,1]² (polygons of the face's rim that use another texture) form the
  // part "face_rim"; every part but the face gets a UV tile of its own, u in
  // [2 + p, 3 + p), so that UV-space stages see only the face chart.
  std::vector<RigPart> parts;
  // The 68 iBUG landmarks as OBJ vertex ids (overrides landmarks.json when non-empty).
  std::vector<int> landmark_ids;
  // Keep only the first N identity modes (sorted by name); -1 keeps all.
  int max_identity_modes = -1;
  // Region mask resolution (masks derived from the 68 landmarks when present).
  int region_mask_size = 512;
  // Deltas smaller than this (mm) are stored as exact zeros (cleans export noise).
  double zero_threshold_mm = 0.0;
  // OBJ texture coordinates have v growing upwards; crease's UV convention has v
  // growing downwards like image rows (DESIGN.md), so v is flipped on import.
  bool flip_v = true;

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Parses the --units flag: "mm", "cm", "m" → the factor to mm.
double UnitsToMm(const std::string& units);

struct RigImportReport {
  int obj_files = 0;
  int original_vertices = 0;  // in the OBJ files
  int face_region_vertices = 0;
  int split_vertices = 0;     // extra vertices created along UV seams
  int dropped_triangles = 0;  // outside the face region (or in no part)
  std::vector<std::pair<std::string, int>> part_vertices;  // per part of the rig, its vertex count
  std::vector<std::string> warnings;
};

// Imports the folder. Errors name the offending file: missing neutral, a shape
// whose topology differs from the neutral's, malformed OBJ, landmark ids out of range.
FaceRig ImportObjRig(const std::filesystem::path& folder, const RigImportOptions& options,
                     RigImportReport* report = nullptr);

}  // namespace crease
