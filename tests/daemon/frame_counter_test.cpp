#include "daemon/frame_counter.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <sstream>

#include "daemon/gateway.hpp"
#include "daemon/offline.hpp"

namespace pumptherm::daemon {
namespace {

protocol::TimedFrame Frame(std::uint32_t id, bool extended = false) {
  protocol::TimedFrame f;
  f.frame.id = id;
  f.frame.extended = extended;
  f.frame.len = 8;
  return f;
}

TEST(FrameCounter, CountsPerInterfaceAndId) {
  FrameCounter g({});
  const auto a = g.Interface("can0");
  const auto b = g.Interface("can1");
  EXPECT_EQ(g.Interface("can0"), a);
  g.OnFrame(a, Frame(0x181));
  g.OnFrame(a, Frame(0x181));
  g.OnFrame(b, Frame(0x181));
  g.OnFrame(a, Frame(0x181, true));
  auto err = Frame(0x80);
  err.frame.error = true;
  g.OnFrame(a, err);
  EXPECT_EQ(g.total_rx(), 4U);
  EXPECT_EQ(g.counts().at({a, false, 0x181}), 2U);
  EXPECT_EQ(g.counts().at({b, false, 0x181}), 1U);
  EXPECT_EQ(g.counts().at({a, true, 0x181}), 1U);
  EXPECT_EQ(g.counters(a).rx_error_frames, 1U);
  EXPECT_EQ(g.CountTable(),
            "interface          can_id       frames\n"
            "can0                  181            2\n"
            "can0             00000181            1\n"
            "can1                  181            1\n");
}

TEST(FrameCounter, HeartbeatKeepsItsPeriodWithoutDrift) {
  GatewayConfig c;
  c.heartbeat_period_s = 0.1;
  c.heartbeat_id = 0x7F0;
  FrameCounter g(c);
  int beats = 0;
  // Ticks arrive late and irregularly (every 7 ms); beats still come 10 per second.
  for (std::int64_t t = 0; t <= 10'000'000; t += 7000) {
    if (auto f = g.HeartbeatDue(t)) {
      ++beats;
      EXPECT_EQ(f->id, 0x7F0U);
      EXPECT_EQ(f->len, 8);
    }
  }
  // The last tick is at 9.996 s: beats due at 0, 0.1, ..., 9.9 s, and no more.
  EXPECT_EQ(beats, 100);
}

TEST(FrameCounter, HeartbeatCarriesUptimeAndFrameCount) {
  GatewayConfig c;
  c.heartbeat_period_s = 1.0;
  FrameCounter g(c);
  ASSERT_TRUE(g.HeartbeatDue(5'000'000));
  const auto i = g.Interface("can0");
  for (int k = 0; k < 300; ++k) g.OnFrame(i, Frame(0x100));
  const auto f = g.HeartbeatDue(8'000'000);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->data[0], 3);  // uptime 3 s
  EXPECT_EQ(f->data[4] | (f->data[5] << 8), 300);
  EXPECT_FALSE(g.HeartbeatDue(8'500'000));
}

TEST(FrameCounter, DisabledHeartbeatNeverComes) {
  GatewayConfig c;
  c.heartbeat_period_s = 0.0;
  FrameCounter g(c);
  EXPECT_FALSE(g.HeartbeatDue(0));
  EXPECT_FALSE(g.HeartbeatDue(100'000'000));
}

// The status line (systemd STATUS=) counts what the fault injection test looks at: error
// frames, and with LCM configured the messages sent and those that failed.
TEST(Gateway, StatusLineCountsErrorFramesAndLcmFailures) {
  struct FailingSink : OutputSink {
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
    bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
      return false;
    }
  };
  DaemonConfig c;
  c.gateway.heartbeat_period_s = 0.0;
  Gateway quiet(c);
  EXPECT_EQ(quiet.StatusLine().find("lcm"), std::string::npos) << quiet.StatusLine();
  c.lcm.url = "memq://";
  Gateway g(c);
  const auto i = g.Interface("can0");
  auto err = Frame(0x8);
  err.frame.error = true;
  g.OnFrame(i, err);
  g.OnFrame(i, err);
  g.OnFrame(i, Frame(0x123));
  FailingSink sink;
  g.Advance(1'000'000, sink);  // the gateway's health message is due: it fails
  EXPECT_EQ(g.counters().lcm_failed, 1U);
  EXPECT_EQ(g.StatusLine(),
            "0 pumps, 0 warning, 0 trip; rx 1 frames, 1 IDs, 0 rx drops; tx 0 frames, 0 tx "
            "dropped; can0:up; "
            "1 unknown, 0 bad length, 2 error frames; lcm 0 sent, 1 failed");
}

TEST(Offline, CountsFramesAndSkipsMalformedLines) {
  std::istringstream log(
      "(1.000000) can0 181#0102\n"
      "garbage\n"
      "\n"
      "(1.010000) can0 181#0102\n"
      "(1.020000) can1 18FF5001#00\n"
      "(1.030000) can0 181#01020\n");
  Gateway g(DaemonConfig{});  // no pumps: frames are only counted
  const auto r = RunOffline(log, "t.log", g);
  EXPECT_EQ(r.lines, 6U);
  EXPECT_EQ(r.frames, 3U);
  EXPECT_EQ(r.bad_lines, 2U);
  EXPECT_EQ(g.counter().counts().at({g.Interface("can0"), false, 0x181}), 2U);
  EXPECT_EQ(g.counter().counts().at({g.Interface("can1"), true, 0x18FF5001}), 1U);
}

TEST(Offline, ReadsEveryCandumpFormatAndSkipsUntimedLines) {
  // One frame of 181 per format: -l/-L, -L -x, asc2log, screen -t a, screen -t a -x; then the
  // screen format without a timestamp (counted apart, the pipeline needs the time) and -t A.
  std::istringstream log(
      "(1.000000) can0 181#0102\n"
      "(1.010000) can0 181#0102 R\n"
      "(1.020000) can0 181#0102 T\r\n"
      " (1.030000)  can0  181   [2]  01 02\n"
      " (1.040000)  can0  RX - -  181   [2]  01 02\n"
      "  can0  181   [2]  01 02\n"
      " (2015-07-10 06:17:32.249713)  can0  181   [2]  01 02\n"
      "(1.050000) can0 181#0102");  // the last line has no newline
  Gateway g(DaemonConfig{});
  const auto r = RunOffline(log, "t.log", g);
  EXPECT_EQ(r.lines, 8U);
  EXPECT_EQ(r.frames, 6U);
  EXPECT_EQ(r.untimed_lines, 1U);
  EXPECT_EQ(r.bad_lines, 1U);
  EXPECT_EQ(g.counter().counts().at({g.Interface("can0"), false, 0x181}), 6U);
}

TEST(Offline, ReadsLinesAcrossTheReadersBlocks) {
  // More than one read block (1 MiB) of lines, one of them longer than a block (a bad line):
  // every line is seen whole.
  std::string text;
  const int n = 60000;
  for (int k = 0; k < n; ++k) {
    text += fmt::format("({}.{:06d}) can0 {:03X}#0102030405060708\n", 1 + k / 1000,
                        (k % 1000) * 1000, k % 0x7FF);
    if (k == n / 2) text += std::string(1 << 21, 'x') + "\n";
  }
  std::istringstream log(text);
  Gateway g(DaemonConfig{});
  const auto r = RunOffline(log, "t.log", g);
  EXPECT_EQ(r.lines, static_cast<std::uint64_t>(n) + 1);
  EXPECT_EQ(r.frames, static_cast<std::uint64_t>(n));
  EXPECT_EQ(r.bad_lines, 1U);
  EXPECT_EQ(g.counter().total_rx(), static_cast<std::uint64_t>(n));
}

}  // namespace
}  // namespace pumptherm::daemon

namespace {
pumptherm::protocol::CanFrame ErrorFrame(std::uint32_t cls, std::uint8_t crtl = 0) {
  pumptherm::protocol::CanFrame f;
  f.error = true;
  f.id = cls;
  f.len = 8;
  f.data[1] = crtl;
  return f;
}
}  // namespace

// linux/can/error.h: CAN_ERR_CRTL 0x4 with data[1] RX/TX warning 0x04/0x08, passive 0x10/0x20,
// active 0x40; CAN_ERR_BUSOFF 0x40; CAN_ERR_RESTARTED 0x100; CAN_ERR_PROT 0x8 (no state).
TEST(BusState, FollowsTheControllerThroughWarningPassiveBusOffAndRestart) {
  using pumptherm::daemon::BusState;
  using pumptherm::daemon::NextBusState;
  BusState s = BusState::kUnknown;
  s = NextBusState(s, ErrorFrame(0x8));  // a protocol error: the controller talks, state unsaid
  EXPECT_EQ(s, BusState::kErrorActive);
  s = NextBusState(s, ErrorFrame(0x4, 0x08));
  EXPECT_EQ(s, BusState::kErrorWarning);
  s = NextBusState(s, ErrorFrame(0x4, 0x20));
  EXPECT_EQ(s, BusState::kErrorPassive);
  s = NextBusState(s, ErrorFrame(0x8));
  EXPECT_EQ(s, BusState::kErrorPassive);  // protocol errors leave it
  s = NextBusState(s, ErrorFrame(0x40));
  EXPECT_EQ(s, BusState::kBusOff);
  s = NextBusState(s, ErrorFrame(0x100));
  EXPECT_EQ(s, BusState::kErrorActive);
  s = NextBusState(s, ErrorFrame(0x4, 0x10));
  s = NextBusState(s, ErrorFrame(0x4, 0x40));
  EXPECT_EQ(s, BusState::kErrorActive);
  pumptherm::protocol::CanFrame data;  // a data frame changes nothing
  data.id = 0x40;
  EXPECT_EQ(NextBusState(BusState::kBusOff, data), BusState::kBusOff);
}

TEST(BusState, CountedPerInterface) {
  pumptherm::daemon::FrameCounter g(pumptherm::daemon::GatewayConfig{});
  const std::size_t a = g.Interface("can0");
  const std::size_t b = g.Interface("can1");
  pumptherm::protocol::TimedFrame t;
  t.frame = ErrorFrame(0x40);
  g.OnFrame(a, t);
  EXPECT_EQ(g.counters(a).bus_state, pumptherm::daemon::BusState::kBusOff);
  EXPECT_EQ(g.counters(b).bus_state, pumptherm::daemon::BusState::kUnknown);
  EXPECT_EQ(g.counters(a).rx_error_frames, 1U);
}
