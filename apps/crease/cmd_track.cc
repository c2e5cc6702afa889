// `crease track`: the global face tracker on a video, an image folder or a studio
// sequence (issue 5). The run itself is eval/track_run.h.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "apps/crease/commands.h"
#include "apps/crease/track_util.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/options.h"
#include "eval/track_run.h"
#include "pipeline/capture/frame_source.h"
#include "pipeline/capture/tracker.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

// `crease track`: its flags, turned into TrackerOptions and TrackRunOptions.
struct TrackArgs {
  TrackingFlags tf;
  std::string out, preview;
  bool no_meshes = false;
  std::vector<std::string> sets;
};

void RunTrackCommand(TrackArgs& a) {
  TrackingFlags& tf = a.tf;
  TrackerOptions options;
  options.landmark_source = tf.tracker_model.empty() ? FromString<LandmarkSourceKind>(tf.landmarks, "--landmarks")
                                                     : LandmarkSourceKind::kRegressor;
  options.tracker_model = tf.tracker_model;
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &options);
  options.Check();
  auto frames = OpenFrameSource(tf.input);
  const FrameSourceInfo& info = frames->info();
  const bool dataset = info.kind == "dataset";
  tf.rig_path = TrackingRigPath(tf.rig_path, info);
  const FaceRig rig = ReadRig(tf.rig_path);
  const CameraIntrinsics K = ResolveIntrinsics(tf.camera_path, info, tf.fov);
  Require(!tf.gt_prior || dataset, "--ground-truth-prior needs a crease sequence dataset as input");
  FrameTracker tracker(rig, K, options, tf.Control(), dataset ? info.path : fs::path());
  TrackRunOptions run;
  run.out = a.out;
  run.preview = a.preview;
  run.max_frames = tf.max_frames;
  run.write_meshes = !a.no_meshes;
  run.input = tf.input;
  const TrackSummary s = RunTracking(run, options, rig, K, frames.get(), &tracker);
  std::printf("%s", s.BriefReport().c_str());
  std::printf("wrote %s\n", a.out.c_str());
}

}  // namespace

void AddTrackCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("track", "Global face tracker: landmarks and the rig fitted per frame (issue 5)");
  auto a = std::make_shared<TrackArgs>();
  AddTrackingFlags(cmd, &a->tf);
  cmd->add_option("--out,-o", a->out, "Output folder")->required();
  cmd->add_option("--preview", a->preview, "Preview video (.avi: MJPG, .mp4: mp4v) with landmarks and mesh");
  cmd->add_flag("--no-meshes", a->no_meshes, "Skip the per-frame PLY/VTP meshes");
  cmd->add_option("--set", a->sets, "Tracker option KEY=VALUE (repeatable; pipeline/capture/tracker.h TrackerOptions)");
  cmd->callback([a] { RunTrackCommand(*a); });
}

}  // namespace crease::app
