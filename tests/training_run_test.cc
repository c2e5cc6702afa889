// The training job `crease train` runs (pipeline/training/training_run.h), driven
// from C++ on a tiny studio scan set: its files, its summary, its lines, and the
// job from saved pairs against the job from the scans.
#include "pipeline/training/training_run.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "tests/test_util.h"
#include "tests/training_test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;

// TinyTrainingOptions with a 10-fern cascade (seconds).
void TinyEdit(TrainingOptions* o) {
  *o = testing::TinyTrainingOptions();
  o->ferns.num_ferns = 10;
}

TEST(TrainingRun, FromScansWritesModelPairsAndReportAndThePairsRetrainTheSameModel) {
  const fs::path dir = testing::TestDir();
  TrainingRunOptions run;
  run.scans = testing::TinyScans();
  run.out = dir / "model.cdm";
  run.save_pairs = dir / "pairs.cpr";
  std::vector<std::string> lines;
  const TrainingRunSummary s = RunTraining(run, TinyEdit, [&](const std::string& l) { lines.push_back(l); });

  // The files: the model, the pairs and the report beside the model (TrainingReportDir).
  EXPECT_TRUE(s.trained);
  EXPECT_EQ(s.model, run.out);
  EXPECT_EQ(s.pairs_file, run.save_pairs);
  EXPECT_EQ(s.report_dir, dir / "model_report");
  const DetailModel model = ReadDetailModel(run.out);
  EXPECT_EQ(model.pca.dimensions(), 6);
  EXPECT_EQ(model.cascade.num_ferns(), 10);
  EXPECT_TRUE(fs::is_regular_file(s.report_dir / "compatible_rig.crig"));
  EXPECT_EQ(ReadFileToString(s.report_dir / "report.md"), s.report_markdown);
  EXPECT_EQ(ReadFileToString(s.report_dir / "report.json"), s.report_json);
  const nlohmann::json report = nlohmann::json::parse(s.report_json);
  // The summary counts the pairs written, as the trainer does.
  const TrainingPairs pairs = ReadTrainingPairs(run.save_pairs);
  EXPECT_GT(s.training_pairs, 10);
  EXPECT_EQ(pairs.texture.rows(), s.training_pairs);
  EXPECT_EQ(report["training_pairs"], s.training_pairs);
  // The lines: what is read first, the trainer's steps indented, the report, where it went.
  ASSERT_GE(lines.size(), 4u);
  EXPECT_EQ(lines.front().rfind("training on " + run.scans.string() + ": 1 actors, 2 scans, lights: ", 0), 0u)
      << lines.front();
  EXPECT_EQ(lines[1].rfind("  ", 0), 0u) << lines[1];
  EXPECT_EQ(lines[lines.size() - 2], "\n" + s.report_markdown);
  EXPECT_EQ(lines.back(), "wrote " + run.out.string() + " and the report in " + s.report_dir.string());

  // From the saved pairs (the regression only): the same model, its own report.
  TrainingRunOptions again;
  again.pairs = {run.save_pairs};
  again.out = dir / "again.cdm";
  const TrainingRunSummary t = RunTraining(again, TinyEdit);
  EXPECT_EQ(t.report_dir, dir / "again_report");
  EXPECT_TRUE(t.pairs_file.empty());
  EXPECT_EQ(t.training_pairs, s.training_pairs);
  const DetailModel back = ReadDetailModel(again.out);
  EXPECT_EQ(back.cascade, model.cascade);
  EXPECT_TRUE(back.pca == model.pca);
  EXPECT_FALSE(fs::exists(t.report_dir / "compatible_rig.crig"));

  // Extraction options cannot change without the scans: an error naming the file and
  // the field, and no report folder left behind.
  again.out = dir / "other.cdm";
  EXPECT_ERROR_HAS(RunTraining(again, [](TrainingOptions* o) { o->patch.patch_size = 16; }), "pairs.cpr");
  EXPECT_FALSE(fs::exists(dir / "other_report"));
  EXPECT_FALSE(fs::exists(again.out));
}

TEST(TrainingRun, PairsOnlyWritesNoModel) {
  const fs::path dir = testing::TestDir();
  TrainingRunOptions run;
  run.scans = testing::TinyScans();
  run.save_pairs = dir / "p.cpr";
  const TrainingRunSummary s = RunTraining(run, TinyEdit);
  EXPECT_FALSE(s.trained);
  EXPECT_TRUE(s.model.empty());
  EXPECT_EQ(s.report_dir, dir / "p_report");
  EXPECT_TRUE(fs::is_regular_file(s.report_dir / "report.json"));
  EXPECT_FALSE(fs::exists(s.report_dir / "compatible_rig.crig"));
  EXPECT_EQ(ReadTrainingPairs(run.save_pairs).texture.rows(), s.training_pairs);
  // Extraction only: the pairs counted, no PCA.
  const nlohmann::json report = nlohmann::json::parse(s.report_json);
  EXPECT_EQ(report["training_pairs"], s.training_pairs);
  EXPECT_TRUE(report["pca_energy"].empty());
}

TEST(TrainingRun, BadRunsAreRefusedBeforeAnyWork) {
  const fs::path dir = testing::TestDir();
  TrainingRunOptions run;
  run.out = dir / "m.cdm";
  EXPECT_ERROR_HAS(RunTraining(run, {}), "give scans (a scan set) or pairs");
  run.scans = dir / "scans";
  run.pairs = {dir / "p.cpr"};
  EXPECT_ERROR_HAS(RunTraining(run, {}), "not both");
  run.pairs.clear();
  run.out.clear();
  EXPECT_ERROR_HAS(RunTraining(run, {}), "give out (the model) and/or save_pairs");
  run.out = dir / "m.cdm";
  // A report folder that holds something else is not replaced.
  fs::create_directories(dir / "m_report");
  testing::WriteText(dir / "m_report" / "notes.txt", "mine");
  EXPECT_ERROR_HAS(RunTraining(run, {}), "is not a training report");
  EXPECT_TRUE(fs::exists(dir / "m_report" / "notes.txt"));
  // A missing scan set is an error naming it.
  fs::remove_all(dir / "m_report");
  EXPECT_ERROR_HAS(RunTraining(run, {}), "not a folder");
}

}  // namespace
}  // namespace crease
