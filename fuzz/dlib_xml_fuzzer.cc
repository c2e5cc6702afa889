// libFuzzer target: a dlib imglab XML landmark file through ReadDlibXmlFaces
// (pipeline/capture/labelled_faces.h, in crease_capture), beside the 8×8 image face.png
// its seeds name (written once with crease's WriteImage). Small crops (box_px 16) keep
// executions fast.
#include <filesystem>

#include <opencv2/core.hpp>

#include "core/image_io.h"
#include "fuzz/fuzz_util.h"
#include "pipeline/capture/labelled_faces.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const bool image_written = [] {
    crease::WriteImage(crease::fuzz::ScratchDir() / "face.png", cv::Mat(8, 8, CV_32FC3, cv::Scalar(0.2, 0.5, 0.8)));
    return true;
  }();
  (void)image_written;
  const auto path = crease::fuzz::WriteInput(data, size, "labels.xml");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadDlibXmlFaces(path, {.crop_scale = 1.0, .box_px = 16}); });
  return 0;
}
