// crease synth actor | render | sequence | scans | mesh | check — the studio's
// datasets (synth/dataset.h) and the realism check (eval/realism_check.h).
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <fmt/format.h>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "eval/realism_check.h"
#include "core/rig_import.h"
#include "synth/dataset.h"
#include "synth/scanned_head.h"

namespace crease::app {
namespace fs = std::filesystem;

namespace {

// The --light choices for --help: the presets of synth/lights.h, or a map file.
std::string LightChoices() {
  std::string names;
  for (const auto& n : LightRigNames()) names += (names.empty() ? "" : ", ") + n;
  return names + ", directional:AZ:EL[:AMBIENT] (degrees), or an environment map (.exr, .hdr)";
}

void ParseSize(const std::string& size, StudioOptions* studio) {
  if (size.empty()) return;
  const auto x = size.find('x');
  try {
    if (x == std::string::npos) throw std::invalid_argument("no x");
    studio->width = std::stoi(size.substr(0, x));
    studio->height = std::stoi(size.substr(x + 1));
  } catch (const std::exception&) {
    throw Error(fmt::format("--size '{}': expected WIDTHxHEIGHT, e.g. 640x480", size));
  }
}

Actor LoadOrGenerateActor(const FaceRig& rig, const std::string& actor_file, uint64_t seed) {
  return actor_file.empty() ? GenerateActor(rig, seed) : ReadActor(actor_file);
}

}  // namespace

void AddSynthDatasetCommands(CLI::App& app) {
  CLI::App* synth = app.get_subcommand("synth");

  // synth actor
  {
    auto* cmd = synth->add_subcommand("actor", "Generate a seeded synthetic actor (identity, wrinkles, pores, skin)");
    static std::string rig_path, out, maps, preview;
    static uint64_t seed = 1;
    cmd->add_option("--rig", rig_path, "Rig (.crig), e.g. from `crease synth rig`")->required();
    cmd->add_option("--seed", seed, "Actor seed")->capture_default_str();
    cmd->add_option("--out,-o", out, "Actor definition (.json)")->required();
    cmd->add_option("--maps", maps, "Also write the actor's maps (displacement layers, skin) to this folder");
    cmd->add_option("--preview", preview, "Also render a preview (PNG) under the studio light");
    static std::vector<std::string> sets;
    cmd->add_option("--set", sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions), e.g. age_min=0.8");
    cmd->callback([] {
      const FaceRig rig = ReadRig(rig_path);
      ActorOptions ao;
      if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &ao);
      const Actor actor = GenerateActor(rig, seed, ao);
      WriteActor(out, actor);
      std::printf("wrote %s (seed %llu, %zu wrinkle lines)\n", out.c_str(), static_cast<unsigned long long>(seed),
                  actor.wrinkles.size());
      if (!maps.empty() || !preview.empty()) {
        const Studio studio(rig, actor, StudioOptions{});
        if (!maps.empty()) {
          const ActorFrame f = studio.model().Frame(Eigen::VectorXd::Zero(rig.num_expressions()), false);
          WriteActorFrameMaps(maps, f);
          WriteActorSkinMaps(maps, studio.model().skin());
          std::printf("wrote the actor's maps to %s\n", maps.c_str());
        }
        if (!preview.empty()) {
          const StudioFrame f = studio.RenderStill(Eigen::VectorXd::Zero(rig.num_expressions()), SequenceFrame{},
                                                   nullptr, nullptr, seed);
          WriteImage(preview, f.image.decoded);
          std::printf("wrote %s\n", preview.c_str());
        }
      }
    });
  }

  // synth render
  {
    auto* cmd = synth->add_subcommand("render", "Render one still of an actor: expression, head pose, light rig");
    static std::string rig_path, actor_file, out, expression, light = "studio", size, exr;
    static uint64_t seed = 1;
    static double yaw = 0, pitch = 0, fov = 50;
    static int samples = 2;
    cmd->add_option("--rig", rig_path, "Rig (.crig)")->required();
    cmd->add_option("--actor", actor_file, "Actor definition (.json); default: generated from --seed");
    cmd->add_option("--seed", seed, "Actor seed when no --actor is given")->capture_default_str();
    cmd->add_option("--expression,-e", expression, "Expression weights NAME=W,NAME=W (NAME without _L/_R drives both)");
    cmd->add_option("--light", light, "Light rig: " + LightChoices())->capture_default_str();
    cmd->add_option("--yaw", yaw, "Head yaw (degrees)");
    cmd->add_option("--pitch", pitch, "Head pitch (degrees)");
    cmd->add_option("--fov", fov, "Horizontal field of view (degrees); smaller zooms in")->capture_default_str();
    cmd->add_option("--size", size, "Image size WIDTHxHEIGHT (default 640x480)");
    cmd->add_option("--samples", samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
    cmd->add_option("--exr", exr, "Also write the noiseless linear render (EXR)");
    cmd->add_option("--out,-o", out, "Output image (PNG)")->required();
    cmd->callback([] {
      const FaceRig rig = ReadRig(rig_path);
      const Actor actor = LoadOrGenerateActor(rig, actor_file, seed);
      StudioOptions so;
      ParseSize(size, &so);
      so.samples_per_axis = samples;
      so.light = light;
      so.fov_deg = fov;
      const Studio studio(rig, actor, so);
      SequenceFrame pose;
      pose.yaw_deg = yaw;
      pose.pitch_deg = pitch;
      const Eigen::VectorXd w = ParseExpressionSpec(expression, rig);
      const LightRig lights = LightRigFromSpec(light);
      const StudioFrame f = studio.RenderStill(w, pose, &lights, nullptr, seed);
      cv::Mat srgb;
      f.image.srgb8.convertTo(srgb, CV_8U);
      WriteImage(out, srgb, {.srgb = false});
      if (!exr.empty()) WriteImage(exr, f.render.image);
      std::printf("wrote %s (%dx%d, render %.0f ms, surface %.0f ms, %d hi-res vertices)\n", out.c_str(), so.width,
                  so.height, 1e3 * f.render.stats.seconds, 1e3 * f.actor.seconds, f.actor.hires.num_vertices());
    });
  }

  // synth sequence
  {
    auto* cmd = synth->add_subcommand("sequence", "Render a performance of an actor with per-frame ground truth");
    static std::string rig_path, actor_file, preset, script, out, size, light;
    static uint64_t actor_seed = 1, noise_seed = 1;
    static int frames = -1, first = 0, samples = 1;
    static bool exr = false, no_maps = false, overwrite = false, passes = false;
    static double seconds = 0;
    cmd->add_option("--rig", rig_path, "Rig (.crig)")->required();
    cmd->add_option("--actor", actor_file, "Actor definition (.json)");
    cmd->add_option("--actor-seed", actor_seed, "Actor seed when no --actor is given")->capture_default_str();
    auto* p = cmd->add_option("--preset", preset, "Built-in sequence: wrinkle-workout, talking, moving-light, fast-motion, occlusion, workout-talking");
    auto* s = cmd->add_option("--script", script, "Sequence YAML (see synth/sequence.h)");
    p->excludes(s);
    cmd->add_option("--seconds", seconds, "Preset length in seconds (default: the preset's own)");
    cmd->add_option("--frames", frames, "Render at most this many frames");
    cmd->add_option("--first-frame", first, "First frame to render")->capture_default_str();
    cmd->add_option("--size", size, "Image size WIDTHxHEIGHT (default 640x480)");
    cmd->add_option("--light", light, "Light rig when the sequence keys no light (default studio): " + LightChoices());
    cmd->add_option("--samples", samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
    cmd->add_option("--seed", noise_seed, "Sensor noise seed")->capture_default_str();
    cmd->add_flag("--exr", exr, "Also write the noiseless linear frames (EXR)");
    cmd->add_flag("--no-maps", no_maps, "Do not write the per-frame displacement maps");
    cmd->add_flag("--passes", passes, "Also write depth, normal, UV (EXR) and mask (PNG) passes per frame");
    cmd->add_flag("--overwrite", overwrite, "Replace an existing output folder");
    cmd->add_option("--out,-o", out, "Output dataset folder")->required();
    static std::vector<std::string> sets;
    cmd->add_option("--set", sets, "Studio option KEY=VALUE (repeatable; synth/studio.h StudioOptions and the sensor's "
                                   "SensorOptions), e.g. distance_mm=600 jpeg_quality=70");
    cmd->callback([] {
      if (preset.empty() == script.empty()) throw Error("give exactly one of --preset and --script");
      const FaceRig rig = ReadRig(rig_path);
      const Actor actor = LoadOrGenerateActor(rig, actor_file, actor_seed);
      const Sequence seq = preset.empty() ? ReadSequenceYaml(script) : MakePresetSequence(preset, seconds);
      SequenceDatasetOptions o;
      ParseSize(size, &o.studio);
      if (!light.empty()) o.studio.light = light;
      o.studio.samples_per_axis = samples;
      o.studio.seed = noise_seed;
      if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &o.studio);
      o.write_exr = exr;
      o.write_maps = !no_maps;
      o.write_passes = passes;
      o.first_frame = first;
      o.max_frames = frames;
      o.overwrite = overwrite;
      o.ignore_missing_expressions = !preset.empty();
      const DatasetReport r = WriteSequenceDataset(rig, actor, seq, o, out);
      for (const auto& w : r.warnings) std::printf("warning: %s\n", w.c_str());
      std::printf("%s", r.timing.c_str());
      std::printf("wrote %s: %d frames of '%s' in %.1f s (render %.1f s, surfaces %.1f s)\n", out.c_str(), r.frames,
                  seq.name.c_str(), r.seconds, r.render_seconds, r.surface_seconds);
    });
  }

  // synth scans
  {
    auto* cmd = synth->add_subcommand("scans", "Training scans: per actor a neutral and extreme expressions, "
                                               "hi-res meshes, calibrated images, ground truth");
    static std::string rig_path, out, size, lights = "studio";
    static int actors = 4, cameras = 3, samples = 2;
    static uint64_t seed = 100;
    static std::vector<std::string> expressions;
    static bool overwrite = false;
    cmd->add_option("--rig", rig_path, "Rig (.crig)")->required();
    cmd->add_option("--actors", actors, "Number of actors (seeds --seed, --seed + 1, …)")->capture_default_str();
    cmd->add_option("--seed", seed, "First actor seed")->capture_default_str();
    cmd->add_option("--cameras", cameras, "Cameras on an arc in front of the face")->capture_default_str();
    cmd->add_option("--lights", lights, "Light rigs, comma-separated (each scan is imaged under each)")->capture_default_str();
    cmd->add_option("--expression,-e", expressions, "Scan expression NAME=W,NAME=W (repeatable; default: brow raise, "
                                                    "frown, smile with squint, sneer)");
    cmd->add_option("--size", size, "Image size WIDTHxHEIGHT (default 640x480)");
    cmd->add_option("--samples", samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
    cmd->add_flag("--overwrite", overwrite, "Replace an existing output folder");
    static bool any_age = false;
    cmd->add_flag("--no-stratify-ages", any_age,
                  "Each actor draws its age from the whole [age_min, age_max] (default: actor a of n from the a-th "
                  "of n equal parts, so the set spans unlined to lined faces)");
    cmd->add_option("--out,-o", out, "Output folder")->required();
    static std::vector<std::string> sets;
    cmd->add_option("--set", sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions), e.g. "
                                   "resolution=512");
    cmd->callback([] {
      const FaceRig rig = ReadRig(rig_path);
      ActorOptions ao;
      if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &ao);
      ScanSetOptions o;
      ParseSize(size, &o.studio);
      o.studio.samples_per_axis = samples;
      o.cameras = cameras;
      o.light_rigs = SplitComma(lights);
      if (!expressions.empty()) o.expressions = expressions;
      o.overwrite = overwrite;
      o.stratify_ages = !any_age;
      Require(actors >= 1, "--actors must be >= 1");
      std::vector<uint64_t> seeds;
      for (int a = 0; a < actors; ++a) seeds.push_back(seed + static_cast<uint64_t>(a));
      const DatasetReport r = WriteScanSet(rig, seeds, ao, o, out);
      std::printf("wrote %s: %d scans of %d actors in %.1f s\n", out.c_str(), r.frames, actors, r.seconds);
    });
  }

  // synth render-scan
  {
    auto* cmd = synth->add_subcommand("render-scan", "Relight a real scanned head (OBJ/PLY/glTF + albedo [+ displacement map] [+ normal map])");
    static std::string mesh, albedo, displacement, normal_map, units, light = "studio", size, out;
    static ScannedHeadOptions so;
    static double yaw = 0, fov = 30;
    static int samples = 2;
    static uint64_t seed = 1;
    cmd->add_option("--mesh", mesh, "Head mesh with UVs (.obj, .ply, .gltf, .glb)")->required();
    cmd->add_option("--albedo", albedo, "Colour texture in the mesh's UV layout (PNG, EXR, …); optional for glTF "
                                        "files with a base colour texture");
    cmd->add_option("--displacement", displacement, "Displacement map in the same UV layout (EXR, PNG)");
    cmd->add_option("--normal-map", normal_map, "Normal map in the same UV layout (RGB; tangent space unless --normal-space object)");
    cmd->add_option("--normal-space", so.normal_map_space, "Space of the normal map")->check(CLI::IsMember({"tangent", "object"}))->capture_default_str();
    cmd->add_flag("--normal-green-down", so.normal_map_green_down, "Tangent-space map in the DirectX convention (green = −v)");
    cmd->add_option("--displacement-scale", so.displacement_scale_mm, "mm per unit of the displacement map")->capture_default_str();
    cmd->add_option("--midlevel", so.displacement_midlevel, "Map value of zero displacement (0.5 for 8-bit maps)")->capture_default_str();
    cmd->add_option("--grid", so.grid_resolution, "Resampling grid for the displacement, texels per side")->capture_default_str();
    cmd->add_option("--units", units, "Units of the mesh coordinates (default: glTF's metres, mm for OBJ/PLY)")
        ->check(CLI::IsMember({"mm", "cm", "m"}));
    cmd->add_flag("--keep-v", [](int64_t) { so.v_up = "no"; }, "The file's texture v grows downwards (glTF's default)");
    cmd->add_flag("--flip-v", [](int64_t) { so.v_up = "yes"; }, "The file's texture v grows upwards (OBJ/PLY's default; "
                                                               "e.g. three.js glTF assets)");
    cmd->add_option("--light", light, "Light rig: " + LightChoices())
        ->capture_default_str();
    cmd->add_option("--yaw", yaw, "Turn the head (degrees)");
    cmd->add_option("--fov", fov, "Horizontal field of view (degrees)")->capture_default_str();
    cmd->add_option("--size", size, "Image size WIDTHxHEIGHT (default 640x480)");
    cmd->add_option("--samples", samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
    cmd->add_option("--seed", seed, "Sensor noise seed")->capture_default_str();
    cmd->add_option("--out,-o", out, "Output image (PNG)")->required();
    cmd->callback([] {
      if (!units.empty()) so.units_to_mm = UnitsToMm(units);
      const ScannedHead head = LoadScannedHead(mesh, albedo, displacement, so, normal_map);
      for (const auto& w : head.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
      StudioOptions studio;
      ParseSize(size, &studio);
      TriMesh m = head.surface;
      const auto [lo, hi] = BoundingBox(m);
      const Eigen::Vector3d centre = 0.5 * (lo + hi);
      const double r = yaw * std::numbers::pi / 180.0;
      const Eigen::Matrix3d R = Eigen::AngleAxisd(r, Eigen::Vector3d::UnitY()).toRotationMatrix();
      for (int v = 0; v < m.num_vertices(); ++v) m.V.row(v) = (R * (m.V.row(v).transpose() - centre) + centre).transpose();
      if (m.N.rows() == m.num_vertices()) m.N = m.N * R.transpose();  // the normal map's shading normals turn too
      const double radius = 0.5 * (hi - lo).norm();
      const CameraIntrinsics K = CameraIntrinsics::FromFov(fov, studio.width, studio.height);
      const double distance = radius / std::sin(0.5 * std::min(fov, fov * studio.height / studio.width) * std::numbers::pi / 180.0);
      const Camera camera = LookAtCamera(K, centre + Eigen::Vector3d(0, 0, distance), centre, Eigen::Vector3d::UnitY());
      Renderer renderer(m, head.materials, RendererOptions{}, mesh);
      RenderOptions ro;
      ro.samples_per_axis = samples;
      Rng rng(seed);
      const RenderResult img = renderer.Render(camera, LightRigFromSpec(light), ro, rng);
      const SensorImage sensor = ApplySensor(img.image, studio.sensor, rng);
      cv::Mat srgb;
      sensor.srgb8.convertTo(srgb, CV_8U);
      WriteImage(out, srgb, {.srgb = false});
      std::printf("wrote %s (%d scan vertices, %d rendered vertices, %.0f ms)\n", out.c_str(), head.source_vertices,
                  m.num_vertices(), 1e3 * img.stats.seconds);
    });
  }

  // synth mesh
  {
    auto* cmd = synth->add_subcommand("mesh", "Rebuild the high-resolution ground-truth surface of a dataset frame");
    static std::string dataset, out;
    static int frame = 0;
    cmd->add_option("--dataset", dataset, "Sequence dataset folder")->required();
    cmd->add_option("--frame", frame, "Frame index")->required();
    cmd->add_option("--out,-o", out, "Output mesh (.ply, .obj)")->required();
    cmd->callback([] {
      const TriMesh m = RebuildDatasetFrameMesh(dataset, frame);
      WriteMesh(out, m);
      std::printf("wrote %s (%d vertices, %d triangles, head frame, mm)\n", out.c_str(), m.num_vertices(), m.num_faces());
    });
  }

  // synth check
  {
    auto* cmd = synth->add_subcommand("check", "Realism check: dlib's face detector and 68-point landmarks on renders");
    static std::string rig_path, json_out, samples_dir, lights;
    static std::vector<double> yaws;
    static int actors = 4;
    static uint64_t seed = 1;
    cmd->add_option("--rig", rig_path, "Rig (.crig)")->required();
    cmd->add_option("--actors", actors, "Number of actors")->capture_default_str();
    cmd->add_option("--seed", seed, "First actor seed")->capture_default_str();
    cmd->add_option("--lights", lights, "Light rigs, comma-separated (default front,studio,raking-side)");
    cmd->add_option("--yaws", yaws, "Head yaws in degrees, comma-separated (default 0,25; positive turns the face towards raking-side's light)")
        ->delimiter(',');
    cmd->add_option("--samples", samples_dir, "Write every frame with true (green) and detected (red) landmarks here");
    cmd->add_option("--json", json_out, "Write the report as JSON");
    static std::vector<std::string> studio_sets, actor_sets;
    cmd->add_option("--set", studio_sets, "Studio option KEY=VALUE (repeatable; synth/studio.h StudioOptions), e.g. subsurface_mm=1");
    cmd->add_option("--actor-set", actor_sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions)");
    cmd->callback([] {
      const FaceRig rig = ReadRig(rig_path);
      RealismCheckOptions o;
      if (!studio_sets.empty()) SetOptionsFromJson(SetPairsToJson(studio_sets), "--set", &o.studio);
      if (!actor_sets.empty()) SetOptionsFromJson(SetPairsToJson(actor_sets), "--actor-set", &o.actor);
      o.actors = actors;
      o.seed = seed;
      if (!lights.empty()) o.lights = SplitComma(lights);
      if (!yaws.empty()) o.yaws_deg = yaws;
      o.samples_dir = samples_dir;
      const RealismCheckReport r = RunRealismCheck(rig, o);
      std::printf("%s", r.ToTable().c_str());
      std::printf("%d frames in %.1f s\n", r.frames, r.seconds);
      if (!json_out.empty()) {
        WriteFileAtomic(json_out, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
      }
    });
  }
}

}  // namespace crease::app
