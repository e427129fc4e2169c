// The safety state (docs/daemon.md, "State across restarts"): latched trips and clear counters
// in a file of their own whose damage is found by its checksum; a gateway whose safety state
// was lost latches every pump with "safety state lost" and refuses clear commands signed
// before it started; the saved latches override the estimator state's.
#include "daemon/safety_state.hpp"

#include <gtest/gtest.h>

#include <string>

#include "daemon/alarm_clear_auth.hpp"
#include "daemon/config.hpp"
#include "daemon/gateway.hpp"

namespace pumptherm::daemon {
namespace {

constexpr std::int64_t kStateNowUs = 1'763'776'803'000'000;

SafetyState Sample() {
  SafetyState s;
  s.latched["tmp1"] = {{"winding", 131.25}, {"sensor", 90.0}};
  s.latched["tmp-2"] = {};
  s.counters["tmp1"]["0123456789abcdef"] = kStateNowUs + 5;
  s.counters["tmp1"]["shared:operator"] = 17;
  s.refused_up_to_us = kStateNowUs - 60'000'000;
  return s;
}

TEST(SafetyState, RoundTripsThroughItsText) {
  const std::string text = FormatSafetyState(Sample());
  std::string problem;
  const auto back = ParseSafetyState(text, &problem);
  ASSERT_TRUE(back) << problem << "\n" << text;
  ASSERT_EQ(back->latched.at("tmp1").size(), 2U);
  EXPECT_EQ(back->latched.at("tmp1")[0].node, "winding");
  EXPECT_EQ(back->latched.at("tmp1")[0].value_degC, 131.25);
  EXPECT_EQ(back->latched.at("tmp1")[1].node, "sensor");
  EXPECT_TRUE(back->latched.at("tmp-2").empty());
  EXPECT_EQ(back->counters.at("tmp1").at("0123456789abcdef"), kStateNowUs + 5);
  EXPECT_EQ(back->counters.at("tmp1").at("shared:operator"), 17);
  EXPECT_EQ(back->refused_up_to_us, kStateNowUs - 60'000'000);
}

TEST(SafetyState, DamageIsFoundNotGuessed) {
  const std::string text = FormatSafetyState(Sample());
  std::string problem;
  // One byte changed where TOML would still parse: a latch gone, a counter lowered.
  std::string flipped = text;
  const std::size_t at = flipped.find("winding");
  ASSERT_NE(at, std::string::npos);
  flipped[at] = 'W';
  EXPECT_FALSE(ParseSafetyState(flipped, &problem));
  EXPECT_NE(problem.find("checksum does not match"), std::string::npos) << problem;
  // Cut short (a write that stopped halfway, were it not atomic).
  EXPECT_FALSE(ParseSafetyState(text.substr(0, text.size() / 2), &problem));
  EXPECT_NE(problem.find("no checksum line"), std::string::npos) << problem;
  EXPECT_FALSE(ParseSafetyState("", &problem));
  EXPECT_FALSE(ParseSafetyState("version = 1\n", &problem));
}

TEST(SafetyState, AnEarlierVersionsStateFileIsRecognised) {
  EXPECT_TRUE(WrittenBeforeSafetyFile("version = 2\n[clear_auth]\nversion = 1\n"));
  EXPECT_FALSE(WrittenBeforeSafetyFile("version = 2\n[pump]\n"));
  EXPECT_FALSE(WrittenBeforeSafetyFile("not toml ["));
}

class LostSafetyStateTest : public ::testing::Test, public OutputSink {
 protected:
  static DaemonConfig Config(const std::string& lost) {
    return ParseConfig(
        "[gateway]\nheartbeat_period_s = 0\nlost_safety_state = \"" + lost +
            "\"\n[alarms]\n[[alarms.clear_operators]]\nname = \"alice\"\npublic_key = \"" +
            FormatPublicKey(Op().public_key()) +
            "\"\n[[can]]\ninterface = \"can0\"\n[[pump]]\nname = \"tmp1\"\nnode_id = 1\n"
            "[[pump]]\nname = \"tmp2\"\nnode_id = 2\n",
        std::string(PUMPTHERM_SOURCE_DIR) + "/c.toml");
  }
  static SigningKey Op() { return SigningKey(Seed{1, 2, 3}); }
  static SigningKey Gw() { return SigningKey(Seed{9, 9, 9}); }
  static pumptherm::alarm_clear_t Signed(std::int64_t utime, const std::string& node = "") {
    pumptherm::alarm_clear_t m;
    m.utime = utime;
    m.gateway = "pumptherm";
    m.pump = "tmp1";
    m.node = node;
    m.comment = "";
    m.counter = utime;
    SignCommand(Op(), Gw().public_key(), "PUMPTHERM", m);
    return m;
  }
  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
  bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
    return true;
  }
  static std::vector<std::string> Latched(const Gateway& g, std::size_t p) {
    std::vector<std::string> out;
    for (const auto& t : g.pumps()[p]->Save().latched_trips) out.push_back(t.node);
    return out;
  }
};

TEST_F(LostSafetyStateTest, EveryPumpStartsLatchedAndOldCommandsCannotReplay) {
  Gateway g(Config("latch"));
  g.SetGatewayKey(Gw());
  g.LoadClearKeys("");
  testing::internal::CaptureStderr();
  g.SafetyStateLost("safety.toml is missing, while state.toml is there", 0, kStateNowUs);
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_NE(log.find("pump tmp1: latched trip 'safety state lost': safety.toml is missing"),
            std::string::npos)
      << log;
  for (std::size_t p = 0; p < 2; ++p) {
    EXPECT_EQ(Latched(g, p), std::vector<std::string>{"safety_state_lost"});
    const auto& a = g.pumps()[p]->snapshot().alarm;
    EXPECT_EQ(a.level, estimators::AlarmLevel::kTrip);
    EXPECT_EQ(a.reason, estimators::AlarmReason::kSafetyStateLost);
    EXPECT_TRUE(a.trip_latched);
  }
  // A command captured before the start (inside its window, counter never seen): refused.
  const auto captured = Signed(kStateNowUs - 5'000'000);
  EXPECT_FALSE(g.ClearFromLcm(&captured, kStateNowUs, *this));
  EXPECT_EQ(Latched(g, 0), std::vector<std::string>{"safety_state_lost"});
  // A fresh one, after the pump was checked, clears that latch by name.
  const auto fresh = Signed(kStateNowUs + 1'000'000, "safety_state_lost");
  EXPECT_TRUE(g.ClearFromLcm(&fresh, kStateNowUs + 1'000'000, *this));
  EXPECT_TRUE(Latched(g, 0).empty());
  EXPECT_EQ(Latched(g, 1), std::vector<std::string>{"safety_state_lost"});
  // The latch is part of the safety state (so a second restart keeps it).
  const SafetyState s = g.CollectSafetyState();
  ASSERT_EQ(s.latched.at("tmp2").size(), 1U);
  EXPECT_EQ(s.latched.at("tmp2")[0].node, "safety_state_lost");
  EXPECT_EQ(s.refused_up_to_us, kStateNowUs);
}

TEST_F(LostSafetyStateTest, WarnOnlyLeavesThePumpsUnlatchedButStillRefusesOldCommands) {
  Gateway g(Config("warn"));
  g.SetGatewayKey(Gw());
  g.LoadClearKeys("");
  testing::internal::CaptureStderr();
  g.SafetyStateLost("safety.toml is damaged", 0, kStateNowUs);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("lost_safety_state = \"warn\""),
            std::string::npos);
  EXPECT_TRUE(Latched(g, 0).empty());
  EXPECT_EQ(g.clear_auth().refused_up_to_us(), kStateNowUs);
}

TEST_F(LostSafetyStateTest, TheSavedLatchesOverrideTheEstimatorStates) {
  Gateway g(Config("latch"));
  SafetyState s;
  s.latched["tmp1"] = {{"sensor", 95.0}};
  s.latched["tmp2"] = {{"no_such_node", 95.0}};  // the model changed since: latched as lost
  s.counters["tmp1"]["abc"] = 42;
  testing::internal::CaptureStderr();
  g.ApplySafetyState(s, 0);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("tmp2"), std::string::npos);
  EXPECT_EQ(Latched(g, 0), std::vector<std::string>{"sensor"});
  EXPECT_EQ(Latched(g, 1), std::vector<std::string>{"safety_state_lost"});
  EXPECT_EQ(g.clear_auth().last_counter("tmp1", "abc"), 42);
  // A saved state with nothing latched for tmp1 clears a latch the estimator state restored.
  s.latched["tmp1"] = {};
  g.ApplySafetyState(s, 0);
  EXPECT_TRUE(Latched(g, 0).empty());
}

}  // namespace
}  // namespace pumptherm::daemon
