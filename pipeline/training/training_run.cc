// The training job (pipeline/training/training_run.h).
#include "pipeline/training/training_run.h"

#include <optional>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "core/error.h"
#include "core/face_rig.h"
#include "core/file_util.h"

namespace crease {
namespace fs = std::filesystem;

namespace {

using Log = std::function<void(const std::string&)>;

void Say(const Log& log, const std::string& line) {
  if (log) log(line);
}

// The trainer's step lines, indented under the run's own.
Log StepLog(const Log& log) {
  if (!log) return {};
  return [log](const std::string& line) { log("  " + line); };
}

// The pair files as named in messages: comma-separated.
std::string PairsName(const std::vector<fs::path>& files) {
  std::vector<std::string> names;
  for (const auto& f : files) names.push_back(f.string());
  return fmt::format("{}", fmt::join(names, ","));
}

// Writes report.json and report.md into `report` and prints the Markdown.
void WriteReport(const fs::path& report, const TrainingSummary& training, TrainingRunSummary* s, const Log& log) {
  s->report_markdown = WriteTrainingReport(report, training);
  s->report_json = training.ToJson();
  Say(log, "\n" + s->report_markdown);
}

// Writes the model and says where it and the report went.
void WriteModel(const fs::path& path, const DetailModel& model, TrainingRunSummary* s, const Log& log) {
  WriteDetailModel(path, model);
  s->trained = true;
  s->model = path;
  Say(log, fmt::format("wrote {} and the report in {}", path.string(), s->report_dir.string()));
}

// The PCA and the cascade (Sec. 4.3) from saved pairs.
void TrainFromPairs(const TrainingRunOptions& o, const std::function<void(TrainingOptions*)>& edit,
                    TrainingRunSummary* s, const Log& log) {
  const std::string name = PairsName(o.pairs);
  const TrainingPairs pairs = ReadTrainingPairs(o.pairs);
  const TrainingOptions options = OptionsForPairs(pairs, name, [&edit](TrainingOptions* t) {
    if (edit) edit(t);
  });
  s->training_pairs = pairs.texture.rows();
  Say(log, fmt::format("training the PCA and the cascade on {} pairs of {}", s->training_pairs, name));
  TrainingSummary training;
  DetailModel model;
  WriteFolderAtomic(s->report_dir, /*overwrite=*/true, [&](const fs::path& report) {
    model = TrainDetailModelFromPairs(pairs, options, {report}, &training, StepLog(log));
    WriteReport(report, training, s, log);
  });
  WriteModel(o.out, model, s, log);
}

// Extraction (Sec. 4.1–4.2), then the PCA and the cascade unless only pairs are asked for.
void TrainFromScans(const TrainingRunOptions& o, const std::function<void(TrainingOptions*)>& edit,
                    TrainingRunSummary* s, const Log& log) {
  TrainingOptions options;
  if (edit) edit(&options);
  const ScanSet set = ReadScanSet(o.scans);
  fs::path rig_path = o.rig;
  if (rig_path.empty()) {
    Require(!set.rig.empty(), fmt::format("{}: the scan set names no rig; give --rig", o.scans.string()));
    rig_path = set.rig;
  }
  const FaceRig rig = ReadRig(rig_path);
  Say(log, fmt::format("training on {}: {} actors, {} scans, lights: {}", o.scans.string(), set.actors.size(),
                       set.num_scans(), fmt::join(set.lights(), ", ")));
  TrainingSummary training;
  std::optional<DetailModel> model;
  WriteFolderAtomic(s->report_dir, /*overwrite=*/true, [&](const fs::path& report) {
    const TrainingPairs pairs = ExtractTrainingPairs(set, rig, options, {report}, &training, StepLog(log));
    s->training_pairs = pairs.texture.rows();
    if (!o.save_pairs.empty()) {
      WriteTrainingPairs(o.save_pairs, pairs);
      s->pairs_file = o.save_pairs;
      Say(log, fmt::format("wrote {} training pairs to {}", s->training_pairs, o.save_pairs.string()));
    }
    if (!o.out.empty()) {
      model = TrainDetailModelFromPairs(pairs, options, {report}, &training, StepLog(log));
      // The compatible rig (Sec. 4.1) for inspection; capture derives it from the model's G.
      WriteRig(report / "compatible_rig.crig", MakeRigCompatible(rig, model->detail));
    }
    WriteReport(report, training, s, log);
  });
  if (model) WriteModel(o.out, *model, s, log);
}

}  // namespace

void TrainingRunOptions::Check() const {
  Require(scans.empty() != pairs.empty(), "TrainingRunOptions: give scans (a scan set) or pairs (saved pairs), not both");
  Require(!out.empty() || !save_pairs.empty(), "TrainingRunOptions: give out (the model) and/or save_pairs");
  Require(pairs.empty() || save_pairs.empty(), "TrainingRunOptions: save_pairs needs scans");
}

TrainingRunSummary RunTraining(const TrainingRunOptions& options, const std::function<void(TrainingOptions*)>& edit,
                               const std::function<void(const std::string&)>& log) {
  options.Check();
  TrainingRunSummary s;
  // The report replaces its folder as a whole (checked before any work).
  s.report_dir = TrainingReportDir(options.out.empty() ? options.save_pairs : options.out, options.report);
  if (!options.pairs.empty()) {
    TrainFromPairs(options, edit, &s, log);
  } else {
    TrainFromScans(options, edit, &s, log);
  }
  return s;
}

}  // namespace crease
