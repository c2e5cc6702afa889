// libFuzzer target: performance scripts (sequence.yaml) through ParseSequenceYaml
// (synth/sequence.h), in memory.
#include "synth/sequence.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = crease::fuzz::AsString(data, size);
  crease::fuzz::ExpectCleanErrors([&] { crease::ParseSequenceYaml(text, "fuzz.yaml"); });
  return 0;
}
