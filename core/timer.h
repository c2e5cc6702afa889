// Timing: a TimingReport collects named stage times; a ScopedTimer adds the
// time of its scope to one entry. Thread-safe, so parallel stages may report.
//
//   TimingReport report;
//   { ScopedTimer t(&report, "uv_raster"); ... }
//   std::cout << report.ToTable();
#pragma once

#include <chrono>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace crease {

class TimingReport {
 public:
  struct Entry {
    std::string name;
    double total_seconds = 0.0;
    int count = 0;
    double mean_ms() const { return count ? 1e3 * total_seconds / count : 0.0; }
  };

  // Adds `seconds` spent over `calls` calls of stage `name`.
  void Add(const std::string& name, double seconds, int calls = 1);
  // Entries in order of first appearance.
  std::vector<Entry> Entries() const;
  double TotalSeconds() const;
  // Plain-text table: stage, calls, total ms, mean ms, share of total.
  std::string ToTable() const;
  // JSON object {"stage": {"total_s":…, "count":…, "mean_ms":…}, …}.
  std::string ToJson(int indent = 2) const;

 private:
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;
  std::map<std::string, size_t> index_;
};

class ScopedTimer {
 public:
  ScopedTimer(TimingReport* report, std::string name)
      : report_(report), name_(std::move(name)), start_(std::chrono::steady_clock::now()) {}
  ~ScopedTimer() { Stop(); }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;

  // Seconds since construction.
  double Elapsed() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  // Records now instead of at scope exit (idempotent).
  void Stop() {
    if (report_) report_->Add(name_, Elapsed());
    report_ = nullptr;
  }

 private:
  TimingReport* report_;
  std::string name_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace crease
