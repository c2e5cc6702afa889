// Performance sequences for the studio: keyframed curves of expression weights,
// head pose, light and an optional occluder, sampled at a fixed frame rate
// (30 fps by default). Built-in presets (issue 3, part 5):
//   wrinkle-workout  a few seconds of extreme expressions, one after another, as
//                    the paper asks of a new user at the start (Sec. 5.2)
//   talking          moderate, overlapping expressions and head motion
//   moving-light     a directional light sweeping from the front to above while
//                    a brow raise holds (the paper's Fig. 14)
//   fast-motion      fast head turns (for motion blur)
//   occlusion        an occluder passes in front of the face
//   workout-talking  a short wrinkle workout, then talking (the experiments' default)
//   scan-holds       the scan set's expressions (ScanExpressionSpecs) one after
//                    another, each held still for 1 s with the head still: the
//                    capture's detail per expression, on the very expressions the
//                    regressor's training scans show (issue 17's ladder)
// and user sequences from YAML:
//
//   name: my-sequence
//   fps: 30
//   interpolation: smooth        # linear | smooth (cubic ease, flat at keys) | catmull-rom
//   motion_blur: false
//   keys:
//     - t: 0.0                   # seconds
//       expression: {browInnerUp: 0.0, jawOpen: 0.0}
//       pose: {yaw_deg: 0, pitch_deg: 0, roll_deg: 0, tx_mm: 0, ty_mm: 0, tz_mm: 0}
//       light: {azimuth_deg: 0, elevation_deg: 10, intensity: 1.0}
//       occluder: {x_mm: 200, y_mm: 0, z_mm: 150, radius_mm: 40}
//     - t: 1.0
//       expression: {browInnerUp: 1.0}
//
// Each channel (one expression weight, one pose or light parameter) has its own
// keys: a key that does not name a channel leaves it free between its neighbours.
// A channel's value before its first key is that key's value (after its last, the
// last's). Expression weights are clamped to [0, 1].
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace crease {

struct FaceRig;

// The value of every channel at one instant.
struct SequenceFrame {
  int index = 0;
  double time_s = 0.0;
  std::map<std::string, double> expression;  // by expression name as written in the sequence
  double yaw_deg = 0, pitch_deg = 0, roll_deg = 0;  // head rotation, applied yaw·pitch·roll
  double tx_mm = 0, ty_mm = 0, tz_mm = 0;           // head translation in the head's rest frame
  double light_azimuth_deg = 0, light_elevation_deg = 0, light_intensity = 1.0;
  bool has_occluder = false;
  double occluder_x_mm = 0, occluder_y_mm = 0, occluder_z_mm = 0, occluder_radius_mm = 0;
};

struct Keyframe {
  double t = 0.0;                              // seconds, ≥ 0
  std::map<std::string, double> values;        // channel name → value
};

class Sequence {
 public:
  std::string name;
  double fps = 30.0;
  double duration_s = 0.0;  // ≥ last key time; frames = round(duration · fps) + 1
  std::string interpolation = "smooth";
  bool motion_blur = false;
  // Channels: "expression:NAME", "pose:yaw_deg", …, "light:azimuth_deg", …, "occluder:x_mm", …
  std::vector<Keyframe> keys;  // sorted by t

  int num_frames() const;
  SequenceFrame Frame(int index) const;
  // Channel value at any time (for motion blur sub-frames).
  SequenceFrame At(double time_s) const;
  // Expression names used by the sequence.
  std::vector<std::string> ExpressionNames() const;
  // Checks the sequence; throws Error starting with `what`.
  void Validate(const std::string& what) const;
};

// Built-in presets; `seconds` scales their length (≤ 0: the preset's own length).
std::vector<std::string> SequencePresetNames();
// The expressions of a studio scan set by default (ScanSetOptions, synth/dataset.h)
// as "name=w,name=w": they show the main wrinkles (forehead, glabella, crow's feet
// and cheeks, nose).
const std::vector<std::string>& ScanExpressionSpecs();
// "name=w,name=w" → weights by name (as SequenceFrame::expression); errors name
// the item that is not NAME=WEIGHT.
std::map<std::string, double> ParseExpressionWeights(const std::string& spec);
// scan-holds' hold of scan expression `index` (of ScanExpressionSpecs): its first
// and last frame at full weight, at `fps`, for the preset made with `seconds`
// (≤ 0: its own length, 8.6 s). Throws Error for an index out of range or fps ≤ 0.
std::pair<int, int> ScanHoldFrames(int index, double fps = 30.0, double seconds = 0.0);
Sequence MakePresetSequence(const std::string& preset, double seconds = 0.0);

// YAML (see above). Errors name the file, the key index and the field.
Sequence ReadSequenceYaml(const std::filesystem::path& path);
Sequence ParseSequenceYaml(const std::string& text, const std::string& what);
std::string SequenceToYaml(const Sequence& sequence);

// Maps a frame's expression weights onto a rig's expressions. A name the rig has
// is used as is; a name it lacks but whose "_L" and "_R" variants it has drives
// both. Any other name is an Error listing the rig's expressions.
std::vector<double> ExpressionWeightsForRig(const SequenceFrame& frame, const FaceRig& rig);

}  // namespace crease
