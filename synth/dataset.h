// Self-describing dataset folders written by the studio (issue 3, part 6).
//
// Sequence dataset (`crease synth sequence`):
//   dataset.json      what is here: format, version, frame count, fps, image size,
//                     the studio options, and the file layout below
//   rig.crig          the generic rig (core/face_rig.h; zlib, lossless): the truth moves with
//                     PersonalRig(rig, actor), the actor's own expressions
//   tracking_rig.crig the rig's skin parts only (SequenceDatasetOptions::tracking_parts),
//                     which `crease track` and `crease capture` fit by default
//                     (dataset.json "tracking_rig"; absent when nothing is dropped)
//   actor.json        the actor definition (synth/actor.h): with the rig, enough to
//                     rebuild every layer of every frame
//   sequence.yaml     the performance (synth/sequence.h)
//   camera.json       intrinsics and cam_from_world (core/camera.h; head pose is per frame)
//   frames/NNNNNN.png         what the camera recorded (sRGB, 8-bit, sensor noise)
//   frames/NNNNNN.exr         optional: the noiseless linear render
//   truth/NNNNNN.json         rig parameters (expression weights by name, identity),
//                             head pose, cam_from_head, light, the 2D projection
//                             and visibility of every landmark
//   truth/NNNNNN_vertices.bin float32 triples (x px, y px, visible 0/1), one per
//                             coarse rig vertex
//   maps/NNNNNN_expression_displacement.exr  medium-scale expression displacement
//                             D (mm, along the coarse normal; the quantity the paper
//                             regresses, Sec. 4.1), in the rig's UV layout
//   maps/static_displacement.exr, maps/mesoscopic_displacement.exr  the actor's
//                             person-specific medium shape and pores (mm), all frames
//   maps/albedo.exr, specular.exr, roughness.exr  the actor's skin
//   passes/NNNNNN_{depth,normal,uv}.exr, NNNNNN_mask.png   optional render passes at
//                             pixel centres: depth (mm along the camera's z), shading
//                             normal (camera frame), UV, and where the head is seen
// The folder is written under a temporary name and renamed when complete.
//
// Scan set (`crease synth scans`): per actor a neutral and extreme expressions,
// each with its high-resolution mesh (PLY, head frame), images from calibrated
// cameras under one or more light rigs, and the ground-truth maps:
//   scans.json, rig.crig, actor_NNN/actor.json,
//   actor_NNN/SCAN/{mesh.ply, camK_LIGHT.png, camK.json, truth.json,
//                   expression_displacement.exr}
#pragma once

#include <filesystem>
#include <string>
#include <vector>
#include <nlohmann/json_fwd.hpp>

#include "core/dataset_info.h"  // dataset.json's reader
#include "core/face_rig.h"
#include "core/tri_mesh.h"
#include "synth/actor.h"
#include "synth/sequence.h"
#include "synth/studio.h"

namespace crease {

struct SequenceDatasetOptions {
  StudioOptions studio;
  bool write_exr = false;   // also the noiseless linear frame as EXR
  bool write_maps = true;   // per-frame expression displacement maps
  bool write_passes = false;  // per-frame render passes: depth, normal, UV (EXR) and the face mask (PNG)
  int first_frame = 0;      // frame range [first_frame, first_frame + max_frames)
  int max_frames = -1;      // -1: all frames of the sequence
  bool overwrite = false;   // replace an existing output folder
  // Drop sequence channels for expressions the rig lacks (with a warning in the
  // report) instead of failing — for built-in presets on rigs with fewer expressions.
  bool ignore_missing_expressions = false;
  // The parts of the tracking rig written beside the dataset (tracking_rig.crig,
  // ExtractParts: the skin of the head without eyes, teeth, gums and mouth
  // interior, which the tracker never fits), when they drop any vertex; the
  // dataset's generic rig.crig stays the truth's. Empty: no tracking rig.
  std::vector<std::string> tracking_parts = {"face", "face_rim", "head_neck", "scalp_hair",
                                             "cranium", "hair", "neck", "ears"};
};

struct DatasetReport {
  int frames = 0;
  double seconds = 0.0;
  double render_seconds = 0.0;
  double surface_seconds = 0.0;
  std::string path;
  std::vector<std::string> warnings;
  std::string timing;  // per-stage time table (core/timer.h)
};

DatasetReport WriteSequenceDataset(const FaceRig& rig, const Actor& actor, const Sequence& sequence,
                                   const SequenceDatasetOptions& options, const std::filesystem::path& out);

struct ScanSetOptions {
  StudioOptions studio;              // image size, sensor, samples; cameras are made here
  int cameras = 3;                   // on an arc in front of the face
  double camera_arc_deg = 50.0;      // total horizontal spread of the cameras
  std::vector<std::string> light_rigs = {"studio"};  // each scan is imaged under every rig
  // Expressions per scan: "name=w,name=w"; the defaults show the main wrinkles
  // (the sequence preset scan-holds holds the same ones).
  std::vector<std::string> expressions = ScanExpressionSpecs();
  // Actor a of n draws its age from the a-th of n equal parts of [age_min, age_max]
  // (ActorOptions), so a set spans unlined to deeply lined faces as the paper's
  // several actors do, instead of leaving it to chance (the quickstart's seeds drew
  // three nearly unlined actors of four: ages 0.04, 0.09, 0.65, 0.06). false: each
  // actor draws from the whole range.
  bool stratify_ages = true;
  bool overwrite = false;
};

// Actors are generated from `actor_seeds` with `actor_options` (ages stratified,
// ScanSetOptions::stratify_ages).
DatasetReport WriteScanSet(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                           const ActorOptions& actor_options, const ScanSetOptions& options,
                           const std::filesystem::path& out);

// One frame's ground truth as WriteSequenceDataset writes it: TRUTH_DIR/NAME.json
// (rig parameters, pose, landmarks) and TRUTH_DIR/NAME_vertices.bin (float32 x px,
// y px, visible, one triple per coarse rig vertex); eval reads it (ReadFrameTruth).
void WriteFrameTruth(const std::filesystem::path& truth_dir, const std::string& name, const StudioFrameTruth& truth,
                     const FaceRig& rig, const Actor& actor);

// Rebuilds the full high-resolution ground-truth surface of frame `frame` of a
// sequence dataset (head frame, mm). Errors name the file that is missing or wrong.
TriMesh RebuildDatasetFrameMesh(const std::filesystem::path& dataset, int frame);

// "name=w,name=w" → expression weights for the rig (names resolve like sequences: a
// name without _L/_R drives both sides).
Eigen::VectorXd ParseExpressionSpec(const std::string& spec, const FaceRig& rig);

}  // namespace crease
