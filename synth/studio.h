// The studio: an actor of a rig on a posable head, lit by a light rig, seen by a
// camera, rendered by the Embree renderer through the sensor model — with the
// exact ground truth of every frame. Used by the dataset writers (synth/dataset.h)
// and the realism check.
//
// Scene per frame (one topology for the whole sequence, so the BVH is refitted,
// never rebuilt, and any frame can be relit):
//   * the actor's high-resolution face surface (the rig's UV chart [0,1]², with
//     static shape, wrinkles and pores), textured with the actor's skin maps;
//   * the rig's other parts (cranium, ears, neck, eyes, mouth cavity, hair, …)
//     at the same identity and expression, with per-part materials;
//   * an underlay: the rig's face part pushed 3 mm inwards (less within 10 mm of
//     the seam with the rest of the head, down to 0.05 mm at it), hiding the
//     texel-wide cracks between the resampled face and the rest of the head; the
//     face's static shape and skin maps fade into the parts' uniform material
//     towards that seam, so it shows no step, slit or change of colour;
//   * optionally an occluder (a sphere) that sequences move in front of the face.
// The head is posed (yaw, pitch, roll about the head centre, then translated);
// camera and lights stay fixed in the world (lights attached to the camera).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/camera.h"
#include "core/face_rig.h"
#include "core/options.h"
#include "core/rng.h"
#include "core/timer.h"
#include "synth/actor.h"
#include "synth/lights.h"
#include "synth/renderer.h"
#include "synth/sensor.h"
#include "synth/sequence.h"

namespace crease {

// A light rig by name (a preset of synth/lights.h: front, raking-above, raking-side,
// studio, ceiling, studio-env, overcast, window), "directional:AZ:EL[:AMBIENT]" (one
// camera-attached directional light at azimuth/elevation in degrees, DirectionalRig,
// with ambient occlusion AMBIENT, default 0.05: for sweeps of the light direction),
// "sphere:AZ:EL:DIAMETER[:AMBIENT]" (the same light from a sphere DIAMETER degrees
// wide, e.g. a lamp or softbox, whose shadows have a penumbra) or a lat-long environment map file (.exr, .hdr: linear radiance, importance sampled).
// Errors name the preset or the file.
LightRig LightRigFromSpec(const std::string& spec);

struct StudioOptions {
  int width = 640;                  // image size, pixels (a webcam, as in the paper's capture)
  int height = 480;
  double fov_deg = 50.0;            // horizontal field of view, degrees
  double distance_mm = 450.0;       // camera to face centre, mm
  std::string light = "studio";     // light rig when the sequence keys none: a preset or an EXR (LightRigFromSpec)
  double light_fill = 0.15;         // ambient fill under a sequence-driven directional light
  // Anti-aliasing: N×N stratified samples per pixel, box-filtered, as a sensor's
  // pixels integrate the light over their area. 2 since crease 0.4.17 (was 1, point
  // sampling, while the scans were rendered at 2): point sampling aliases the pores,
  // brows and hair edges into a speckle that a camera does not record. On the holds'
  // novel actors (seeds 1–3, rung R2, `gated-level`) 2×2 raises D^t's wrinkle band
  // correlation with D* from 0.305 to 0.332 and the still face from 0.78 to 0.85, and
  // lowers L~^t + D^t's band normal error from 1.21 to 1.08 × L~^t's, on every seed
  // (README, "Pixels that integrate"). Rendering takes about 4 × as long (a whole
  // sequence with its files 1.3–2.2 ×).
  int samples_per_axis = 2;
  double subsurface_mm = 0.0;       // skin subsurface blur of the diffuse light (RenderOptions::subsurface_mm)
  int motion_blur_subframes = 5;    // sub-frames over the shutter when the sequence asks for motion blur
  double shutter = 0.5;             // shutter interval as a fraction of the frame time
  bool occluder = true;             // add the occluder sphere when the sequence keys one
  // Linear RGB of what rays that miss the head see (the studio's wall behind the actor).
  std::vector<double> background = {0.02, 0.02, 0.025};
  SensorOptions sensor;
  uint64_t seed = 1;                // noise seed (frame i uses a stream derived from it and i)

  void VisitFields(OptionVisitor& v);
  void Check() const;
};

// Ground truth of one rendered frame.
struct StudioFrameTruth {
  int index = 0;
  double time_s = 0.0;
  Eigen::VectorXd expression;     // rig expression weights β
  Rigid3d cam_from_head;          // includes the head pose
  double yaw_deg = 0, pitch_deg = 0, roll_deg = 0;
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
  MatX2d vertex_pixels;           // #V×2 projection of every coarse rig vertex
  std::vector<uint8_t> vertex_visible;  // #V: 1 when the vertex is seen (not occluded, in the image)
  MatX2d landmark_pixels;         // #landmarks×2, rig landmark order
  std::vector<uint8_t> landmark_visible;
  std::string light_description;
};

struct StudioFrame {
  SensorImage image;        // what the camera records
  RenderResult render;      // the noiseless linear render and its passes
  ActorFrame actor;         // coarse and high-resolution surfaces, displacement maps
  StudioFrameTruth truth;
};

class Studio {
 public:
  Studio(const FaceRig& rig, const Actor& actor, const StudioOptions& options);
  ~Studio();

  // Renders frame `index` of `sequence`. Deterministic for a given seed.
  StudioFrame RenderFrame(const Sequence& sequence, int index) const;
  // Renders one still: given expression weights (by rig index), pose and light rig.
  StudioFrame RenderStill(const Eigen::VectorXd& expression, const SequenceFrame& pose_and_light,
                          const LightRig* light_override, const Camera* camera_override, uint64_t seed) const;

  const Camera& camera() const { return camera_; }
  const ActorModel& model() const { return *model_; }
  const StudioOptions& options() const { return options_; }
  // Time spent per stage over all frames rendered so far.
  const TimingReport& timing() const { return *timing_; }
  // World-from-head transform for a pose.
  Rigid3d WorldFromHead(const SequenceFrame& f) const;
  // The light rig of a frame: the sequence's directional light if it keys one,
  // else options.light.
  LightRig FrameLights(const Sequence& sequence, const SequenceFrame& f) const;

 private:
  struct Scene;
  // Scene positions (and, when `normals` is given, unit normals) of a frame.
  MatX3d SceneVertices(const ActorFrame& frame, const SequenceFrame& f, const Rigid3d& world_from_head,
                       MatX3d* normals = nullptr) const;
  StudioFrame Render(const Eigen::VectorXd& expression, const SequenceFrame& f, const LightRig& lights,
                     const Camera& camera, bool motion_blur, double frame_dt, const Sequence* sequence,
                     uint64_t seed) const;

  StudioOptions options_;
  std::unique_ptr<ActorModel> model_;
  Camera camera_;
  Eigen::Vector3d head_centre_;
  LightRig default_lights_;
  std::unique_ptr<TimingReport> timing_ = std::make_unique<TimingReport>();  // options.light, resolved once (environment maps are read once)
  std::unique_ptr<Scene> scene_;
};

}  // namespace crease
