#include "daemon/failure_report.hpp"

#include <gtest/gtest.h>

namespace pumptherm::daemon {
namespace {

using Kind = FailureReport::Kind;
constexpr std::int64_t kS = 1'000'000;

TEST(FailureReport, FirstFailureAtOnceThenRemindersThenRecovery) {
  FailureReport r(600 * kS);
  EXPECT_EQ(r.Success(0).kind, Kind::kQuiet);  // successes alone say nothing
  auto a = r.Failure(10 * kS, "No space left on device");
  EXPECT_EQ(a.kind, Kind::kFirst);
  EXPECT_EQ(a.failures_since_report, 1U);
  EXPECT_TRUE(r.failing());
  // The same failure every second: quiet for ten minutes, then one reminder with the count.
  int lines = 0;
  FailureReport::Report last;
  for (std::int64_t t = 11; t <= 615; ++t) {
    const auto x = r.Failure(t * kS, "No space left on device");
    if (x.kind != Kind::kQuiet) {
      ++lines;
      last = x;
    }
  }
  EXPECT_EQ(lines, 1);
  EXPECT_EQ(last.kind, Kind::kReminder);
  EXPECT_EQ(last.failures_since_report, 600U);  // 11..610 s: the 600 since the first line
  EXPECT_EQ(last.run_failures, 601U);
  EXPECT_DOUBLE_EQ(last.run_s, 600.0);
  EXPECT_EQ(r.failures(), 606U);
  const auto ok = r.Success(620 * kS);
  EXPECT_EQ(ok.kind, Kind::kRecovered);
  EXPECT_EQ(ok.run_failures, 606U);
  EXPECT_EQ(ok.failures_since_report, 5U);
  EXPECT_DOUBLE_EQ(ok.run_s, 610.0);
  EXPECT_FALSE(r.failing());
  EXPECT_EQ(r.Success(621 * kS).kind, Kind::kQuiet);
  EXPECT_EQ(r.successes(), 3U);
  // A new run starts over with a first line.
  EXPECT_EQ(r.Failure(700 * kS, "No space left on device").kind, Kind::kFirst);
}

TEST(FailureReport, AChangedReasonIsReportedAtOnce) {
  FailureReport r(600 * kS);
  EXPECT_EQ(r.Failure(0, "Network is unreachable").kind, Kind::kFirst);
  EXPECT_EQ(r.Failure(1 * kS, "Network is unreachable").kind, Kind::kQuiet);
  const auto c = r.Failure(2 * kS, "Operation not permitted");
  EXPECT_EQ(c.kind, Kind::kChanged);
  EXPECT_EQ(c.failures_since_report, 2U);
  EXPECT_EQ(r.Failure(3 * kS, "Operation not permitted").kind, Kind::kQuiet);
}

}  // namespace
}  // namespace pumptherm::daemon
