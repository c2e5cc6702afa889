// Held-out validation of the global tracker's landmark stage (paper Sec. 5, the
// DDE-style tracker of Cao et al. 2014; pipeline/capture/shape_regressor.h): the mean
// point-to-point error over the 68 iBUG points of a landmark source or of a trained
// regressor on labelled faces (pipeline/capture/labelled_faces.h), in pixels and over
// the inter-ocular distance (IOD, the outer eye corners). Values only: reports and
// their text or JSON live with the caller (tracker_training.h, the CLI).
//
// Initialisations of the regressor, both as in its training (ShapeRegressorOptions):
//   * "tracking": the truth under a random similarity (the previous frame of a tracker);
//   * "box": the mean shape in the truth's jittered square box (a detector start);
//   * "detector": RegressorLandmarkSource from a cold start — dlib's HOG box, the mean
//     shape in it and the cascade (detection rate and error on the detected frames).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "pipeline/capture/labelled_faces.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease {

// A landmark source from a cold start on each face (Reset, then Track: the
// detector, then the landmarks): detection rate, mean error on the faces it found,
// and the time per face.
struct LandmarkSourceEvaluation {
  std::string source;
  int faces = 0, found = 0;
  double error_px = 0, error_iod = 0;
  double ms_per_face = 0;
};
LandmarkSourceEvaluation EvaluateLandmarkSource(LandmarkSource& source, const std::vector<LabelledFace>& faces);

struct LandmarkErrorStats {
  int frames = 0;
  double initial_iod = 0, initial_px = 0;  // mean point-to-point error of the initial shapes
  double final_iod = 0, final_px = 0;      // … of the regressor's output
};

struct ShapeRegressorEvaluation {
  LandmarkErrorStats tracking;        // initialised from the perturbed truth
  LandmarkErrorStats box;             // initialised with the mean shape in a jittered box
  LandmarkSourceEvaluation detector;  // cold start (faces = 0 when not run)
  double predict_ms = 0;              // mean Predict time per image (one thread)
};

// Errors of `regressor` on `faces` from the "tracking" and "box" initialisations
// (random draws from `seed`); `detector_frames` > 0 also runs RegressorLandmarkSource
// from a cold start on the first that many faces.
ShapeRegressorEvaluation EvaluateShapeRegressor(const ShapeRegressor& regressor, const std::vector<LabelledFace>& faces,
                                                uint64_t seed, int detector_frames);

struct SequenceTrackingEvaluation {
  int frames = 0, found = 0, detections = 0;  // detections: frames where the detector ran
  double error_iod = 0, error_px = 0;         // on the frames where a face was found
  double track_ms = 0;                        // mean Track time on the frames without detection
};

// Runs RegressorLandmarkSource over `frames` in order (a video: each frame
// initialised from the previous one, the detector only at the start and after a loss).
SequenceTrackingEvaluation EvaluateSequenceTracking(const ShapeRegressor& regressor,
                                                    const std::vector<LabelledFace>& frames);

}  // namespace crease
