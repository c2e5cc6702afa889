// A training scan set on disk (paper Sec. 4.1: "high-quality 3D face scans,
// consisting of various extreme expressions … from several different actors,
// including the captured images"). The format is the same for the studio's
// synthetic scans (`crease synth scans`) and for real ones; docs/formats.md has
// the full description. In short, a folder with scans.json:
//
//   {"format": "crease scan set", "version": 2,
//    "rig": "rig.crig",                                  (optional)
//    "actors": [{"folder": "actor_000", "neutral": "neutral",
//                "scans": [{"name": "neutral", "mesh": "neutral/mesh.ply",
//                           "images": [{"camera": "neutral/cam0.json",
//                                       "image": "neutral/cam0_studio.png",
//                                       "light": "studio"}],
//                           "truth": {"expression_displacement": "…exr"}}, …]}]}
//
// Paths are relative to the actor's folder. All scans of an actor share one
// topology; "neutral" names the neutral scan (default: the scan named "neutral",
// else the first). Meshes are PLY or OBJ in mm in a head frame; cameras are
// core/camera.h JSON (intrinsics, cam_from_head); images any format OpenImageIO
// reads, sRGB. "truth" is optional (synthetic sets): the ground-truth medium-scale
// expression displacement (mm, the rig's UV layout) to validate detail extraction.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace crease {

struct ScanImage {
  std::filesystem::path camera;  // camera JSON
  std::filesystem::path image;   // the photograph
  std::string light;             // light-rig name ("" when not given)
};

struct ScanEntry {
  std::string name;
  std::filesystem::path mesh;
  std::vector<ScanImage> images;
  std::filesystem::path truth_displacement;  // empty when the set has no ground truth
};

struct ScanActor {
  std::string name;  // the folder name
  std::filesystem::path folder;
  int neutral = 0;   // index into scans
  std::vector<ScanEntry> scans;
};

// The indices of the actor's scans, the neutral first (the order Sec. 4.1 extracts in).
std::vector<int> NeutralFirst(const ScanActor& actor);

struct ScanSet {
  std::filesystem::path root;
  std::filesystem::path rig;  // empty when the set names no rig
  std::vector<ScanActor> actors;

  int num_scans() const;
  // Light names present in the images, in order of first appearance.
  std::vector<std::string> lights() const;
};

// Reads and checks scans.json in `dir`: every named file exists, each actor has a
// neutral and at least one image per scan. Errors name the file and the entry.
ScanSet ReadScanSet(const std::filesystem::path& dir);

}  // namespace crease
