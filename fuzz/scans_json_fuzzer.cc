// libFuzzer target: a scan set's scans.json through ReadScanSet
// (pipeline/training/scan_set.h). The scratch folder holds the files that the seed
// (fuzz/corpus/scans_json) names, so mutations get past the existence checks.
#include <fstream>

#include "pipeline/training/scan_set.h"
#include "fuzz/fuzz_util.h"

namespace {
const std::filesystem::path& ScanSetDir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = crease::fuzz::ScratchDir() / "scans";
    for (const char* scan : {"neutral", "smile"}) {
      std::filesystem::create_directories(d / "actor_000" / scan);
      for (const char* file : {"mesh.ply", "cam0.json", "cam0_studio.png", "expression_displacement.exr"})
        std::ofstream(d / "actor_000" / scan / file) << "x";
    }
    std::ofstream(d / "rig.crig") << "x";
    return d;
  }();
  return dir;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::filesystem::path& dir = ScanSetDir();
  std::ofstream(dir / "scans.json", std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  crease::fuzz::ExpectCleanErrors([&] { crease::ReadScanSet(dir); });
  return 0;
}
