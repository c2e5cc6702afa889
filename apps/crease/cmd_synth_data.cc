// crease synth actor | render | sequence | scans | mesh | check — the studio's
// datasets (synth/dataset.h) and the realism check (eval/realism_check.h).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>
#include <fmt/format.h>
#include <fmt/ranges.h>

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
  return names + ", directional:AZ:EL[:AMBIENT], sphere:AZ:EL:DIAMETER[:AMBIENT] (degrees), or an environment map (.exr, .hdr)";
}

void ParseSize(const std::string& size, StudioOptions* studio) {
  ParseSizeFlag(size, "640x480", &studio->width, &studio->height);
}

Actor LoadOrGenerateActor(const FaceRig& rig, const std::string& actor_file, uint64_t seed) {
  return actor_file.empty() ? GenerateActor(rig, seed) : ReadActor(actor_file);
}

// synth actor
struct ActorArgs {
  std::string rig_path, out, maps, preview;
  uint64_t seed = 1;
  std::vector<std::string> sets;
};

void RunActor(const ActorArgs& a) {
  const FaceRig rig = ReadRig(a.rig_path);
  ActorOptions ao;
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &ao);
  const Actor actor = GenerateActor(rig, a.seed, ao);
  WriteActor(a.out, actor);
  std::printf("wrote %s (seed %llu, %zu wrinkle lines)\n", a.out.c_str(), static_cast<unsigned long long>(a.seed),
              actor.wrinkles.size());
  if (a.maps.empty() && a.preview.empty()) return;
  const Studio studio(rig, actor, StudioOptions{});
  if (!a.maps.empty()) {
    const ActorFrame f = studio.model().Frame(Eigen::VectorXd::Zero(rig.num_expressions()), false);
    WriteActorFrameMaps(a.maps, f);
    WriteActorSkinMaps(a.maps, studio.model().skin());
    std::printf("wrote the actor's maps to %s\n", a.maps.c_str());
  }
  if (!a.preview.empty()) {
    const StudioFrame f = studio.RenderStill(Eigen::VectorXd::Zero(rig.num_expressions()), SequenceFrame{}, nullptr,
                                             nullptr, a.seed);
    WriteImage(a.preview, f.image.decoded);
    std::printf("wrote %s\n", a.preview.c_str());
  }
}

void AddActorCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("actor", "Generate a seeded synthetic actor (identity, wrinkles, pores, skin)");
  auto a = std::make_shared<ActorArgs>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig), e.g. from `crease synth rig`")->required();
  cmd->add_option("--seed", a->seed, "Actor seed")->capture_default_str();
  cmd->add_option("--out,-o", a->out, "Actor definition (.json)")->required();
  cmd->add_option("--maps", a->maps, "Also write the actor's maps (displacement layers, skin) to this folder");
  cmd->add_option("--preview", a->preview, "Also render a preview (PNG) under the studio light");
  cmd->add_option("--set", a->sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions), e.g. age_min=0.8");
  cmd->callback([a] { RunActor(*a); });
}

// synth render
struct RenderArgs {
  std::string rig_path, actor_file, out, expression, light = "studio", size, exr;
  uint64_t seed = 1;
  double yaw = 0, pitch = 0, fov = 50;
  int samples = 2;
};

void RunRender(const RenderArgs& a) {
  const FaceRig rig = ReadRig(a.rig_path);
  const Actor actor = LoadOrGenerateActor(rig, a.actor_file, a.seed);
  StudioOptions so;
  ParseSize(a.size, &so);
  so.samples_per_axis = a.samples;
  so.light = a.light;
  so.fov_deg = a.fov;
  const Studio studio(rig, actor, so);
  SequenceFrame pose;
  pose.yaw_deg = a.yaw;
  pose.pitch_deg = a.pitch;
  const Eigen::VectorXd w = ParseExpressionSpec(a.expression, rig);
  const LightRig lights = LightRigFromSpec(a.light);
  const StudioFrame f = studio.RenderStill(w, pose, &lights, nullptr, a.seed);
  cv::Mat srgb;
  f.image.srgb8.convertTo(srgb, CV_8U);
  WriteImage(a.out, srgb, {.srgb = false});
  if (!a.exr.empty()) WriteImage(a.exr, f.render.image);
  std::printf("wrote %s (%dx%d, render %.0f ms, surface %.0f ms, %d hi-res vertices)\n", a.out.c_str(), so.width,
              so.height, 1e3 * f.render.stats.seconds, 1e3 * f.actor.seconds, f.actor.hires.num_vertices());
}

void AddRenderCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("render", "Render one still of an actor: expression, head pose, light rig");
  auto a = std::make_shared<RenderArgs>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig)")->required();
  cmd->add_option("--actor", a->actor_file, "Actor definition (.json); default: generated from --seed");
  cmd->add_option("--seed", a->seed, "Actor seed when no --actor is given")->capture_default_str();
  cmd->add_option("--expression,-e", a->expression, "Expression weights NAME=W,NAME=W (NAME without _L/_R drives both)");
  cmd->add_option("--light", a->light, "Light rig: " + LightChoices())->capture_default_str();
  cmd->add_option("--yaw", a->yaw, "Head yaw (degrees)");
  cmd->add_option("--pitch", a->pitch, "Head pitch (degrees)");
  cmd->add_option("--fov", a->fov, "Horizontal field of view (degrees); smaller zooms in")->capture_default_str();
  cmd->add_option("--size", a->size, "Image size WIDTHxHEIGHT (default 640x480)");
  cmd->add_option("--samples", a->samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
  cmd->add_option("--exr", a->exr, "Also write the noiseless linear render (EXR)");
  cmd->add_option("--out,-o", a->out, "Output image (PNG)")->required();
  cmd->callback([a] { RunRender(*a); });
}

// synth sequence
struct SequenceArgs {
  std::string rig_path, actor_file, preset, script, out, size, light;
  uint64_t actor_seed = 1, noise_seed = 1;
  int frames = -1, first = 0, samples = StudioOptions{}.samples_per_axis;
  bool exr = false, no_maps = false, overwrite = false, passes = false;
  double seconds = 0;
  std::vector<std::string> sets;
};

void RunSequence(const SequenceArgs& a) {
  if (a.preset.empty() == a.script.empty()) throw Error("give exactly one of --preset and --script");
  const FaceRig rig = ReadRig(a.rig_path);
  const Actor actor = LoadOrGenerateActor(rig, a.actor_file, a.actor_seed);
  const Sequence seq = a.preset.empty() ? ReadSequenceYaml(a.script) : MakePresetSequence(a.preset, a.seconds);
  SequenceDatasetOptions o;
  ParseSize(a.size, &o.studio);
  if (!a.light.empty()) o.studio.light = a.light;
  o.studio.samples_per_axis = a.samples;
  o.studio.seed = a.noise_seed;
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &o.studio);
  o.write_exr = a.exr;
  o.write_maps = !a.no_maps;
  o.write_passes = a.passes;
  o.first_frame = a.first;
  o.max_frames = a.frames;
  o.overwrite = a.overwrite;
  o.ignore_missing_expressions = !a.preset.empty();
  const DatasetReport r = WriteSequenceDataset(rig, actor, seq, o, a.out);
  for (const auto& w : r.warnings) std::printf("warning: %s\n", w.c_str());
  std::printf("%s", r.timing.c_str());
  std::printf("wrote %s: %d frames of '%s' in %.1f s (render %.1f s, surfaces %.1f s)\n", a.out.c_str(), r.frames,
              seq.name.c_str(), r.seconds, r.render_seconds, r.surface_seconds);
}

void AddSequenceCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("sequence", "Render a performance of an actor with per-frame ground truth");
  auto a = std::make_shared<SequenceArgs>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig)")->required();
  cmd->add_option("--actor", a->actor_file, "Actor definition (.json)");
  cmd->add_option("--actor-seed", a->actor_seed, "Actor seed when no --actor is given")->capture_default_str();
  auto* p = cmd->add_option("--preset", a->preset,
                            fmt::format("Built-in sequence (synth/sequence.h): {}", fmt::join(SequencePresetNames(), ", ")));
  auto* s = cmd->add_option("--script", a->script, "Sequence YAML (see synth/sequence.h)");
  p->excludes(s);
  cmd->add_option("--seconds", a->seconds, "Preset length in seconds (default: the preset's own)");
  cmd->add_option("--frames", a->frames, "Render at most this many frames");
  cmd->add_option("--first-frame", a->first, "First frame to render")->capture_default_str();
  cmd->add_option("--size", a->size, "Image size WIDTHxHEIGHT (default 640x480)");
  cmd->add_option("--light", a->light, "Light rig when the sequence keys no light (default studio): " + LightChoices());
  cmd->add_option("--samples", a->samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
  cmd->add_option("--seed", a->noise_seed, "Sensor noise seed")->capture_default_str();
  cmd->add_flag("--exr", a->exr, "Also write the noiseless linear frames (EXR)");
  cmd->add_flag("--no-maps", a->no_maps, "Do not write the per-frame displacement maps");
  cmd->add_flag("--passes", a->passes, "Also write depth, normal, UV (EXR) and mask (PNG) passes per frame");
  cmd->add_flag("--overwrite", a->overwrite, "Replace an existing output folder");
  cmd->add_option("--out,-o", a->out, "Output dataset folder")->required();
  cmd->add_option("--set", a->sets, "Studio option KEY=VALUE (repeatable; synth/studio.h StudioOptions and the sensor's "
                                    "SensorOptions in section sensor), e.g. distance_mm=600 sensor.jpeg_quality=70");
  cmd->callback([a] { RunSequence(*a); });
}

// synth scans
struct ScansArgs {
  std::string rig_path, out, size, lights = "studio";
  int actors = 4, cameras = 3, samples = 2;
  uint64_t seed = 100;
  std::vector<std::string> expressions;
  bool overwrite = false, any_age = false;
  std::vector<std::string> sets;
};

void RunScans(const ScansArgs& a) {
  const FaceRig rig = ReadRig(a.rig_path);
  ActorOptions ao;
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &ao);
  ScanSetOptions o;
  ParseSize(a.size, &o.studio);
  o.studio.samples_per_axis = a.samples;
  o.cameras = a.cameras;
  o.light_rigs = SplitComma(a.lights);
  if (!a.expressions.empty()) o.expressions = a.expressions;
  o.overwrite = a.overwrite;
  o.stratify_ages = !a.any_age;
  Require(a.actors >= 1, "--actors must be >= 1");
  std::vector<uint64_t> seeds;
  for (int i = 0; i < a.actors; ++i) seeds.push_back(a.seed + static_cast<uint64_t>(i));
  const DatasetReport r = WriteScanSet(rig, seeds, ao, o, a.out);
  std::printf("wrote %s: %d scans of %d actors in %.1f s\n", a.out.c_str(), r.frames, a.actors, r.seconds);
}

void AddScansCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("scans", "Training scans: per actor a neutral and extreme expressions, "
                                             "hi-res meshes, calibrated images, ground truth");
  auto a = std::make_shared<ScansArgs>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig)")->required();
  cmd->add_option("--actors", a->actors, "Number of actors (seeds --seed, --seed + 1, …)")->capture_default_str();
  cmd->add_option("--seed", a->seed, "First actor seed")->capture_default_str();
  cmd->add_option("--cameras", a->cameras, "Cameras on an arc in front of the face")->capture_default_str();
  cmd->add_option("--lights", a->lights, "Light rigs, comma-separated (each scan is imaged under each)")->capture_default_str();
  cmd->add_option("--expression,-e", a->expressions, "Scan expression NAME=W,NAME=W (repeatable; default: brow raise, "
                                                     "frown, smile with squint, sneer)");
  cmd->add_option("--size", a->size, "Image size WIDTHxHEIGHT (default 640x480)");
  cmd->add_option("--samples", a->samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
  cmd->add_flag("--overwrite", a->overwrite, "Replace an existing output folder");
  cmd->add_flag("--no-stratify-ages", a->any_age,
                "Each actor draws its age from the whole [age_min, age_max] (default: actor a of n from the a-th "
                "of n equal parts, so the set spans unlined to lined faces)");
  cmd->add_option("--out,-o", a->out, "Output folder")->required();
  cmd->add_option("--set", a->sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions), e.g. "
                                    "resolution=512");
  cmd->callback([a] { RunScans(*a); });
}

// synth render-scan
struct RenderScanArgs {
  std::string mesh, albedo, displacement, normal_map, units, light = "studio", size, out;
  std::string normal_space = ToString(ScannedHeadOptions().normal_map_space);
  ScannedHeadOptions so;
  double yaw = 0, fov = 30;
  int samples = 2;
  uint64_t seed = 1;
};

void RunRenderScan(RenderScanArgs& a) {
  if (!a.units.empty()) a.so.units_to_mm = UnitsToMm(a.units);
  a.so.normal_map_space = FromString<NormalMapSpace>(a.normal_space, "--normal-space");
  const ScannedHead head = LoadScannedHead(a.mesh, a.albedo, a.displacement, a.so, a.normal_map);
  for (const auto& w : head.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  StudioOptions studio;
  ParseSize(a.size, &studio);
  ScanRenderOptions ro;
  ro.yaw_deg = a.yaw;
  ro.fov_deg = a.fov;
  ro.width = studio.width;
  ro.height = studio.height;
  ro.samples_per_axis = a.samples;
  ro.light = a.light;
  ro.sensor = studio.sensor;
  ro.seed = a.seed;
  const ScanRender img = RenderScannedHead(head, ro, a.mesh);
  cv::Mat srgb;
  img.image.srgb8.convertTo(srgb, CV_8U);
  WriteImage(a.out, srgb, {.srgb = false});
  std::printf("wrote %s (%d scan vertices, %d rendered vertices, %.0f ms)\n", a.out.c_str(), head.source_vertices,
              img.rendered_vertices, 1e3 * img.render.stats.seconds);
}

void AddRenderScanCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("render-scan", "Relight a real scanned head (OBJ/PLY/glTF + albedo [+ displacement map] [+ normal map])");
  auto a = std::make_shared<RenderScanArgs>();
  ScannedHeadOptions& so = a->so;
  cmd->add_option("--mesh", a->mesh, "Head mesh with UVs (.obj, .ply, .gltf, .glb)")->required();
  cmd->add_option("--albedo", a->albedo, "Colour texture in the mesh's UV layout (PNG, EXR, …); optional for glTF "
                                         "files with a base colour texture");
  cmd->add_option("--displacement", a->displacement, "Displacement map in the same UV layout (EXR, PNG)");
  cmd->add_option("--normal-map", a->normal_map, "Normal map in the same UV layout (RGB; tangent space unless --normal-space object)");
  cmd->add_option("--normal-space", a->normal_space, "Space of the normal map")->check(CLI::IsMember(EnumNames<NormalMapSpace>()))->capture_default_str();
  cmd->add_flag("--normal-green-down", so.normal_map_green_down, "Tangent-space map in the DirectX convention (green = −v)");
  cmd->add_option("--displacement-scale", so.displacement_scale_mm, "mm per unit of the displacement map")->capture_default_str();
  cmd->add_option("--midlevel", so.displacement_midlevel, "Map value of zero displacement (0.5 for 8-bit maps)")->capture_default_str();
  cmd->add_option("--grid", so.grid_resolution, "Resampling grid for the displacement, texels per side")->capture_default_str();
  cmd->add_option("--units", a->units, "Units of the mesh coordinates (default: glTF's metres, mm for OBJ/PLY)")
      ->check(CLI::IsMember({"mm", "cm", "m"}));
  cmd->add_flag("--keep-v", [a](int64_t) { a->so.v_up = TextureVUp::kNo; }, "The file's texture v grows downwards (glTF's default)");
  cmd->add_flag("--flip-v", [a](int64_t) { a->so.v_up = TextureVUp::kYes; }, "The file's texture v grows upwards (OBJ/PLY's default; "
                                                                  "e.g. three.js glTF assets)");
  cmd->add_option("--light", a->light, "Light rig: " + LightChoices())
      ->capture_default_str();
  cmd->add_option("--yaw", a->yaw, "Turn the head (degrees)");
  cmd->add_option("--fov", a->fov, "Horizontal field of view (degrees)")->capture_default_str();
  cmd->add_option("--size", a->size, "Image size WIDTHxHEIGHT (default 640x480)");
  cmd->add_option("--samples", a->samples, "Anti-aliasing samples per pixel axis")->capture_default_str();
  cmd->add_option("--seed", a->seed, "Sensor noise seed")->capture_default_str();
  cmd->add_option("--out,-o", a->out, "Output image (PNG)")->required();
  cmd->callback([a] { RunRenderScan(*a); });
}

// synth mesh
struct MeshArgs {
  std::string dataset, out;
  int frame = 0;
};

void AddMeshCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("mesh", "Rebuild the high-resolution ground-truth surface of a dataset frame");
  auto a = std::make_shared<MeshArgs>();
  cmd->add_option("--dataset", a->dataset, "Sequence dataset folder")->required();
  cmd->add_option("--frame", a->frame, "Frame index")->required();
  cmd->add_option("--out,-o", a->out, "Output mesh (.ply, .obj)")->required();
  cmd->callback([a] {
    const TriMesh m = RebuildDatasetFrameMesh(a->dataset, a->frame);
    WriteMesh(a->out, m);
    std::printf("wrote %s (%d vertices, %d triangles, head frame, mm)\n", a->out.c_str(), m.num_vertices(),
                m.num_faces());
  });
}

// synth check
struct CheckArgs {
  std::string rig_path, json_out, samples_dir, lights;
  std::vector<double> yaws;
  int actors = 4;
  uint64_t seed = 1;
  std::vector<std::string> studio_sets, actor_sets;
};

void RunCheck(const CheckArgs& a) {
  const FaceRig rig = ReadRig(a.rig_path);
  RealismCheckOptions o;
  if (!a.studio_sets.empty()) SetOptionsFromJson(SetPairsToJson(a.studio_sets), "--set", &o.studio);
  if (!a.actor_sets.empty()) SetOptionsFromJson(SetPairsToJson(a.actor_sets), "--actor-set", &o.actor);
  o.actors = a.actors;
  o.seed = a.seed;
  if (!a.lights.empty()) o.lights = SplitComma(a.lights);
  if (!a.yaws.empty()) o.yaws_deg = a.yaws;
  o.samples_dir = a.samples_dir;
  const RealismCheckReport r = RunRealismCheck(rig, o);
  std::printf("%s", r.ToTable().c_str());
  std::printf("%d frames in %.1f s\n", r.frames, r.seconds);
  if (!a.json_out.empty()) {
    WriteFileAtomic(a.json_out, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
  }
}

void AddCheckCommand(CLI::App* synth) {
  auto* cmd = synth->add_subcommand("check", "Realism check: dlib's face detector and 68-point landmarks on renders");
  auto a = std::make_shared<CheckArgs>();
  cmd->add_option("--rig", a->rig_path, "Rig (.crig)")->required();
  cmd->add_option("--actors", a->actors, "Number of actors")->capture_default_str();
  cmd->add_option("--seed", a->seed, "First actor seed")->capture_default_str();
  cmd->add_option("--lights", a->lights, "Light rigs, comma-separated (default front,studio,raking-side)");
  cmd->add_option("--yaws", a->yaws, "Head yaws in degrees, comma-separated (default 0,25; positive turns the face towards raking-side's light)")
      ->delimiter(',');
  cmd->add_option("--samples", a->samples_dir, "Write every frame with true (green) and detected (red) landmarks here");
  cmd->add_option("--json", a->json_out, "Write the report as JSON");
  cmd->add_option("--set", a->studio_sets, "Studio option KEY=VALUE (repeatable; synth/studio.h StudioOptions), e.g. subsurface_mm=1");
  cmd->add_option("--actor-set", a->actor_sets, "Actor option KEY=VALUE (repeatable; synth/actor.h ActorOptions)");
  cmd->callback([a] { RunCheck(*a); });
}

}  // namespace

void AddSynthDatasetCommands(CLI::App& app) {
  CLI::App* synth = app.get_subcommand("synth");
  AddActorCommand(synth);
  AddRenderCommand(synth);
  AddSequenceCommand(synth);
  AddScansCommand(synth);
  AddRenderScanCommand(synth);
  AddMeshCommand(synth);
  AddCheckCommand(synth);
}

}  // namespace crease::app
