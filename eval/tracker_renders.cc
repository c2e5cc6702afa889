#include "eval/tracker_renders.h"

#include <algorithm>
#include <fmt/format.h>

#include "core/error.h"
#include "core/rng.h"
#include "core/timer.h"
#include "synth/actor.h"
#include "synth/sensor.h"
#include "synth/studio.h"

namespace crease {

namespace fs = std::filesystem;

namespace {

// The random settings of one render.
struct RenderDraw {
  Eigen::VectorXd weights;  // blendshape weights
  SequenceFrame pose;
  size_t light = 0;         // index into the light rigs
  SensorOptions sensor;
  uint64_t render_seed = 0;
};

RenderDraw DrawRender(const TrackerTrainingOptions& options, int E, size_t num_lights, Rng& rng) {
  RenderDraw d;
  // Expression: a few random blendshapes, some at full weight (extreme).
  d.weights = Eigen::VectorXd::Zero(E);
  const int active = E > 0 ? rng.UniformInt(0, std::min(options.max_active_expressions, E)) : 0;
  for (int a = 0; a < active; ++a) {
    const int e = static_cast<int>(rng.UniformInt(static_cast<uint64_t>(E)));
    d.weights[e] = rng.Uniform() < options.extreme_probability ? 1.0 : rng.Uniform();
  }
  d.pose.yaw_deg = rng.Uniform(-options.max_yaw_deg, options.max_yaw_deg);
  d.pose.pitch_deg = rng.Uniform(-options.max_pitch_deg, options.max_pitch_deg);
  d.pose.roll_deg = rng.Uniform(-options.max_roll_deg, options.max_roll_deg);
  d.pose.tx_mm = rng.Uniform(-options.max_shift_mm, options.max_shift_mm);
  d.pose.ty_mm = rng.Uniform(-options.max_shift_mm, options.max_shift_mm);
  d.pose.tz_mm = rng.Uniform(-options.max_depth_mm, options.max_depth_mm);
  d.light = rng.UniformInt(static_cast<uint64_t>(num_lights));
  d.sensor.exposure = rng.Uniform(options.exposure_min, options.exposure_max);
  d.sensor.full_well_electrons = rng.Uniform(options.full_well_min, options.full_well_max);
  d.sensor.jpeg_quality = rng.Uniform() < options.jpeg_probability ? rng.UniformInt(40, 95) : 0;
  d.render_seed = rng.NextU64();
  return d;
}

}  // namespace

std::vector<LabelledFace> RenderLabelledFaces(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                                              const TrackerTrainingOptions& options) {
  options.Check();
  std::vector<int> ibug(68);
  for (int i = 0; i < 68; ++i) {
    ibug[i] = rig.LandmarkIndex(fmt::format("ibug_{}", i + 1));
    Require(ibug[i] >= 0, fmt::format("tracker training: the rig has no landmark ibug_{}", i + 1));
  }
  std::vector<LightRig> lights;
  for (const auto& spec : options.lights) lights.push_back(LightRigFromSpec(spec));
  ActorOptions ao;
  ao.resolution = options.actor_resolution;
  ao.surface_min_vertices = 0;
  StudioOptions so;
  so.width = options.width;
  so.height = options.height;
  so.fov_deg = options.fov_deg;
  so.samples_per_axis = 1;
  so.sensor.noise = false;  // the sensor is applied below with per-render settings
  const int E = rig.num_expressions();
  std::vector<LabelledFace> out;
  for (uint64_t actor_seed : actor_seeds) {
    const Actor actor = GenerateActor(rig, actor_seed, ao);
    const Studio studio(rig, actor, so);
    Rng rng(options.data_seed ^ (0x9E3779B97F4A7C15ULL * (actor_seed + 1)));
    for (int k = 0; k < options.renders_per_actor; ++k) {
      const RenderDraw d = DrawRender(options, E, lights.size(), rng);
      const StudioFrame f = studio.RenderStill(d.weights, d.pose, &lights[d.light], nullptr, d.render_seed);
      Rng sensor_rng(d.render_seed + 1);
      LabelledFace face;
      face.name = fmt::format("actor{:06d}_{:04d}", actor_seed, k);
      face.image = ApplySensor(f.render.image, d.sensor, sensor_rng).srgb8;
      face.landmarks.resize(68, 2);
      for (int i = 0; i < 68; ++i) face.landmarks.row(i) = f.truth.landmark_pixels.row(ibug[i]);
      out.push_back(std::move(face));
    }
  }
  return out;
}

TrackerTrainingResult TrainTrackerOnRenders(const FaceRig& rig, const TrackerTrainingOptions& options,
                                            const fs::path& save_dir, const std::vector<LabelledFace>& extra_train) {
  options.Check();
  const ScopedTimer timer(nullptr, "");
  std::vector<uint64_t> train_seeds, test_seeds;
  for (int a = 0; a < options.train_actors; ++a) train_seeds.push_back(options.data_seed * 1000 + a);
  for (int a = 0; a < options.test_actors; ++a) test_seeds.push_back(options.data_seed * 1000 + 500 + a);
  std::vector<LabelledFace> train = RenderLabelledFaces(rig, train_seeds, options);
  train.insert(train.end(), extra_train.begin(), extra_train.end());
  const std::vector<LabelledFace> test = RenderLabelledFaces(rig, test_seeds, options);
  if (!save_dir.empty()) {
    WriteLabelledFaces(save_dir / "train", train);
    WriteLabelledFaces(save_dir / "test", test);
  }
  const double data_s = timer.Elapsed();
  TrackerTrainingResult r = TrainAndEvaluateTracker(train, test, options);
  r.report.data_seconds = data_s;
  r.report.seconds = timer.Elapsed();
  return r;
}

}  // namespace crease
