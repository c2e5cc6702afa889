// libFuzzer target: landmark trackers (.ctrk) through LoadShapeRegressor
// (pipeline/capture/shape_regressor.h).
#include "pipeline/capture/shape_regressor.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.ctrk");
  crease::fuzz::ExpectCleanErrors([&] { crease::LoadShapeRegressor(path); });
  return 0;
}
