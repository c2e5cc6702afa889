// Helpers for tests that build their fixtures with the studio (synth/).
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "core/face_rig.h"
#include "synth/procedural_rig.h"

namespace crease::testing {

// The studio's procedural head rig, built once per process.
inline const FaceRig& ProceduralRig() {
  static const FaceRig rig = BuildProceduralRig();
  return rig;
}

// An empty folder for a fixture shared by the cases of one test binary. One folder
// per process: ctest runs the cases of a file in parallel processes.
inline std::filesystem::path FixtureDir(const std::string& name) {
  const std::filesystem::path d =
      std::filesystem::path(::testing::TempDir()) / "crease_tests" / (name + "_" + std::to_string(getpid()));
  std::filesystem::remove_all(d);
  return d;
}

}  // namespace crease::testing
