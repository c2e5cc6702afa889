// libFuzzer target: Wavefront OBJ through ReadObj (core/mesh_io.h): the polygon
// parser, seam splitting and triangulation, and mesh validation.
#include "core/mesh_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.obj");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadObj(path); });
  return 0;
}
