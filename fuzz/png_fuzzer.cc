// libFuzzer target: PNG images through ReadImage (core/image_io.h): the header
// checks (layout, at most 10^8 pixels) and the decode through OpenImageIO.
#include <opencv2/core/mat.hpp>

#include "core/image_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.png");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadImage(path); });
  return 0;
}
