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
//                                ids are vertex ids of the OBJ files (0-based)
// Polygons are fan-triangulated, vertices carrying several UVs are split along the
// seams (FaceRig::original_vertex maps back), coordinates are scaled to mm.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/options.h"

namespace crease {

struct RigImportOptions {
  double units_to_mm = 1.0;  // scale of the OBJ coordinates: 10 for cm, 1 for mm, 1000 for m
  // Face region as a half-open range [face_first, face_last) of OBJ vertex ids;
  // face_last = -1 means all vertices. Triangles with a corner outside are dropped.
  int face_first = 0;
  int face_last = -1;
  // Alternatively, an explicit list of OBJ vertex ids (overrides the range when non-empty).
  std::vector<int> face_vertices;
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
  int dropped_triangles = 0;  // outside the face region
  std::vector<std::string> warnings;
};

// Imports the folder. Errors name the offending file: missing neutral, a shape
// whose topology differs from the neutral's, malformed OBJ, landmark ids out of range.
FaceRig ImportObjRig(const std::filesystem::path& folder, const RigImportOptions& options,
                     RigImportReport* report = nullptr);

}  // namespace crease
