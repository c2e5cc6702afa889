// The training report's folder and files (pipeline/training/trainer.h).
#include <fmt/format.h>

#include "core/error.h"
#include "core/file_util.h"
#include "pipeline/training/trainer.h"

namespace crease {
namespace fs = std::filesystem;

fs::path TrainingReportDir(const fs::path& model, const fs::path& report) {
  const fs::path dir = report.empty() ? model.parent_path() / (model.stem().string() + "_report") : report;
  std::error_code ec;
  Require(!fs::is_directory(dir, ec) || fs::is_empty(dir, ec) || fs::is_regular_file(dir / "report.json", ec),
          fmt::format("{}: exists and is not a training report (no report.json); the report replaces its "
                      "folder, so choose another --report",
                      dir.string()));
  return dir;
}

std::string WriteTrainingReport(const fs::path& report_dir, const TrainingSummary& summary) {
  WriteFileAtomic(report_dir / "report.json", [&](std::ostream& o) { o << summary.ToJson(); });
  const std::string md = summary.ToMarkdown();
  WriteFileAtomic(report_dir / "report.md", [&](std::ostream& o) { o << md; });
  return md;
}

}  // namespace crease
