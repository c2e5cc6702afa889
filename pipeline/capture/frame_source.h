// Frames for the tracker and capture: a video file (OpenCV VideoCapture: mp4,
// avi, mov, mkv, …), a folder of images (png, jpg, exr, tif, bmp; sorted by name),
// or a crease sequence dataset (`crease synth sequence`: its frames/ folder and its
// calibrated camera). Frames come out as linear-light float RGB (CV_32FC3), the
// in-memory convention of DESIGN.md.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"

namespace crease {

struct FrameSourceInfo {
  std::string kind;  // "video", "images" or "dataset"
  std::filesystem::path path;
  int width = 0, height = 0;
  double fps = 30.0;        // from the video or dataset; 30 for image folders
  int frame_count = -1;     // −1 when the video does not say
  std::optional<Camera> camera;  // the dataset's calibration (intrinsics; cam_from_head of its first frame)
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The next frame as linear float RGB; false at the end. Throws Error naming the
  // file when a frame cannot be decoded.
  virtual bool Next(cv::Mat* frame) = 0;
  const FrameSourceInfo& info() const { return info_; }
  // The index of the frame Next() returned last: the number in its file name for
  // image folders and datasets whose files are numbered (a dataset written from
  // frame 30 on starts at 30), else its position from 0.
  int index() const { return index_; }

 protected:
  FrameSourceInfo info_;
  int index_ = -1;
};

// Opens a video file, an image folder or a crease dataset folder. Throws Error
// naming the path for a missing path, an unreadable or empty video, a folder
// without images.
std::unique_ptr<FrameSource> OpenFrameSource(const std::filesystem::path& path);

}  // namespace crease
