// Progress for long loops. On a terminal (stderr is a TTY) it draws a bar with
// the count, rate and remaining time, redrawn at most ~10 times per second; when
// stderr is not a terminal (CI, pipes, log files) it prints nothing at all.
// Thread-safe: Advance() may be called from TBB workers.
//
//   Progress progress("rendering", num_frames);
//   for (...) { ...; progress.Advance(); }
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace crease {

class Progress {
 public:
  // `force_enabled` overrides the TTY detection (for tests).
  Progress(std::string label, int64_t total, int force_enabled = -1);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void Advance(int64_t n = 1);
  // Completes the bar (prints the final line on a terminal).
  void Finish();

  int64_t done() const { return done_.load(); }
  bool enabled() const { return enabled_; }
  // The line that would be drawn now (without the carriage return).
  std::string Line() const;

 private:
  void Draw(bool final);
  std::string label_;
  int64_t total_;
  bool enabled_;
  bool finished_ = false;
  std::atomic<int64_t> done_{0};
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

}  // namespace crease
