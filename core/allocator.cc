#include "core/allocator.h"

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace crease {

bool KeepLargeBlocksInHeap() {
#if defined(__GLIBC__)
  constexpr int kMaxMmapThreshold = 32 * 1024 * 1024;  // glibc's DEFAULT_MMAP_THRESHOLD_MAX on 64-bit
  constexpr int kTrimThreshold = 1024 * 1024 * 1024;
  // mallopt returns 1 on success; a fixed threshold also turns off glibc's
  // adaptive one.
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, kMaxMmapThreshold) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, kTrimThreshold) == 1;
  return mmap_ok && trim_ok;
#else
  return false;
#endif
}

}  // namespace crease
