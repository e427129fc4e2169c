#include "protocol/candump_log.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <random>

namespace pumptherm::protocol {
namespace {

TEST(CandumpLog, ParsesClassicFrame) {
  const auto p = ParseCandumpLine("(1436509052.249713) vcan0 044#2A366C2BBA");
  ASSERT_TRUE(p.ok) << p.error;
  EXPECT_EQ(p.record.time_us, 1436509052249713);
  EXPECT_EQ(p.record.interface, "vcan0");
  EXPECT_EQ(p.record.frame.id, 0x044U);
  EXPECT_FALSE(p.record.frame.extended);
  ASSERT_EQ(p.record.frame.len, 5);
  EXPECT_EQ(p.record.frame.data[0], 0x2A);
  EXPECT_EQ(p.record.frame.data[4], 0xBA);
}

TEST(CandumpLog, ParsesExtendedRemoteFdAndErrorFrames) {
  auto p = ParseCandumpLine("(0.000001) can1 1F334455#R");
  ASSERT_TRUE(p.ok) << p.error;
  EXPECT_TRUE(p.record.frame.extended);
  EXPECT_TRUE(p.record.frame.remote);
  EXPECT_EQ(p.record.frame.id, 0x1F334455U);

  p = ParseCandumpLine("(1.5) can0 123##1" + std::string(24, 'A'));
  ASSERT_TRUE(p.ok) << p.error;
  EXPECT_TRUE(p.record.frame.fd);
  EXPECT_EQ(p.record.frame.fd_flags, 1);
  EXPECT_EQ(p.record.frame.len, 12);
  EXPECT_EQ(p.record.time_us, 1500000);

  p = ParseCandumpLine("(1.000000) can0 20000080#0000000000000000");
  ASSERT_TRUE(p.ok) << p.error;
  EXPECT_TRUE(p.record.frame.error);
  EXPECT_EQ(p.record.frame.id, 0x80U);
}

TEST(CandumpLog, SkipsBlankAndCommentLines) {
  EXPECT_TRUE(ParseCandumpLine("").skip);
  EXPECT_TRUE(ParseCandumpLine("   ").skip);
  EXPECT_TRUE(ParseCandumpLine("# recorded on the bench").skip);
}

TEST(CandumpLog, ErrorsNameTheColumn) {
  struct Case {
    const char* line;
    std::size_t column;
  };
  const Case cases[] = {
      {"1436509052.249713) vcan0 044#00", 1},      // no '('
      {"(1436509052.249713 vcan0 044#00", 19},     // no ')'
      {"(1.0) vcan0 04G#00", 15},                  // bad hex in the id
      {"(1.0) vcan0 0444#00", 13},                 // 4-digit id
      {"(1.0) vcan0 800#00", 13},                  // 11-bit id out of range
      {"(1.0) vcan0 044#0", 18},                   // half a byte
      {"(1.0) vcan0 044#000102030405060708", 33},  // 9 bytes classic
      {"(1.0) vcan0 044", 16},                     // no '#'
      {"(1.0) vcan0 40000123#00", 13},             // bit 30 (the RTR flag) set: above 29 bits
      {"(1.0) vcan0 FFFFFFFF#00", 13},             // above 29 bits, not an error frame
      {"(1.0) vcan0 123##1001122", 25},            // FD length 3 ok, 3 bytes + flags
  };
  for (const auto& c : cases) {
    const auto p = ParseCandumpLine(c.line);
    if (std::string_view(c.line) == "(1.0) vcan0 123##1001122") {
      EXPECT_TRUE(p.ok) << c.line;
      continue;
    }
    EXPECT_FALSE(p.ok) << c.line;
    EXPECT_EQ(p.column, c.column) << c.line << ": " << p.error;
    EXPECT_STRNE(p.error, "") << c.line;
  }
}

TEST(CandumpLog, FormatRoundTrips) {
  const char* lines[] = {
      "(1436509052.249713) vcan0 044#2A366C2BBA",
      "(0000000001.000000) can0 1F334455#R",
      "(0000000002.000000) can0 123##1AABBCCDDEEFF001122334455",
      "(0000000003.000000) can0 7FF#",
      // Found by candump_log_fuzz: a remote frame's length digit was dropped by the formatter.
      "(0000000004.000000) can0 7FF#R3",
      "(0000000005.000000) can0 12345678#R8",
  };
  for (const char* line : lines) {
    const auto p = ParseCandumpLine(line);
    ASSERT_TRUE(p.ok) << line << ": " << p.error;
    const std::string out = FormatCandumpLine(p.record.time_us, p.record.interface, p.record.frame);
    const auto q = ParseCandumpLine(out);
    ASSERT_TRUE(q.ok) << out;
    EXPECT_EQ(q.record.time_us, p.record.time_us);
    EXPECT_EQ(q.record.frame.id, p.record.frame.id);
    EXPECT_EQ(q.record.frame.len, p.record.frame.len);
    EXPECT_EQ(q.record.frame.data, p.record.frame.data);
    EXPECT_EQ(q.record.frame.fd, p.record.frame.fd);
    EXPECT_EQ(q.record.frame.remote, p.record.frame.remote);
  }
  EXPECT_EQ(FormatCandumpLine(1436509052249713, "vcan0", ParseCandumpLine("(1.0) x 044#2A366C2BBA").record.frame),
            "(1436509052.249713) vcan0 044#2A366C2BBA");
  EXPECT_EQ(FormatCandumpLine(4000000, "can0", ParseCandumpLine("(4.0) can0 7FF#R3").record.frame),
            "(0000000004.000000) can0 7FF#R3");
  EXPECT_EQ(FormatCandumpLine(4000000, "can0", ParseCandumpLine("(4.0) can0 7FF#R").record.frame),
            "(0000000004.000000) can0 7FF#R");
}

// The formatter before it was made allocation-free (one fmt::format per field), kept as the
// oracle: the plant's "same seed, same bytes" and every golden log depend on identical output.
std::string ReferenceFormat(std::int64_t time_us, std::string_view interface, const CanFrame& frame) {
  std::string out = fmt::format("({:010d}.{:06d}) {} ", time_us / 1000000, time_us % 1000000, interface);
  if (frame.error) {
    out += fmt::format("{:08X}#", frame.id | 0x20000000U);
  } else if (frame.extended) {
    out += fmt::format("{:08X}#", frame.id);
  } else {
    out += fmt::format("{:03X}#", frame.id);
  }
  if (frame.remote) {
    out += 'R';
    if (frame.len > 0 && frame.len <= 8) out += static_cast<char>('0' + frame.len);
    return out;
  }
  if (frame.fd) out += fmt::format("#{:X}", frame.fd_flags & 0xF);
  for (std::size_t k = 0; k < frame.len; ++k) out += fmt::format("{:02X}", frame.data[k]);
  return out;
}

TEST(CandumpLog, FormatEqualsTheReferenceFormatter) {
  std::mt19937_64 rng(7);
  std::string appended = "prefix ";
  std::string expected = "prefix ";
  for (int i = 0; i < 20000; ++i) {
    CanFrame f;
    const std::uint64_t r = rng();
    f.extended = (r & 1) != 0;
    f.error = (r & 2) != 0 && (r & 4) != 0;
    f.remote = (r & 8) != 0 && (r & 16) != 0;
    f.fd = !f.remote && (r & 32) != 0;
    f.fd_flags = static_cast<std::uint8_t>((r >> 8) & 0xFF);
    f.id = static_cast<std::uint32_t>(rng()) & (f.extended || f.error ? 0x1FFFFFFFU : 0x7FFU);
    f.len = static_cast<std::uint8_t>((r >> 16) % (f.fd ? 65 : 9));
    for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
    std::int64_t t = static_cast<std::int64_t>(rng() >> 12);  // up to 4.4e15 us
    if (i % 97 == 0) t = -t / 1000;
    if (i % 89 == 0) t = 0;
    const std::string iface = i % 3 == 0 ? "vcan0" : (i % 3 == 1 ? "can1" : "a-very-long-if");
    ASSERT_EQ(FormatCandumpLine(t, iface, f), ReferenceFormat(t, iface, f)) << "frame " << i;
    AppendCandumpLine(appended, t, iface, f);
    appended += '\n';
    expected += ReferenceFormat(t, iface, f) + '\n';
  }
  EXPECT_EQ(appended, expected);
}

}  // namespace
}  // namespace pumptherm::protocol
