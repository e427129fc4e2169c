// A second sender on the bus (docs/threat-model.md, "CAN"): frames of the gateway's own IDs it
// did not send, a pump's message faster than its cycle, a rolling counter that repeats or runs
// back are counted, raised as the pump's second-sender warning and named in the journal once;
// lost frames and a clean bus raise nothing.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "daemon/can_plausibility.hpp"
#include "daemon/config.hpp"
#include "daemon/gateway.hpp"

namespace pumptherm::daemon {
namespace {

constexpr std::int64_t kT0 = 1'700'000'000'000'000;

TEST(RateCheck, CountsOverWindowsOfTwentyCycles) {
  RateCheck r(0.1);  // 10 Hz: windows of 2 s, at most 1.5 x 20 + 2 = 32 frames
  bool raised = false;
  for (int k = 0; k < 100; ++k) raised = raised || r.OnFrame(kT0 + k * 100'000);
  EXPECT_FALSE(raised);
  EXPECT_NEAR(r.last_rate_Hz(), 10.0, 0.6);
  // Jitter and bursts (frames queued and read together) do not matter: only the count does.
  RateCheck bursty(0.1);
  for (int k = 0; k < 100; ++k) raised = raised || bursty.OnFrame(kT0 + (k / 5) * 500'000);
  EXPECT_FALSE(raised);
  // A forger adding one frame per real one: caught at the end of the first window.
  RateCheck doubled(0.1);
  int first = -1;
  for (int k = 0; k < 100 && first < 0; ++k) {
    if (doubled.OnFrame(kT0 + k * 50'000)) first = k;
  }
  EXPECT_EQ(first, 80) << "two windows (4 s) of frames at 20 Hz";
  EXPECT_NEAR(doubled.last_rate_Hz(), 20.0, 0.6);
  // A sender that stalled 3 s and caught up at once (canplayer behind on a loaded machine): one
  // window holds what the one before it lacked; never evidence.
  RateCheck caught_up(0.1);
  for (int k = 0; k < 200; ++k) {
    const std::int64_t due = kT0 + k * 100'000;
    const std::int64_t stall_end = kT0 + 8'000'000;
    const std::int64_t sent = due > kT0 + 5'000'000 && due < stall_end ? stall_end : due;
    EXPECT_FALSE(caught_up.OnFrame(sent)) << k;
  }
  RateCheck off(0.0);  // no cycle time: not checked
  for (int k = 0; k < 1000; ++k) EXPECT_FALSE(off.OnFrame(kT0 + k));
}

TEST(CounterCheck, LostFramesSkipForwardASecondSenderRepeatsOrRunsBack) {
  CounterCheck lossy(16, 0.01);
  bool raised = false;
  for (int k = 0; k < 300; ++k) {
    if (k % 3 == 2 || k % 7 == 4) continue;  // frames lost: the counter skips forward
    raised = raised || lossy.OnCounter(kT0 + k * 10'000, k % 16);
  }
  EXPECT_FALSE(raised);
  EXPECT_EQ(lossy.bad_steps(), 0U);
  // One double reception (a bus error in the last bit): one bad step, no evidence yet.
  CounterCheck once(16, 0.01);
  for (int k = 0; k < 50; ++k) raised = raised || once.OnCounter(kT0 + k * 10'000, k % 16);
  raised = raised || once.OnCounter(kT0 + 500'000, 49 % 16);
  EXPECT_FALSE(raised);
  EXPECT_EQ(once.bad_steps(), 1U);
  // A forger who sends the next value ahead of the drive: the drive's frame then repeats it.
  CounterCheck forged(16, 0.01);
  int first = -1;
  for (int k = 0; k < 100 && first < 0; ++k) {
    const std::int64_t t = kT0 + k * 10'000;
    if (forged.OnCounter(t, k % 16)) first = k;
    if (k >= 50 && forged.OnCounter(t + 5'000, (k + 1) % 16)) first = k;
  }
  EXPECT_EQ(first, 53) << "the third repeat (k = 51, 52, 53)";
  // Frames further apart than 1.5 cycles are not compared: after lost frames the counter may
  // have wrapped (the alarm matrix's link losing 99.5 % of the frames).
  CounterCheck silent(16, 0.01);
  EXPECT_FALSE(silent.OnCounter(kT0, 3));
  EXPECT_FALSE(silent.OnCounter(kT0 + 5'000'000, 3));
  EXPECT_FALSE(silent.OnCounter(kT0 + 5'020'000, 1));
  EXPECT_EQ(silent.bad_steps(), 0U);
  CounterCheck unchecked;  // no cycle: not checked
  for (int k = 0; k < 10; ++k) EXPECT_FALSE(unchecked.OnCounter(kT0 + k * 1'000, 0));
}

/// A gateway with pumps tmp1 (node 1) and tmp2 (node 2) on can0, fed frames of the shipped DBC.
class SecondSender : public ::testing::Test, public OutputSink {
 protected:
  SecondSender()
      : g_(ParseConfig("[gateway]\nheartbeat_id = 0x7F0\n[alarms]\nhold_s = 2\n[[can]]\n"
                       "interface = \"can0\"\n[[pump]]\nname = \"tmp1\"\nnode_id = 1\n"
                       "[[pump]]\nname = \"tmp2\"\nnode_id = 2\n",
                       std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml")),
        iface_(g_.Interface("can0")) {}
  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
  bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
    return true;
  }

  void Frame(std::int64_t t_us, std::uint32_t id, std::uint64_t bits) {
    protocol::TimedFrame tf;
    tf.time_us = t_us;
    tf.frame.id = id;
    tf.frame.len = 8;
    for (int i = 0; i < 8; ++i)
      tf.frame.data[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(bits >> (8 * i));
    g_.OnFrame(iface_, tf);
  }
  /// PUMP_STATUS of `node`: 800 rpm, steady, frame at `frame_degC`, ambient 25 degC.
  void Status(std::int64_t t_us, std::uint32_t node, double frame_degC, unsigned counter) {
    const auto raw_frame = static_cast<std::uint64_t>((frame_degC + 50.0) / 0.1 + 0.5);
    Frame(t_us, 0x180 + node,
          400ULL | (2ULL << 16) | (raw_frame << 19) | (750ULL << 31) |
              (static_cast<std::uint64_t>(counter % 16) << 56));
  }
  /// PUMP_FAST_I of `node` (2 A, 80 rad/s) with rolling counter `counter`.
  void FastI(std::int64_t t_us, std::uint32_t node, unsigned counter) {
    Frame(t_us, 0x100 + node,
          400ULL | (400ULL << 16) | (8000ULL << 32) |
              (static_cast<std::uint64_t>(counter % 16) << 56));
  }
  /// Seconds of a clean bus from `start_us`, 100 Hz fast and 10 Hz status frames of both pumps.
  std::int64_t Clean(std::int64_t start_us, double seconds, unsigned* counter) {
    const int steps = static_cast<int>(seconds * 100);
    for (int k = 0; k < steps; ++k) {
      const std::int64_t t = start_us + k * 10'000;
      for (std::uint32_t node : {1U, 2U}) {
        FastI(t, node, *counter);
        if (k % 10 == 0) Status(t + 1'000, node, 30.0, *counter);
      }
      ++*counter;
      if (k % 10 == 0) g_.Advance(t + 2'000, *this);
    }
    return start_us + steps * 10'000;
  }
  bool Warned(std::size_t p) const {
    return g_.pumps()[p]->snapshot().alarm.active_reasons &
           (1U << static_cast<unsigned>(estimators::AlarmReason::kSecondSender));
  }

  Gateway g_;
  std::size_t iface_;
};

TEST_F(SecondSender, ACleanBusRaisesNothing) {
  unsigned counter = 0;
  Clean(kT0, 20.0, &counter);
  EXPECT_EQ(g_.counters().rx_second_sender, 0U);
  EXPECT_FALSE(Warned(0));
  EXPECT_FALSE(Warned(1));
}

TEST_F(SecondSender, TheGatewaysOwnIdsFromElsewhereAreNamedOnce) {
  unsigned counter = 0;
  std::int64_t t = Clean(kT0, 5.0, &counter);
  testing::internal::CaptureStderr();
  Frame(t, 0x201, 0);  // GW_ALARM of tmp1, "normal": sent by someone else
  Frame(t + 100'000, 0x201, 0);
  t = Clean(t + 200'000, 2.0, &counter);
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(g_.counters().rx_second_sender, 2U);
  EXPECT_EQ(g_.counter().counters(iface_).rx_second_sender, 2U);
  EXPECT_EQ(g_.counters().rx_unknown_id, 0U);
  EXPECT_TRUE(Warned(0));
  EXPECT_FALSE(Warned(1));
  std::size_t lines = 0;
  for (std::size_t at = log.find("a second sender on the bus"); at != std::string::npos;
       at = log.find("a second sender on the bus", at + 1)) {
    ++lines;
  }
  EXPECT_EQ(lines, 1U) << log;
  EXPECT_NE(log.find("pump tmp1: a second sender on the bus: ID 201 on can0: a frame of the "
                     "gateway's own output ID"),
            std::string::npos)
      << log;
  EXPECT_EQ(g_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kWarning);
  // The heartbeat's ID belongs to no pump: every pump on that interface is warned.
  Frame(t, 0x7F0, 0);
  g_.Advance(t + 1'000, *this);
  EXPECT_TRUE(Warned(1));
}

TEST_F(SecondSender, ForgedHotStatusFramesBetweenTheRealOnesAreCaught) {
  unsigned counter = 0;
  std::int64_t t = Clean(kT0, 5.0, &counter);
  testing::internal::CaptureStderr();
  // The audit's attack: PUMP_STATUS of tmp1 with a 95 degC frame, one between each real one.
  for (int k = 0; k < 500; ++k, t += 10'000) {
    FastI(t, 1, counter);
    FastI(t, 2, counter);
    ++counter;
    if (k % 10 == 0) Status(t + 1'000, 1, 30.0, 0);
    if (k % 10 == 5) Status(t + 1'000, 1, 95.0, 0);
    if (k % 10 == 0) g_.Advance(t + 2'000, *this);
  }
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_TRUE(Warned(0)) << log;
  EXPECT_FALSE(Warned(1));
  EXPECT_NE(log.find("pump tmp1: a second sender on the bus: ID 181 on can0: 20.0 frames/s, where "
                     "its cycle of 100 ms allows 10.0"),
            std::string::npos)
      << log;
}

TEST_F(SecondSender, ARollingCounterThatRepeatsIsCaught) {
  unsigned counter = 0;
  std::int64_t t = Clean(kT0, 5.0, &counter);
  testing::internal::CaptureStderr();
  // A forger sends tmp2's next fast frame ahead of its drive, a few times a second (too few to
  // change the rate): the drive's own frame then repeats the counter.
  for (int k = 0; k < 300; ++k, t += 10'000) {
    FastI(t, 1, counter);
    FastI(t, 2, counter);
    if (k % 30 == 0) FastI(t + 5'000, 2, counter + 1);
    ++counter;
    if (k % 10 == 0) g_.Advance(t + 2'000, *this);
  }
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_TRUE(Warned(1)) << log;
  EXPECT_FALSE(Warned(0));
  EXPECT_NE(log.find("pump tmp2: a second sender on the bus: ID 102 on can0: its rolling counter "
                     "repeated or ran back 3 times within 10 s"),
            std::string::npos)
      << log;
}

}  // namespace
}  // namespace pumptherm::daemon
