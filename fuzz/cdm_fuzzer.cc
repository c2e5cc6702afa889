// libFuzzer target: detail models (.cdm, core/array_file.h container) through
// ReadDetailModel (pipeline/training/detail_model.h), which validates the model.
#include "pipeline/training/detail_model.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.cdm");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadDetailModel(path); });
  return 0;
}
