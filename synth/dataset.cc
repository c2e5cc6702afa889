#include "synth/dataset.h"

#include <unistd.h>

#include <cctype>
#include <chrono>
#include <cmath>
#include <numbers>
#include <fstream>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/rig_import.h"
#include "core/file_util.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/mesh_io.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/timer.h"

namespace crease {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json RigidToJson(const Rigid3d& r) {
  const auto& q = r.rotation;
  return {{"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
          {"translation_mm", {r.translation.x(), r.translation.y(), r.translation.z()}}};
}

json TruthToJson(const StudioFrameTruth& t, const FaceRig& rig, const Actor& actor) {
  json j;
  j["frame"] = t.index;
  j["time_s"] = t.time_s;
  json expr = json::object();
  for (int i = 0; i < t.expression.size(); ++i) expr[rig.expression_names[i]] = t.expression[i];
  j["expression"] = expr;
  j["identity"] = std::vector<double>(actor.identity.data(), actor.identity.data() + actor.identity.size());
  j["pose"] = {{"yaw_deg", t.yaw_deg}, {"pitch_deg", t.pitch_deg}, {"roll_deg", t.roll_deg},
               {"translation_mm", {t.translation_mm.x(), t.translation_mm.y(), t.translation_mm.z()}}};
  j["cam_from_head"] = RigidToJson(t.cam_from_head);
  j["light"] = t.light_description;
  json lms = json::array();
  for (size_t i = 0; i < rig.landmarks.size(); ++i) {
    lms.push_back({{"name", rig.landmarks[i].name},
                   {"vertex", rig.landmarks[i].vertex},
                   {"x", t.landmark_pixels(static_cast<int>(i), 0)},
                   {"y", t.landmark_pixels(static_cast<int>(i), 1)},
                   {"visible", t.landmark_visible[i] != 0}});
  }
  j["landmarks"] = lms;
  return j;
}

void WriteVertexTruth(const fs::path& path, const StudioFrameTruth& t) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    std::vector<float> buf(static_cast<size_t>(t.vertex_pixels.rows()) * 3);
    for (Eigen::Index v = 0; v < t.vertex_pixels.rows(); ++v) {
      buf[3 * v] = static_cast<float>(t.vertex_pixels(v, 0));
      buf[3 * v + 1] = static_cast<float>(t.vertex_pixels(v, 1));
      buf[3 * v + 2] = t.vertex_visible[v] ? 1.0f : 0.0f;
    }
    out.write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(buf.size() * sizeof(float)));
  });
}

std::string FrameName(int i) { return fmt::format("{:06d}", i); }

}  // namespace

void WriteFrameTruth(const fs::path& truth_dir, const std::string& name, const StudioFrameTruth& truth,
                     const FaceRig& rig, const Actor& actor) {
  WriteJsonFile(truth_dir / (name + ".json"), TruthToJson(truth, rig, actor));
  WriteVertexTruth(truth_dir / (name + "_vertices.bin"), truth);
}

Eigen::VectorXd ParseExpressionSpec(const std::string& spec, const FaceRig& rig) {
  SequenceFrame f;
  f.expression = ParseExpressionWeights(spec);
  const std::vector<double> w = ExpressionWeightsForRig(f, rig);
  return Eigen::Map<const Eigen::VectorXd>(w.data(), static_cast<Eigen::Index>(w.size()));
}

namespace {

// Writes `rig` restricted to `parts` to `path` when that drops vertices; returns
// whether it did.
bool WriteTrackingRig(const FaceRig& rig, const std::vector<std::string>& parts, const fs::path& path) {
  if (parts.empty() || rig.part_names.empty() || rig.PartIndex("face") < 0) return false;
  const FaceRig tracking = ExtractParts(rig, parts);
  if (tracking.num_vertices() == rig.num_vertices()) return false;
  WriteRig(path, tracking, {.compress = true});
  return true;
}

}  // namespace

DatasetReport WriteSequenceDataset(const FaceRig& rig, const Actor& actor, const Sequence& input_sequence,
                                   const SequenceDatasetOptions& options, const fs::path& out) {
  input_sequence.Validate(input_sequence.name);
  options.studio.Check();
  DatasetReport report;
  // Expressions the rig lacks fail before anything is rendered, or, when asked,
  // have their channels dropped with a warning.
  Sequence sequence = input_sequence;
  for (const auto& name : input_sequence.ExpressionNames()) {
    SequenceFrame probe;
    probe.expression[name] = 0.0;
    try {
      ExpressionWeightsForRig(probe, rig);
    } catch (const Error&) {
      if (!options.ignore_missing_expressions) throw;
      report.warnings.push_back(fmt::format("the rig has no expression '{}' (nor '{}_L'/'{}_R'): its channel is dropped",
                                            name, name, name));
      for (auto& k : sequence.keys) k.values.erase("expression:" + name);
    }
  }
  const int first = options.first_frame;
  const int count = options.max_frames < 0 ? sequence.num_frames() - first
                                           : std::min(options.max_frames, sequence.num_frames() - first);
  Require(first >= 0 && count > 0, fmt::format("frame range starting at {} is empty (the sequence has {} frames)",
                                               first, sequence.num_frames()));
  report.path = out.string();
  const auto start = std::chrono::steady_clock::now();
  WriteFolderAtomic(out, options.overwrite, [&](const fs::path& dir) {
    const Studio studio(rig, actor, options.studio);
    WriteRig(dir / "rig.crig", rig, {.compress = true});
    const bool tracking_rig = WriteTrackingRig(rig, options.tracking_parts, dir / "tracking_rig.crig");
    WriteActor(dir / "actor.json", actor);
    WriteFileAtomic(dir / "sequence.yaml", [&](std::ostream& o) { o << SequenceToYaml(sequence); });
    WriteCamera(dir / "camera.json", Camera(studio.camera().intrinsics, studio.camera().cam_from_head));
    fs::create_directories(dir / "frames");
    fs::create_directories(dir / "truth");
    fs::create_directories(dir / "maps");
    WriteImage(dir / "maps" / "static_displacement.exr", studio.model().static_displacement());
    WriteImage(dir / "maps" / "mesoscopic_displacement.exr", studio.model().mesoscopic_displacement());
    WriteImage(dir / "maps" / "albedo.exr", studio.model().skin().albedo, {.half = true});
    WriteImage(dir / "maps" / "specular.exr", studio.model().skin().specular, {.half = true});
    WriteImage(dir / "maps" / "roughness.exr", studio.model().skin().roughness, {.half = true});
    Progress progress("rendering " + sequence.name, count);
    TimingReport timing;
    for (int i = first; i < first + count; ++i) {
      ScopedTimer t_frame(&timing, "render frame (studio)");
      const StudioFrame frame = studio.RenderFrame(sequence, i);
      t_frame.Stop();
      report.render_seconds += frame.render.stats.seconds;
      report.surface_seconds += frame.actor.seconds;
      ScopedTimer t_write(&timing, "write frame + truth");
      cv::Mat srgb;
      frame.image.srgb8.convertTo(srgb, CV_8U);
      WriteImage(dir / "frames" / (FrameName(i) + ".png"), srgb, {.srgb = false});
      if (options.write_exr) WriteImage(dir / "frames" / (FrameName(i) + ".exr"), frame.render.image);
      WriteFrameTruth(dir / "truth", FrameName(i), frame.truth, rig, actor);
      t_write.Stop();
      ScopedTimer t_maps(&timing, "write maps + passes");
      if (options.write_maps) {
        WriteImage(dir / "maps" / (FrameName(i) + "_expression_displacement.exr"), frame.actor.expression_displacement);
      }
      if (options.write_passes) {
        const fs::path p = dir / "passes";
        WriteImage(p / (FrameName(i) + "_depth.exr"), frame.render.depth);
        WriteImage(p / (FrameName(i) + "_normal.exr"), frame.render.normal);
        cv::Mat uv3;
        cv::Mat zero = cv::Mat::zeros(frame.render.uv.size(), CV_32FC1);
        std::vector<cv::Mat> ch;
        cv::split(frame.render.uv, ch);
        ch.push_back(zero);
        cv::merge(ch, uv3);
        WriteImage(p / (FrameName(i) + "_uv.exr"), uv3);
        cv::Mat mask = frame.render.triangle_id >= 0;
        WriteImage(p / (FrameName(i) + "_mask.png"), mask, {.srgb = false});
      }
      t_maps.Stop();
      ++report.frames;
      progress.Advance();
    }
    for (const auto& e : studio.timing().Entries()) timing.Add("  " + e.name, e.total_seconds, e.count);
    report.timing = timing.ToTable();
    json ds;
    ds["format"] = SequenceDatasetInfo::kFormat;
    ds["version"] = SequenceDatasetInfo::kVersion;
    ds["sequence"] = sequence.name;
    ds["first_frame"] = first;
    ds["frames"] = count;
    ds["fps"] = sequence.fps;
    ds["width"] = options.studio.width;
    ds["height"] = options.studio.height;
    ds["rig"] = "rig.crig";
    if (tracking_rig) ds["tracking_rig"] = "tracking_rig.crig";
    ds["actor"] = "actor.json";
    ds["camera"] = "camera.json";
    ds["studio"] = json::parse(OptionsToJson(options.studio));
    ds["files"] = {
        {"frame", "frames/{frame:06d}.png"},
        {"frame_linear", options.write_exr ? "frames/{frame:06d}.exr" : ""},
        {"truth", "truth/{frame:06d}.json"},
        {"vertex_truth", "truth/{frame:06d}_vertices.bin (float32 x, y, visible per coarse vertex)"},
        {"expression_displacement", options.write_maps ? "maps/{frame:06d}_expression_displacement.exr" : ""},
        {"passes", options.write_passes ? "passes/{frame:06d}_{depth,normal,uv}.exr, passes/{frame:06d}_mask.png" : ""},
        {"static_displacement", "maps/static_displacement.exr"},
        {"mesoscopic_displacement", "maps/mesoscopic_displacement.exr"}};
    ds["units"] = "mm; images linear float in EXR, sRGB 8-bit in PNG; UV v grows downwards";
    WriteJsonFile(dir / "dataset.json", ds);
  });
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

DatasetReport WriteScanSet(const FaceRig& rig, const std::vector<uint64_t>& actor_seeds,
                           const ActorOptions& actor_options, const ScanSetOptions& options, const fs::path& out) {
  options.studio.Check();
  Require(!actor_seeds.empty(), "scan set: no actors");
  Require(options.cameras >= 1, "ScanSetOptions.cameras must be >= 1");
  std::vector<LightRig> light_rigs;
  for (const auto& l : options.light_rigs) light_rigs.push_back(LightRigFromSpec(l));
  std::vector<Eigen::VectorXd> expressions = {Eigen::VectorXd::Zero(rig.num_expressions())};
  std::vector<std::string> names = {"neutral"};
  for (const auto& spec : options.expressions) {
    expressions.push_back(ParseExpressionSpec(spec, rig));
    std::string name = spec.substr(0, spec.find('='));
    names.push_back(fmt::format("{:02d}_{}", names.size(), name));
  }
  DatasetReport report;
  report.path = out.string();
  const auto start = std::chrono::steady_clock::now();
  WriteFolderAtomic(out, options.overwrite, [&](const fs::path& dir) {
    WriteRig(dir / "rig.crig", rig, {.compress = true});
    json index;
    index["format"] = "crease scan set";
    index["version"] = 2;
    index["generator"] = "crease synth scans";
    index["rig"] = "rig.crig";
    index["light_rigs"] = options.light_rigs;
    index["cameras"] = options.cameras;
    json actors = json::array();
    Progress progress("scanning", static_cast<int64_t>(actor_seeds.size() * expressions.size()));
    for (size_t a = 0; a < actor_seeds.size(); ++a) {
      ActorOptions ao = actor_options;
      if (options.stratify_ages) {
        const double span = (actor_options.age_max - actor_options.age_min) / static_cast<double>(actor_seeds.size());
        ao.age_min = actor_options.age_min + span * static_cast<double>(a);
        ao.age_max = ao.age_min + span;
      }
      const Actor actor = GenerateActor(rig, actor_seeds[a], ao);
      const Studio studio(rig, actor, options.studio);
      const fs::path adir = dir / fmt::format("actor_{:03d}", a);
      fs::create_directories(adir);
      WriteActor(adir / "actor.json", actor);
      json scans = json::array();
      for (size_t e = 0; e < expressions.size(); ++e) {
        const fs::path sdir = adir / names[e];
        fs::create_directories(sdir);
        json images = json::array();
        bool mesh_written = false;
        for (int c = 0; c < options.cameras; ++c) {
          const double az = options.cameras == 1 ? 0.0
                                                 : -0.5 * options.camera_arc_deg + options.camera_arc_deg * c / (options.cameras - 1);
          // Cameras on an arc about the face centre, all looking at it.
          const Camera& front = studio.camera();
          const Eigen::Vector3d centre_in_head = front.cam_from_head.Inverse() * Eigen::Vector3d(0, 0, options.studio.distance_mm);
          const double r = az * std::numbers::pi / 180.0;
          const Eigen::Vector3d eye = centre_in_head + options.studio.distance_mm * Eigen::Vector3d(std::sin(r), 0, std::cos(r));
          const Camera cam = LookAtCamera(front.intrinsics, eye, centre_in_head, Eigen::Vector3d::UnitY());
          WriteCamera(sdir / fmt::format("cam{}.json", c), cam);
          for (size_t li = 0; li < options.light_rigs.size(); ++li) {
            const LightRig& lights = light_rigs[li];
            const std::string light_name = fs::path(options.light_rigs[li]).stem().string();
            const StudioFrame f = studio.RenderStill(expressions[e], SequenceFrame{}, &lights, &cam,
                                                     static_cast<uint64_t>(1000 * e + 10 * c));
            report.render_seconds += f.render.stats.seconds;
            cv::Mat srgb;
            f.image.srgb8.convertTo(srgb, CV_8U);
            WriteImage(sdir / fmt::format("cam{}_{}.png", c, light_name), srgb, {.srgb = false});
            images.push_back({{"camera", fmt::format("{}/cam{}.json", names[e], c)},
                              {"image", fmt::format("{}/cam{}_{}.png", names[e], c, light_name)},
                              {"light", light_name}});
            if (!mesh_written) {
              WritePly(sdir / "mesh.ply", f.actor.hires, {.binary = true, .double_precision = false});
              WriteImage(sdir / "expression_displacement.exr", f.actor.expression_displacement);
              json truth;
              json w = json::object();
              for (int i = 0; i < rig.num_expressions(); ++i) w[rig.expression_names[i]] = expressions[e][i];
              truth["expression"] = w;
              truth["identity"] = std::vector<double>(actor.identity.data(), actor.identity.data() + actor.identity.size());
              WriteJsonFile(sdir / "truth.json", truth);
              mesh_written = true;
            }
          }
        }
        scans.push_back({{"name", names[e]},
                         {"mesh", names[e] + "/mesh.ply"},
                         {"images", images},
                         {"truth",
                          {{"expression_displacement", names[e] + "/expression_displacement.exr"},
                           {"parameters", names[e] + "/truth.json"}}}});
        ++report.frames;
        progress.Advance();
      }
      actors.push_back({{"folder", adir.filename().string()},
                        {"seed", actor_seeds[a]},
                        {"neutral", names[0]},
                        {"actor", "actor.json"},
                        {"scans", scans}});
    }
    index["actors"] = actors;
    WriteJsonFile(dir / "scans.json", index);
  });
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

TriMesh RebuildDatasetFrameMesh(const fs::path& dataset, int frame) {
  const SequenceDatasetInfo info = ReadSequenceDatasetInfo(dataset);
  const FaceRig rig = ReadRig(info.RigPath());
  const Actor actor = ReadActor(dataset / "actor.json");
  const fs::path truth_path = info.TruthPath(frame);
  Require(info.HasFrame(frame) && fs::exists(truth_path),
          fmt::format("{}: frame {} is not in this dataset (frames {}..{})", truth_path.string(), frame,
                      info.first_frame, info.last_frame()));
  const json truth = ReadJsonFile(truth_path);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.num_expressions());
  for (auto it = truth.at("expression").begin(); it != truth.at("expression").end(); ++it) {
    const int i = rig.ExpressionIndex(it.key());
    Require(i >= 0, fmt::format("{}: expression '{}' is not in the rig", truth_path.string(), it.key()));
    w[i] = it->get<double>();
  }
  const ActorModel model(rig, actor);
  return model.Frame(w, true).hires;
}

}  // namespace crease
