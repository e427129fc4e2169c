// The journal line writer: control characters in logged text cannot start a line of their own
// or forge a priority prefix.
#include "daemon/log.hpp"

#include <gtest/gtest.h>

namespace pumptherm::daemon {
namespace {

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

TEST(Log, ALineWithANewlineIsWrittenAsOneLine) {
  testing::internal::CaptureStderr();
  LogLine(LogLevel::kNotice, "clear from op\n<2>forged");
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(err, "pumpthermd: clear from op\\n<2>forged\n");
}

TEST(Log, FieldsAreNotWrittenOutsideTheJournal) {
  testing::internal::CaptureStderr();
  LogFields(LogLevel::kWarning, {{"PUMP", "pump3"}, {"LEVEL", "trip"}}, "pump {}: trip", "pump3");
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "pumpthermd: warning: pump pump3: trip\n");
}

}  // namespace
}  // namespace pumptherm::daemon
