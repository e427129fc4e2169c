// PumpWatch: the table `pumptherm watch` prints from the gateway's LCM messages.
#include "tools/pumptherm/watch.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <tuple>

namespace pumptherm::tools {
namespace {

pumptherm::temperatures_t Temps(const std::string& pump) {
  pumptherm::temperatures_t m{};
  m.pump = pump;
  m.winding_resistance_degC = 84.25;
  m.winding_resistance_sd_K = 0.5;
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

/// Columns of a line, "±" counted once (it is one character on a terminal).
std::size_t Columns(const std::string& line) {
  std::size_t n = 0;
  for (char c : line) n += (static_cast<unsigned char>(c) & 0xC0) != 0x80;
  return n;
}

/// pump3 of the demo: tripped, its cooling lost since 2026-01-01 00:04:01 UTC, every condition.
pumptherm::alarm_t TrippedWithEverything(const std::string& pump) {
  pumptherm::alarm_t a = Trip(pump);
  a.conditions[0].value_degC = 121.34;
  a.conditions[0].threshold_degC = 120.0;
  for (int reason : {7, 3, 4, 5, 8}) {
    pumptherm::alarm_condition_t c{};
    c.level = pumptherm::alarm_t::LEVEL_WARNING;
    c.reason = static_cast<std::int8_t>(reason);
    c.node = reason == 4 ? "telemetry" : "frame";
    c.value_degC = std::numeric_limits<double>::quiet_NaN();
    a.conditions.push_back(c);
  }
  a.num_conditions = static_cast<std::int32_t>(a.conditions.size());
  a.time_to_trip_s = 0.0;  // the forecast of a pump already at its trip level
  a.forecast_node = "winding";
  a.mismatch_state = pumptherm::alarm_t::MISMATCH_PLANT_CHANGE;
  a.mismatch_effect = pumptherm::alarm_t::EFFECT_FRAME_AMBIENT_RESISTANCE;
  a.mismatch_value = 20.0;
  a.mismatch_since_utime = 1767225841'000'000;
  return a;
}

class PumpWatchUtc : public testing::Test {
 protected:
  void SetUp() override {
    setenv("TZ", "UTC", 1);
    tzset();
  }
};

TEST_F(PumpWatchUtc, OneLinePerPumpWithinAHundredColumns) {
  PumpWatch w;
  w.OnTemperatures(Temps("pump1"), 1'000'000);
  w.OnAlarm(Trip("pump1"), 1'000'000);
  w.OnTemperatures(Temps("a_pump_with_a_long_name"), 1'000'000);
  w.OnAlarm(TrippedWithEverything("a_pump_with_a_long_name"), 1'000'000);
  const std::string t = w.Table(3'000'000, 15.0);
  std::size_t lines = 0;
  for (std::size_t b = 0, e; b < t.size(); b = e + 1, ++lines) {
    e = t.find('\n', b);
    EXPECT_LE(Columns(t.substr(b, e - b)), kWatchColumns) << t.substr(b, e - b);
  }
  EXPECT_EQ(lines, 3u) << "a header and one line per pump:\n" << t;
  EXPECT_NE(t.find("winding 91.3 ±3.0"), std::string::npos) << t;  // the hottest, +-2 sd
  EXPECT_NE(t.find("TRIP winding latched +5"), std::string::npos) << t;
  EXPECT_NE(t.find("cooling lost since 00:04"), std::string::npos) << t;
  EXPECT_NE(t.find("2 s"), std::string::npos) << t;
  EXPECT_EQ(t.find("trip in"), std::string::npos) << "no time to trip on a tripped pump:\n" << t;
  EXPECT_EQ(t.find("STALE"), std::string::npos) << t;
}

TEST_F(PumpWatchUtc, DetailTellsThePumpsStory) {
  PumpWatch w;
  pumptherm::temperatures_t temps = Temps("pump3");
  temps.magnet_flux_degC = 95.24;
  temps.magnet_flux_sd_K = 2.9;
  w.OnTemperatures(temps, 1'000'000);
  w.OnAlarm(TrippedWithEverything("pump3"), 1'000'000);
  pumptherm::telemetry_t m{};
  m.pump = "pump3";
  m.frame_sensor_degC = 100.70000000000002;
  m.ambient_degC = 22.2;
  m.speed_rpm = 21000;
  m.iq_A = 4.5;
  w.OnTelemetry(m, 1'000'000);
  w.SetMeasuredNode("pump3", "frame");
  const std::string d = w.Detail("pump3", 2'000'000, 15.0);
  for (const char* must :
       {"alarm: TRIP", "TRIP     winding 121.3 degC when raised, level 120 degC, latched",
        "WARNING  forecast (frame)",
        "cause: cooling lost (frame-to-ambient resistance x20 or more) since 2026-01-01 00:04:01 "
        "UTC",
        "frame            40.0 ±0.4      (39.6 to 40.4)", "winding          91.3 ±3.0",
        "frame sensor             100.7 degC", "ambient                  22.2 degC",
        "winding from resistance  84.2 ±1.0 degC (identification tracking)",
        "magnet from flux         95.2 ±5.8 degC"})
    EXPECT_NE(d.find(must), std::string::npos) << must << "\n" << d;
  EXPECT_EQ(d.find("time to trip"), std::string::npos) << "tripped already:\n" << d;

  // A warning with a forecast: the time to trip, in minutes.
  pumptherm::alarm_t a = TrippedWithEverything("pump3");
  a.level = pumptherm::alarm_t::LEVEL_WARNING;
  a.conditions.erase(a.conditions.begin());
  a.time_to_trip_s = 276.2;
  w.OnAlarm(a, 1'000'000);
  const std::string f = w.Detail("pump3", 2'000'000, 15.0);
  EXPECT_NE(f.find("time to trip at the present load: 4 min 36 s (winding)"), std::string::npos)
      << f;
  EXPECT_NE(f.find("WARNING  trip in 4 min 36 s"), std::string::npos) << f;
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
  EXPECT_EQ(AlarmReasonLabel(200), "reason 200");
  EXPECT_EQ(IdentStatusName(99), "code 99");
  EXPECT_EQ(AlarmReasonLabel(4), "stale telemetry");
  EXPECT_EQ(IdentStatusName(3), "not identifiable");
}

#ifdef PUMPTHERM_CLI
TEST(PumpthermWatchCli, SaysNothingWasHeardAndExitsOne) {
  const std::string cmd =
      std::string(PUMPTHERM_CLI) + " watch --url memq:// --period-s 0.05 --count 2 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[256];
  while (fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  EXPECT_EQ(WEXITSTATUS(status), 1) << out;
  EXPECT_NE(out.find("no pumptherm messages yet"), std::string::npos) << out;
}

/// Runs `pumptherm watch ARGS`; returns the exit status and the output (both streams).
std::pair<int, std::string> Watch(const std::string& args) {
  FILE* p = popen((std::string(PUMPTHERM_CLI) + " watch " + args + " 2>&1").c_str(), "r");
  std::string out;
  char buf[256];
  while (p != nullptr && fgets(buf, sizeof buf, p)) out += buf;
  const int status = p != nullptr ? pclose(p) : -1;
  return {WEXITSTATUS(status), out};
}

// The URL and prefix come from the gateway's configuration, as for clear-trip.
TEST(PumpthermWatchCli, ReadsTheGatewaysConfiguration) {
  const std::string dir = testing::TempDir() + "watch_cli_" + std::to_string(getpid());
  std::filesystem::create_directories(dir);
  {
    std::ifstream in(std::string(PUMPTHERM_SOURCE_DIR) + "/tools/demo/pumpthermd-demo.toml");
    std::ofstream out(dir + "/gw.toml");
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("url = ", 0) == 0) line = "url = \"memq://\"";
      if (line.rfind("channel_prefix = ", 0) == 0) line = "channel_prefix = \"HALL_B\"";
      out << line << "\n";
    }
  }
  auto [code, out] = Watch("-c " + dir + "/gw.toml --period-s 0.05 --count 1");
  EXPECT_EQ(code, 1) << out;
  EXPECT_NE(out.find("watching HALL_B on memq://"), std::string::npos) << out;
  // Without the configuration and without --url: exit 2, naming the file and what to give.
  std::tie(code, out) = Watch("-c " + dir + "/absent.toml --count 1");
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("absent.toml"), std::string::npos) << out;
  EXPECT_NE(out.find("give --url"), std::string::npos) << out;
  // The option's earlier name still works, and says the new one.
  std::tie(code, out) = Watch("-c " + dir +
                              "/absent.toml --lcm-url memq:// --period-s 0.05 "
                              "--count 1");
  EXPECT_EQ(code, 1) << out;
  EXPECT_NE(out.find("--lcm-url is now called --url"), std::string::npos) << out;
  std::filesystem::remove_all(dir);
}
#endif

}  // namespace
}  // namespace pumptherm::tools
