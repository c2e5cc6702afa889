// libFuzzer target: a capture folder's capture.json through ReadCaptureJson
// (pipeline/capture/capture_io.h), as `crease eval` reads it.
#include <nlohmann/json.hpp>

#include "pipeline/capture/capture_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "capture.json");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadCaptureJson(path); });
  return 0;
}
