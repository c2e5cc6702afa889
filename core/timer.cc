#include "core/timer.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace crease {

void TimingReport::Add(const std::string& name, double seconds, int calls) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = index_.find(name);
  if (it == index_.end()) {
    index_.emplace(name, entries_.size());
    entries_.push_back({name, seconds, calls});
  } else {
    entries_[it->second].total_seconds += seconds;
    entries_[it->second].count += calls;
  }
}

std::vector<TimingReport::Entry> TimingReport::Entries() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return entries_;
}

double TimingReport::TotalSeconds() const {
  double t = 0.0;
  for (const auto& e : Entries()) t += e.total_seconds;
  return t;
}

std::string TimingReport::ToTable() const {
  const auto entries = Entries();
  const double total = TotalSeconds();
  size_t width = 5;
  for (const auto& e : entries) width = std::max(width, e.name.size());
  std::string s = fmt::format("{:<{}}  {:>7}  {:>11}  {:>10}  {:>6}\n", "stage", width, "calls",
                              "total ms", "mean ms", "share");
  for (const auto& e : entries) {
    s += fmt::format("{:<{}}  {:>7}  {:>11.2f}  {:>10.3f}  {:>5.1f}%\n", e.name, width, e.count,
                     1e3 * e.total_seconds, e.mean_ms(),
                     total > 0 ? 100.0 * e.total_seconds / total : 0.0);
  }
  return s;
}

std::string TimingReport::ToJson(int indent) const {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& e : Entries()) {
    j[e.name] = {{"total_s", e.total_seconds}, {"count", e.count}, {"mean_ms", e.mean_ms()}};
  }
  return j.dump(indent);
}

}  // namespace crease
