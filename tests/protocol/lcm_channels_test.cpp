// Channel names of protocol/lcm/channels.hpp: building, validating, parsing, and the all-pumps
// pattern checked against LCM's own channel matching over memq://.

#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>
#include <pumptherm/alarm_clear_t.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "protocol/lcm/channels.hpp"

namespace pumptherm::lcm_channels {
namespace {

TEST(LcmChannels, NamesFollowTheDocumentedScheme) {
  EXPECT_EQ(PumpChannelName(kDefaultPrefix, "tmp1", PumpChannel::kTelemetry),
            "PUMPTHERM/tmp1/TELEMETRY");
  EXPECT_EQ(PumpChannelName(kDefaultPrefix, "tmp1", PumpChannel::kTemperatures),
            "PUMPTHERM/tmp1/TEMPS");
  EXPECT_EQ(PumpChannelName(kDefaultPrefix, "tmp1", PumpChannel::kAlarm), "PUMPTHERM/tmp1/ALARM");
  EXPECT_EQ(PumpChannelName(kDefaultPrefix, "tmp1", PumpChannel::kAlarmClear),
            "PUMPTHERM/tmp1/ALARM_CLEAR");
  EXPECT_EQ(GatewayHealthChannelName(kDefaultPrefix), "PUMPTHERM/GATEWAY/HEALTH");
  EXPECT_EQ(PumpChannelName("SITE.1/PT", "line-2_a", PumpChannel::kTemperatures),
            "SITE.1/PT/line-2_a/TEMPS");
}

TEST(LcmChannels, InvalidNamesAreRefusedWithTheName) {
  for (const std::string& pump : std::vector<std::string>{
           "", "GATEWAY", "a/b", "tmp 1", "pump\xc3\xa4", "a*", std::string(65, 'p')}) {
    EXPECT_FALSE(IsValidPumpName(pump)) << pump;
    try {
      PumpChannelName(kDefaultPrefix, pump, PumpChannel::kAlarm);
      ADD_FAILURE() << "no exception for pump '" << pump << "'";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find("'" + pump + "'"), std::string::npos)
          << error.what();
    }
  }
  EXPECT_TRUE(IsValidPumpName(std::string(64, 'p')));
  for (const std::string& prefix :
       std::vector<std::string>{"", "/", "A/", "/A", "A//B", "A B", "A+"}) {
    EXPECT_FALSE(IsValidPrefix(prefix)) << prefix;
    EXPECT_THROW(GatewayHealthChannelName(prefix), std::invalid_argument) << prefix;
    EXPECT_THROW(AllPumpsPattern(prefix, PumpChannel::kAlarm), std::invalid_argument) << prefix;
  }
  EXPECT_TRUE(IsValidPrefix("SITE.1/GATEWAY/PT"));
}

TEST(LcmChannels, ParseInvertsPumpChannelName) {
  for (const PumpChannel c :
       {PumpChannel::kTelemetry, PumpChannel::kTemperatures, PumpChannel::kAlarm,
        PumpChannel::kAlarmClear, PumpChannel::kAlarmClearReply}) {
    const auto parsed = ParsePumpChannel("SITE.1/PT", PumpChannelName("SITE.1/PT", "tmp-7", c));
    ASSERT_TRUE(parsed.has_value());
    EXPECT_EQ(parsed->pump, "tmp-7");
    EXPECT_EQ(parsed->channel, c);
  }
  for (const char* other : {"PUMPTHERM/GATEWAY/HEALTH", "PUMPTHERM/tmp1/HEALTH", "PUMPTHERM/tmp1",
                            "PUMPTHERM/tmp1/TEMPS/x", "PUMPTHERMX/tmp1/TEMPS", "OTHER/tmp1/TEMPS",
                            "PUMPTHERM//TEMPS", "PUMPTHERM", ""}) {
    EXPECT_FALSE(ParsePumpChannel(kDefaultPrefix, other).has_value()) << other;
  }
}

/// Records channel names (LCM 1.3 subscribeFunction: a plain function and a context pointer).
void Record(const lcm::ReceiveBuffer*, const std::string& channel,
            std::vector<std::string>* received) {
  received->push_back(channel);
}

// The pattern goes through LCM's own regular-expression matching: every pump's channel and
// nothing else, '.' in the prefix taken literally.
TEST(LcmChannels, AllPumpsPatternMatchesInLcm) {
  const std::string prefix = "SITE.1/PT";
  const std::string pattern = AllPumpsPattern(prefix, PumpChannel::kAlarmClear);
  EXPECT_EQ(pattern, "SITE\\.1/PT/[^/]+/ALARM_CLEAR");

  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  std::vector<std::string> received;
  ASSERT_NE(lcm.subscribeFunction(pattern, &Record, &received), nullptr);
  const std::vector<std::string> matching{
      PumpChannelName(prefix, "tmp1", PumpChannel::kAlarmClear),
      PumpChannelName(prefix, "line-2.b", PumpChannel::kAlarmClear)};
  const std::vector<std::string> not_matching{
      "SITEx1/PT/tmp1/ALARM_CLEAR",
      "SITE.1/PT/tmp1/ALARM",
      "SITE.1/PT/a/b/ALARM_CLEAR",
      "SITE.1/PT/tmp1/ALARM_CLEAR2",
      "X/SITE.1/PT/tmp1/ALARM_CLEAR",
      PumpChannelName(prefix, "tmp1", PumpChannel::kAlarmClearReply)};
  pumptherm::alarm_clear_t message;
  message.utime = 1;
  for (const std::string& channel : not_matching) {
    ASSERT_EQ(lcm.publish(channel, &message), 0);
  }
  for (const std::string& channel : matching) {
    ASSERT_EQ(lcm.publish(channel, &message), 0);
  }
  while (received.size() < matching.size() && lcm.handleTimeout(1000) > 0) {
  }
  EXPECT_EQ(lcm.handleTimeout(50), 0) << "more messages matched than expected";
  EXPECT_EQ(received, matching);
}

}  // namespace
}  // namespace pumptherm::lcm_channels
