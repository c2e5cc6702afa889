// The capture run (pipeline/capture/capture_run.h; issue 18): RunCapture on a tiny
// studio sequence (5 frames of 160×120) with a tiny detail model and a global
// tracker that reports the truth and loses one frame writes the capture folder
// `crease capture` writes, and its CaptureSummary counts what happened: frames,
// tracked and lost frames, frames with D^t, the steady-state speed and its split.
// The model is valid, not good: its wrinkle map, layout, PCA and cascade are fitted
// to noise textures (the run's bookkeeping is under test, not the regression).
// The last case runs the job from files (eval/capture_job.h) with the ground-truth fit.
#include "pipeline/capture/capture_run.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/options.h"
#include "eval/capture_job.h"
#include "eval/tracking_metrics.h"
#include "pipeline/training/patches.h"
#include "pipeline/training/trainer.h"
#include "pipeline/training/wrinkle_map.h"
#include "synth/actor.h"
#include "synth/dataset.h"
#include "synth/sequence.h"
#include "pipeline/capture/capture_io.h"
#include "tests/detail_model_test_util.h"
#include "tests/test_util.h"
#include "tests/synth_test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;

const FaceRig& Rig() { return testing::ProceduralRig(); }

constexpr int kR = 128;      // map resolution of the model and the session
constexpr int kFrames = 5;   // frames of the sequence
constexpr int kLost = 2;     // the frame the tracker loses

// A valid detail model fitted to noise: uniform textures in [0.3, 0.7], Gaussian
// displacements (σ 0.05 mm); G = 0, so the compatible rig is the rig.
DetailModel NoiseModel() {
  DetailModel m;
  m.map_resolution = kR;
  m.detail.lowpass_bandwidth_mm = 0.0;
  m.detail.map_resolution = kR;
  m.patch.patch_size = 8;
  cv::RNG rng(7);
  std::vector<cv::Mat> textures, displacements, responses;
  WrinkleMapBuilder builder(kR, cv::Mat(), Rig().regions, m.wrinkle);
  for (int i = 0; i < 4; ++i) {
    cv::Mat t(kR, kR, CV_32F), d(kR, kR, CV_32F);
    rng.fill(t, cv::RNG::UNIFORM, 0.3, 0.7);
    rng.fill(d, cv::RNG::NORMAL, 0.0, 0.05);
    textures.push_back(t);
    displacements.push_back(d);
    responses.push_back(builder.Add(t));
  }
  const PatchLayout layout = PlacePatches(builder.Finish(), m.patch);
  Require(layout.num_patches() > 0, "the noise wrinkle map placed no patches");
  testing::FitTinyRegressor(layout, textures, responses, displacements, /*pca_dimensions=*/4, /*num_ferns=*/10, &m);
  return m;
}

// The tiny sequence dataset: frames 0–4 of the wrinkle workout, 160×120, front light.
fs::path TinySequence() {
  static const fs::path dir = testing::TinySequenceDataset("capture_run_sequence", "wrinkle-workout", kFrames);
  return dir;
}

// A global tracker that reports the dataset's truth (eval/tracking_metrics.h) and
// loses frame `lost`; it detects on the first frame and on the frame after a loss.
class TruthTracker : public GlobalTracker {
 public:
  TruthTracker(const FaceRig& rig, fs::path dataset, int lost) : rig_(rig), dataset_(std::move(dataset)), lost_(lost) {}
  TrackedFrame Track(const cv::Mat&, int index) override {
    TrackedFrame t;
    t.frame = index;
    if (index != lost_) {
      const FrameTruth truth = ReadFrameTruth(dataset_, index, -1);
      if (identity_.size() == 0) identity_ = TruthIdentity(rig_, truth);
      t = TruthAsTrackedFrame(rig_, truth, index);
      t.detected = detect_next_;
    }
    detect_next_ = index == lost_;
    return t;
  }
  Eigen::VectorXd identity() const override {
    return identity_.size() ? identity_ : Eigen::VectorXd::Zero(rig_.num_identity());
  }
  std::string source_name() const override { return "truth"; }

 private:
  const FaceRig& rig_;
  fs::path dataset_;
  int lost_;
  bool detect_next_ = true;
  Eigen::VectorXd identity_;
};

CaptureOptions TinyCaptureOptions() {
  CaptureOptions co;
  co.detail.wrinkle_frames = 2;
  co.detail.fill.fill_resolution = 64;
  co.hifi.hifi_mesh_resolution = 64;
  return co;
}

int CountLines(const fs::path& path) {
  std::ifstream in(path);
  int n = 0;
  for (std::string line; std::getline(in, line);) ++n;
  return n;
}

TEST(CaptureRun, WritesTheFolderAndSummarisesTheRun) {
  const fs::path dataset = TinySequence();
  const fs::path root = testing::FixtureDir("capture_run");
  const DetailModel model = NoiseModel();
  auto frames = OpenFrameSource(dataset);
  ASSERT_TRUE(frames->info().camera.has_value());
  const CameraIntrinsics K = frames->info().camera->intrinsics;
  const FaceRig rig = CompatibleRig(Rig(), model);
  TruthTracker tracker(rig, dataset, kLost);
  CaptureSession session(rig, model, K, TinyCaptureOptions());

  CaptureRunOptions run;
  run.out = root / "cap";
  run.preview = (root / "cap.avi").string();
  run.mesh_every = 2;
  run.write_textures = true;
  run.input = dataset.string();
  run.model_path = "noise.cdm";
  run.source_rig = "procedural";
  run.setup_s = 1.5;
  const CaptureSummary s = RunCapture(run, TinyCaptureOptions(), model, K, frames.get(), &tracker, &session);

  // The counts: every frame returned once and in order, one lost, D^t on the rest.
  EXPECT_EQ(s.frames, kFrames);
  EXPECT_EQ(s.frame_indices, (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_EQ(s.tracked_frames, kFrames - 1);
  EXPECT_EQ(s.lost_frames(), 1);
  EXPECT_EQ(s.detail_frames, kFrames - 1);
  EXPECT_EQ(s.landmark_source, "truth");
  EXPECT_EQ(s.wrinkle_frames, 2);
  ASSERT_TRUE(session.layout_fixed());
  EXPECT_EQ(s.patches, session.detail().layout().num_patches());
  EXPECT_EQ(s.map_resolution, kR);
  EXPECT_EQ(s.identity.size(), rig.num_identity());
  EXPECT_DOUBLE_EQ(s.setup_s, 1.5);
  // The speed, frames overlapped (the default): frames 1 and 4 are steady (not
  // detected, not the first textured frame), but only frame 4 is finished in a step
  // of its own that begins no detected frame (the last step; frame 1 is finished with
  // frame 0, after the wrinkle map).
  EXPECT_TRUE(s.overlapped);
  EXPECT_EQ(s.steady_frames, 1);
  EXPECT_GT(s.fps, 0.0);
  EXPECT_GT(s.stage_ms_per_frame, 0.0);
  EXPECT_NEAR(s.fps * s.ms_per_frame, 1000.0, 1e-6);
  EXPECT_NEAR(s.tracking_share + s.detail_share, 1.0, 1e-9);
  ASSERT_FALSE(s.timing.empty());
  EXPECT_EQ(s.timing.front().name, "global tracker: landmarks");
  EXPECT_EQ(s.timing.front().count, kFrames - 1);
  EXPECT_NE(s.BriefReport().find("captured 5 frames: 4 tracked, 4 with detail"), std::string::npos) << s.BriefReport();

  // The folder: capture.json is the summary, a CSV row and a record per frame, D^t
  // and T^t where tracked, meshes of the even frames only, previews, the maps.
  EXPECT_EQ(s.out, run.out);
  EXPECT_EQ(s.capture_json, run.out / "capture.json");
  const nlohmann::json j = ReadJsonFile(s.capture_json);
  EXPECT_EQ(j, nlohmann::json::parse(s.ToJson()));
  EXPECT_EQ(j["frames"], kFrames);
  EXPECT_EQ(j["tracked_frames"], kFrames - 1);
  EXPECT_EQ(j["landmark_source"], "truth");
  EXPECT_EQ(j["options"], nlohmann::json::parse(OptionsToJson(TinyCaptureOptions())));
  EXPECT_EQ(CountLines(s.timings_csv), 1 + kFrames);
  for (int f = 0; f < kFrames; ++f) {
    const std::string n = fmt::format("{:06d}", f);
    EXPECT_TRUE(fs::is_regular_file(run.out / "frames" / (n + ".json"))) << n;
    EXPECT_TRUE(fs::is_regular_file(run.out / "frames" / (n + ".cfr"))) << n;
    EXPECT_EQ(fs::exists(run.out / "displacement" / (n + ".exr")), f != kLost) << n;
    EXPECT_EQ(fs::exists(run.out / "textures" / (n + ".png")), f != kLost) << n;
    EXPECT_EQ(fs::exists(run.out / "meshes" / "hifi" / (n + ".ply")), f % 2 == 0 && f != kLost) << n;
  }
  EXPECT_EQ(ReadJsonFile(run.out / "frames" / "000002.json")["tracked"], false);
  for (const char* f : {"rig.crig", "coarse.pvd", "refined.pvd", "hifi.pvd", "maps/mesoscopic.exr",
                        "maps/wrinkle_map.exr", "maps/wrinkle_map.png", "previews/000000.png"}) {
    EXPECT_TRUE(fs::is_regular_file(run.out / f)) << f;
  }
  EXPECT_GT(fs::file_size(root / "cap.avi"), 0u);

  // An existing folder is not replaced without overwrite; bad options name the field.
  EXPECT_THROW(RunCapture(run, TinyCaptureOptions(), model, K, frames.get(), &tracker, &session), Error);
  CaptureRunOptions bad = run;
  bad.out = root / "cap_bad";
  bad.mesh_every = 0;
  try {
    RunCapture(bad, TinyCaptureOptions(), model, K, frames.get(), &tracker, &session);
    ADD_FAILURE() << "mesh_every = 0 was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mesh_every"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(bad.out));
}

// Rung R2-pairs: with a folder of truth maps, pairs.cpr holds every pairs_every-th
// frame's pairs (one "actor" per frame, frame_NNNNNN), each displacement row cut from
// that frame's own map; a missing map is an error that leaves no folder behind.
TEST(CaptureRun, ThePairsOfEveryNthFrameCarryThatFramesTruth) {
  const fs::path dataset = TinySequence();
  const fs::path root = testing::FixtureDir("capture_run_pairs");
  const DetailModel model = NoiseModel();
  auto frames = OpenFrameSource(dataset);
  const CameraIntrinsics K = frames->info().camera->intrinsics;
  const FaceRig rig = CompatibleRig(Rig(), model);
  const fs::path maps = root / "truth";
  fs::create_directories(maps);
  for (int f = 0; f < kFrames; ++f) {  // frame f's truth: 0.01·(f + 1) mm everywhere
    WriteImage(maps / fmt::format("{:06d}.exr", f), cv::Mat(kR, kR, CV_32F, cv::Scalar(0.01f * (f + 1))));
  }
  CaptureRunOptions run;
  run.out = root / "cap";
  run.write_meshes = false;
  run.pairs_truth_maps = maps.string();
  run.pairs_every = 2;  // frames 0, 2 and 4; frame 2 is lost
  CaptureOptions co = TinyCaptureOptions();
  co.detail.patch_max_unseen_fraction = 1.0;  // keep every patch of the tiny frames
  TruthTracker tracker(rig, dataset, kLost);
  CaptureSession session(rig, model, K, co);
  RunCapture(run, co, model, K, frames.get(), &tracker, &session);
  const TrainingPairs pairs = ReadTrainingPairs(run.out / "pairs.cpr");
  ASSERT_EQ(pairs.actor_names, (std::vector<std::string>{"frame_000000", "frame_000004"}));
  const int n = model.patch.patch_size * model.patch.patch_size;
  ASSERT_GT(pairs.texture.rows(), 0);
  ASSERT_EQ(pairs.texture.cols(), n);
  ASSERT_EQ(pairs.actor.size(), static_cast<size_t>(pairs.texture.rows()));
  EXPECT_EQ(pairs.texture.rows(), 2 * session.detail().layout().num_patches());
  for (Eigen::Index i = 0; i < pairs.displacement.rows(); ++i) {
    const float expected = pairs.actor[i] == 0 ? 0.01f : 0.05f;
    ASSERT_NEAR(pairs.displacement.row(i).minCoeff(), expected, 1e-6f) << "row " << i;
    ASSERT_NEAR(pairs.displacement.row(i).maxCoeff(), expected, 1e-6f) << "row " << i;
  }
  EXPECT_EQ(nlohmann::json::parse(pairs.options_json), nlohmann::json::parse(model.training_json).value(
                                                          "options", nlohmann::json::object()));

  // A frame without its map: an error naming the file, and no output folder.
  fs::remove(maps / "000004.exr");
  run.out = root / "cap_missing";
  auto frames2 = OpenFrameSource(dataset);
  TruthTracker tracker2(rig, dataset, kLost);
  CaptureSession session2(rig, model, K, co);
  EXPECT_ERROR_HAS(RunCapture(run, co, model, K, frames2.get(), &tracker2, &session2),
                   "000004.exr: missing (pairs_truth_maps");
  EXPECT_FALSE(fs::exists(run.out));
  run.pairs_every = 0;
  EXPECT_ERROR_HAS(run.Check(), "pairs_every");
}

// Overlapped frames (the default: frame t+1's tracking and texture beside frame t's
// D^t and H^t) write the serial order's files byte for byte, with the same frames
// in the same order; only the stage times and the speed's bookkeeping differ.
TEST(CaptureRun, OverlappedFramesWriteWhatTheSerialOrderWrites) {
  const fs::path dataset = TinySequence();
  const fs::path root = testing::FixtureDir("capture_run_overlap");
  const DetailModel model = NoiseModel();
  const FaceRig rig = CompatibleRig(Rig(), model);
  std::vector<CaptureSummary> s;
  for (const bool overlap : {false, true}) {
    auto frames = OpenFrameSource(dataset);
    const CameraIntrinsics K = frames->info().camera->intrinsics;
    TruthTracker tracker(rig, dataset, kLost);
    CaptureSession session(rig, model, K, TinyCaptureOptions());
    CaptureRunOptions run;
    run.out = root / (overlap ? "overlapped" : "serial");
    run.overwrite = true;
    run.mesh_every = 2;
    run.write_textures = true;
    run.overlap_frames = overlap;
    s.push_back(RunCapture(run, TinyCaptureOptions(), model, K, frames.get(), &tracker, &session));
  }
  EXPECT_FALSE(s[0].overlapped);
  EXPECT_EQ(s[0].steady_frames, 2);  // frames 1 and 4, their stage times summed
  EXPECT_DOUBLE_EQ(s[0].ms_per_frame, s[0].stage_ms_per_frame);
  EXPECT_TRUE(s[1].overlapped);
  EXPECT_EQ(s[1].frame_indices, s[0].frame_indices);
  EXPECT_EQ(s[1].detail_frames, s[0].detail_frames);

  // Every file but the timings, byte for byte; the per-frame records without their times.
  const auto without_times = [](nlohmann::json j) {
    j.erase("timing_ms");
    return j;
  };
  int compared = 0;
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(s[0].out)) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), s[0].out);
    const fs::path other = s[1].out / rel;
    ASSERT_TRUE(fs::is_regular_file(other)) << rel;
    if (rel == "capture.json" || rel == "timings.csv") continue;
    if (rel.parent_path() == "frames" && rel.extension() == ".json") {
      EXPECT_EQ(without_times(ReadJsonFile(e.path())), without_times(ReadJsonFile(other))) << rel;
    } else {
      EXPECT_EQ(ReadFileToString(e.path()), ReadFileToString(other)) << rel;
    }
    ++compared;
  }
  EXPECT_GE(compared, 5 * 3 + 4 + 4);  // frames (.json, .cfr, the meshes), D^t and T^t of the tracked ones
}

// A source without frames is an error naming the input, and leaves no folder behind.
// Issue 19: NaN in the truth (and in a capture's tracked frame) was accepted and
// every error computed on it; both readers refuse it, naming the file.
TEST(CaptureRun, NanTruthAndNanCapturesAreRefused) {
  const fs::path dir = testing::TestDir();
  fs::create_directories(dir / "truth");
  for (const char* f : {"000000.json", "000000_vertices.bin"}) fs::copy_file(TinySequence() / "truth" / f, dir / "truth" / f);
  EXPECT_EQ(ReadFrameTruth(dir, 0, -1).vertices.rows() > 0, true);
  {
    std::fstream bin(dir / "truth" / "000000_vertices.bin", std::ios::in | std::ios::out | std::ios::binary);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    bin.write(reinterpret_cast<const char*>(&nan), sizeof(nan));
  }
  EXPECT_ERROR_HAS(ReadFrameTruth(dir, 0, -1), "000000_vertices.bin: NaN or infinite vertex projections");
  CaptureFrameArrays a;
  a.frame = 3;
  a.tracked = true;
  a.coarse = MatX3d::Zero(4, 3);
  a.refined = MatX3d::Zero(4, 3);
  a.landmarks = MatX2d::Zero(68, 2);
  WriteCaptureFrameArrays(dir / "f.cfr", a);
  EXPECT_NO_THROW(ReadCaptureFrameArrays(dir / "f.cfr"));
  a.refined(2, 1) = std::numeric_limits<double>::quiet_NaN();
  WriteCaptureFrameArrays(dir / "f.cfr", a);
  EXPECT_ERROR_HAS(ReadCaptureFrameArrays(dir / "f.cfr"), "f.cfr: a tracked frame holds NaN");
  a.tracked = false;  // a lost frame's arrays carry no claim
  WriteCaptureFrameArrays(dir / "f.cfr", a);
  EXPECT_NO_THROW(ReadCaptureFrameArrays(dir / "f.cfr"));
}

// Issue 19: a truth pose with short arrays was read past their end (truth_json_fuzzer);
// capture.json without frame_indices, or with fields of the wrong type, was an
// internal error without the file (capture_json_fuzzer). Both name file and field.
TEST(CaptureRun, MalformedTruthPoseAndCaptureJsonNameTheField) {
  const fs::path dir = testing::TestDir();
  fs::create_directories(dir / "truth");
  for (const char* f : {"000000.json", "000000_vertices.bin"}) fs::copy_file(TinySequence() / "truth" / f, dir / "truth" / f);
  nlohmann::json truth = ReadJsonFile(dir / "truth" / "000000.json");
  truth["cam_from_head"]["rotation_wxyz"] = {1.0};
  WriteJsonFile(dir / "truth" / "000000.json", truth);
  EXPECT_ERROR_HAS(ReadFrameTruth(dir, 0, -1), "000000.json: cam_from_head needs rotation_wxyz (4 numbers)");
  truth["cam_from_head"]["rotation_wxyz"] = {0.0, 0.0, 0.0, 0.0};
  WriteJsonFile(dir / "truth" / "000000.json", truth);
  EXPECT_ERROR_HAS(ReadFrameTruth(dir, 0, -1), "rotation_wxyz is not a unit quaternion");

  const fs::path cap = dir / "capture.json";
  auto read_with = [&](const nlohmann::json& j) {
    WriteJsonFile(cap, j);
    return testing::ErrorOf([&] { ReadCaptureJson(cap); });
  };
  EXPECT_NE(read_with({{"map_resolution", 64}}).find(cap.string() + ": field 'frame_indices'"), std::string::npos);
  EXPECT_NE(read_with({{"frame_indices", {0, -1}}}).find("not a frame number"), std::string::npos);
  EXPECT_NE(read_with({{"frame_indices", {0}}, {"fps", "fast"}}).find("field 'fps' must be a number"),
            std::string::npos);
  EXPECT_NE(read_with({{"frame_indices", {0}}, {"map_resolution", 0}}).find("field 'map_resolution'"),
            std::string::npos);
  EXPECT_NE(read_with(nlohmann::json::array()).find("not a JSON object"), std::string::npos);
  EXPECT_EQ(read_with({{"frame_indices", {0, 1}}, {"options", nlohmann::json::object()}}), "");
}

// capture.json's options as `crease eval` reads them (CaptureOptionsOfJson): the
// sectioned form capture writes now, and the flat form of captures from before option
// sections, whose keys are read as their new keys — renamed ones included
// (refine_expression_prior_weight is now refinement.expression_prior_weight).
TEST(CaptureRun, CaptureOptionsReadFromSectionedAndFlatCaptureJson) {
  CaptureOptions o;
  o.refinement.lk_window = 15;
  o.refinement.fit_expression_prior_weight = 0.25;
  o.texture.max_view_angle_deg = 70.0;
  o.refine = false;
  const nlohmann::json sectioned = {{"frame_indices", {0}}, {"options", nlohmann::json::parse(OptionsToJson(o))}};
  const nlohmann::json flat = {{"frame_indices", {0}},
                               {"options",
                                {{"lk_window", 15},
                                 {"refine_expression_prior_weight", 0.25},
                                 {"max_view_angle_deg", 70.0},
                                 {"refine", false}}}};
  for (const nlohmann::json& j : {sectioned, flat}) {
    const CaptureOptions read = CaptureOptionsOfJson(j, "capture.json");
    EXPECT_EQ(read.refinement.lk_window, 15);
    EXPECT_EQ(read.refinement.fit_expression_prior_weight, 0.25);
    EXPECT_EQ(read.texture.max_view_angle_deg, 70.0);
    EXPECT_FALSE(read.refine);
    EXPECT_EQ(read.tracker.fit.fit_max_iterations, CaptureOptions().tracker.fit.fit_max_iterations);
  }
  EXPECT_EQ(CaptureOptionsOfJson({{"frame_indices", {0}}}, "capture.json").refinement.lk_window,
            CaptureOptions().refinement.lk_window);
  EXPECT_ERROR_HAS(CaptureOptionsOfJson({{"options", {{"lk_window", "wide"}}}}, "old/capture.json"),
                   "old/capture.json");
  EXPECT_ERROR_HAS(CaptureOptionsOfJson({{"options", {{"lk_window", 2}}}}, "old/capture.json"), "lk_window = 2");
}

// Issue 19 (cfr_fuzzer): a .cfr header claiming 2^63 − 1 vertices overflowed 3 × n.
TEST(CaptureRun, CfrVertexCountIsBounded) {
  const fs::path dir = testing::TestDir();
  CaptureFrameArrays a;
  a.coarse = MatX3d::Zero(4, 3);
  a.refined = MatX3d::Zero(4, 3);
  WriteCaptureFrameArrays(dir / "f.cfr", a);
  const std::string from = "\"num_vertices\":4", to = "\"num_vertices\":9223372036854775807";
  const std::string bytes = testing::EditArrayFileHeader(ReadFileToString(dir / "f.cfr"), [&](std::string header) {
    EXPECT_NE(header.find(from), std::string::npos) << header;
    return header.replace(header.find(from), from.size(), to);
  });
  testing::WriteText(dir / "huge.cfr", bytes);
  EXPECT_ERROR_HAS(ReadCaptureFrameArrays(dir / "huge.cfr"), "huge.cfr: num_vertices above");
}

TEST(CaptureRun, NoFramesIsAnError) {
  const fs::path dataset = TinySequence();
  const fs::path root = testing::FixtureDir("capture_run_empty");
  const DetailModel model = NoiseModel();
  auto frames = OpenFrameSource(dataset);
  const CameraIntrinsics K = frames->info().camera->intrinsics;
  const FaceRig rig = CompatibleRig(Rig(), model);
  TruthTracker tracker(rig, dataset, -1);
  CaptureSession session(rig, model, K, TinyCaptureOptions());
  CaptureRunOptions run;
  run.out = root / "cap";
  run.max_frames = 0;
  run.input = "the-input";
  try {
    RunCapture(run, TinyCaptureOptions(), model, K, frames.get(), &tracker, &session);
    ADD_FAILURE() << "a run without frames succeeded";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the-input: no frames"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(run.out));
}

// The job `crease capture` runs from files (eval/capture_job.h): the rig defaults to
// the dataset's tracking rig, the camera to its calibration, the ground-truth fit
// tracks every frame, and the set-up the job times is what capture.json records.
TEST(CaptureRun, FromFilesTracksWithTheDatasetsRigAndRecordsTheSetUp) {
  const fs::path dataset = TinySequence();
  const fs::path root = testing::FixtureDir("capture_from_files");
  fs::create_directories(root);
  CaptureFiles files;
  files.input = dataset.string();
  files.model = (root / "noise.cdm").string();
  WriteDetailModel(files.model, NoiseModel());
  files.control.ground_truth_fit = true;
  CaptureRunOptions run;
  run.out = root / "cap";
  run.max_frames = 3;
  run.write_meshes = false;
  run.setup_s = -1.0;  // replaced by the job's own set-up time
  std::vector<std::string> lines;
  const CaptureSummary s =
      CaptureFromFiles(files, TinyCaptureOptions(), run, [&](const std::string& l) { lines.push_back(l); });

  EXPECT_EQ(s.input, files.input);
  EXPECT_EQ(s.model, files.model);
  EXPECT_EQ(s.source_rig, DatasetTrackingRig(dataset));
  EXPECT_EQ(s.landmark_source, "ground-truth-fit");
  EXPECT_EQ(s.frames, 3);
  EXPECT_EQ(s.tracked_frames, 3);
  EXPECT_EQ(s.detail_frames, 3);
  // The two set-up lines, whose times (0.1 s rounding) add up to the recorded set-up.
  ASSERT_EQ(lines.size(), 2u);
  double rig_s = -1, session_s = -1;
  ASSERT_EQ(std::sscanf(lines[0].c_str(), "rig made compatible with the model's lowpass (Sec. 4.1) in %lf s", &rig_s), 1)
      << lines[0];
  ASSERT_EQ(std::sscanf(lines[1].c_str(), "capture set up (UV raster, geodesics, stencils) in %lf s", &session_s), 1)
      << lines[1];
  EXPECT_GT(s.setup_s, 0.0);
  EXPECT_NEAR(s.setup_s, rig_s + session_s, 0.1 + 1e-9);
  EXPECT_DOUBLE_EQ(ReadJsonFile(s.capture_json)["setup_s"].get<double>(), s.setup_s);
  // A rig that is not there: an error naming it, and no folder.
  files.rig = (root / "missing.crig").string();
  run.out = root / "cap2";
  EXPECT_ERROR_HAS(CaptureFromFiles(files, TinyCaptureOptions(), run), "missing.crig");
  EXPECT_FALSE(fs::exists(run.out));
}

}  // namespace
}  // namespace crease
