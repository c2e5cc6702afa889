// libFuzzer target: VTK XML PolyData through ReadVtp (core/vtk_io.h), with its
// point-data fields: the size checks of core/vtp_check.h, then VTK's reader.
#include <vector>

#include "core/vtk_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = crease::fuzz::WriteInput(data, size, "input.vtp");
  crease::fuzz::ExpectCleanErrors([&] {
    std::vector<crease::VertexField> fields;
    crease::ReadVtp(path, &fields);
  });
  return 0;
}
