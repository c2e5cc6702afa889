#include "core/painted_regions.h"

#include <fmt/format.h>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"

namespace crease {
namespace fs = std::filesystem;

void SetRegionFromPicture(const std::string& name, const cv::Mat& picture, const std::string& what, FaceRig* rig) {
  Require(picture.rows == picture.cols, fmt::format("{}: region masks must be square", what));
  cv::Mat gray;
  if (picture.channels() > 1) {
    std::vector<cv::Mat> ch;
    cv::split(picture, ch);
    gray = ch[0];
  } else {
    gray = picture;
  }
  const cv::Mat mask = gray > 0.5f;
  bool replaced = false;
  for (auto& r : rig->regions) {
    if (r.name == name) {
      r.mask = mask;
      replaced = true;
    }
  }
  if (!replaced) rig->regions.push_back({name, mask});
}

std::vector<fs::path> AddPaintedRegions(const fs::path& dir, FaceRig* rig) {
  std::vector<fs::path> used;
  if (!fs::is_directory(dir)) return used;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (LowerExtension(e.path()) != ".png") continue;
    SetRegionFromPicture(e.path().stem().string(), ReadImage(e.path(), /*srgb=*/false), e.path().string(), rig);
    used.push_back(e.path());
  }
  return used;
}

}  // namespace crease
