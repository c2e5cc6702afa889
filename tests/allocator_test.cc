#include "core/allocator.h"

#include <gtest/gtest.h>

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace crease {
namespace {

// An 8 MB block (two 1024² float maps) is mmapped by glibc's default threshold
// (128 KB) and comes from the heap once KeepLargeBlocksInHeap has run.
TEST(Allocator, LargeBlocksComeFromTheHeap) {
#if defined(__GLIBC__)
  ASSERT_TRUE(KeepLargeBlocksInHeap());
  const size_t mmapped_before = mallinfo2().hblks;
  void* block = std::malloc(size_t{8} << 20);
  ASSERT_NE(block, nullptr);
  static_cast<volatile char*>(block)[0] = 1;
  EXPECT_EQ(mallinfo2().hblks, mmapped_before);
  std::free(block);
#else
  GTEST_SKIP() << "KeepLargeBlocksInHeap only acts on glibc";
#endif
}

}  // namespace
}  // namespace crease
