// PumpWatch: the table `pumptherm watch` prints from the gateway's LCM messages.
#include "tools/pumptherm/watch.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace pumptherm::tools {
namespace {

pumptherm::temperatures_t Temps(const std::string& pump) {
  pumptherm::temperatures_t m{};
  m.pump = pump;
  m.resistance_winding_degC = 84.25;
  m.resistance_winding_sd_K = 0.5;
  m.ident_status = 2;
  m.num_nodes = 2;
  m.node_names = {"frame", "winding"};
  m.node_degC = {40.04, 91.26};
  m.node_sd_K = {0.2, 1.5};
  m.nis = 0.7;
  m.filter_status = pumptherm::temperatures_t::FILTER_TRACKING;
  return m;
}

pumptherm::alarm_t Trip(const std::string& pump) {
  pumptherm::alarm_t a{};
  a.pump = pump;
  a.level = pumptherm::alarm_t::LEVEL_TRIP;
  a.time_to_trip_s = std::numeric_limits<double>::infinity();
  pumptherm::alarm_condition_t c{};
  c.level = pumptherm::alarm_t::LEVEL_TRIP;
  c.reason = 1;
  c.node = "winding";
  c.latched = true;
  a.conditions.push_back(c);
  a.num_conditions = 1;
  return a;
}

TEST(PumpWatch, ShowsEveryNodeWithItsBandAndTheAlarmByName) {
  PumpWatch w;
  w.OnTemperatures(Temps("pump1"), 1'000'000);
  w.OnAlarm(Trip("pump1"), 1'000'000);
  const std::string t = w.Table(3'000'000, 15.0);
  EXPECT_NE(t.find("pump1"), std::string::npos) << t;
  EXPECT_NE(t.find("frame 40.0±0.4"), std::string::npos) << t;
  EXPECT_NE(t.find("winding 91.3±3.0"), std::string::npos) << t;
  EXPECT_NE(t.find("84.2±1.0 (tracking)"), std::string::npos) << t;
  EXPECT_NE(t.find("TRIP [TRIP estimated_over_temperature winding LATCHED]"), std::string::npos)
      << t;
  EXPECT_NE(t.find(" 2s "), std::string::npos) << t;
  EXPECT_EQ(t.find("STALE"), std::string::npos) << t;
}

TEST(PumpWatch, MarksASilentPumpStaleAndSortsByName) {
  PumpWatch w;
  w.OnTemperatures(Temps("pump2"), 0);
  w.OnTemperatures(Temps("pump1"), 20'000'000);
  const std::string t = w.Table(21'000'000, 15.0);
  const auto p1 = t.find("pump1"), p2 = t.find("pump2");
  ASSERT_NE(p1, std::string::npos);
  ASSERT_NE(p2, std::string::npos);
  EXPECT_LT(p1, p2) << t;
  EXPECT_EQ(t.find("STALE"), t.find("STALE", p2)) << "only pump2 is stale:\n" << t;
  EXPECT_NE(t.find("STALE", p2), std::string::npos) << t;
}

TEST(PumpWatch, UnknownCodesAreShownAsNumbersNotHidden) {
  EXPECT_EQ(AlarmReasonLabel(200), "reason200");
  EXPECT_EQ(IdentStatusName(99), "code99");
}

#ifdef PUMPTHERM_CLI
TEST(PumpthermWatchCli, SaysNothingWasHeardAndExitsOne) {
  const std::string cmd =
      std::string(PUMPTHERM_CLI) + " watch --lcm-url memq:// --period-s 0.05 --count 2 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[256];
  while (fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  EXPECT_EQ(WEXITSTATUS(status), 1) << out;
  EXPECT_NE(out.find("no pumptherm messages yet"), std::string::npos) << out;
}
#endif

}  // namespace
}  // namespace pumptherm::tools
