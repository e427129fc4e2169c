// The journal line writer: control characters in logged text cannot start a line of their own
// or forge a priority prefix.
#include "daemon/log.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <ctime>

#include "daemon/operator_text.hpp"

namespace pumptherm::daemon {
namespace {

/// 2026-01-01 00:04:01.250 UTC, us since the Unix epoch (date -d '2026-01-01 00:04:01Z' +%s).
constexpr std::int64_t kT_us = 1767225841'250'000;

/// Runs the test in UTC, stamped with kT_us (the offline pipeline's way).
class LogAt : public testing::Test {
 protected:
  void SetUp() override {
    setenv("TZ", "UTC", 1);
    tzset();
    SetLogTime(kT_us);
  }
};

TEST(Log, ControlCharactersAreEscaped) {
  EXPECT_EQ(EscapeControl("plain text, 25 degC"), "plain text, 25 degC");
  EXPECT_EQ(EscapeControl("a\nb"), "a\\nb");
  EXPECT_EQ(EscapeControl("x\r\t\x01\x7f"), "x\\r\\t\\x01\\x7f");
  // A forged journal line: a newline then a priority prefix stays on the one line.
  EXPECT_EQ(EscapeControl("op\n<5>pumpthermd: trip cleared"), "op\\n<5>pumpthermd: trip cleared");
  // Backslashes are doubled, so an escape in the text cannot be told for an escaped character.
  EXPECT_EQ(EscapeControl("a\\nb"), "a\\\\nb");
  // Bytes above 0x7f (UTF-8) pass unchanged.
  EXPECT_EQ(EscapeControl("25 \xc2\xb0"
                          "C"),
            "25 \xc2\xb0"
            "C");
}

TEST_F(LogAt, ALineWithANewlineIsWrittenAsOneLine) {
  testing::internal::CaptureStderr();
  LogLine(LogLevel::kNotice, "clear from op\n<2>forged");
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(err, "2026-01-01 00:04:01.250 UTC pumpthermd: clear from op\\n<2>forged\n");
}

TEST_F(LogAt, FieldsAreNotWrittenOutsideTheJournal) {
  testing::internal::CaptureStderr();
  LogFields(LogLevel::kWarning, {{"PUMP", "pump3"}, {"LEVEL", "trip"}}, "{}: trip", "pump3");
  EXPECT_EQ(testing::internal::GetCapturedStderr(),
            "2026-01-01 00:04:01.250 UTC pumpthermd: warning: pump3: trip\n");
}

TEST_F(LogAt, TimesAreLocalWithTheZone) {
  EXPECT_EQ(LocalTimeText(kT_us), "2026-01-01 00:04:01 UTC");
  EXPECT_EQ(LocalTimeText(kT_us, true), "2026-01-01 00:04:01.250 UTC");
  setenv("TZ", "CET-1CEST,M3.5.0,M10.5.0/3", 1);  // POSIX rule: no zone database needed
  tzset();
  EXPECT_EQ(LocalTimeText(kT_us), "2026-01-01 01:04:01 CET");
  EXPECT_EQ(LocalTimeText(kT_us + 181LL * 86'400'000'000), "2026-07-01 02:04:01 CEST");
  setenv("TZ", "UTC", 1);
  tzset();
}

}  // namespace
}  // namespace pumptherm::daemon
