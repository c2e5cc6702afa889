// Helpers for tests that build their fixtures with the studio (synth/).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/face_rig.h"
#include "synth/actor.h"
#include "synth/dataset.h"
#include "synth/procedural_rig.h"
#include "synth/sequence.h"
#include "test_util.h"

namespace crease::testing {

// The studio's procedural head rig, built once per process.
inline const FaceRig& ProceduralRig() {
  static const FaceRig rig = BuildProceduralRig();
  return rig;
}

// An empty folder for a fixture shared by the cases of one test binary. One folder
// per process: ctest runs the cases of a file in parallel processes. Removed at exit
// when the process's tests passed.
inline std::filesystem::path FixtureDir(const std::string& name) { return ProcessTempDir(name); }

// Expression weights β (one per blendshape of `rig`) with the named ones set and
// the rest 0; a name the rig does not have fails the test.
inline Eigen::VectorXd ExpressionWeights(const FaceRig& rig,
                                         const std::vector<std::pair<std::string, double>>& weights) {
  Eigen::VectorXd beta = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const auto& [name, value] : weights) {
    const int e = rig.ExpressionIndex(name);
    EXPECT_GE(e, 0) << name;
    if (e >= 0) beta[e] = value;
  }
  return beta;
}

// A tiny studio sequence dataset in FixtureDir(name): the first `frames` frames of
// the sequence preset `preset`, actor 3 on the procedural rig, 160×120 under front
// light, without maps or a tracking rig.
inline std::filesystem::path TinySequenceDataset(const std::string& name, const std::string& preset, int frames) {
  const std::filesystem::path d = FixtureDir(name);
  ActorOptions ao;
  ao.resolution = 256;
  ao.surface_min_vertices = 1000;
  SequenceDatasetOptions o;
  o.studio.width = 160;
  o.studio.height = 120;
  o.studio.samples_per_axis = 1;
  o.studio.light = "front";
  o.write_maps = false;
  o.max_frames = frames;
  o.tracking_parts.clear();
  WriteSequenceDataset(ProceduralRig(), GenerateActor(ProceduralRig(), 3, ao), MakePresetSequence(preset), o, d);
  return d;
}

}  // namespace crease::testing
