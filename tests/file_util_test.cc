#include "core/file_util.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include "tests/test_util.h"

#include "core/error.h"

namespace crease {
namespace {

using testing::TestDir;

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

}  // namespace
}  // namespace crease
