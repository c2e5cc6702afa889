// Training the landmark regressor of the global tracker (paper Sec. 5, the DDE-style
// tracker of Cao et al. 2014; crease's ESR cascade, pipeline/capture/shape_regressor.h)
// on labelled faces: photographs read from a folder or a dlib XML file
// (pipeline/capture/labelled_faces.h), or studio renders (eval/tracker_renders.h,
// which adds the rendering). The method returns the regressor and its training facts
// (TrainTrackerOnFaces); held-out validation (pipeline/capture/landmark_evaluation.h)
// is a separate call, and TrainAndEvaluateTracker joins the two into the report that
// `crease train-tracker` writes (TrackerTrainingReport; its text and JSON are made in
// tracker_report.cc).
//
// Differences from the paper:
//   1. Sec. 5 tracks with DDE's regressor of the displaced dynamic expression trained
//      on the user's blendshapes; crease trains an ESR landmark cascade (68 iBUG points)
//      on labelled faces and fits the rig separately (shape_regressor.h, difference 1).
//   2. The paper's training data are not available: crease trains on studio renders,
//      on labelled photographs (iBUG 300-W, dlib's XML), or on both.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/options.h"
#include "pipeline/capture/labelled_faces.h"
#include "pipeline/capture/landmark_evaluation.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease {

// The fields from train_actors to actor_resolution set the studio renders
// (eval/tracker_renders.h) and are ignored when training on labelled faces; their keys
// stay here, beside the others, and one config trains either way.
struct TrackerTrainingOptions {
  // Actors rendered for training. 36 since 0.4.7 (was 12): on the six novel actors of
  // the paper profile's `tracking-refinement` (seeds 1–3, `talking` and `fast-motion`,
  // crease track) the landmark error fell from 4.6–11.2 px (mean 7.6) to 4.0–4.9 px
  // (mean 4.6), the visible-vertex error from 8.4 to 6.2 px. With 12 actors it reached
  // 0.09 inter-ocular distances on faces unlike theirs (a skin darker than all but one
  // of them; a mouth opening wide). Training takes about 3 min on an idle 2-core
  // machine (quickstart: 164 s of renders, 23 s of training; 12 actors: 100 s in all).
  int train_actors = 36;
  int test_actors = 3;               // held-out actors (other seeds), ≥ 1
  int renders_per_actor = 40;        // stills per actor
  uint64_t data_seed = 1;            // actors (seeds data_seed·1000 + a), expressions, poses, lights, sensor, held-out inits
  int width = 320;                   // image size, pixels
  int height = 240;
  double fov_deg = 50.0;             // horizontal field of view, degrees
  double max_yaw_deg = 30.0;         // head yaw uniform in ±max_yaw_deg
  double max_pitch_deg = 20.0;       // head pitch uniform in ±max_pitch_deg
  double max_roll_deg = 15.0;        // head roll uniform in ±max_roll_deg
  double max_shift_mm = 20.0;        // head translation x, y uniform in ±max_shift_mm
  double max_depth_mm = 60.0;        // head translation z (towards/away from the camera) in ±max_depth_mm
  int max_active_expressions = 4;    // blendshapes active per render: uniform in [0, max]
  double extreme_probability = 0.3;  // chance that an active blendshape is at weight 1 (else uniform in [0, 1])
  // Light rigs (presets of synth/lights.h or environment maps), one drawn per render.
  std::vector<std::string> lights = {"front", "studio", "raking-side", "raking-above", "overcast", "window"};
  double exposure_min = 0.5;         // sensor exposure uniform in [exposure_min, exposure_max]
  double exposure_max = 1.5;
  double full_well_min = 1000.0;     // shot noise: full well uniform in [min, max] electrons (smaller = noisier)
  double full_well_max = 10000.0;
  double jpeg_probability = 0.3;     // chance of JPEG compression at quality uniform in [40, 95]
  int actor_resolution = 256;        // ActorOptions::resolution of the rendered actors (texels), speed over detail
  double test_fraction = 0.2;        // from a folder: the last fraction of the names (sorted) is held out
  int max_detector_tests = 60;       // held-out images the "detector" evaluation runs on (0 = none)
  ShapeRegressorOptions regressor;

  // The regressor's fields are visited by their own names (its "seed" seeds the regressor).
  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// What training produced, besides the regressor.
struct TrackerTrainingSummary {
  int train_images = 0;
  ShapeRegressorTrainingReport regressor;       // the cascade's training facts
  int detector_calibration_faces = 0;           // training images whose HOG detection fitted ShapeRegressor::detector_box
  Eigen::Vector3d detector_box{0.0, 0.0, 1.0};  // its value
  double seconds = 0;                           // training and calibration
};

struct TrainedTracker {
  ShapeRegressor regressor;
  TrackerTrainingSummary summary;
};

// The method: trains the regressor on `train` (options.regressor) and fits its
// detector box onto the landmark box of the training faces (CalibrateDetectorBox).
TrainedTracker TrainTrackerOnFaces(const std::vector<LabelledFace>& train, const TrackerTrainingOptions& options);

struct LabelledSplit {
  std::vector<LabelledFace> train, test;
};
// Reads a folder: its train/ and test/ subfolders when both exist, else the folder
// (or a dlib XML file) split by name, the last `test_fraction` of the faces held out.
LabelledSplit ReadLabelledSplit(const std::filesystem::path& folder, double test_fraction);

// Training facts and held-out errors, as `crease train-tracker` reports them.
struct TrackerTrainingReport {
  int train_images = 0, test_images = 0;
  double data_seconds = 0;            // rendering or reading
  TrackerTrainingSummary training;
  ShapeRegressorEvaluation held_out;  // on the test faces (seed data_seed + 7777)
  // Optional: RegressorLandmarkSource run over a sequence (frames = 0 when not run).
  SequenceTrackingEvaluation sequence;
  double seconds = 0;                 // everything

  // Formatting only (tracker_report.cc).
  std::string ToText() const;
  std::string ToJson() const;
};

struct TrackerTrainingResult {
  ShapeRegressor regressor;
  TrackerTrainingReport report;
};

// Trains on `train` and evaluates on `test` (held out; the "detector" start on the
// first options.max_detector_tests faces).
TrackerTrainingResult TrainAndEvaluateTracker(const std::vector<LabelledFace>& train,
                                              const std::vector<LabelledFace>& test,
                                              const TrackerTrainingOptions& options);
// Reads a folder (ReadLabelledSplit), trains and evaluates.
TrackerTrainingResult TrainTrackerOnFolder(const std::filesystem::path& folder, const TrackerTrainingOptions& options);

// The report file of a trained tracker (`crease train-tracker`): `report` when given,
// else <out without extension>_report.json beside the model file `out`.
std::filesystem::path TrackerReportPath(const std::filesystem::path& out, const std::filesystem::path& report);

// Landmark errors on labelled faces, as `crease eval-landmarks` reports them: landmark
// sources from a cold start, and a trained regressor from the perturbed truth and
// from a jittered box (without the detector).
struct LandmarkEvaluationReport {
  std::string data;  // where the faces came from, as given
  int faces = 0;
  std::vector<LandmarkSourceEvaluation> sources;  // cold start: dlib and/or the regressor, in that order
  bool has_regressor = false;
  ShapeRegressorEvaluation regressor;  // without the detector (detector_frames = 0); with has_regressor

  // Formatting only (tracker_report.cc). A line per source, then the regressor's.
  std::string ToText() const;
  // data, faces, an object per source (by its name), regressor_tracking_init and
  // regressor_box_init: 2-space indented JSON, keys sorted.
  std::string ToJson() const;
};

// Evaluates dlib's detector and 68-point model (with `dlib`) and `regressor` (unless
// null; its perturbed initialisations drawn from `seed`) on `faces`, read from `data`.
LandmarkEvaluationReport EvaluateLandmarks(const std::vector<LabelledFace>& faces, const std::string& data, bool dlib,
                                           const ShapeRegressor* regressor, uint64_t seed);

}  // namespace crease
