// libFuzzer target: a sequence dataset's frame truth (truth/NNNNNN.json) through
// ReadFrameTruth (eval/tracking_metrics.h), beside a valid truth/NNNNNN_vertices.bin
// of four vertices (the .bin is checked against its own length).
#include <filesystem>
#include <fstream>

#include "eval/tracking_metrics.h"
#include "fuzz/fuzz_util.h"

namespace {

// The dataset folder: <scratch>/truth/ with the vertices file written once.
const std::filesystem::path& Dataset() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = crease::fuzz::ScratchDir();
    std::filesystem::create_directories(d / "truth");
    const float vertices[12] = {10, 20, 1, 30, 20, 1, 30, 40, 0, 10, 40, 1};
    std::ofstream(d / "truth" / "000000_vertices.bin", std::ios::binary)
        .write(reinterpret_cast<const char*>(vertices), sizeof(vertices));
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::filesystem::path& dataset = Dataset();
  crease::fuzz::WriteInput(data, size, "truth/000000.json");
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadFrameTruth(dataset, 0, -1); });
  return 0;
}
