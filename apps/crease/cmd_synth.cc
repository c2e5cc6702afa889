// crease synth rig — the studio's procedural head rig (synth/procedural_rig.h).
#include <cstdio>
#include <memory>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/image_io.h"
#include "synth/procedural_rig.h"
#include "synth/studio_rig.h"

namespace crease::app {

void AddSynthCommands(CLI::App& app) {
  auto* synth = app.add_subcommand("synth", "The synthetic face studio: procedural rig, actors, renders");
  synth->require_subcommand(1);

  // synth rig
  {
    auto* cmd = synth->add_subcommand("rig", "Build a studio head rig (.crig): the realistic ICT-FaceKit head or "
                                             "the procedural one");
    struct Args {
      std::string out, preview, head, from;
      std::vector<std::string> sets;
      int preview_tile = 512;
    };
    auto a = std::make_shared<Args>();
    cmd->add_option("--out,-o", a->out, "Output rig file (.crig)")->required();
    cmd->add_option("--head", a->head, "ict: the realistic ICT-FaceKit head (default, synth/ict_head.h); "
                                    "procedural: the SDF head (synth/procedural_rig.h)")
        ->check(CLI::IsMember(EnumNames<StudioHead>()));
    cmd->add_option("--from", a->from, "With --head ict: the imported ICT rig (default: the vendored "
                                    "data/ict/ict_face_light.crig)");
    cmd->add_option("--set", a->sets,
                    "Rig option KEY=VALUE (repeatable): ict.identity_modes=40, procedural.face_columns=72 "
                    ", … (synth/studio_rig.h)");
    cmd->add_option("--preview", a->preview, "Also write a contact sheet of renders (neutral and expressions)");
    cmd->add_option("--preview-tile", a->preview_tile, "Preview tile size, pixels")->capture_default_str();
    cmd->callback([a] {
      StudioRigOptions opt;
      if (!a->sets.empty()) SetOptionsFromJson(SetPairsToJson(a->sets), "--set", &opt);
      if (!a->head.empty()) opt.head = FromString<StudioHead>(a->head, "--head");
      if (!a->from.empty()) opt.ict_rig = a->from;
      const FaceRig rig = BuildStudioRig(opt);
      WriteRig(a->out, rig);
      const ChartDistortion d = MeasureFaceChartDistortion(rig);
      std::printf("wrote %s: %d vertices, %d triangles, %d identity modes, %d expressions, %zu landmarks, "
                  "%zu regions\n",
                  a->out.c_str(), rig.num_vertices(), rig.neutral.num_faces(), rig.num_identity(),
                  rig.num_expressions(), rig.landmarks.size(), rig.regions.size());
      std::printf("face UV chart: %d triangles, area ratio p05/p50/p95 %.3f/%.3f/%.3f (min %.3f, max %.3f), "
                  "conformal distortion mean %.3f p95 %.3f, %d flipped\n",
                  d.triangles, d.area_ratio_p05, d.area_ratio_p50, d.area_ratio_p95, d.area_ratio_min,
                  d.area_ratio_max, d.conformal_mean, d.conformal_p95, d.flipped);
      if (!a->preview.empty()) {
        if (a->preview_tile < 64 || a->preview_tile > 4096) throw Error("--preview-tile must be in [64, 4096]");
        WriteImage(a->preview, RigContactSheet(rig, a->preview_tile));
        std::printf("wrote %s\n", a->preview.c_str());
      }
    });
  }
}

}  // namespace crease::app
