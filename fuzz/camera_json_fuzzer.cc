// libFuzzer target: camera.json / camK.json through ReadCamera (core/camera.h).
#include "core/camera.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "camera.json");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadCamera(path); });
  return 0;
}
