// FaceRig — the blendshape model of the global tracker (paper Sec. 5, the
// "blendshape prior"; DDE, Cao et al. 2014): a neutral mesh with one UV chart,
// a linear identity basis and expression blendshapes stored as per-vertex
// deltas, named expressions, named landmark vertices (the iBUG-68 layout when
// present) and named region masks in UV.
//
//   V(identity α, expression β) = V0 + Σ_k α_k · I_k + Σ_b β_b · B_b      (all #V×3, mm)
//
// Expression deltas are relative to the neutral of the mean identity (additive
// model, as in FaceWarehouse-style and light-stage rigs).
//
// File format (.crig, versioned binary; see docs/formats.md):
//   "CREASRIG" | u32 version | u64 header length | header (JSON, UTF-8) | arrays
// The header lists names, landmarks, region names, metadata and, for each array,
// its name, dtype and shape; arrays follow in that order, little-endian.
// Version 2 adds compact storage (RigWriteOptions::compact): an array may be
// zlib-compressed ("encoding": "zlib", "stored_bytes": n) and the blendshape
// bases may be 16-bit integers ("dtype": "i16", "scale": mm per step). Version 1
// files are still read.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/tri_mesh.h"

namespace crease {

struct RigLandmark {
  std::string name;  // e.g. "ibug_37"
  int vertex = -1;   // vertex id in the rig's neutral mesh
};

struct RegionMask {
  std::string name;  // e.g. "forehead"
  cv::Mat mask;      // CV_8U, square, 255 inside the region, 0 outside; texel convention of DESIGN.md
};

// The region names every rig is expected to provide (training uses forehead, eye
// and cheek regions, Sec. 4.2).
const std::vector<std::string>& StandardRegionNames();

struct FaceRig {
  static constexpr uint32_t kFormatVersion = 2;

  TriMesh neutral;                 // mean identity, neutral expression; UVs required.
  Eigen::MatrixXf identity_basis;  // (3·#V)×#I deltas (x0, y0, z0, x1, …), mm.
  Eigen::MatrixXf expression_basis;  // (3·#V)×#E deltas, mm.
  std::vector<std::string> identity_names;    // #I (e.g. "identity000").
  std::vector<std::string> expression_names;  // #E (e.g. "browInnerUp_L", ARKit/FACS names).
  std::vector<RigLandmark> landmarks;
  std::vector<RegionMask> regions;
  // Per vertex, the vertex id in the file(s) it was imported from (seam splits map
  // several vertices to one id); empty for rigs made by crease.
  std::vector<int> original_vertex;
  // Optional parts of a full head (e.g. "face", "cranium", "eyeball_left",
  // "mouth_cavity"): part_names[vertex_part[v]] is vertex v's part. Empty = all
  // one part. The face region is the part of the UV layout inside [0,1]²; other
  // parts may carry UVs outside it, which UV-space stages (texture, displacement
  // maps) ignore.
  std::vector<std::string> part_names;
  std::vector<uint8_t> vertex_part;
  std::string source;  // free text: where the rig came from

  int num_vertices() const { return neutral.num_vertices(); }
  // -1 when absent.
  int PartIndex(const std::string& name) const;
  int num_identity() const { return static_cast<int>(identity_basis.cols()); }
  int num_expressions() const { return static_cast<int>(expression_basis.cols()); }

  // Positions for identity coefficients α (#I, missing entries = 0 if shorter)
  // and expression weights β (#E); both may be empty (= zeros). Throws if longer.
  MatX3d EvaluatePositions(const Eigen::VectorXd& identity, const Eigen::VectorXd& expression) const;
  // The mesh (neutral's topology, UVs; normals not computed).
  TriMesh Evaluate(const Eigen::VectorXd& identity, const Eigen::VectorXd& expression) const;

  // -1 when absent.
  int ExpressionIndex(const std::string& name) const;
  int LandmarkIndex(const std::string& name) const;
  const RegionMask* FindRegion(const std::string& name) const;
  // True when uv lies in the named region (false for unknown regions / outside [0,1]²).
  bool InRegion(const std::string& name, const Eigen::Vector2d& uv) const;

  // Checks sizes, names (unique, non-empty), landmark ids, masks, finiteness and
  // the neutral mesh (UVs required). Throws Error starting with `what`.
  void Validate(const std::string& what) const;
};

struct RigWriteOptions {
  // Compact storage, e.g. for a rig shipped in a repository: the identity and
  // expression deltas quantised to quantum_mm (16-bit; a coarser step where a
  // basis exceeds ±32767 steps) and every array zlib-compressed.
  bool compact = false;
  double quantum_mm = 0.005;  // mm per step of the quantised deltas (error ≤ half a step)
  // Lossless: every array zlib-compressed, the deltas kept as 32-bit floats (a
  // dataset's rig, from which its ground truth is rebuilt bit for bit).
  bool compress = false;
};

void WriteRig(const std::filesystem::path& path, const FaceRig& rig, const RigWriteOptions& options = {});
// Errors name the file: wrong magic ("not a crease rig"), another version, truncated data.
FaceRig ReadRig(const std::filesystem::path& path);

// The rig's triangles that form the face chart (the UV layout of texture and
// displacement maps): all corners in the part "face" when the rig has parts, else
// all triangles with every corner's UV in [0, 1]². Throws Error when there are none.
MatX3i FaceChartTriangles(const FaceRig& rig);

// Region masks of StandardRegionNames() derived from the 68 iBUG landmarks'
// positions in UV (the rig must have landmarks "ibug_1" … "ibug_68"): forehead
// above the brows, glabella between them, each eye with its surroundings (crow's
// feet and under-eye), cheeks between eye, nose, mouth corner and jaw, nose,
// mouth, chin. Left/right are the subject's. `size` is the mask resolution.
std::vector<RegionMask> RegionsFromLandmarks(const FaceRig& rig, int size = 512);

// iBUG-68 landmark names "ibug_1" … "ibug_68" (1-based, as in the iBUG 300-W annotation).
std::vector<std::string> IbugLandmarkNames();

}  // namespace crease
