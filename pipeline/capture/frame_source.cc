#include "pipeline/capture/frame_source.h"

#include <algorithm>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <vector>

#include "core/color.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"

namespace crease {

namespace fs = std::filesystem;

namespace {

// 8-bit BGR (OpenCV's video decoding) → linear float RGB.
cv::Mat LinearFromBgr8(const cv::Mat& bgr) {
  static const std::vector<float> lut = [] {
    std::vector<float> t(256);
    for (int i = 0; i < 256; ++i) t[i] = static_cast<float>(SrgbToLinear(i / 255.0));
    return t;
  }();
  cv::Mat out(bgr.size(), CV_32FC3);
  for (int j = 0; j < bgr.rows; ++j) {
    const uint8_t* p = bgr.ptr<uint8_t>(j);
    cv::Vec3f* q = out.ptr<cv::Vec3f>(j);
    const int c = bgr.channels();
    for (int i = 0; i < bgr.cols; ++i) {
      if (c >= 3) {
        q[i] = cv::Vec3f(lut[p[c * i + 2]], lut[p[c * i + 1]], lut[p[c * i]]);
      } else {
        q[i] = cv::Vec3f(lut[p[i]], lut[p[i]], lut[p[i]]);
      }
    }
  }
  return out;
}

cv::Mat ToRgb(const cv::Mat& image) {
  if (image.channels() == 3) return image;
  cv::Mat out;
  if (image.channels() == 1) {
    cv::Mat planes[] = {image, image, image};
    cv::merge(planes, 3, out);
  } else {
    // RGBA (or 2 channels: gray + alpha): drop the alpha.
    std::vector<cv::Mat> planes;
    cv::split(image, planes);
    if (planes.size() >= 3) {
      planes.resize(3);
    } else {
      planes = {planes[0], planes[0], planes[0]};
    }
    cv::merge(planes, out);
  }
  return out;
}

class VideoSource final : public FrameSource {
 public:
  explicit VideoSource(const fs::path& path) : capture_(path.string()) {
    Require(capture_.isOpened(), fmt::format("{}: cannot open this video (unsupported codec or not a video)",
                                             path.string()));
    info_.kind = "video";
    info_.path = path;
    info_.fps = capture_.get(cv::CAP_PROP_FPS);
    if (!(info_.fps > 0)) info_.fps = 30.0;
    const double n = capture_.get(cv::CAP_PROP_FRAME_COUNT);
    info_.frame_count = n > 0 ? static_cast<int>(n) : -1;
    // Decode the first frame now: an empty or broken video is an error at open.
    Require(capture_.read(first_) && !first_.empty(), fmt::format("{}: the video has no frames", path.string()));
    info_.width = first_.cols;
    info_.height = first_.rows;
  }
  bool Next(cv::Mat* frame) override {
    cv::Mat bgr;
    ++index_;
    if (!first_.empty()) {
      bgr = first_;
      first_.release();
    } else if (!capture_.read(bgr) || bgr.empty()) {
      return false;
    }
    *frame = LinearFromBgr8(bgr);
    return true;
  }

 private:
  cv::VideoCapture capture_;
  cv::Mat first_;
};

class ImageFolderSource final : public FrameSource {
 public:
  ImageFolderSource(const fs::path& folder, const std::string& kind) {
    info_.kind = kind;
    info_.path = folder;
    for (const auto& e : fs::directory_iterator(folder)) {
      const std::string ext = LowerExtension(e.path());
      if (e.is_regular_file() &&
          (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".exr" || ext == ".tif" || ext == ".tiff" ||
           ext == ".bmp")) {
        files_.push_back(e.path());
      }
    }
    std::sort(files_.begin(), files_.end());
    Require(!files_.empty(), fmt::format("{}: no images (png, jpg, exr, tif, bmp) in this folder", folder.string()));
    info_.frame_count = static_cast<int>(files_.size());
    const cv::Mat first = ReadImage(files_.front());
    info_.width = first.cols;
    info_.height = first.rows;
  }
  FrameSourceInfo& mutable_info() { return info_; }
  bool Next(cv::Mat* frame) override {
    if (next_ >= files_.size()) return false;
    const fs::path& f = files_[next_];
    const std::string stem = f.stem().string();
    const bool numbered = !stem.empty() && stem.size() < 10 &&
                          std::all_of(stem.begin(), stem.end(), [](char c) { return c >= '0' && c <= '9'; });
    index_ = numbered ? std::stoi(stem) : static_cast<int>(next_);
    ++next_;
    cv::Mat image = ToRgb(ReadImage(f));
    Require(image.cols == info_.width && image.rows == info_.height,
            fmt::format("{}: {}×{} differs from the first frame's {}×{}", f.string(), image.cols, image.rows,
                        info_.width, info_.height));
    *frame = image;
    return true;
  }

 private:
  std::vector<fs::path> files_;
  size_t next_ = 0;
};

// dataset.json's frame rate (30 when absent). A top-level array or an "fps" that is
// not a number was nlohmann's type_error, an internal error (fuzz/dataset_json_fuzzer,
// issue 19).
double DatasetFps(const nlohmann::json& ds, const fs::path& json_path) {
  Require(ds.is_object(), fmt::format("{}: a dataset description must be a JSON object, not {}", json_path.string(),
                                      ds.type_name()));
  const auto fps = ds.find("fps");
  if (fps == ds.end()) return 30.0;
  Require(fps->is_number() && fps->get<double>() > 0,
          fmt::format("{}: fps must be a positive number, got {}", json_path.string(), fps->dump()));
  return fps->get<double>();
}

}  // namespace

std::unique_ptr<FrameSource> OpenFrameSource(const fs::path& path) {
  Require(fs::exists(path), fmt::format("{}: does not exist", path.string()));
  if (fs::is_directory(path)) {
    if (fs::is_regular_file(path / "dataset.json")) {
      // A crease sequence dataset: its frames and its camera.
      const double fps = DatasetFps(ReadJsonFile(path / "dataset.json"), path / "dataset.json");
      auto source = std::make_unique<ImageFolderSource>(path / "frames", "dataset");
      FrameSourceInfo& info = source->mutable_info();
      info.path = path;
      info.fps = fps;
      if (fs::is_regular_file(path / "camera.json")) info.camera = ReadCamera(path / "camera.json");
      return source;
    }
    return std::make_unique<ImageFolderSource>(path, "images");
  }
  RequireReadableFile(path);
  return std::make_unique<VideoSource>(path);
}

}  // namespace crease
