#include "core/timer.h"

#include <gtest/gtest.h>

#include <thread>

#include "core/progress.h"

namespace crease {
namespace {

TEST(Timer, ScopedTimersAccumulatePerStage) {
  TimingReport report;
  for (int i = 0; i < 3; ++i) {
    ScopedTimer t(&report, "a");
  }
  { ScopedTimer t(&report, "b"); }
  report.Add("a", 0.5);
  const auto e = report.Entries();
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].name, "a");
  EXPECT_EQ(e[0].count, 4);
  EXPECT_GE(e[0].total_seconds, 0.5);
  EXPECT_NE(report.ToTable().find("share"), std::string::npos);
  EXPECT_NE(report.ToJson().find("\"mean_ms\""), std::string::npos);
}

TEST(Timer, ThreadSafe) {
  TimingReport report;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 1000; ++i) report.Add("x", 0.001);
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(report.Entries()[0].count, 4000);
  EXPECT_NEAR(report.TotalSeconds(), 4.0, 1e-9);
}

TEST(Progress, QuietWhenNotATerminalAndCounts) {
  Progress p("work", 10, /*force_enabled=*/0);
  EXPECT_FALSE(p.enabled());
  for (int i = 0; i < 10; ++i) p.Advance();
  EXPECT_EQ(p.done(), 10);
  EXPECT_NE(p.Line().find("10/10"), std::string::npos) << p.Line();
  p.Finish();
}

}  // namespace
}  // namespace crease
