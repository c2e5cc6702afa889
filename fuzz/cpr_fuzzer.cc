// libFuzzer target: training pairs (.cpr) through ReadTrainingPairs
// (pipeline/training/trainer.h).
#include "pipeline/training/trainer.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.cpr");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadTrainingPairs(path); });
  return 0;
}
