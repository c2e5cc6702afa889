// libFuzzer target: actor.json through ReadActor (synth/actor.h).
#include "synth/actor.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "actor.json");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadActor(path); });
  return 0;
}
