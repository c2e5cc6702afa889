// `crease train` (paper Sec. 4) and `crease model info`.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "apps/crease/commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/options.h"
#include "core/progress.h"
#include "eval/detail_truth.h"
#include "eval/pair_metrics.h"
#include "pipeline/training/detail_model.h"
#include "pipeline/training/trainer.h"
#include "pipeline/training/training_run.h"

namespace crease::app {

namespace fs = std::filesystem;

namespace {

// Comma-separated pair files (--pairs A.cpr,B.cpr).
std::vector<fs::path> PairFiles(const std::string& list) {
  std::vector<fs::path> files;
  for (const auto& p : SplitComma(list)) files.emplace_back(p);
  return files;
}

// train
struct TrainArgs {
  std::string scans, rig_path, out, config, report, pairs_in, pairs_out;
  std::vector<std::string> sets;
};

// --config, then --set, onto `options`.
void ApplyUserOptions(const TrainArgs& a, TrainingOptions* options) {
  if (!a.config.empty()) SetOptionsFromYaml(ReadFileToString(a.config), a.config, options);
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", options);
}

void PrintProgressLine(const std::string& l) { std::printf("  %s\n", l.c_str()); }

// train --scans or --pairs: the job (pipeline/training/training_run.h), with its lines printed.
void RunTrainCommand(const TrainArgs& a) {
  TrainingRunOptions run;
  run.scans = a.scans;
  run.pairs = PairFiles(a.pairs_in);
  run.rig = a.rig_path;
  run.out = a.out;
  run.save_pairs = a.pairs_out;
  run.report = a.report;
  RunTraining(run, [&a](TrainingOptions* o) { ApplyUserOptions(a, o); },
              [](const std::string& line) { std::printf("%s\n", line.c_str()); });
}

void AddTrainCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("train", "Train the detail model (paper Sec. 4) on a scan set");
  auto a = std::make_shared<TrainArgs>();
  auto* scans_opt = cmd->add_option("--scans", a->scans, "Scan set folder (scans.json; e.g. from `crease synth scans`)");
  auto* pairs_opt = cmd->add_option("--pairs", a->pairs_in,
                                    "Train the PCA and the cascade (Sec. 4.3) from saved training pairs instead of "
                                    "scans (several files: comma-separated); only PCA and cascade options may then "
                                    "change");
  scans_opt->excludes(pairs_opt);
  cmd->add_option("--save-pairs", a->pairs_out,
                  "Also save the training pairs (t_i, d_i of Sec. 4.2; CREASPRS file); without --out, stop there");
  cmd->add_option("--rig", a->rig_path, "The tracker's rig (.crig); default: the rig the scan set names");
  cmd->add_option("--out,-o", a->out, "Model file to write (.cdm)");
  cmd->add_option("--config", a->config, "Training options (YAML; keys: pipeline/training/trainer.h TrainingOptions)");
  cmd->add_option("--set", a->sets, "Training option KEY=VALUE (repeatable), e.g. ferns.num_ferns=640 pca.dimensions=8");
  cmd->add_option("--report", a->report, "Report folder (default: <out without extension>_report)");
  cmd->callback([a] {
    if (a->scans.empty() == a->pairs_in.empty()) throw Error("train: give --scans (a scan set) or --pairs (saved pairs)");
    if (a->out.empty() && a->pairs_out.empty()) throw Error("train: give --out (the model) and/or --save-pairs");
    Require(a->pairs_in.empty() || a->pairs_out.empty(), "train: --save-pairs needs --scans");
    RunTrainCommand(*a);
  });
}

// eval-extraction
struct EvalExtractionArgs {
  std::string scans, config, json_out, write_truth;
  double exact_phong_alpha = 0.0;
  double rim_margin_mm = 0.0;
  std::vector<std::string> sets;
  int actors = 0;
};

void RunEvalExtraction(const EvalExtractionArgs& a) {
  TrainingOptions training;
  if (!a.config.empty()) SetOptionsFromYaml(ReadFileToString(a.config), a.config, &training);
  if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", &training);
  ExtractionTruthOptions o;
  o.detail = training.detail;
  o.band_mm = training.validation_band_mm;
  o.max_actors = a.actors;
  o.write_truth = a.write_truth;
  o.exact_phong_alpha = a.exact_phong_alpha;
  o.rim_margin_mm = a.rim_margin_mm;
  const ExtractionTruthReport r = EvaluateExtraction(a.scans, o);
  std::printf("%s%zu scans in %.1f s\n", r.ToTable().c_str(), r.rows.size(), r.seconds);
  if (!a.json_out.empty()) WriteFileAtomic(a.json_out, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
}

void AddEvalExtractionCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("eval-extraction",
                                 "Detail extraction (Sec. 4.1) of a studio scan set against the truth: the wrinkle "
                                 "layer alone and with the coarse expression's medium band (eval/detail_truth.h)");
  auto a = std::make_shared<EvalExtractionArgs>();
  cmd->add_option("--scans", a->scans, "Scan set folder from `crease synth scans`")->required();
  cmd->add_option("--config", a->config, "Training options (YAML; the detail extraction's and validation_band_mm are used)");
  cmd->add_option("--set", a->sets, "Training option KEY=VALUE (repeatable), e.g. detail.lowpass_bandwidth_mm=2");
  cmd->add_option("--actors", a->actors, "Evaluate the first N actors only (0 = all)")->capture_default_str();
  cmd->add_option("--json", a->json_out, "Write the rows as JSON");
  cmd->add_option("--write-truth", a->write_truth,
                  "Also write each scan's D* as DIR/<actor>/<scan>.exr (the targets of `crease train --set "
                  "training_targets=maps --set target_maps=DIR`)");
  cmd->add_option("--exact-phong-alpha", a->exact_phong_alpha,
                  "The exact detail's base: the compatible surface Phong-tessellated with this shape factor (0 = "
                  "flat, as H^t's base; the studio's surface uses 0.75)")
      ->capture_default_str();
  cmd->add_option("--rim-margin-mm", a->rim_margin_mm,
                  "Compare only texels at least this far (mm) from the chart's open edges (lips, eyelids, nostrils, "
                  "outer rim); the wrinkle band is still taken on the whole chart")
      ->check(CLI::Range(0.0, 50.0))
      ->capture_default_str();
  cmd->callback([a] { RunEvalExtraction(*a); });
}

// truth-maps
struct TruthMapsArgs {
  std::string dataset, model_path, out;
  int frames = -1;
};

void AddTruthMapsCommand(CLI::App& app) {
  auto* cmd = app.add_subcommand("truth-maps",
                                 "The true detail D* (Sec. 4.1, eval/detail_truth.h) of a studio sequence's frames, "
                                 "with a model's G: the maps `capture --set wrinkle_map_from_maps=DIR` reads (rung R1) "
                                 "and `--set detail_from_truth_maps=DIR` assembles D^t from (rung R2-oracle)");
  auto a = std::make_shared<TruthMapsArgs>();
  cmd->add_option("--dataset,-d", a->dataset, "Sequence folder from `crease synth sequence`")->required();
  cmd->add_option("--model,-m", a->model_path, "Detail model (.cdm): its G and map resolution")->required();
  cmd->add_option("--frames", a->frames, "The first N frames only (-1 = all)")->capture_default_str();
  cmd->add_option("--out,-o", a->out, "Folder to write NNNNNN.exr into (replaced)")->required();
  cmd->callback([a] {
    const DetailModel model = ReadDetailModel(a->model_path);
    const int n = WriteDetailTruthMaps(a->dataset, model.detail, a->frames, a->out);
    std::printf("wrote %d maps of D* (%d x %d) to %s\n", n, model.detail.map_resolution, model.detail.map_resolution,
                a->out.c_str());
  });
}

// model eval-pairs
struct EvalPairsArgs {
  std::string model, pairs, json;
};

void AddModelEvalPairsCommand(CLI::App* model_cmd) {
  auto* cmd = model_cmd->add_subcommand(
      "eval-pairs", "The model's patch regression (Sec. 4.3) on training pairs, seen or held out (issue 17's rung R0)");
  auto a = std::make_shared<EvalPairsArgs>();
  cmd->add_option("model", a->model, "Detail model file")->required();
  cmd->add_option("--pairs", a->pairs, "Pair files (from `crease train --save-pairs`), comma-separated")->required();
  cmd->add_option("--json", a->json, "Write the metrics as JSON");
  cmd->callback([a] {
    const PairRegressionMetrics m =
        EvaluatePairs(ReadDetailModel(a->model), ReadTrainingPairs(PairFiles(a->pairs)), a->pairs);
    std::printf("%s", m.ToTable().c_str());
    if (!a->json.empty()) WriteFileAtomic(a->json, [&](std::ostream& out) { out << m.ToJson() << "\n"; });
  });
}

// model loao
struct LoaoArgs {
  std::string pairs, json, config, regressors = "ferns,ridge,nearest";
  std::vector<std::string> sets;
};

void RunLoao(const LoaoArgs& a) {
  const TrainingPairs pairs = ReadTrainingPairs(PairFiles(a.pairs));
  const TrainingOptions options = OptionsForPairs(pairs, a.pairs, [&a](TrainingOptions* o) {
    if (!a.config.empty()) SetOptionsFromYaml(ReadFileToString(a.config), a.config, o);
    if (!a.sets.empty()) SetOptionsFromJson(SetPairsToJson(a.sets), "--set", o);
  });
  const LeaveOneActorOutResult r =
      EvaluateLeaveOneActorOut(pairs, options, SplitComma(a.regressors), a.pairs, PrintProgressLine);
  std::printf("%s", r.ToTable().c_str());
  if (!a.json.empty()) WriteFileAtomic(a.json, [&](std::ostream& out) { out << r.ToJson() << "\n"; });
}

void AddModelLoaoCommand(CLI::App* model_cmd) {
  auto* cmd = model_cmd->add_subcommand(
      "loao", "Leave one actor out (issue 17's rung R0): train on all actors' pairs but one, score the held-out one");
  auto a = std::make_shared<LoaoArgs>();
  cmd->add_option("--pairs", a->pairs, "Pair files (from `crease train --save-pairs`), comma-separated")->required();
  cmd->add_option("--regressors", a->regressors, "Regressors scored, comma-separated: ferns, ridge, nearest")
      ->capture_default_str();
  cmd->add_option("--config", a->config, "Training options (YAML; only PCA and cascade options may differ)");
  cmd->add_option("--set", a->sets, "Training option KEY=VALUE (repeatable), e.g. ferns.num_ferns=640");
  cmd->add_option("--json", a->json, "Write the folds and their means as JSON");
  cmd->callback([a] { RunLoao(*a); });
}

// model info | eval-pairs | loao
void AddModelCommands(CLI::App& app) {
  auto* model_cmd = app.add_subcommand("model", "Inspect trained models");
  model_cmd->require_subcommand(1);
  auto* cmd = model_cmd->add_subcommand("info", "Describe a detail model file");
  auto path = std::make_shared<std::string>();
  cmd->add_option("model", *path, "Detail model file")->required();
  cmd->callback([path] { std::printf("%s", DescribeDetailModel(ReadDetailModel(*path)).c_str()); });
  AddModelEvalPairsCommand(model_cmd);
  AddModelLoaoCommand(model_cmd);
}

}  // namespace

void AddTrainCommands(CLI::App& app) {
  AddTrainCommand(app);
  AddEvalExtractionCommand(app);
  AddTruthMapsCommand(app);
  AddModelCommands(app);
}

}  // namespace crease::app
