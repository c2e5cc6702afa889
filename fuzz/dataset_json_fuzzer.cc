// libFuzzer target: a sequence dataset's dataset.json as `crease track`, `capture`
// and `eval` read it: OpenFrameSource on the dataset folder
// (pipeline/capture/frame_source.h; the scratch folder holds one 2×2 frame) and the
// frame file pattern check DatasetFramePattern (synth/dataset.h).
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/image_io.h"
#include "core/json_io.h"
#include "pipeline/capture/frame_source.h"
#include "synth/dataset.h"
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
  crease::fuzz::ExpectCleanErrors([&] { crease::DatasetFramePattern(crease::ReadJsonFile(json_path), json_path); });
  return 0;
}
