// Pictures to look at, not checks (issue 18: preview writers that were tests):
//
//   build/bench/previews actor DIR RIG [SEED]   a lined actor (age ≥ 0.6, no static lines)
//       in a few poses: its expression wrinkle map, raking renders of the hi-res surface
//       (whole and a forehead close-up), the coarse surface, and its albedo, static
//       shape, mesoscopic, specular and roughness maps; prints the deepest point of
//       each wrinkle family per pose. RIG: a .crig file or "procedural".
//   build/bench/previews renderer DIR           a smooth and a bumpy sphere under every
//       light rig (synth/lights.h), through the sensor model.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/image_io.h"
#include "core/mesh_primitives.h"
#include "core/preview_render.h"
#include "synth/actor.h"
#include "synth/lights.h"
#include "synth/procedural_rig.h"
#include "synth/renderer.h"
#include "synth/sensor.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using Pose = std::pair<std::string, std::vector<std::pair<std::string, double>>>;

// Expression weights with the named ones set (names the rig lacks are skipped).
Eigen::VectorXd Weights(const FaceRig& rig, const std::vector<std::pair<std::string, double>>& named) {
  Eigen::VectorXd beta = Eigen::VectorXd::Zero(rig.num_expressions());
  for (const auto& [name, value] : named) {
    if (const int e = rig.ExpressionIndex(name); e >= 0) beta[e] = value;
  }
  return beta;
}

// Neutral, brow raise, frown, smile, sneer; both the ARKit names with _L/_R and without.
std::vector<Pose> Poses() {
  return {{"neutral", {}},
          {"brow_raise", {{"browInnerUp", 1.0}, {"browInnerUp_L", 1.0}, {"browInnerUp_R", 1.0},
                          {"browOuterUp_L", 1.0}, {"browOuterUp_R", 1.0}}},
          {"frown", {{"browDown", 1.0}, {"browDown_L", 1.0}, {"browDown_R", 1.0}}},
          {"smile", {{"mouthSmile_L", 1.0}, {"mouthSmile_R", 1.0}, {"eyeSquint_L", 0.6}, {"eyeSquint_R", 0.6},
                     {"cheekSquint_L", 0.6}, {"cheekSquint_R", 0.6}}},
          {"sneer", {{"noseSneer_L", 1.0}, {"noseSneer_R", 1.0}}}};
}

void ActorPreviews(const fs::path& dir, const FaceRig& rig, uint64_t seed) {
  fs::create_directories(dir);
  ActorOptions opt;
  opt.age_min = 0.6;
  opt.static_lines = false;  // the forehead is smooth at neutral
  const ActorModel model(rig, GenerateActor(rig, seed, opt));
  PreviewRenderOptions ro;
  ro.key_light_dir = {0.0, 1.0, 0.3};
  ro.azimuth_deg = 0;
  ro.elevation_deg = 0;
  ro.width = ro.height = 1600;
  for (const auto& [name, weights] : Poses()) {
    const ActorFrame f = model.Frame(Weights(rig, weights));
    std::printf("%s: %d hi-res vertices (grid %d², maps %d²), %d faces, %.3f s\n", name.c_str(),
                f.hires.num_vertices(), model.layout().resolution, model.layout().map_resolution,
                f.hires.num_faces(), f.seconds);
    std::map<WrinkleFamily, double> deepest;  // mm, per wrinkle family
    for (const auto& smp : model.wrinkles().samples()) {
      double& x = deepest[model.wrinkles().lines()[smp.line].family];
      x = std::min(x, static_cast<double>(f.expression_displacement.ptr<float>()[smp.texel]));
    }
    for (const auto& [family, depth] : deepest) std::printf("  %s %.3f", ToString(family).c_str(), depth);
    std::printf("\n");
    WriteImage(dir / ("wrinkles_" + name + ".png"), f.expression_displacement * 1.5 + 0.5, {.srgb = false});
    const PreviewRender r = RenderPreview(f.hires, ro);
    WriteImage(dir / ("render_" + name + ".png"), r.image);
    WriteImage(dir / ("closeup_" + name + ".png"), r.image(cv::Rect(400, 250, 800, 600)).clone());
    PreviewRenderOptions co = ro;
    co.width = co.height = 800;
    WriteImage(dir / ("coarse_" + name + ".png"), RenderPreview(f.coarse, co).image);
  }
  WriteImage(dir / "albedo.png", model.skin().albedo);
  WriteImage(dir / "static_shape.png", model.static_displacement() + 0.5, {.srgb = false});
  WriteImage(dir / "mesoscopic.png", model.mesoscopic_displacement() * 8.0 + 0.5, {.srgb = false});
  WriteImage(dir / "specular.png", model.skin().specular * 0.5, {.srgb = false});
  WriteImage(dir / "roughness.png", model.skin().roughness, {.srgb = false});
}

void RendererPreviews(const fs::path& dir) {
  fs::create_directories(dir);
  const TriMesh smooth = MakeUVSphere(80.0, 256, 512);
  TriMesh bumpy = smooth;
  const MatX3d n = smooth.V / 80.0;
  for (int i = 0; i < bumpy.num_vertices(); ++i) {
    const double bump = 1.5 * std::sin(23.0 * n(i, 0)) * std::cos(19.0 * n(i, 1)) * std::sin(17.0 * n(i, 2)) +
                        0.3 * std::sin(120.0 * n(i, 1));
    bumpy.V.row(i) = (80.0 + bump) * n.row(i);
  }
  cv::Mat albedo(256, 256, CV_32FC3);
  for (int y = 0; y < 256; ++y) {
    for (int x = 0; x < 256; ++x) {
      const float t = 0.5f + 0.5f * std::sin(x * 0.1f) * std::sin(y * 0.1f);
      albedo.at<cv::Vec3f>(y, x) = cv::Vec3f(0.55f + 0.1f * t, 0.38f + 0.05f * t, 0.30f);
    }
  }
  SceneMaterials m;
  m.albedo = albedo;
  const Camera cam = LookAtCamera(CameraIntrinsics::FromFov(30.0, 320, 240), Eigen::Vector3d(0, 0, 450.0),
                                  Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  for (const auto& [name, mesh] : {std::pair<std::string, const TriMesh*>{"sphere", &smooth}, {"bumpy", &bumpy}}) {
    Renderer renderer(*mesh, m);
    for (const auto& rig_name : LightRigNames()) {
      RenderOptions options;
      options.samples_per_axis = 2;
      options.subsurface_mm = 1.0;
      options.background = {0.05, 0.05, 0.06};
      Rng rng(1), sensor_rng(2);
      const RenderResult r = renderer.Render(cam, MakeLightRig(rig_name), options, rng);
      const SensorImage s = ApplySensor(r.image, SensorOptions{}, sensor_rng);
      WriteImage(dir / (name + "_" + rig_name + ".png"), s.srgb8, ImageWriteOptions{.srgb = false});
    }
  }
  std::printf("wrote %s\n", dir.c_str());
}

int Main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "";
  if (what == "actor" && (argc == 4 || argc == 5)) {
    const std::string rig_arg = argv[3];
    const FaceRig rig = rig_arg == "procedural" ? BuildProceduralRig() : ReadRig(rig_arg);
    ActorPreviews(argv[2], rig, argc == 5 ? std::strtoull(argv[4], nullptr, 10) : 5);
    return 0;
  }
  if (what == "renderer" && argc == 3) {
    RendererPreviews(argv[2]);
    return 0;
  }
  std::fprintf(stderr, "usage: %s actor DIR RIG.crig|procedural [SEED]\n       %s renderer DIR\n", argv[0], argv[0]);
  return 2;
}

}  // namespace
}  // namespace crease

int main(int argc, char** argv) {
  try {
    return crease::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "previews: %s\n", e.what());
    return 1;
  }
}
