#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/file_util.h"
#include "pipeline/training/trainer.h"
#include "tests/test_util.h"

namespace crease {
namespace {

namespace fs = std::filesystem;
using testing::TestDir;
using testing::WriteText;

// The default folder sits beside the model; an existing folder is reused only when
// it is empty or an earlier report, since the report replaces it.
TEST(TrainingReport, FolderIsBesideTheModelAndNeverAStrangersFolder) {
  const fs::path dir = TestDir();
  EXPECT_EQ(TrainingReportDir(dir / "m.cdm", ""), dir / "m_report");
  EXPECT_EQ(TrainingReportDir(dir / "m.cdm", dir / "elsewhere"), dir / "elsewhere");
  fs::create_directories(dir / "m_report");
  EXPECT_EQ(TrainingReportDir(dir / "m.cdm", ""), dir / "m_report");  // empty
  WriteText(dir / "m_report" / "report.json", "{}");
  EXPECT_EQ(TrainingReportDir(dir / "m.cdm", ""), dir / "m_report");  // an earlier report
  fs::create_directories(dir / "photos");
  WriteText(dir / "photos" / "holiday.jpg", "x");
  EXPECT_ERROR_HAS(TrainingReportDir(dir / "m.cdm", dir / "photos"),
                   (dir / "photos").string() + ": exists and is not a training report");
}

TEST(TrainingReport, WritesTheSummaryAsJsonAndMarkdown) {
  const fs::path dir = TestDir();
  TrainingSummary summary;
  summary.training_pairs = 1234;
  summary.pca_energy = {0.5, 0.8};
  summary.seconds = 2.5;
  const std::string md = WriteTrainingReport(dir, summary);
  EXPECT_EQ(md, summary.ToMarkdown());
  EXPECT_EQ(ReadFileToString(dir / "report.md"), md);
  const std::string json = ReadFileToString(dir / "report.json");
  EXPECT_EQ(json, summary.ToJson());
  EXPECT_EQ(nlohmann::json::parse(json)["training_pairs"], 1234);
}

}  // namespace
}  // namespace crease
