// The gateway's time-driven work runs when it is due (Gateway::NextDueUs): a caller that advances
// it only at its next due time gets every periodic output on its grid, none late or missing; a
// first frame from a pump makes work due at once; an Advance before the due time sends nothing.
// The byte-for-byte equality with advancing after every frame is offline_golden's.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"

namespace pumptherm::daemon {
namespace {

struct CountingSink : OutputSink {
  std::vector<std::pair<std::int64_t, std::uint32_t>> frames;  // time, CAN ID
  std::vector<std::pair<std::int64_t, std::string>> lcm;       // time, channel
  void SendFrame(std::size_t, std::int64_t t, const protocol::CanFrame& f) override {
    frames.emplace_back(t, f.id);
  }
  bool PublishLcm(const std::string& channel, std::int64_t t,
                  const std::vector<std::uint8_t>&) override {
    lcm.emplace_back(t, channel);
    return true;
  }
};

// Two pumps on can0 that are never heard from: after stale_after_s each raises stale telemetry,
// and from then on only its alarm frame (GW_ALARM, 100 ms) and LCM messages go out.
const char* kConfig = R"(
[gateway]
heartbeat_period_s = 0

[lcm]
period_s = 1.0
health_period_s = 5.0

[alarms]
stale_after_s = 2.0

[[can]]
interface = "can0"

[[pump]]
name = "p1"
node_id = 1
motor = "han2019-tmp"
thermal_model = "tmp-generic"

[[pump]]
name = "p2"
node_id = 2
motor = "han2019-tmp"
thermal_model = "tmp-generic"
)";

constexpr std::uint32_t kGwAlarmId = 0x200;  // GW_ALARM (BO_ 512) + node ID
constexpr std::int64_t kAlarmPeriodUs = 100'000;

TEST(Scheduling, AdvancingOnlyAtTheNextDueTimeKeepsEveryOutputOnItsGrid) {
  Gateway g(ParseConfig(kConfig, "scheduling.toml"));
  CountingSink sink;
  EXPECT_EQ(g.NextDueUs(), std::numeric_limits<std::int64_t>::min());
  std::int64_t now = 0;
  int advances = 0;
  while (now <= 20'000'000) {
    g.Advance(now, sink);
    ++advances;
    const std::int64_t due = g.NextDueUs();
    ASSERT_GT(due, now) << "after Advance(" << now << ") work is still due";
    const std::size_t frames = sink.frames.size(), messages = sink.lcm.size();
    g.Advance(due - 1, sink);  // before the due time: nothing
    ASSERT_EQ(sink.frames.size(), frames) << "a frame sent before the due time " << due;
    ASSERT_EQ(sink.lcm.size(), messages) << "an LCM message sent before the due time " << due;
    now = due;
  }
  // Each pump's alarm frames once the stale alarm stands (raised at 5 s: stale_after_s and the
  // alarm hold; before it, a frame goes out with each change of the alarm state): every 100 ms
  // without a gap to the end.
  for (std::uint32_t node : {1U, 2U}) {
    std::vector<std::int64_t> times;
    for (const auto& [t, id] : sink.frames) {
      if (id == kGwAlarmId + node && t >= 6'000'000) times.push_back(t);
    }
    ASSERT_FALSE(times.empty()) << "node " << node << ": no stale alarm in 20 s";
    EXPECT_LT(times.front(), 6'000'000 + kAlarmPeriodUs) << "node " << node;
    for (std::size_t k = 1; k < times.size(); ++k) {
      ASSERT_EQ(times[k] - times[k - 1], kAlarmPeriodUs)
          << "node " << node << ": frame " << k << " at " << times[k];
    }
    EXPECT_GE(times.back(), 20'000'000 - kAlarmPeriodUs) << "node " << node << ": frames stopped";
  }
  // The health message every 5 s from the first Advance.
  std::vector<std::int64_t> health;
  for (const auto& [t, channel] : sink.lcm) {
    if (channel.find("HEALTH") != std::string::npos) health.push_back(t);
  }
  EXPECT_EQ(health, (std::vector<std::int64_t>{0, 5'000'000, 10'000'000, 15'000'000, 20'000'000}));
  // Far fewer calls than a 10 ms tick would make (2001 in 20 s): at most 2 pumps x 10 Hz alarm
  // frames, their thermal-period checks and LCM, and the health message.
  EXPECT_LT(advances, 450) << advances;
}

TEST(Scheduling, AFirstFrameFromAPumpMakesWorkDueAtOnce) {
  Gateway g(ParseConfig(kConfig, "scheduling.toml"));
  CountingSink sink;
  g.Advance(0, sink);
  ASSERT_GT(g.NextDueUs(), 0);
  const std::size_t can0 = g.Interface("can0");
  protocol::TimedFrame status;  // PUMP_STATUS of node 1, all zero
  status.time_us = 10'000;
  status.frame.id = 0x180 + 1;
  status.frame.len = 8;
  g.OnFrame(can0, status);
  EXPECT_EQ(g.NextDueUs(), std::numeric_limits<std::int64_t>::min());
  g.Advance(10'000, sink);
  EXPECT_GT(g.NextDueUs(), 10'000);
  // A second frame of the same pump brings nothing due.
  const std::int64_t due = g.NextDueUs();
  status.time_us = 20'000;
  g.OnFrame(can0, status);
  EXPECT_EQ(g.NextDueUs(), due);
}

}  // namespace
}  // namespace pumptherm::daemon
