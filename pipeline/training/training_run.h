// Running and recording a training job (paper Sec. 4): the job `crease train` runs,
// callable from C++. From a scan set (extraction, Sec. 4.1–4.2, then the PCA and the
// cascade, Sec. 4.3) or from saved training pairs (Sec. 4.3 only), it writes
//   the model file (out; .cdm)                 unless only pairs are asked for
//   the pairs file (save_pairs; CREASPRS)      with save_pairs, from a scan set
//   the report folder (TrainingReportDir):     report.json, report.md, the trainer's
//                                              pictures and, from a scan set with a
//                                              model, compatible_rig.crig (Sec. 4.1)
// The report folder is written under a temporary name and renamed when complete, so a
// killed run leaves no partial report.
//
//   TrainingRunOptions run;
//   run.scans = "scans";
//   run.out = "model.cdm";
//   const TrainingRunSummary s = RunTraining(run, [](TrainingOptions* o) { ... }, log);
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "pipeline/training/trainer.h"

namespace crease {

struct TrainingRunOptions {
  // The input: a scan set folder (scans.json) or saved pair files, exactly one.
  std::filesystem::path scans;
  std::vector<std::filesystem::path> pairs;
  std::filesystem::path rig;         // the tracker's rig (.crig); empty: the one the scan set names
  std::filesystem::path out;         // the model file (.cdm); empty: extract and save the pairs only
  std::filesystem::path save_pairs;  // also write the training pairs here (scans only); empty: no
  std::filesystem::path report;      // the report folder; empty: TrainingReportDir's default

  // Throws Error: not exactly one input, neither out nor save_pairs, save_pairs
  // with pairs as input.
  void Check() const;
};

// What a training run did and where it went. The trainer's TrainingSummary is the
// report's content: report_json and report_markdown hold it as written.
struct TrainingRunSummary {
  std::string report_json;              // report.json as written (TrainingSummary::ToJson)
  std::string report_markdown;          // report.md as written (TrainingSummary::ToMarkdown)
  int64_t training_pairs = 0;           // rows of the pairs trained on or saved
  bool trained = false;                 // a model was trained and written
  std::filesystem::path model;          // the model file (empty: none)
  std::filesystem::path pairs_file;     // the pairs file written (empty: none)
  std::filesystem::path report_dir;     // the report folder
};

// Runs the job of `options` (above). `edit` sets the TrainingOptions (from their
// defaults, or from the pairs' own; may be empty): from pairs only the regression's
// options may change (OptionsForPairs). `log` receives each line `crease train`
// prints, without its newline: what is read, the trainer's steps (indented by two
// spaces), what is written, and the report's Markdown. Throws Error for bad options,
// a scan set without a rig when none is given, and the trainer's errors; the report
// folder is then not left behind.
TrainingRunSummary RunTraining(const TrainingRunOptions& options, const std::function<void(TrainingOptions*)>& edit,
                               const std::function<void(const std::string&)>& log = {});

}  // namespace crease
