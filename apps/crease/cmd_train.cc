// `crease train` (paper Sec. 4) and `crease model info`.
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <fstream>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/options.h"
#include "core/progress.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/trainer.h"

namespace crease::app {

namespace fs = std::filesystem;

void AddTrainCommands(CLI::App& app) {
  {
    auto* cmd = app.add_subcommand("train", "Train the detail model (paper Sec. 4) on a scan set");
    static std::string scans, rig_path, out, config, report;
    static std::vector<std::string> sets;
    cmd->add_option("--scans", scans, "Scan set folder (scans.json; e.g. from `crease synth scans`)")->required();
    cmd->add_option("--rig", rig_path, "The tracker's rig (.crig); default: the rig the scan set names");
    cmd->add_option("--out,-o", out, "Model file to write (.cdm)")->required();
    cmd->add_option("--config", config, "Training options (YAML; keys: pipeline/training/trainer.h TrainingOptions)");
    cmd->add_option("--set", sets, "Training option KEY=VALUE (repeatable), e.g. num_ferns=640 dimensions=8");
    cmd->add_option("--report", report, "Report folder (default: <out without extension>_report)");
    cmd->callback([] {
      TrainingOptions options;
      if (!config.empty()) SetOptionsFromYaml(ReadFileToString(config), config, &options);
      if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &options);
      const ScanSet set = ReadScanSet(scans);
      if (rig_path.empty()) {
        Require(!set.rig.empty(), fmt::format("{}: the scan set names no rig; give --rig", scans));
        rig_path = set.rig.string();
      }
      const FaceRig rig = ReadRig(rig_path);
      const fs::path out_path(out);
      const fs::path report_dir =
          report.empty() ? out_path.parent_path() / (out_path.stem().string() + "_report") : fs::path(report);
      std::printf("training on %s: %zu actors, %d scans, lights: %s\n", scans.c_str(), set.actors.size(),
                  set.num_scans(), fmt::format("{}", fmt::join(set.lights(), ", ")).c_str());
      TrainingSummary summary;
      const DetailModel model = TrainDetailModel(set, rig, options, {report_dir}, &summary,
                                                 [](const std::string& line) { std::printf("  %s\n", line.c_str()); });
      WriteDetailModel(out_path, model);
      // The compatible rig (Sec. 4.1) for inspection; capture derives it from the model's G.
      WriteRig(report_dir / "compatible_rig.crig", MakeRigCompatible(rig, model.detail));
      WriteFileAtomic(report_dir / "report.json", [&](std::ostream& o) { o << summary.ToJson(); });
      const std::string md = summary.ToMarkdown();
      WriteFileAtomic(report_dir / "report.md", [&](std::ostream& o) { o << md; });
      std::printf("\n%s\n", md.c_str());
      std::printf("wrote %s and the report in %s\n", out.c_str(), report_dir.string().c_str());
    });
  }
  {
    auto* model_cmd = app.add_subcommand("model", "Inspect trained models");
    model_cmd->require_subcommand(1);
    auto* cmd = model_cmd->add_subcommand("info", "Describe a detail model file");
    static std::string path;
    cmd->add_option("model", path, "Detail model file")->required();
    cmd->callback([] { std::printf("%s", DescribeDetailModel(ReadDetailModel(path)).c_str()); });
  }
}

}  // namespace crease::app
