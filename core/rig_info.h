// A rig described for people and tools (`crease rig info`, `crease rig evaluate`):
// its summary as JSON, the standard regions it lacks, a picture of its regions in
// UV, the region of each vertex, and coefficients given by name.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"

namespace crease {

// The names of StandardRegionNames() the rig has no region for, in that order.
std::vector<std::string> MissingStandardRegions(const FaceRig& rig);

// The rig's summary (`crease rig info --json`): file, source, vertices, triangles,
// extent_mm of the neutral's bounding box, identity_modes, expressions, landmarks
// (name → vertex), regions (name → mask size and covered fraction) and
// missing_standard_regions.
nlohmann::json RigInfoJson(const FaceRig& rig, const std::string& file);

// The rig's UV layout as a size×size linear RGB picture (CV_32FC3): region masks
// tinted in distinct colours (a later region paints over an earlier one), the
// neutral's triangles as grey lines and the landmarks as white dots, for a person
// to check the regions.
cv::Mat RegionPicture(const FaceRig& rig, int size);

// Per vertex of `mesh` (the rig's topology and UVs), the index in rig.regions of
// the first region whose mask contains the vertex's UV, or -1 (#V×1).
Eigen::MatrixXd VertexRegionIndices(const FaceRig& rig, const TriMesh& mesh);

// Coefficients indexed like `names` from "NAME=VALUE" items (unlisted names are 0).
// A name may also be given as its index ("3=0.5": identity modes). Errors name
// the item as "--<kind> 'ITEM'" and, for an unknown name, list the known ones.
Eigen::VectorXd ParseNamedCoefficients(const std::vector<std::string>& items, const std::vector<std::string>& names,
                                       const std::string& kind);

}  // namespace crease
