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

// The screen format (candump without -l/-L), as candump.c prints it: " " [timestamp] " "
// "%*s" interface ["  RX - -" with -x] "  " and lib.c's sprint_long_canframe: the ID (3 digits,
// or 8; 11-bit IDs indented to 8 once an extended one was seen), "[8]" (CAN FD: "[%02d]"), two
// spaces, the bytes separated by spaces, or "remote request"; -a adds the ASCII column.
TEST(CandumpLog, ReadsTheScreenFormat) {
  auto p = ParseCandumpLine("  can0  123   [8]  11 22 33 44 55 66 77 88");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_FALSE(p.record.has_time);
  EXPECT_EQ(p.record.interface, "can0");
  EXPECT_EQ(p.record.frame.id, 0x123U);
  ASSERT_EQ(p.record.frame.len, 8);
  EXPECT_EQ(p.record.frame.data[0], 0x11);
  EXPECT_EQ(p.record.frame.data[7], 0x88);
  EXPECT_EQ(p.record.direction, 0);

  p = ParseCandumpLine(" (1436509052.249713)  vcan0  12345678   [2]  0A FF");  // -t a
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_TRUE(p.record.has_time);
  EXPECT_EQ(p.record.time_us, 1436509052249713);
  EXPECT_TRUE(p.record.frame.extended);
  EXPECT_EQ(p.record.frame.id, 0x12345678U);
  EXPECT_EQ(p.record.frame.data[1], 0xFF);

  p = ParseCandumpLine(" (000.010000)  can1       7FF   [0]  ");  // -t z, indented 11-bit ID
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_EQ(p.record.time_us, 10000);
  EXPECT_EQ(p.record.frame.id, 0x7FFU);
  EXPECT_EQ(p.record.frame.len, 0);

  p = ParseCandumpLine("  can0  123   [4]  remote request");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_TRUE(p.record.frame.remote);
  EXPECT_EQ(p.record.frame.len, 4);

  p = ParseCandumpLine("  can0  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB");  // CAN FD
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_TRUE(p.record.frame.fd);
  EXPECT_EQ(p.record.frame.len, 12);
  EXPECT_EQ(p.record.frame.data[11], 0xBB);

  p = ParseCandumpLine("  can0  123   [3]  41 42 43               'ABC'");  // -a
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_EQ(p.record.frame.len, 3);
  EXPECT_EQ(p.record.frame.data[2], 0x43);

  p = ParseCandumpLine("  can0  20000004   [8]  00 04 00 00 00 00 00 00   ERRORFRAME");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_TRUE(p.record.frame.error);
  EXPECT_EQ(p.record.frame.id, 0x4U);
  EXPECT_EQ(p.record.frame.data[1], 0x04);
}

// candump -x: "  RX - -" / "  TX B E" after the interface (direction; CAN FD BRS and ESI) on
// the screen, " R" / " T" after the frame in the log format.
TEST(CandumpLog, ReadsTheDirectionAndFlagsOfExtraInfo) {
  auto p = ParseCandumpLine(" (1436509052.249713)  can0  RX - -  123   [2]  11 22");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_EQ(p.record.direction, 'R');
  EXPECT_EQ(p.record.frame.len, 2);
  EXPECT_FALSE(p.record.frame.fd);

  p = ParseCandumpLine("  can0  TX B E  123  [08]  01 02 03 04 05 06 07 08");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_EQ(p.record.direction, 'T');
  EXPECT_TRUE(p.record.frame.fd);
  EXPECT_EQ(p.record.frame.fd_flags, 3);
  EXPECT_EQ(p.record.frame.len, 8);

  p = ParseCandumpLine("(1436509052.249713) can0 123#1122 T");
  ASSERT_TRUE(p.ok) << p.error << " at " << p.column;
  EXPECT_EQ(p.record.direction, 'T');
  EXPECT_EQ(p.record.frame.len, 2);
  EXPECT_EQ(p.record.frame.data[1], 0x22);
}

// What can-utils 2020.11's asc2log wrote here for `log2asc -I in.log -O out.asc can0 can1`
// of a log holding one frame of each kind, read back with `asc2log -I out.asc`: the log format
// with " R" (the ASC direction "Rx"); the error frame has none.
TEST(CandumpLog, ReadsAsc2logOutput) {
  const char* lines[] = {
      "(1795643917.565645) can0 044#2A366C2BBA R",
      "(1795643917.765779) can1 1F334455#R R",
      "(1795643917.965913) can0 123##1112233 R",
      "(1795643918.015932) can0 7FF# R",
      "(1795643918.115932) can0 20000080#0000000000000000",
      "(1795643918.215932) can0 123#R3 R",
  };
  for (const char* line : lines) {
    const auto p = ParseCandumpLine(line);
    ASSERT_TRUE(p.ok) << line << ": " << p.error << " at " << p.column;
  }
  auto p = ParseCandumpLine(lines[1]);
  EXPECT_TRUE(p.record.frame.remote);
  EXPECT_TRUE(p.record.frame.extended);
  EXPECT_EQ(p.record.direction, 'R');
  p = ParseCandumpLine(lines[2]);
  EXPECT_TRUE(p.record.frame.fd);
  EXPECT_EQ(p.record.frame.len, 3);
  p = ParseCandumpLine(lines[3]);
  EXPECT_EQ(p.record.frame.len, 0);
  EXPECT_EQ(p.record.direction, 'R');
  p = ParseCandumpLine(lines[4]);
  EXPECT_TRUE(p.record.frame.error);
  EXPECT_EQ(p.record.direction, 0);
  p = ParseCandumpLine(lines[5]);
  EXPECT_TRUE(p.record.frame.remote);
  EXPECT_EQ(p.record.frame.len, 3);
}

TEST(CandumpLog, ScreenFormatErrorsSayWhatIsWrong) {
  struct Case {
    const char* line;
    std::size_t column;
    const char* says;
  };
  const Case cases[] = {
      {" (2015-07-10 06:17:32.249713)  can0  123   [1]  11", 7, "date stamp"},  // -t A
      {"  can0  123   [3]  11 22", 25, "fewer payload bytes"},
      {"  can0  123   [1]  11 22", 23, "more payload bytes"},
      {"  can0  123   [9]  11", 17, "out of range"},
      {"  can0  123  [13]  11", 17, "out of range"},  // no FD length
      {"  can0  123   8  11", 15, "expected '['"},
      {"  can0  123   [2]  1 22", 20, "two hex digits"},
      {"  can0  RX x -  123   [0]", 12, "candump -x flags"},
      {"this is not a candump line", 1, "not a candump line"},
      {"  can0", 3, "not a candump line"},
  };
  for (const auto& c : cases) {
    const auto p = ParseCandumpLine(c.line);
    EXPECT_FALSE(p.ok) << c.line;
    EXPECT_EQ(p.column, c.column) << c.line << ": " << p.error;
    EXPECT_NE(std::string_view(p.error).find(c.says), std::string_view::npos)
        << c.line << ": " << p.error;
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
  EXPECT_EQ(FormatCandumpLine(1436509052249713, "vcan0",
                              ParseCandumpLine("(1.0) x 044#2A366C2BBA").record.frame),
            "(1436509052.249713) vcan0 044#2A366C2BBA");
  EXPECT_EQ(FormatCandumpLine(4000000, "can0", ParseCandumpLine("(4.0) can0 7FF#R3").record.frame),
            "(0000000004.000000) can0 7FF#R3");
  EXPECT_EQ(FormatCandumpLine(4000000, "can0", ParseCandumpLine("(4.0) can0 7FF#R").record.frame),
            "(0000000004.000000) can0 7FF#R");
}

// The formatter before it was made allocation-free (one fmt::format per field), kept as the
// oracle: the plant's "same seed, same bytes" and every golden log depend on identical output.
std::string ReferenceFormat(std::int64_t time_us, std::string_view interface,
                            const CanFrame& frame) {
  std::string out =
      fmt::format("({:010d}.{:06d}) {} ", time_us / 1000000, time_us % 1000000, interface);
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

namespace pumptherm::protocol {
namespace {

// What a recording's stamps count, from its first stamps: Unix time from 2001 on; -t z never
// goes back; -t d goes up and down with the gaps between frames, or stays put when they are
// even.
TEST(CandumpTimeBaseTest, StampsAreClassified) {
  const std::int64_t unix_us[] = {1700000000000000, 1700000000010000, 1700000000020000};
  EXPECT_EQ(ClassifyCandumpStamps(unix_us, 3), CandumpTimeBase::kAbsolute);
  // -t z: 10 ms frames with a 100 ms one among them.
  const std::int64_t z[] = {0, 10000, 10100, 20000, 20100, 30000, 100000, 100100};
  EXPECT_EQ(ClassifyCandumpStamps(z, 8), CandumpTimeBase::kSinceFirst);
  // -t d of the same frames: the gaps.
  const std::int64_t d[] = {0, 10000, 100, 9900, 100, 9900, 70000, 100};
  EXPECT_EQ(ClassifyCandumpStamps(d, 8), CandumpTimeBase::kSincePrevious);
  // -t d of evenly spaced frames: the same gap every time.
  const std::int64_t even[] = {0, 10000, 10000, 10000, 10000};
  EXPECT_EQ(ClassifyCandumpStamps(even, 5), CandumpTimeBase::kSincePrevious);
  // Too few to tell: both read the same.
  EXPECT_EQ(ClassifyCandumpStamps(d, 2), CandumpTimeBase::kSinceFirst);
  // A small (1970) clock with -l's stamps still runs forward: read as it is.
  const std::int64_t boot[] = {12000000, 12010000, 12020000, 12030000};
  EXPECT_EQ(ClassifyCandumpStamps(boot, 4), CandumpTimeBase::kSinceFirst);

  CandumpTimeline timeline(CandumpTimeBase::kSincePrevious);
  std::int64_t t = 0;
  for (std::int64_t s : d) t = timeline.TimeUs(s);
  EXPECT_EQ(t, 100100);
  CandumpTimeline same(CandumpTimeBase::kSinceFirst);
  EXPECT_EQ(same.TimeUs(42), 42);
}

}  // namespace
}  // namespace pumptherm::protocol
