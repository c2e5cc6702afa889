// libFuzzer target: option YAML (`crease capture --config`) through SetOptionsFromYaml
// (core/options.h) into CaptureOptions, the largest options struct (every capture
// stage's fields), followed by its Check(), as the CLI does.
#include "core/options.h"
#include "pipeline/capture/capture.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = crease::fuzz::AsString(data, size);
  crease::fuzz::ExpectCleanErrors([&] {
    crease::CaptureOptions options;
    crease::SetOptionsFromYaml(text, "fuzz.yaml", &options);
    options.Check();
  });
  return 0;
}
