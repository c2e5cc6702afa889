// Writes the seed corpus of the binary and mesh fuzz targets with crease's own
// writers, so the seeds are files crease writes (issue 19): tiny meshes (PLY binary
// and ascii, OBJ, VTP binary and ascii with a field), images (PNG 8/16-bit, EXR
// float/half), a rig in each storage mode (.crig), a detail model (.cdm), a landmark
// tracker (.ctrk), training pairs (.cpr), a camera, an actor, a capture frame (.cfr,
// tracked with flow points and lost), a capture.json and a frame's truth JSON (the
// dlib XML seeds are text, in fuzz/corpus/dlib_xml_fuzzer/). Tiny on purpose:
// small seeds give fast executions. Usage: write_seeds OUT (makes OUT/<target>/...).
#include <cstdio>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/image_io.h"
#include "core/mesh_io.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/vtk_io.h"
#include "pipeline/capture/capture_io.h"
#include "pipeline/capture/capture_run.h"
#include "pipeline/capture/shape_regressor.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/trainer.h"
#include "synth/actor.h"
#include "synth/dataset.h"

namespace fs = std::filesystem;
using namespace crease;

namespace {

TriMesh Quad() {
  TriMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 10, 1;
  m.F.resize(2, 3);
  m.F << 0, 1, 2, 0, 2, 3;
  m.UV.resize(4, 2);
  m.UV << 0.1, 0.9, 0.9, 0.9, 0.9, 0.1, 0.1, 0.1;
  m.N.resize(4, 3);
  m.N << 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1;
  return m;
}

void WriteMeshes(const fs::path& out) {
  const TriMesh m = Quad();
  WritePly(out / "ply_fuzzer" / "binary.ply", m);
  WritePly(out / "ply_fuzzer" / "ascii.ply", m, {.binary = false, .double_precision = true});
  WritePly(out / "ply_fuzzer" / "float.ply", m, {.binary = true, .double_precision = false});
  WriteObj(out / "obj_fuzzer" / "quad.obj", m);
  VertexField field{"error", Eigen::MatrixXd::Constant(4, 1, 0.5)};
  WriteVtp(out / "vtp_fuzzer" / "binary.vtp", m, {field}, true);
  WriteVtp(out / "vtp_fuzzer" / "ascii.vtp", m, {field}, false);
}

void WriteImages(const fs::path& out) {
  cv::Mat rgb(3, 4, CV_32FC3, cv::Scalar(0.2, 0.5, 0.8));
  cv::Mat gray(2, 2, CV_32FC1, cv::Scalar(0.5));
  WriteImage(out / "png_fuzzer" / "rgb8.png", rgb);
  WriteImage(out / "png_fuzzer" / "gray16.png", gray, {.srgb = false, .bits = 16});
  WriteImage(out / "exr_fuzzer" / "rgb.exr", rgb);
  WriteImage(out / "exr_fuzzer" / "gray_half.exr", gray, {.half = true});
}

FaceRig TinyRig() {
  FaceRig rig;
  rig.neutral = Quad();
  rig.neutral.N.resize(0, 3);
  rig.identity_basis = Eigen::MatrixXf::Constant(12, 1, 0.25f);
  rig.expression_basis = Eigen::MatrixXf::Constant(12, 2, -0.5f);
  rig.identity_names = {"identity000"};
  rig.expression_names = {"jawOpen", "browDown_L"};
  rig.landmarks = {{"ibug_31", 2}};
  rig.regions = {{"forehead", cv::Mat(8, 8, CV_8U, cv::Scalar(255))}};
  rig.source = "fuzz/write_seeds.cc";
  return rig;
}

void WriteRigs(const fs::path& out) {
  const FaceRig rig = TinyRig();
  WriteRig(out / "crig_fuzzer" / "plain.crig", rig);
  WriteRig(out / "crig_fuzzer" / "compressed.crig", rig, {.compress = true});
  WriteRig(out / "crig_fuzzer" / "compact.crig", rig, {.compact = true});
}

void WriteDetailModelSeed(const fs::path& out) {
  DetailModel m;
  const int w = 2, n = w * w, D = 2;
  m.map_resolution = 16;
  m.patch.patch_size = w;
  m.pca.mean = Eigen::VectorXf::Zero(n);
  m.pca.basis = Eigen::MatrixXf::Identity(n, D);
  m.pca.variances = Eigen::VectorXd::LinSpaced(n, 1.0, 0.1).reverse();
  m.pca.energy = {0.5, 0.8, 0.95, 1.0};
  m.cascade.options.num_ferns = 2;
  m.cascade.options.fern_depth = 1;
  m.cascade.options.num_sampled_pixels = 2;
  m.cascade.patch_pixels = n;
  m.cascade.dimensions = D;
  m.cascade.mean = {0.0f, 0.1f};
  m.cascade.pixel_a = {0, 1};
  m.cascade.pixel_b = {1, 2};
  m.cascade.thresholds = {0.0f, 0.01f};
  m.cascade.outputs = {0.1f, -0.1f, 0.2f, -0.2f, 0.3f, -0.3f, 0.4f, -0.4f};
  m.Validate("seed detail model");
  WriteDetailModel(out / "cdm_fuzzer" / "tiny.cdm", m);
}

void WriteTrackerSeed(const fs::path& out) {
  ShapeRegressor r;
  r.options.num_stages = 1;
  r.options.num_ferns = 1;
  r.options.fern_depth = 1;
  r.options.num_sampled_pixels = 2;
  r.num_landmarks = 2;
  r.mean_shape.resize(2, 2);
  r.mean_shape << -0.5, 0.0, 0.5, 0.0;
  r.pixel_landmark = {0, 1};
  r.pixel_offset = {0.1f, 0.0f, -0.1f, 0.0f};
  r.fern_pixel_a = {0};
  r.fern_pixel_b = {1};
  r.fern_threshold = {0.0f};
  r.fern_output = {0.01f, 0.0f, -0.01f, 0.0f, 0.0f, 0.01f, 0.0f, -0.01f};
  r.Check("seed shape regressor");
  SaveShapeRegressor(out / "ctrk_fuzzer" / "tiny.ctrk", r);
}

void WritePairsSeed(const fs::path& out) {
  TrainingPairs p;
  p.texture = Eigen::MatrixXf::Constant(3, 4, 0.5f);
  p.displacement = Eigen::MatrixXf::Constant(3, 4, -0.01f);
  p.options_json = "{}";
  p.scan_set = "scans";
  p.actors = 1;
  p.scans = 2;
  p.actor = {0, 0, 0};
  p.actor_names = {"actor_000"};
  WriteTrainingPairs(out / "cpr_fuzzer" / "tiny.cpr", p);
}

void WriteJsonSeeds(const fs::path& out) {
  const CameraIntrinsics K = CameraIntrinsics::FromFov(30.0, 64, 48);
  WriteCamera(out / "camera_json_fuzzer" / "camera.json",
              LookAtCamera(K, Eigen::Vector3d(0, 0, -500), Eigen::Vector3d::Zero(), Eigen::Vector3d(0, -1, 0)));
  Actor actor;
  actor.identity = Eigen::VectorXd::Constant(2, 0.5);
  WriteActor(out / "actor_json_fuzzer" / "actor.json", actor);
}

void WriteCaptureSeeds(const fs::path& out) {
  CaptureFrameArrays a;
  a.frame = 3;
  a.tracked = true;
  a.coarse = MatX3d::Constant(4, 3, 1.5);
  a.refined = MatX3d::Constant(4, 3, 1.25);
  a.landmarks = MatX2d::Constant(68, 2, 20.0);
  a.flow_vertex = {0, 2};
  a.flow_status = {0, 1};
  a.flow_projected = a.flow_positions = a.flow_fitted = MatX2d::Constant(2, 2, 12.0);
  WriteCaptureFrameArrays(out / "cfr_fuzzer" / "tracked.cfr", a);
  CaptureFrameArrays lost;
  lost.frame = 4;
  WriteCaptureFrameArrays(out / "cfr_fuzzer" / "lost.cfr", lost);

  CaptureSummary s;
  s.input = "seq";
  s.frames = s.tracked_frames = s.detail_frames = 2;
  s.frame_indices = {30, 31};
  s.map_resolution = 16;
  s.detail_extraction_json = "{\"lowpass_bandwidth_mm\": 3.0}";
  s.options_json = "{\"lk_window\": 21, \"map_resolution\": 16}";
  s.timing = {{"texture T^t", 0.002, 2}};
  s.identity = Eigen::VectorXd::Constant(2, 0.5);
  WriteFileAtomic(out / "capture_json_fuzzer" / "capture.json", [&](std::ostream& o) { o << s.ToJson(); });
}

void WriteTruthSeed(const fs::path& out) {
  FaceRig rig = TinyRig();
  rig.landmarks.clear();
  for (int i = 0; i < 68; ++i) rig.landmarks.push_back({"ibug_" + std::to_string(i), i % 4});
  Actor actor;
  actor.identity = Eigen::VectorXd::Constant(1, 0.5);
  StudioFrameTruth t;
  t.expression = Eigen::VectorXd::Constant(2, 0.25);
  t.vertex_pixels = MatX2d::Constant(4, 2, 10.0);
  t.vertex_visible = {1, 1, 0, 1};
  t.landmark_pixels = MatX2d::Constant(68, 2, 11.0);
  t.landmark_visible.assign(68, 1);
  t.light_description = "studio";
  WriteFrameTruth(out / "truth_json_fuzzer", "000000", t, rig, actor);
  fs::remove(out / "truth_json_fuzzer" / "000000_vertices.bin");  // the target writes its own
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUT_FOLDER\n", argv[0]);
    return 2;
  }
  const fs::path out = argv[1];
  try {
    WriteMeshes(out);
    WriteImages(out);
    WriteRigs(out);
    WriteDetailModelSeed(out);
    WriteTrackerSeed(out);
    WritePairsSeed(out);
    WriteJsonSeeds(out);
    WriteCaptureSeeds(out);
    WriteTruthSeed(out);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "write_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
