// dataset.json of a crease sequence dataset (written by synth/dataset.h,
// WriteSequenceDataset): its one typed reader, used by every stage that opens a
// dataset (capture's frame source, track, eval, the detail truth, the studio's
// rebuild of a frame). Every field is checked when the file is read, and errors name
// dataset.json and the key (issue 19: a version 99, a negative width or a top-level
// array were accepted, or ended in "internal error").
#pragma once

#include <filesystem>
#include <string>

#include <nlohmann/json_fwd.hpp>

namespace crease {

struct SequenceDatasetInfo {
  static constexpr const char* kFormat = "crease synthetic sequence";
  static constexpr int kVersion = 1;

  std::filesystem::path dir;        // the dataset folder
  std::filesystem::path json_path;  // dir / "dataset.json", for error messages
  std::string sequence;             // the performance's name
  int first_frame = 0;              // frame numbers first_frame … first_frame + frames − 1
  int frames = 0;                   // ≥ 1
  double fps = 30.0;
  int width = 0, height = 0;        // image size, pixels
  std::string rig = "rig.crig";     // the rendering rig, relative to dir
  std::string tracking_rig;         // the rig track and capture fit by default ("" = rig)
  std::string frame_pattern = "frames/{frame:06d}.png";  // files.frame
  // files.expression_displacement: the true D per frame; "" when the dataset was
  // rendered without maps (--no-maps).
  std::string displacement_pattern = "maps/{frame:06d}_expression_displacement.exr";

  int last_frame() const { return first_frame + frames - 1; }
  bool HasFrame(int frame) const { return frame >= first_frame && frame <= last_frame(); }
  std::filesystem::path FramePath(int frame) const;
  std::filesystem::path TruthPath(int frame) const;  // truth/NNNNNN.json
  // The true expression displacement map of `frame`; throws Error naming dataset.json
  // when the dataset has none.
  std::filesystem::path DisplacementPath(int frame) const;
  std::filesystem::path RigPath() const;
  std::filesystem::path TrackingRigPath() const;  // tracking_rig, else rig
};

// True when `dir` holds a dataset.json (a sequence dataset, not yet validated).
bool IsSequenceDataset(const std::filesystem::path& dir);

// Reads and checks dir/dataset.json. Throws Error naming the file and the key when it
// is missing, not a crease sequence dataset of a known version, or a field is absent,
// of the wrong type or out of range (frames ≥ 1, width and height 16–8192, fps in
// (0, 1000], file names relative and inside the folder, patterns as below).
SequenceDatasetInfo ReadSequenceDatasetInfo(const std::filesystem::path& dir);

// A frame file pattern of dataset.json (at `dataset_json`) under files.KEY: a fmt
// pattern whose one field is {frame} (default `fallback` when the key is absent).
// Throws Error naming dataset.json and the key when it is not a string, names
// another field, is malformed, or pads wider than 32 characters (a width of
// 999999999 made eval take 6.2 GB, issue 19). An empty string stays empty.
std::string DatasetFilePattern(const nlohmann::json& info, const std::filesystem::path& dataset_json,
                               const std::string& key, const std::string& fallback);

// files.frame (default "frames/{frame:06d}.png").
std::string DatasetFramePattern(const nlohmann::json& info, const std::filesystem::path& dataset_json);

}  // namespace crease
