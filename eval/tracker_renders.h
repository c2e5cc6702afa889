// Training the global tracker's landmark regressor (paper Sec. 5, the DDE-style
// tracker of Cao et al. 2014; pipeline/capture/shape_regressor.h) on studio renders
// (issue 5, part 1): random actors, expressions (including extreme ones), head poses,
// light rigs and sensor settings, rendered with synth/ and labelled with the rig's
// iBUG landmarks; a held-out split of other actors. The training, the held-out
// evaluation and the report are the studio-free pipeline/capture/tracker_training.h;
// this file only renders the faces.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/face_rig.h"
#include "pipeline/capture/labelled_faces.h"
#include "pipeline/capture/tracker_training.h"

namespace crease {

// Renders `renders_per_actor` labelled stills of each actor seed (random expression,
// pose, light and sensor settings as in `options`). Deterministic for the same seeds.
// The rig must have the landmarks "ibug_1" … "ibug_68".
std::vector<LabelledFace> RenderLabelledFaces(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                                              const TrackerTrainingOptions& options);

// Renders train_actors + test_actors actors (seeds data_seed·1000 + a and
// data_seed·1000 + 500 + a) and trains (TrainAndEvaluateTracker; held-out = the test
// actors). `save_dir` (optional) also writes the renders (train/ and test/ subfolders).
// `extra_train`: labelled faces (e.g. photographs) added to the training renders.
TrackerTrainingResult TrainTrackerOnRenders(const FaceRig& rig, const TrackerTrainingOptions& options,
                                            const std::filesystem::path& save_dir = {},
                                            const std::vector<LabelledFace>& extra_train = {});

}  // namespace crease
