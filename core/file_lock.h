// An exclusive advisory lock of a file (flock), held for the lifetime of the
// object. The kernel drops it when the process ends however it ends, so a killed
// holder never leaves a stale lock. flock locks belong to an open file: two
// FileLocks of one file conflict even within one process. On a network file
// system the lock is only as good as its flock support (NFSv4: yes).
#pragma once

#include <filesystem>

namespace crease {

class FileLock {
 public:
  // Creates `file` (and its folder) if missing and blocks until the lock is held.
  // Throws Error naming the file when it cannot be opened or locked.
  explicit FileLock(const std::filesystem::path& file);
  ~FileLock();
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace crease
