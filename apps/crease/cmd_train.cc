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
#include "eval/detail_truth.h"
#include "eval/pair_metrics.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/trainer.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

// Comma-separated pair files (--pairs A.cpr,B.cpr).
std::vector<fs::path> PairFiles(const std::string& list) {
  std::vector<fs::path> files;
  for (const auto& p : SplitComma(list)) files.emplace_back(p);
  return files;
}

}  // namespace

void AddTrainCommands(CLI::App& app) {
  {
    auto* cmd = app.add_subcommand("train", "Train the detail model (paper Sec. 4) on a scan set");
    static std::string scans, rig_path, out, config, report, pairs_in, pairs_out;
    static std::vector<std::string> sets;
    auto* scans_opt = cmd->add_option("--scans", scans, "Scan set folder (scans.json; e.g. from `crease synth scans`)");
    auto* pairs_opt = cmd->add_option("--pairs", pairs_in,
                                      "Train the PCA and the cascade (Sec. 4.3) from saved training pairs instead of "
                                      "scans (several files: comma-separated); only PCA and cascade options may then "
                                      "change");
    scans_opt->excludes(pairs_opt);
    cmd->add_option("--save-pairs", pairs_out,
                    "Also save the training pairs (t_i, d_i of Sec. 4.2; CREASPRS file); without --out, stop there");
    cmd->add_option("--rig", rig_path, "The tracker's rig (.crig); default: the rig the scan set names");
    cmd->add_option("--out,-o", out, "Model file to write (.cdm)");
    cmd->add_option("--config", config, "Training options (YAML; keys: pipeline/training/trainer.h TrainingOptions)");
    cmd->add_option("--set", sets, "Training option KEY=VALUE (repeatable), e.g. num_ferns=640 dimensions=8");
    cmd->add_option("--report", report, "Report folder (default: <out without extension>_report)");
    cmd->callback([] {
      if (scans.empty() == pairs_in.empty()) throw Error("train: give --scans (a scan set) or --pairs (saved pairs)");
      if (out.empty() && pairs_out.empty()) throw Error("train: give --out (the model) and/or --save-pairs");
      Require(pairs_in.empty() || pairs_out.empty(), "train: --save-pairs needs --scans");
      auto apply_user_options = [](TrainingOptions* options) {
        if (!config.empty()) SetOptionsFromYaml(ReadFileToString(config), config, options);
        if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", options);
      };
      const fs::path out_path(out.empty() ? pairs_out : out);
      const fs::path report_dir =
          report.empty() ? out_path.parent_path() / (out_path.stem().string() + "_report") : fs::path(report);
      auto write_report = [&](const TrainingSummary& summary) {
        WriteFileAtomic(report_dir / "report.json", [&](std::ostream& o) { o << summary.ToJson(); });
        const std::string md = summary.ToMarkdown();
        WriteFileAtomic(report_dir / "report.md", [&](std::ostream& o) { o << md; });
        std::printf("\n%s\n", md.c_str());
      };
      auto line = [](const std::string& l) { std::printf("  %s\n", l.c_str()); };
      if (!pairs_in.empty()) {
        const TrainingPairs pairs = ReadTrainingPairs(PairFiles(pairs_in));
        const TrainingOptions options = OptionsForPairs(pairs, pairs_in, apply_user_options);
        std::printf("training the PCA and the cascade on %lld pairs of %s\n", static_cast<long long>(pairs.texture.rows()),
                    pairs_in.c_str());
        TrainingSummary summary;
        const DetailModel model = TrainDetailModelFromPairs(pairs, options, {report_dir}, &summary, line);
        WriteDetailModel(out_path, model);
        write_report(summary);
        std::printf("wrote %s and the report in %s\n", out.c_str(), report_dir.string().c_str());
        return;
      }
      TrainingOptions options;
      apply_user_options(&options);
      const ScanSet set = ReadScanSet(scans);
      if (rig_path.empty()) {
        Require(!set.rig.empty(), fmt::format("{}: the scan set names no rig; give --rig", scans));
        rig_path = set.rig.string();
      }
      const FaceRig rig = ReadRig(rig_path);
      std::printf("training on %s: %zu actors, %d scans, lights: %s\n", scans.c_str(), set.actors.size(),
                  set.num_scans(), fmt::format("{}", fmt::join(set.lights(), ", ")).c_str());
      TrainingSummary summary;
      const TrainingPairs pairs = ExtractTrainingPairs(set, rig, options, {report_dir}, &summary, line);
      if (!pairs_out.empty()) {
        WriteTrainingPairs(pairs_out, pairs);
        std::printf("wrote %lld training pairs to %s\n", static_cast<long long>(pairs.texture.rows()),
                    pairs_out.c_str());
      }
      if (out.empty()) {
        write_report(summary);
        return;
      }
      const DetailModel model = TrainDetailModelFromPairs(pairs, options, {report_dir}, &summary, line);
      WriteDetailModel(out_path, model);
      // The compatible rig (Sec. 4.1) for inspection; capture derives it from the model's G.
      WriteRig(report_dir / "compatible_rig.crig", MakeRigCompatible(rig, model.detail));
      write_report(summary);
      std::printf("wrote %s and the report in %s\n", out.c_str(), report_dir.string().c_str());
    });
  }
  {
    auto* cmd = app.add_subcommand("eval-extraction",
                                   "Detail extraction (Sec. 4.1) of a studio scan set against the truth: the wrinkle "
                                   "layer alone and with the coarse expression's medium band (eval/detail_truth.h)");
    static std::string scans, config, json_out;
    static std::vector<std::string> sets;
    static int actors = 0;
    cmd->add_option("--scans", scans, "Scan set folder from `crease synth scans`")->required();
    cmd->add_option("--config", config, "Training options (YAML; the detail extraction's and validation_band_mm are used)");
    cmd->add_option("--set", sets, "Training option KEY=VALUE (repeatable), e.g. lowpass_bandwidth_mm=2");
    cmd->add_option("--actors", actors, "Evaluate the first N actors only (0 = all)")->capture_default_str();
    cmd->add_option("--json", json_out, "Write the rows as JSON");
    cmd->callback([] {
      TrainingOptions training;
      if (!config.empty()) SetOptionsFromYaml(ReadFileToString(config), config, &training);
      if (!sets.empty()) SetOptionsFromJson(SetPairsToJson(sets), "--set", &training);
      ExtractionTruthOptions o;
      o.detail = training.detail;
      o.band_mm = training.validation_band_mm;
      o.max_actors = actors;
      const ExtractionTruthReport r = EvaluateExtraction(scans, o);
      std::printf("%s%zu scans in %.1f s\n", r.ToTable().c_str(), r.rows.size(), r.seconds);
      if (!json_out.empty()) WriteFileAtomic(json_out, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
    });
  }
  {
    auto* cmd = app.add_subcommand("truth-maps",
                                   "The true detail D* (Sec. 4.1, eval/detail_truth.h) of a studio sequence's frames, "
                                   "with a model's G: the maps `capture --set wrinkle_map_from_maps=DIR` reads");
    static std::string dataset, model_path, out;
    static int frames = -1;
    cmd->add_option("--dataset,-d", dataset, "Sequence folder from `crease synth sequence`")->required();
    cmd->add_option("--model,-m", model_path, "Detail model (.cdm): its G and map resolution")->required();
    cmd->add_option("--frames", frames, "The first N frames only (-1 = all)")->capture_default_str();
    cmd->add_option("--out,-o", out, "Folder to write NNNNNN.exr into (replaced)")->required();
    cmd->callback([] {
      const DetailModel model = ReadDetailModel(model_path);
      const int n = WriteDetailTruthMaps(dataset, model.detail, frames, out);
      std::printf("wrote %d maps of D* (%d x %d) to %s\n", n, model.detail.map_resolution, model.detail.map_resolution,
                  out.c_str());
    });
  }
  {
    auto* model_cmd = app.add_subcommand("model", "Inspect trained models");
    model_cmd->require_subcommand(1);
    auto* cmd = model_cmd->add_subcommand("info", "Describe a detail model file");
    static std::string path;
    cmd->add_option("model", path, "Detail model file")->required();
    cmd->callback([] { std::printf("%s", DescribeDetailModel(ReadDetailModel(path)).c_str()); });
    auto* eval_cmd = model_cmd->add_subcommand(
        "eval-pairs", "The model's patch regression (Sec. 4.3) on training pairs, seen or held out (issue 17's rung R0)");
    static std::string eval_model, eval_pairs, eval_json;
    eval_cmd->add_option("model", eval_model, "Detail model file")->required();
    eval_cmd->add_option("--pairs", eval_pairs, "Pair files (from `crease train --save-pairs`), comma-separated")
        ->required();
    eval_cmd->add_option("--json", eval_json, "Write the metrics as JSON");
    eval_cmd->callback([] {
      const PairRegressionMetrics m =
          EvaluatePairs(ReadDetailModel(eval_model), ReadTrainingPairs(PairFiles(eval_pairs)), eval_pairs);
      std::printf("%s", m.ToTable().c_str());
      if (!eval_json.empty()) WriteFileAtomic(eval_json, [&](std::ostream& out) { out << m.ToJson() << "\n"; });
    });
    auto* loao_cmd = model_cmd->add_subcommand(
        "loao", "Leave one actor out (issue 17's rung R0): train on all actors' pairs but one, score the held-out one");
    static std::string loao_pairs, loao_json, loao_config, loao_regressors = "ferns,ridge,nearest";
    static std::vector<std::string> loao_sets;
    loao_cmd->add_option("--pairs", loao_pairs, "Pair files (from `crease train --save-pairs`), comma-separated")
        ->required();
    loao_cmd->add_option("--regressors", loao_regressors, "Regressors scored, comma-separated: ferns, ridge, nearest")
        ->capture_default_str();
    loao_cmd->add_option("--config", loao_config, "Training options (YAML; only PCA and cascade options may differ)");
    loao_cmd->add_option("--set", loao_sets, "Training option KEY=VALUE (repeatable), e.g. num_ferns=640");
    loao_cmd->add_option("--json", loao_json, "Write the folds and their means as JSON");
    loao_cmd->callback([] {
      const TrainingPairs pairs = ReadTrainingPairs(PairFiles(loao_pairs));
      const TrainingOptions options = OptionsForPairs(pairs, loao_pairs, [](TrainingOptions* o) {
        if (!loao_config.empty()) SetOptionsFromYaml(ReadFileToString(loao_config), loao_config, o);
        if (!loao_sets.empty()) SetOptionsFromJson(SetPairsToJson(loao_sets), "--set", o);
      });
      const LeaveOneActorOutResult r = EvaluateLeaveOneActorOut(
          pairs, options, SplitComma(loao_regressors), loao_pairs, [](const std::string& l) { std::printf("  %s\n", l.c_str()); });
      std::printf("%s", r.ToTable().c_str());
      if (!loao_json.empty()) WriteFileAtomic(loao_json, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
    });
  }
}

}  // namespace crease::app
