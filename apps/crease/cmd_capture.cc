// `crease capture` (paper Sec. 5: online capture from a video to H^t) and
// `crease eval` (its metrics against a studio sequence's ground truth), issue 6.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "apps/crease/commands.h"
#include "apps/crease/track_util.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/options.h"
#include "eval/capture_job.h"
#include "eval/capture_metrics.h"
#include "pipeline/capture/capture.h"
#include "pipeline/capture/capture_run.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

// `crease capture`: its flags, turned into CaptureOptions and CaptureRunOptions.
struct CaptureArgs {
  TrackingFlags tf;
  std::string model_path, out, preview, config, pairs_truth;
  int mesh_every = 1, pairs_every = 1;
  bool no_meshes = false, no_maps = false, write_textures = false, overwrite = false, serial = false;
  std::vector<std::string> sets;
};

void RunCaptureCommand(const CaptureArgs& a) {
  const TrackingFlags& tf = a.tf;
  CaptureOptions options;
  options.tracker.landmark_source = tf.tracker_model.empty() ? FromString<LandmarkSourceKind>(tf.landmarks, "--landmarks")
                                                             : LandmarkSourceKind::kRegressor;
  options.tracker.tracker_model = tf.tracker_model;
  if (!a.config.empty()) SetOptionsFromYaml(ReadFileToString(a.config), a.config, &options);
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &options);
  options.Check();
  Require(a.mesh_every >= 1, "--mesh-every must be at least 1");
  CaptureFiles files;
  files.input = tf.input;
  files.model = a.model_path;
  files.rig = tf.rig_path;
  files.camera = tf.camera_path;
  files.fov_deg = tf.fov;
  files.control = tf.Control();
  CaptureRunOptions run;
  run.out = a.out;
  run.overwrite = a.overwrite;
  run.preview = a.preview;
  run.max_frames = tf.max_frames;
  run.mesh_every = a.mesh_every;
  run.write_meshes = !a.no_meshes;
  run.write_maps = !a.no_maps;
  run.write_textures = a.write_textures;
  run.overlap_frames = !a.serial;
  run.pairs_truth_maps = a.pairs_truth;
  run.pairs_every = a.pairs_every;
  const CaptureSummary summary =
      CaptureFromFiles(files, options, run, [](const std::string& line) { std::printf("%s\n", line.c_str()); });
  std::printf("%s", summary.BriefReport().c_str());
  std::printf("wrote %s\n", a.out.c_str());
}

void AddCaptureCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("capture", "Online capture (paper Sec. 5): L^t, refined L~^t, D^t and H^t per frame");
  auto a = std::make_shared<CaptureArgs>();
  AddTrackingFlags(cmd, &a->tf);
  cmd->add_flag("--ground-truth-fit", a->tf.gt_fit,
                "Experimental control: the dataset's true pose, expression weights and identity as the tracker's fit "
                "(exact geometry up to the actor's personal deviations), to isolate the detail path; never a default");
  cmd->add_flag("--ground-truth-surface", a->tf.gt_surface,
                "Experimental control: --ground-truth-fit on the actor's own expression shapes, so that L^t is the "
                "true coarse surface (no model error); never a default");
  cmd->add_option("--model,-m", a->model_path, "Detail model (.cdm, from `crease train`)")->required();
  cmd->add_option("--out,-o", a->out, "Output folder (written under a temporary name, renamed when complete)")->required();
  cmd->add_option("--preview", a->preview, "Preview video (.avi: MJPG, .mp4: mp4v): the frame with L~^t beside D^t");
  cmd->add_option("--mesh-every", a->mesh_every, "Write the meshes of every N-th frame")->capture_default_str();
  cmd->add_flag("--no-meshes", a->no_meshes, "Skip the per-frame PLY/VTP meshes");
  cmd->add_flag("--textures", a->write_textures, "Also write every frame's texture T^t (textures/NNNNNN.png, sRGB gray)");
  cmd->add_flag("--no-maps", a->no_maps, "Skip the per-frame displacement maps D^t (EXR)");
  cmd->add_option("--pairs-truth", a->pairs_truth,
                  "Issue 17's rung R2-pairs: a folder of the frames' true D* maps (`crease truth-maps`); writes "
                  "pairs.cpr, the video's own regression pairs (T^t and D* on the capture's patches), for `crease "
                  "model eval-pairs`");
  cmd->add_option("--pairs-every", a->pairs_every, "With --pairs-truth: the pairs of every N-th frame")
      ->capture_default_str();
  cmd->add_option("--config", a->config, "YAML of capture options (pipeline/capture/capture.h CaptureOptions)");
  cmd->add_option("--set", a->sets, "Capture option KEY=VALUE (repeatable), e.g. detail.wrinkle_frames=20 refine=false");
  cmd->add_flag("--overwrite", a->overwrite, "Replace an existing output folder");
  cmd->add_flag("--serial", a->serial,
                "One frame after another instead of overlapping frame t+1's tracking and texture with frame t's detail "
                "(the same outputs; each stage's time alone)");
  cmd->callback([a] { RunCaptureCommand(*a); });
}

// `crease eval`: a capture's metrics against a studio sequence's ground truth.
struct EvalArgs {
  std::string capture_dir, dataset_dir, out;
  std::vector<std::string> sets;
};

void RunEvalCommand(const EvalArgs& a) {
  CaptureEvalOptions options;
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &options);
  const CaptureEvalSummary s = EvaluateCapture(a.capture_dir, a.dataset_dir, options);
  const fs::path dir = a.out.empty() ? fs::path(a.capture_dir) : fs::path(a.out);
  WriteCaptureEval(dir, s);
  if (!s.error_vectors.empty()) {
    std::printf("wrote %s (frame %d: 2D error vectors of L^t and L~^t)\n",
                (dir / "error_vectors.png").string().c_str(), s.error_vectors_frame);
  }
  std::printf("%s\nwrote %s/eval.{md,json} and eval_frames.csv\n", s.ToMarkdown().c_str(), dir.string().c_str());
}

void AddEvalCommand(CLI::App& app) {
  auto* ev = app.add_subcommand("eval", "Metrics of a capture against a studio sequence's ground truth (issue 6)");
  auto a = std::make_shared<EvalArgs>();
  ev->add_option("--capture,-c", a->capture_dir, "Capture folder (from `crease capture`)")->required();
  ev->add_option("--dataset,-d", a->dataset_dir, "Sequence dataset (from `crease synth sequence`)")->required();
  ev->add_option("--out,-o", a->out, "Output folder (default: the capture folder)");
  ev->add_option("--set", a->sets, "Eval option KEY=VALUE (eval/capture_metrics.h), e.g. surface_every=10");
  ev->callback([a] { RunEvalCommand(*a); });
}

}  // namespace

void AddCaptureCommands(CLI::App& app) {
  AddCaptureCommand(app);
  AddEvalCommand(app);
}

}  // namespace crease::app
