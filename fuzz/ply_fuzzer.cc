// libFuzzer target: PLY meshes (ascii and binary) through ReadPly (core/mesh_io.h).
#include "core/mesh_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.ply");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadPly(path); });
  return 0;
}
