// libFuzzer target: a sequence dataset's dataset.json through its one reader,
// ReadSequenceDatasetInfo (core/dataset_info.h), with the paths it derives, and
// OpenFrameSource on the dataset folder (pipeline/capture/frame_source.h; the scratch
// folder holds one 2×2 frame), as `crease track`, `capture` and `eval` read it.
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/image_io.h"
#include "core/json_io.h"
#include "pipeline/capture/frame_source.h"
#include "core/dataset_info.h"
#include "fuzz/fuzz_util.h"

namespace {
const std::filesystem::path& DatasetDir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = crease::fuzz::ScratchDir() / "dataset";
    crease::WriteImage(d / "frames" / "000000.png", cv::Mat(2, 2, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5)));
    return d;
  }();
  return dir;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::filesystem::path& dir = DatasetDir();
  const std::filesystem::path json_path = dir / "dataset.json";
  std::ofstream(json_path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  crease::fuzz::ExpectCleanErrors([&] { crease::OpenFrameSource(dir); });
  crease::fuzz::ExpectCleanErrors([&] {
    const crease::SequenceDatasetInfo info = crease::ReadSequenceDatasetInfo(dir);
    (void)info.FramePath(info.last_frame());
    (void)info.TrackingRigPath();
    if (!info.displacement_pattern.empty()) (void)info.DisplacementPath(info.first_frame);
  });
  return 0;
}
