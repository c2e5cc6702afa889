#include "core/file_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

#include "core/error.h"

namespace crease {

FileLock::FileLock(const std::filesystem::path& file) {
  std::filesystem::create_directories(file.parent_path());
  fd_ = open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  Require(fd_ >= 0, fmt::format("{}: cannot open the lock file: {}", file.string(), std::strerror(errno)));
  while (flock(fd_, LOCK_EX) != 0) {
    if (errno != EINTR) {
      const int e = errno;
      close(fd_);
      throw Error(fmt::format("{}: cannot lock: {}", file.string(), std::strerror(e)));
    }
  }
}

FileLock::~FileLock() { close(fd_); }

}  // namespace crease
