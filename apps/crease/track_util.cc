#include "apps/crease/track_util.h"

namespace crease::app {

void AddTrackingFlags(CLI::App* cmd, TrackingFlags* f) {
  cmd->add_option("--input,-i", f->input, "Video file, image folder or crease sequence dataset")->required();
  cmd->add_option("--rig", f->rig_path, "Rig (.crig); default: the dataset's rig.crig");
  cmd->add_option("--landmarks", f->landmarks, "Landmark source: dlib or regressor")->capture_default_str();
  cmd->add_option("--tracker", f->tracker_model, "Regressor model (from `crease train-tracker`); implies --landmarks regressor");
  cmd->add_option("--camera", f->camera_path, "Camera JSON (intrinsics); default: the dataset's, else --fov");
  cmd->add_option("--fov", f->fov, "Horizontal field of view, degrees, when there is no calibration")
      ->capture_default_str();
  cmd->add_option("--max-frames", f->max_frames, "Stop after this many frames");
  cmd->add_flag("--ground-truth-prior", f->gt_prior,
                "Experimental control: fit the rig to the dataset's ground-truth landmarks (+ --noise), "
                "to isolate later stages; never a default");
  cmd->add_option("--noise", f->noise, "Ground-truth-prior landmark noise, px (σ)")->capture_default_str();
  cmd->add_option("--seed", f->seed, "Seed of the ground-truth-prior noise")->capture_default_str();
}

}  // namespace crease::app
