// libFuzzer target: crease rigs (.crig, zlib-compressed arrays) through ReadRig
// (core/face_rig.h).
#include "core/face_rig.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.crig");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadRig(path); });
  return 0;
}
