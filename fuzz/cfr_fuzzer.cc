// libFuzzer target: a capture frame (frames/NNNNNN.cfr) through ReadCaptureFrameArrays
// (pipeline/capture/capture_io.h), as `crease eval` reads it.
#include "pipeline/capture/capture_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "000000.cfr");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadCaptureFrameArrays(path); });
  return 0;
}
