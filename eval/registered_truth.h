// The truth as the capture's own UV mapping sees it (issue 17: where the detail
// ladder's R2 → R3 step loses the signal).
//
// D^t lives in the UV layout of the tracked mesh L~^t: texel u holds the detail
// regressed from the image pixel π(L~^t(u)). When L~^t is off by a few pixels, that
// pixel shows another part of the true face, so even a D^t that draws every
// wrinkle exactly where the image shows it would not correlate with D*(u). This
// unit moves a truth map through the image: texel u of the registered map holds
// the truth at the true surface point seen at pixel π(L~^t(u)):
//
//   1. splat: every truth texel seen by the camera from the true mesh (the texture
//      extractor's visibility: depth buffer and view angle) is averaged into the
//      pixel nearest its projection — the truth map as an image;
//   2. resample: that image is sampled bilinearly at π(L~^t(u)) with the capture's
//      texture extractor, exactly as T^t is; a texel whose four pixels do not all
//      hold splatted truth is NaN (no data), as is a texel L~^t does not see.
//
// With L~^t equal to the true mesh the registered map is the truth at the image's
// resolution (R2 of the ladder); the drop in correlation from the truth to its
// registered map measures what the tracker's misregistration alone costs, and
// D^t against the registered truth measures the regression on the image as it
// was tracked. An evaluation tool: the method never sees it.
#pragma once

#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/types.h"
#include "pipeline/capture/frame_texture.h"

namespace crease {

class TruthRegistration {
 public:
  // The rig whose UV layout the maps use (the capture's), the camera and the
  // capture's texture options (map resolution R, visibility).
  TruthRegistration(const FaceRig& rig, const CameraIntrinsics& intrinsics, const FrameTextureOptions& options);

  // `maps`: R×R CV_32F truth maps in the rig's UV layout; `true_cam` and
  // `tracked_cam`: the true mesh and L~^t (#V×3, camera frame, mm). Returns one
  // registered R×R CV_32F map per input (NaN where there is no data). Throws Error
  // for wrong map sizes or vertex arrays.
  std::vector<cv::Mat> Register(const MatX3d& true_cam, const MatX3d& tracked_cam,
                                const std::vector<cv::Mat>& maps) const;

  const FrameTextureExtractor& extractor() const { return extractor_; }

 private:
  FrameTextureExtractor extractor_;
  cv::Mat zero_image_;  // H×W CV_32F, for the true mesh's visibility
};

}  // namespace crease
