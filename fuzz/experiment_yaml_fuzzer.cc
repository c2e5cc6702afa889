// libFuzzer target: experiment configs through ParseExperimentConfig (eval/experiment.h),
// in memory: YAML parsing with its alias limit, sections, sweep, profiles, variants.
#include "eval/experiment.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = crease::fuzz::AsString(data, size);
  crease::fuzz::ExpectCleanErrors([&] { crease::ParseExperimentConfig(text, "fuzz.yaml"); });
  return 0;
}
