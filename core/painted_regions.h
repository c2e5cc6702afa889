// Region masks painted by hand (`crease rig import`: OBJS/regions/NAME.png), which
// override or add to the regions an importer derives from the landmarks.
// Part of crease_core_image (it reads pictures through core/image_io.h).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"

namespace crease {

// Sets region `name` of `rig` from a square picture (linear, one or more channels):
// inside where the first channel exceeds 0.5. Replaces a region of that name, else
// adds one. Throws Error naming `what` when the picture is not square.
void SetRegionFromPicture(const std::string& name, const cv::Mat& picture, const std::string& what, FaceRig* rig);

// SetRegionFromPicture for every DIR/NAME.png (region NAME), in directory order;
// returns the pictures used (none when DIR is not a folder).
std::vector<std::filesystem::path> AddPaintedRegions(const std::filesystem::path& dir, FaceRig* rig);

}  // namespace crease
