// Training crease's landmark regressor (pipeline/capture/shape_regressor.h) on studio
// renders (issue 5, part 1): random actors, expressions (including extreme ones),
// head poses, light rigs and sensor settings, rendered on the fly or read from a
// folder; a held-out split of other actors; and the report — the mean landmark error
// (normalised by the inter-ocular distance, and in pixels) before (at the initial
// shapes) and after the regressor, on held-out renders.
//
// Held-out initialisations, both as in training (ShapeRegressorOptions):
//   * "tracking": the truth under a random similarity (the previous frame of a tracker);
//   * "box": the mean shape in the truth's jittered square box (a detector start);
//   * "detector": RegressorLandmarkSource from a cold start — dlib's HOG box, the mean
//     shape in it and the cascade (detection rate and error on the detected frames).
//
// Folder format (read and written): NAME.png (8-bit sRGB) with NAME.pts, the iBUG
// 300-W point format ("version: 1", "n_points: 68", "{", one "x y" per line, "}"),
// pixel centres at integer coordinates (crease's convention; 300-W files count from 1,
// so real 300-W data is off by one pixel).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/face_rig.h"
#include "core/options.h"
#include "core/types.h"
#include "pipeline/capture/landmarks.h"
#include "pipeline/capture/shape_regressor.h"

namespace crease {

struct TrackerTrainingOptions {
  int train_actors = 12;             // actors rendered for training
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

struct LabelledFace {
  std::string name;
  cv::Mat image;      // CV_8UC3 sRGB (R, G, B), what a camera file holds
  MatX2d landmarks;   // 68×2 truth pixels (iBUG order)
};

// Renders `renders_per_actor` labelled stills of each actor seed (random expression,
// pose, light and sensor settings as in `options`). Deterministic for the same seeds.
// The rig must have the landmarks "ibug_1" … "ibug_68".
std::vector<LabelledFace> RenderLabelledFaces(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                                              const TrackerTrainingOptions& options);
// Folder I/O (format in the file comment). Reading sorts by name; errors name the file.
// ReadLabelledFaces also takes a dlib XML file (ReadDlibXmlFaces, default options).
void WriteLabelledFaces(const std::filesystem::path& folder, const std::vector<LabelledFace>& faces);
std::vector<LabelledFace> ReadLabelledFaces(const std::filesystem::path& folder);

// dlib's imglab XML: the format of dlib's release of iBUG 300-W
// (labels_ibug_300W_train.xml, …) and of its example faces:
//   <image file='F'> <box top='' left='' width='' height=''> <part name='00' x='' y=''/> … </box> … </image>
// Image paths are relative to the XML's folder. Every box with the 68 parts (names
// 00 … 67, any order) becomes one LabelledFace, named after the image and the box:
// a square crop centred on the box, `crop_scale` times the box's larger side,
// resampled (bilinear; black outside the image) so that the box's larger side is
// `box_px` pixels — real photographs hold faces of any size and several per image,
// the regressor and the detector are run on one face of a known scale. Boxes marked
// ignore='1' or without 68 parts are skipped. Errors name the file and line.
struct DlibXmlOptions {
  double crop_scale = 2.5;
  int box_px = 100;
};
std::vector<LabelledFace> ReadDlibXmlFaces(const std::filesystem::path& xml, const DlibXmlOptions& options = {});

// A landmark source from a cold start on each face (Reset, then Track: the
// detector, then the landmarks): detection rate, mean point-to-point error over the
// 68 points on the faces it found (px and / inter-ocular distance, the outer eye
// corners), and the time per face.
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

struct TrackerTrainingReport {
  int train_images = 0, test_images = 0;
  double data_seconds = 0;          // rendering or reading
  ShapeRegressorTrainingReport training;
  LandmarkErrorStats tracking;      // held-out, initialised from the perturbed truth
  LandmarkErrorStats box;           // held-out, initialised with the mean shape in a jittered box
  int detector_calibration_faces = 0;  // training images whose HOG detection fitted ShapeRegressor::detector_box
  Eigen::Vector3d detector_box{0.0, 0.0, 1.0};  // its value
  int detector_frames = 0, detector_found = 0;
  double detector_error_iod = 0, detector_error_px = 0;  // on the frames where a face was found
  double predict_ms = 0;            // mean Predict time per image (one thread)
  // Optional: RegressorLandmarkSource run over a sequence (frames in name order, each
  // frame initialised from the previous one; the detector only at the start and after a loss).
  int sequence_frames = 0, sequence_found = 0, sequence_detections = 0;
  double sequence_error_iod = 0, sequence_error_px = 0;  // on the frames where a face was found
  double sequence_track_ms = 0;     // mean Track time on the frames without detection
  double seconds = 0;               // everything

  std::string ToText() const;
  std::string ToJson() const;
};

struct TrackerTrainingResult {
  ShapeRegressor regressor;
  TrackerTrainingReport report;
};

// Errors of `regressor` on `faces` from the "tracking" and "box" initialisations
// (random draws from `seed`); `detector_frames` > 0 also runs RegressorLandmarkSource
// from a cold start on the first that many faces.
void EvaluateShapeRegressor(const ShapeRegressor& regressor, const std::vector<LabelledFace>& faces,
                            uint64_t seed, int detector_frames, TrackerTrainingReport* report);

// Runs RegressorLandmarkSource over `frames` in order (a video) and fills the
// report's sequence_* fields.
void EvaluateSequenceTracking(const ShapeRegressor& regressor, const std::vector<LabelledFace>& frames,
                              TrackerTrainingReport* report);

// Trains on `train` and reports on `test` (held out).
TrackerTrainingResult TrainTrackerOnFaces(const std::vector<LabelledFace>& train,
                                          const std::vector<LabelledFace>& test,
                                          const TrackerTrainingOptions& options);
// Renders train_actors + test_actors actors and trains (held-out = the test actors).
// `save_dir` (optional) also writes the renders (train/ and test/ subfolders).
// `extra_train`: labelled faces (e.g. photographs) added to the training renders.
TrackerTrainingResult TrainTrackerOnRenders(const FaceRig& rig, const TrackerTrainingOptions& options,
                                            const std::filesystem::path& save_dir = {},
                                            const std::vector<LabelledFace>& extra_train = {});
// Reads a folder (train/ and test/ subfolders when both exist, else one folder split
// by test_fraction) and trains.
TrackerTrainingResult TrainTrackerOnFolder(const std::filesystem::path& folder, const TrackerTrainingOptions& options);

}  // namespace crease
