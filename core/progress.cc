#include "core/progress.h"

#include <unistd.h>

#include <cstdio>
#include <fmt/format.h>

namespace crease {

Progress::Progress(std::string label, int64_t total, int force_enabled)
    : label_(std::move(label)),
      total_(total),
      enabled_(force_enabled >= 0 ? force_enabled != 0 : ::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

Progress::~Progress() { Finish(); }

void Progress::Advance(int64_t n) {
  done_.fetch_add(n);
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  Draw(false);
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_) Draw(true);
}

std::string Progress::Line() const {
  const int64_t done = done_.load();
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double frac = total_ > 0 ? std::min(1.0, static_cast<double>(done) / total_) : 0.0;
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(frac * kWidth);
  const double rate = elapsed > 0 ? done / elapsed : 0.0;
  const double eta = rate > 0 && total_ > done ? (total_ - done) / rate : 0.0;
  return fmt::format("{} [{}{}] {}/{} {:.1f}/s eta {:.0f}s", label_, std::string(filled, '#'),
                     std::string(kWidth - filled, '.'), done, total_, rate, eta);
}

void Progress::Draw(bool final) {
  std::fprintf(stderr, "\r%s%s", Line().c_str(), final ? "\n" : "");
  std::fflush(stderr);
}

}  // namespace crease
