// Publish/subscribe of every pumptherm LCM type through LCM's in-process memq:// provider
// (LCM 1.3: handler class methods, handleTimeout), on the channels of docs/lcm.md.

#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>
#include <string>
#include <vector>

#include "lcm_test_messages.hpp"

namespace pumptherm::test {
namespace {

/// Collects what arrives, one vector per type, with the channel it came on.
class Collector {
 public:
  void OnTelemetry(const lcm::ReceiveBuffer*, const std::string& channel, const telemetry_t* m) {
    telemetry.push_back(*m);
    channels.push_back(channel);
  }
  void OnTemperatures(const lcm::ReceiveBuffer*, const std::string& channel,
                      const temperatures_t* m) {
    temperatures.push_back(*m);
    channels.push_back(channel);
  }
  void OnAlarm(const lcm::ReceiveBuffer*, const std::string& channel, const alarm_t* m) {
    alarms.push_back(*m);
    channels.push_back(channel);
  }
  void OnAlarmClear(const lcm::ReceiveBuffer*, const std::string& channel, const alarm_clear_t* m) {
    clears.push_back(*m);
    channels.push_back(channel);
  }
  void OnGatewayHealth(const lcm::ReceiveBuffer*, const std::string& channel,
                       const gateway_health_t* m) {
    health.push_back(*m);
    channels.push_back(channel);
  }

  std::size_t Count() const { return channels.size(); }

  std::vector<telemetry_t> telemetry;
  std::vector<temperatures_t> temperatures;
  std::vector<alarm_t> alarms;
  std::vector<alarm_clear_t> clears;
  std::vector<gateway_health_t> health;
  std::vector<std::string> channels;
};

/// Dispatches until `expected` messages arrived or a handleTimeout() finds nothing for 1 s.
void Drain(lcm::LCM& lcm, const Collector& collector, std::size_t expected) {
  while (collector.Count() < expected) {
    const int status = lcm.handleTimeout(1000);
    ASSERT_GE(status, 0) << "handleTimeout failed";
    if (status == 0) {
      return;  // timed out: the caller's count check reports what is missing
    }
  }
}

TEST(LcmMemq, EveryTypeArrivesOnItsChannel) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  Collector collector;
  ASSERT_NE(lcm.subscribe("PUMPTHERM/tmp-07/TELEMETRY", &Collector::OnTelemetry, &collector),
            nullptr);
  ASSERT_NE(lcm.subscribe("PUMPTHERM/tmp-07/TEMPS", &Collector::OnTemperatures, &collector),
            nullptr);
  ASSERT_NE(lcm.subscribe("PUMPTHERM/tmp-07/ALARM", &Collector::OnAlarm, &collector), nullptr);
  ASSERT_NE(lcm.subscribe("PUMPTHERM/tmp-07/ALARM_CLEAR", &Collector::OnAlarmClear, &collector),
            nullptr);
  ASSERT_NE(lcm.subscribe("PUMPTHERM/GATEWAY/HEALTH", &Collector::OnGatewayHealth, &collector),
            nullptr);

  const telemetry_t telemetry = SampleTelemetry();
  const temperatures_t temperatures = SampleTemperatures();
  const alarm_t alarm = SampleAlarm(2);
  const alarm_clear_t clear = SampleAlarmClear();
  const gateway_health_t health = SampleGatewayHealth(2);
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/TELEMETRY", &telemetry), 0);
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/TEMPS", &temperatures), 0);
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/ALARM", &alarm), 0);
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/ALARM_CLEAR", &clear), 0);
  ASSERT_EQ(lcm.publish("PUMPTHERM/GATEWAY/HEALTH", &health), 0);
  // Nobody subscribes to another pump's channel: it must not reach any handler.
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-08/TEMPS", &temperatures), 0);

  Drain(lcm, collector, 5);
  EXPECT_EQ(lcm.handleTimeout(50), 0) << "a message arrived that nobody subscribed to";

  ASSERT_EQ(collector.telemetry.size(), 1U);
  ASSERT_EQ(collector.temperatures.size(), 1U);
  ASSERT_EQ(collector.alarms.size(), 1U);
  ASSERT_EQ(collector.clears.size(), 1U);
  ASSERT_EQ(collector.health.size(), 1U);
  ExpectSame(telemetry, collector.telemetry[0]);
  ExpectSame(temperatures, collector.temperatures[0]);
  ExpectSame(alarm, collector.alarms[0]);
  ExpectSame(clear, collector.clears[0]);
  ExpectSame(health, collector.health[0]);
  EXPECT_EQ(collector.channels,
            (std::vector<std::string>{"PUMPTHERM/tmp-07/TELEMETRY", "PUMPTHERM/tmp-07/TEMPS",
                                      "PUMPTHERM/tmp-07/ALARM", "PUMPTHERM/tmp-07/ALARM_CLEAR",
                                      "PUMPTHERM/GATEWAY/HEALTH"}));
}

// A subscriber of many pumps uses a channel regular expression; order and content survive a burst.
TEST(LcmMemq, RegexSubscriptionReceivesEveryPumpInOrder) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  Collector collector;
  ASSERT_NE(lcm.subscribe("PUMPTHERM/.*/TEMPS", &Collector::OnTemperatures, &collector), nullptr);

  constexpr int kPumps = 32;
  for (int i = 0; i < kPumps; ++i) {
    temperatures_t m = SampleTemperatures();
    m.pump = "tmp-" + std::to_string(i);
    m.utime += i;
    ASSERT_EQ(lcm.publish("PUMPTHERM/" + m.pump + "/TEMPS", &m), 0);
  }
  Drain(lcm, collector, kPumps);
  ASSERT_EQ(collector.temperatures.size(), static_cast<std::size_t>(kPumps));
  for (int i = 0; i < kPumps; ++i) {
    const std::string pump = "tmp-" + std::to_string(i);
    EXPECT_EQ(collector.temperatures[static_cast<std::size_t>(i)].pump, pump);
    EXPECT_EQ(collector.channels[static_cast<std::size_t>(i)], "PUMPTHERM/" + pump + "/TEMPS");
  }
}

// A message of another type on a subscribed channel fails to decode: the typed handler is not
// called with garbage.
TEST(LcmMemq, WrongTypeOnAChannelIsNotDelivered) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  Collector collector;
  ASSERT_NE(lcm.subscribe("PUMPTHERM/tmp-07/ALARM_CLEAR", &Collector::OnAlarmClear, &collector),
            nullptr);
  const alarm_t alarm = SampleAlarm(1);
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/ALARM_CLEAR", &alarm), 0);
  const alarm_clear_t clear = SampleAlarmClear();
  ASSERT_EQ(lcm.publish("PUMPTHERM/tmp-07/ALARM_CLEAR", &clear), 0);
  // The first handle() dispatches the undecodable message (handler skipped), the second the good
  // one.
  for (int i = 0; i < 2; ++i) {
    ASSERT_GT(lcm.handleTimeout(1000), 0);
  }
  ASSERT_EQ(collector.clears.size(), 1U);
  ExpectSame(clear, collector.clears[0]);
}

}  // namespace
}  // namespace pumptherm::test
