#include "core/file_util.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tests/test_util.h"

#include "core/error.h"

namespace crease {
namespace {

using testing::TestDir;
using testing::WriteText;

namespace fs = std::filesystem;

// Issue 19: reading /dev/zero allocated 4.3 GB and decoding it as an image never
// returned; a FIFO without a writer blocks forever. Both are refused up front.
TEST(FileUtil, DevicesAndFifosAreRefused) {
  EXPECT_ERROR_HAS(ReadFileToString("/dev/zero"), "/dev/zero: is not a regular file");
  const fs::path fifo = TestDir() / "pipe.ply";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_ERROR_HAS(RequireReadableFile(fifo), fifo.string() + ": is not a regular file");
  EXPECT_ERROR_HAS(RequireReadableFile(fifo.parent_path()), "is a folder");
  EXPECT_ERROR_HAS(RequireReadableFile(fifo.parent_path() / "none"), "file does not exist");
}

// Issue 19: killed `synth sequence` and `capture` runs left ".NAME.tmp-PID/" folders
// that nothing removed. The next write of NAME removes those of processes that are
// gone on this host, and keeps a live process's and another host's.
TEST(FileUtil, StaleTemporaryFoldersOfDeadProcessesAreRemoved) {
  const std::filesystem::path dir = crease::testing::TestDir();
  char host[256] = {0};
  ASSERT_EQ(::gethostname(host, sizeof(host) - 1), 0);
  const auto tmp = [&](const std::string& owner) { return dir / (".seq.tmp-" + owner); };
  const std::string dead = std::string(host) + "-999999999";  // above any pid_max
  const std::string live = std::string(host) + "-" + std::to_string(::getppid());
  for (const auto& owner : {dead, live, std::string("elsewhere-999999999")}) {
    std::filesystem::create_directories(tmp(owner) / "frames");
  }
  std::filesystem::create_directories(dir / ".other.tmp-" / "x");
  EXPECT_EQ(RemoveStaleTemporaries(dir / "seq"), 1);
  EXPECT_FALSE(std::filesystem::exists(tmp(dead)));
  EXPECT_TRUE(std::filesystem::exists(tmp(live)));
  EXPECT_TRUE(std::filesystem::exists(tmp("elsewhere-999999999")));
  std::filesystem::create_directories(tmp(dead));
  WriteFolderAtomic(dir / "seq", false, [](const std::filesystem::path& d) { WriteText(d / "a.txt", "a"); });
  EXPECT_FALSE(std::filesystem::exists(tmp(dead)));
  EXPECT_TRUE(std::filesystem::is_regular_file(dir / "seq" / "a.txt"));
}

// Issue 19: `eval` failing on eval_frames.csv left a new eval.json beside the old
// table. A group of files is written whole or not at all.
TEST(FileUtil, FileGroupsAreWrittenWholeOrNotAtAll) {
  const std::filesystem::path dir = crease::testing::TestDir();
  auto text = [](const std::string& t) { return [t](const std::filesystem::path& p) { WriteText(p, t); }; };
  WriteText(dir / "eval.json", "old");
  const auto fails = [](const std::filesystem::path&) { throw Error("disk full"); };
  EXPECT_THROW(WriteFilesAtomic({{dir / "eval_frames.csv", text("new")}, {dir / "x.md", fails},
                                 {dir / "eval.json", text("new")}}),
               Error);
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  EXPECT_EQ(names, std::vector<std::string>{"eval.json"}) << "a file of the failed group or a temporary is left";
  WriteFilesAtomic({{dir / "eval_frames.csv", text("new")}, {dir / "eval.json", text("new")}});
  EXPECT_EQ(ReadFileToString(dir / "eval.json"), "new");
  EXPECT_EQ(ReadFileToString(dir / "eval_frames.csv"), "new");
}

}  // namespace
}  // namespace crease
