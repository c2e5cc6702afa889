// libFuzzer target: glTF scans through ReadGltfMesh (synth/scanned_head.h). An input
// starting with the binary magic "glTF" is read as .glb, anything else as .gltf
// (JSON); the embedded base-colour texture is decoded too.
#include <cstring>

#include <opencv2/core/mat.hpp>

#include "synth/scanned_head.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  const auto path = crease::fuzz::WriteInput(data, size, binary ? "input.glb" : "input.gltf");
  crease::fuzz::ExpectCleanErrors([&] {
    cv::Mat base_color;
    crease::ReadGltfMesh(path, &base_color);
  });
  return 0;
}
