// A tiny studio scan set and training options small enough for tests of the
// training stage (tests/trainer_test.cc, tests/training_run_test.cc).
#pragma once

#include <filesystem>

#include "pipeline/training/trainer.h"
#include "synth/dataset.h"
#include "tests/synth_test_util.h"

namespace crease::testing {

// One old actor (deep wrinkles), a neutral and a brow raise, at 256² maps, on the
// procedural rig (the set names it): written once per process.
inline const std::filesystem::path& TinyScans() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = FixtureDir("trainer_tiny_scans");
    ActorOptions ao;
    ao.resolution = 256;
    ao.surface_min_vertices = 1000;
    ao.age_min = ao.age_max = 1.0;  // many deep lines
    // The rig's own expressions: tests/trainer_test.cc's bounds test extraction on
    // scans the rig fits exactly. With the default personal deviations (σ 0.3,
    // 40 mm) the rig-fit residual leaks into D^j: forehead band correlation 0.56,
    // RMSE 0.027 mm against a true RMS of 0.019 mm (issue 17).
    ao.expression_deviation = 0.0;
    ScanSetOptions so;
    so.studio.width = 320;
    so.studio.height = 240;
    so.studio.samples_per_axis = 1;
    so.cameras = 2;
    so.expressions = {"browInnerUp=1,browOuterUp=1"};
    so.overwrite = true;
    WriteScanSet(ProceduralRig(), {11}, ao, so, d);
    return d;
  }();
  return dir;
}

// Training options for TinyScans: 256² maps, 8² patches, 6 PCA dimensions, 40 ferns.
inline TrainingOptions TinyTrainingOptions() {
  TrainingOptions o;
  o.detail.map_resolution = 256;
  o.detail.operator_resolution = 96;
  o.patch.patch_size = 8;
  o.pca.dimensions = 6;
  o.ferns.num_ferns = 40;
  o.ferns.num_sampled_pixels = 20;
  o.ferns.shrinkage = 10;
  o.fit.max_fit_vertices = 400;
  return o;
}

}  // namespace crease::testing
